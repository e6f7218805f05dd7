"""The N-frame window dataset: numpy core, and the PyTorch wrapper where torch is installed."""

from __future__ import annotations

import pickle
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from pedscan_data import PedscanError, TorchWindowDataset, WindowDataset, class_weight, open_sequences


def test_windows_stay_inside_their_sequence(sample: Path) -> None:
    ds = WindowDataset(sample, length=3)
    assert len(ds) == 4
    assert [(ds[i]["sequence"], ds[i]["frame"]) for i in range(len(ds))] == [(0, 2), (0, 3), (1, 2), (1, 3)]
    strided = WindowDataset(sample, length=2, stride=2)
    assert [(w["sequence"], w["frame"]) for w in (strided[i] for i in range(len(strided)))] == [
        (0, 1), (0, 3), (1, 1), (1, 3)
    ]
    assert len(WindowDataset(sample, length=5)) == 0
    assert len(WindowDataset(sample / "seq_000001.h5", length=4)) == 1


def test_window_holds_n_ranges_and_the_last_frames_targets(sample: Path) -> None:
    ds = WindowDataset(sample, length=3)
    item = ds[3]
    with h5py.File(sample / "seq_000001.h5", "r") as f:
        assert item["range"].shape == (3, 16, 512) and item["range"].dtype == np.float32
        np.testing.assert_array_equal(item["range"], f["range"][1:4])
        np.testing.assert_array_equal(item["label"], f["label"][3])
        np.testing.assert_array_equal(item["velocity"], f["velocity"][3])
        assert item["velocity"].shape == (16, 512, 3)
        assert "instance" not in item
        with_instance = WindowDataset(sample, length=3, targets=("label", "instance"))[3]
        np.testing.assert_array_equal(with_instance["instance"], f["instance"][3])


def test_lengths_and_strides_below_one_are_refused_and_one_is_a_single_frame(sample: Path) -> None:
    for length, stride in ((0, 1), (1, 0), (0, 0), (-2, 1)):
        with pytest.raises(ValueError, match="length and stride must be at least 1"):
            WindowDataset(sample, length=length, stride=stride)
    single = WindowDataset(sample, length=1)
    assert len(single) == 8
    with h5py.File(sample / "seq_000001.h5", "r") as f:
        item = single[6]
        assert (item["sequence"], item["frame"]) == (1, 2) and item["range"].shape == (1, 16, 512)
        np.testing.assert_array_equal(item["range"][0], f["range"][2])


def test_a_list_of_open_sequences_is_used_as_given(sample: Path) -> None:
    sequences = open_sequences(sample)
    ds = WindowDataset(sequences, length=2)
    assert ds.sequences is sequences
    np.testing.assert_array_equal(ds[4]["range"], WindowDataset(sample, length=2)[4]["range"])


def test_class_weight_is_background_over_human_beams(sample: Path) -> None:
    label = np.array([[1, 1, 0, 0], [0, 0, 0, 0], [1, 0, 0, 0]], np.uint8)
    range_m = np.array([[2, 3, 4, 5], [6, 7, 8, 9], [0, 0, 1, 1]], np.float32)
    assert class_weight(label, range_m) == 8 / 2  # the human beam without a return is left out
    assert class_weight(np.zeros_like(label), range_m) == 1.0
    ds = WindowDataset(sample, length=2)
    with h5py.File(sample / "seq_000000.h5", "r") as f:

        def expected(t: int) -> float:
            r, lab = f["range"][t], f["label"][t]
            humans = np.count_nonzero((r > 0) & (lab == 1))
            return (np.count_nonzero(r > 0) - humans) / humans

        for i in range(3):
            assert ds[i]["class_weight"] == pytest.approx(expected(i + 1), rel=1e-6)
            assert ds[i]["class_weight"].dtype == np.float32
        # In a longer window, of its last frame alone (frame 3 of frames 1-3).
        assert WindowDataset(sample, length=3)[1]["class_weight"] == pytest.approx(expected(3), rel=1e-6)


def test_missing_target_is_named(sample_minimal: Path) -> None:
    with pytest.raises(PedscanError, match=r"seq_000000\.h5: no dataset /velocity"):
        WindowDataset(sample_minimal, length=2)
    assert WindowDataset(sample_minimal, length=2, targets=("label",))[0]["range"].shape == (2, 32, 1024)


def test_pickles_for_spawned_workers(sample: Path) -> None:
    ds = WindowDataset(sample, length=2)
    before = ds[1]
    ds[5]  # leaves both files open
    again = pickle.loads(pickle.dumps(ds))
    np.testing.assert_array_equal(again[1]["range"], before["range"])


def test_torch_dataset_without_torch_says_so(sample: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "torch", None)
    with pytest.raises(ImportError, match=r"^TorchWindowDataset needs PyTorch \(pip install torch; .* as numpy arrays$"):
        TorchWindowDataset(sample, length=2)


def test_torch_dataset_batches(sample: Path) -> None:
    import torch  # installed by the test extra: this test never skips
    ds = TorchWindowDataset(sample, length=3)
    batch = next(iter(torch.utils.data.DataLoader(ds, batch_size=4)))
    assert batch["range"].shape == (4, 3, 16, 512) and batch["range"].dtype == torch.float32
    assert batch["label"].shape == (4, 16, 512) and batch["label"].dtype == torch.int64
    assert batch["velocity"].shape == (4, 16, 512, 3)
    assert batch["class_weight"].shape == (4,)
    assert batch["sequence"].tolist() == [0, 0, 1, 1] and batch["frame"].tolist() == [2, 3, 2, 3]
    np.testing.assert_array_equal(batch["label"][3].numpy(), WindowDataset(sample, length=3)[3]["label"])
    # An instance target is an index too: int64.
    item = TorchWindowDataset(sample, length=2, targets=("label", "instance"))[0]
    assert item["instance"].dtype == torch.int64
    # The class weight stays float32 under a float64 default, like every other input.
    default = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    try:
        assert ds[0]["class_weight"].dtype == torch.float32
    finally:
        torch.set_default_dtype(default)
    np.testing.assert_array_equal(item["instance"].numpy(), WindowDataset(sample, length=2, targets=("instance",))[0]["instance"])


def test_flanking_puts_the_frames_own_structure_against_a_persons_sides_moved_to_stand_just_behind() -> None:
    """Each changed cell is background that held nothing or something farther; a row's changed
    cells run on from the person's edge, come from one patch's columns in their order and are
    that patch moved by one range shift, to within the drawn depth behind the person; people
    and not-scored cells never change; the same generator state gives the same result, and a
    person the same patch whoever else is in view;
    probability 0 changes nothing; both sides and each side alone are drawn."""
    from pedscan_data.windows import FLANK_BEHIND_M, FLANK_DEPTH_M, flank_people

    h, w = 6, 256
    r = np.full((h, w), 30.0, dtype=np.float32)  # a far wall
    r[:, 100:140] = 12.0 + 0.02 * np.arange(40)  # a structure with some depth
    r[:, 180:200] = 60.0  # something far (beyond the patch's depth around its median)
    r[0, ::7] = 0.0  # some holes
    label = np.zeros((h, w), dtype=np.uint8)
    instance = np.zeros((h, w), dtype=np.uint16)
    r[1:5, 40:43], label[1:5, 40:43], instance[1:5, 40:43] = 10.0, 1, 3  # a person at 10 m
    r[2:4, 45], label[2:4, 45] = 0.0, 255  # a not-scored cell near it
    r[1:5, 36] = 5.0  # a post in front of the person's left side
    sides = set()
    for seed in range(40):
        got, src = flank_people(r, label, instance, 1.0, np.random.default_rng(seed))
        again = flank_people(r, label, instance, 1.0, np.random.default_rng(seed))
        np.testing.assert_array_equal(got, again[0])
        np.testing.assert_array_equal(src, again[1])
        changed = got != r
        assert not (changed & (label != 0)).any() and not changed[0].any() and not changed[5].any()
        assert (r[changed] == 0).sum() + (r[changed] > got[changed]).sum() == changed.sum()
        assert (src[~changed] == np.broadcast_to(np.arange(w), (h, w))[~changed]).all()
        shift = got[changed] - r[np.nonzero(changed)[0], src[changed]]
        if changed.any():
            assert np.ptp(shift) < 1e-4  # one patch, one shift
            assert (np.abs(got[changed] - 10.0) <= FLANK_BEHIND_M[1] + FLANK_DEPTH_M).all()
        side = (bool(changed[:, :40].any()), bool(changed[:, 43:].any()))
        sides.add(side)
        for row in range(1, 5):
            c = np.nonzero(changed[row])[0]
            for run in (c[c < 40], c[c > 42]):
                if run.size:
                    assert np.unique((src[row, run] - run) % w).size == 1  # one patch, in its order
                    assert run.max() == 39 or run.min() in (43, 44)  # against the person (44: past the not-scored cell)
            assert not changed[row, 36]  # the post in front stays
    assert {(True, False), (False, True), (True, True)} <= sides
    np.testing.assert_array_equal(flank_people(r, label, instance, 0.0, np.random.default_rng(1))[0], r)
    # Drawn for the people asked for: one absent from the frame draws as if present, so a
    # person's patch does not depend on who else is in view.
    two_l, two_i = label.copy(), instance.copy()
    two_l[1:5, 200:202], two_i[1:5, 200:202] = 1, 1
    ids = np.array([1, 3])
    alone = flank_people(r, label, instance, 1.0, np.random.default_rng(7), ids)[0]
    both = flank_people(r, two_l, two_i, 1.0, np.random.default_rng(7), ids)[0]
    np.testing.assert_array_equal(both[:, :150], alone[:, :150])
    assert not np.array_equal(alone, flank_people(r, label, instance, 1.0, np.random.default_rng(7))[0])


def test_widening_grows_a_person_over_what_lies_behind_it_and_never_over_what_stands_in_front() -> None:
    from pedscan_data.windows import widen_people

    w = 64
    col = 2 * np.pi / w  # rad per column
    r = np.full((2, w), 20.0, dtype=np.float32)  # a wall at 20 m
    label = np.zeros((2, w), dtype=np.uint8)
    r[:, 10:12], label[:, 10:12] = 10.0, 1  # a person at 10 m, two columns
    r[0, 8] = 0.0  # no return left of it
    r[:, 13] = 5.0  # a post nearer than the person, right of it
    r[1, 9] = 10.2  # something just behind the person (within 0.3 m): not covered
    label[1, 30] = 255  # not scored, far from the person
    reach = 2.5 * 10.0 * col  # 2.5 columns at 10 m
    got_r, got_l, src = widen_people(r, label, reach)
    assert (got_l[0] == 1).nonzero()[0].tolist() == [8, 9, 10, 11, 12]  # 2 columns left (the hole too), 1 right (then the post)
    assert (got_l[1] == 1).nonzero()[0].tolist() == [10, 11, 12]  # row 1: column 9 lies within 0.3 m behind: it and 8 stay
    assert got_l[1, 30] == 255 and got_r[1, 9] == np.float32(10.2) and got_r[0, 13] == 5.0
    np.testing.assert_array_equal(got_r[0, 8:13], 10.0)
    assert src[0, 8] == 10 and src[0, 9] == 10 and src[0, 12] == 11 and src[0, 20] == 20
    # Columns wrap: a person at the turn's seam grows across it.
    r2, l2 = np.roll(r, -10, axis=1), np.roll(label, -10, axis=1)
    g2 = widen_people(r2, l2, reach)[1]
    assert sorted(g2[0].nonzero()[0].tolist()) == [0, 1, 2, w - 2, w - 1]
    # No reach, or nobody to widen: the same arrays back.
    for lab, reach_m in ((label, 0.0), (np.where(label == 1, 0, label).astype(np.uint8), reach)):
        same = widen_people(r, lab, reach_m)
        np.testing.assert_array_equal(same[0], r)
        np.testing.assert_array_equal(same[1], lab)
        np.testing.assert_array_equal(same[2], np.broadcast_to(np.arange(w), (2, w)))


def test_a_backdrop_is_a_wall_close_behind_a_person_that_hides_only_what_lies_beyond_it() -> None:
    """Each changed cell held nothing or something farther than the wall, now 0.5-2 m behind the
    person (within its tilt and noise); the person, what stands in front of it and not-scored
    cells never change; a person behind the wall is hidden (label 0); the wall reaches past both
    sides and over the person's rows, and across the turn's seam; the same generator state
    gives the same wall, whoever else is in view; probability 0 changes nothing."""
    from pedscan_data.windows import BACKDROP_BEHIND_M, BACKDROP_SIDE_M, BACKDROP_SLOPE, backdrop_people

    h, w = 8, 512
    col = 2 * np.pi / w
    r = np.full((h, w), 40.0, dtype=np.float32)  # a far facade
    r[0] = 0.0  # the sky
    label = np.zeros((h, w), dtype=np.uint8)
    instance = np.zeros((h, w), dtype=np.uint16)
    r[3:7, 100:104], label[3:7, 100:104], instance[3:7, 100:104] = 10.0, 1, 3  # a person at 10 m
    r[3:7, 97] = 6.0  # a post in front of its left side
    r[5, 106], label[5, 106] = 0.0, 255  # not scored
    r[4:6, 108:110], label[4:6, 108:110], instance[4:6, 108:110] = 30.0, 1, 8  # a person far behind
    reach = max(BACKDROP_SIDE_M) + 0.5 * 4 * 10.0 * col * BACKDROP_SLOPE
    for seed in range(30):
        got, lab = backdrop_people(r, label, instance, 1.0, np.random.default_rng(seed), np.array([3]))
        again = backdrop_people(r, label, instance, 1.0, np.random.default_rng(seed), np.array([3]))
        np.testing.assert_array_equal(got, again[0])
        np.testing.assert_array_equal(lab, again[1])
        changed = got != r
        assert changed.any()
        assert not changed[3:7, 100:104].any() and not changed[3:7, 97].any() and not changed[5, 106]
        assert ((r[changed] == 0) | (r[changed] > got[changed])).all()
        behind = got[changed] - 10.0
        assert (behind > BACKDROP_BEHIND_M[0] - BACKDROP_SLOPE * reach - 0.1).all()
        assert (behind < BACKDROP_BEHIND_M[1] + BACKDROP_SLOPE * reach + 0.1).all()
        cols = np.nonzero(changed.any(axis=0))[0]
        assert cols.min() < 100 and cols.max() > 103  # past both sides
        assert cols.min() >= 100 - int(np.ceil(max(BACKDROP_SIDE_M) / (10.0 * col))) - 1
        assert changed[3:7].any(axis=1).all() and not changed[7].any()  # its rows, not below it
        # The person behind the wall, where the wall covers it, is background now.
        hidden = changed[4:6, 108:110]
        assert (lab[4:6, 108:110][hidden] == 0).all() and (lab[4:6, 108:110][~hidden] == 1).all()
        assert ((lab != label) == (changed & (label == 1))).all()
    np.testing.assert_array_equal(backdrop_people(r, label, instance, 0.0, np.random.default_rng(1))[0], r)
    # A person absent from the frame draws as one present: another in view changes no wall.
    ids = np.array([1, 3])
    alone = backdrop_people(r, label, instance, 1.0, np.random.default_rng(7), ids)[0]
    two_l, two_i = label.copy(), instance.copy()
    two_l[3:7, 400:402], two_i[3:7, 400:402] = 1, 1
    both = backdrop_people(r, two_l, two_i, 1.0, np.random.default_rng(7), ids)[0]
    np.testing.assert_array_equal(both[:, :300], alone[:, :300])
    # Across the seam: the person at columns w-2 .. 1 gets a wall on both sides of it.
    rs, ls, iss = (np.roll(a, -101, axis=1) for a in (r, label, instance))
    got = backdrop_people(rs, ls, iss, 1.0, np.random.default_rng(2), np.array([3]))[0]
    changed = np.nonzero((got != rs).any(axis=0))[0]
    assert (changed > w // 2).any() and (changed < w // 2).any() and changed.size < w // 4
