"""Region growing from confident beams (pedscan_data.grow), its calibration and its use by predict."""

from __future__ import annotations

from collections import deque
from pathlib import Path

import h5py
import numpy as np
import pytest

from conftest import net_for, save_model
from pedscan_data import calibrate as cal
from pedscan_data import grow as gr
from pedscan_data import train as tr
from pedscan_data.netio import load_file, load_net
from pedscan_data.predict import human_margin, predict, predict_sequence
from pedscan_data.reader import Sequence


def bfs_components(joined: np.ndarray, range_m: np.ndarray, step: float) -> np.ndarray:
    """The components of :func:`grow.component_roots` by a breadth-first search, each named by
    its smallest flat index."""
    h, w = joined.shape
    name = np.arange(h * w).reshape(h, w)
    seen = np.zeros_like(joined)
    for start in zip(*np.nonzero(joined)):
        if seen[start]:
            continue
        members, todo = [start], deque([start])
        seen[start] = True
        while todo:
            r, c = todo.popleft()
            for rr, cc in ((r - 1, c), (r + 1, c), (r, (c - 1) % w), (r, (c + 1) % w)):
                if 0 <= rr < h and joined[rr, cc] and not seen[rr, cc] and abs(range_m[r, c] - range_m[rr, cc]) < step:
                    seen[rr, cc] = True
                    members.append((rr, cc))
                    todo.append((rr, cc))
        first = min(r * w + c for r, c in members)
        for m in members:
            name[m] = first
    return name


@pytest.mark.parametrize("seed", range(6))
def test_components_are_those_a_breadth_first_search_finds(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = 12, 40
    joined = rng.random((h, w)) < (0.3 + 0.1 * seed)
    range_m = np.round(rng.random((h, w)) * 3.0, 1)  # steps both under and over 0.5 m
    got = gr.component_roots(joined, range_m, 0.5)
    np.testing.assert_array_equal(got, bfs_components(joined, range_m, 0.5))


def test_growing_carries_a_confident_core_to_its_weak_edges_and_no_further() -> None:
    h, w, cut = 8, 16, 2.0
    margin = np.full((h, w), -5.0, dtype=np.float32)
    range_m = np.full((h, w), 20.0, dtype=np.float32)
    margin[2:6, 4] = 4.0  # a person's confident core ...
    margin[2:6, 3] = margin[2:6, 5] = 0.5  # ... and its weak edges, at its range
    range_m[1:7, 3:6] = 10.0
    margin[1, 3:6] = 0.5  # its head, weak too, reached through the edge beams
    range_m[1, 3:6] = 10.2
    margin[2:6, 6] = 0.5  # a wall close behind: weak, but a range step of 5 m away
    range_m[:, 6] = 15.0
    margin[5, 10] = 1.5  # a weak beam alone
    margin[3, 15] = 3.0  # a core on the last column, its edge across the seam
    margin[3, 0] = 0.5
    range_m[3, 15] = range_m[3, 0] = 12.0
    range_m[2, 4] = 0.0  # no return: never joined, its own margin its own (the edges join round it)
    want = margin > cut
    want[1:6, 3] = want[1:6, 5] = want[1, 4] = True
    want[3, 0] = True
    got = gr.human_mask(margin, range_m, cut, {"margin": 0.0, "step_m": 0.5})
    np.testing.assert_array_equal(got, want)
    # Without growing, or with the lower cut at the threshold, it is the plain cut.
    np.testing.assert_array_equal(gr.human_mask(margin, range_m, cut, None), margin > cut)
    np.testing.assert_array_equal(gr.human_mask(margin, range_m, cut, {"margin": cut, "step_m": 0.5}), margin > cut)


def synthetic_frames(n: int, seed: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Frames where no plain cut separates people from background: each person a confident
    core with weak edges (margin 0.5), the background's weak beams alone and surer (margin 1)."""
    rng = np.random.default_rng(seed)
    frames = []
    for _ in range(n):
        margin = rng.uniform(-8.0, -3.0, (16, 64)).astype(np.float32)
        range_m = rng.uniform(30.0, 40.0, (16, 64)).astype(np.float32)
        human = np.zeros((16, 64), dtype=bool)
        for c in rng.choice(np.arange(2, 60, 6), 4, replace=False):
            rows = slice(4, 12)
            human[rows, c - 1:c + 2] = True
            margin[rows, c - 1:c + 2] = 0.5
            margin[rows, c] = 5.0
            range_m[rows, c - 1:c + 2] = 10.0 + rng.uniform(0, 0.1, (8, 3))
        lone = (~human) & (rng.random((16, 64)) < 0.12)
        lone[:, 1:] &= ~lone[:, :-1]  # alone: no two side by side
        margin[lone] = 1.0
        frames.append((margin, range_m, human, np.ones_like(human)))
    return frames


def test_calibration_finds_the_growing_that_a_plain_cut_cannot_give() -> None:
    frames = synthetic_frames(6, 0)
    m = np.concatenate([f[0].ravel() for f in frames]).astype(np.float64)
    y = np.concatenate([f[2].ravel() for f in frames])
    plain_cut, plain_iou = tr.best_cut(m, y)
    assert plain_iou < 0.6
    g = gr.calibrate_grow(frames, plain_cut)
    assert g["iou"] == 1.0 and g["margin"] < 0.5 < 1.0 < g["cut"] < 5.0
    assert len(g["tried"]) == len(gr.LOW_BELOW) * len(gr.STEPS_M)
    # The threshold it found calls exactly the people on frames it never saw.
    for margin, range_m, human, _ in synthetic_frames(3, 1):
        np.testing.assert_array_equal(gr.human_mask(margin, range_m, g["cut"], g), human)


def test_a_grown_model_file_predicts_as_it_was_calibrated_and_plain_calibration_removes_it(
    sample: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    model = save_model(net_for(1, width=4, seed=2), tmp_path / "m.pt", threshold=0.5, training={"sensor": "test16"})
    out = tmp_path / "grown.pt"
    assert cal.main([str(model), "--val", str(sample), "--grow", "--out", str(out), "--device", "cpu"]) == 0
    said = capsys.readouterr().out
    obj = load_file(out)
    c = obj["training"]["calibration"]
    assert len(c["grow_tried"]) == len(gr.LOW_BELOW) * len(gr.STEPS_M)
    if obj.get("grow"):  # kept only where it helped
        assert c["iou_calibrated"] > c["iou_plain"] + 0.001 and "growing from margin" in said
    else:
        assert c["grow"] is None and "does not help" in said
    # Whatever it holds, predict applies: growing of a file's own (set here) included.
    obj["grow"] = {"margin": human_margin(obj) - 3.0, "step_m": 1.0}
    import torch

    torch.save(obj, out)
    predict(out, sample, tmp_path / "pred", device="cpu", quiet=True)
    net, _ = load_net(out, "cpu")
    grew = False
    for p in sorted(sample.glob("seq_*.h5")):
        seq = Sequence(p)
        margin, _, _ = predict_sequence(net, seq, "cpu")
        with h5py.File(tmp_path / "pred" / p.name) as f:
            labels = f["label"][...]
            assert f.attrs["grow"] == '{"margin": %r, "step_m": 1.0}' % obj["grow"]["margin"]
        for t in range(seq.frames):
            want = gr.human_mask(margin[t], seq.read("range", t), human_margin(obj), obj["grow"])
            np.testing.assert_array_equal(labels[t], want)
            grew |= bool((want & ~(margin[t] > human_margin(obj))).any())
    assert grew  # the test reaches beams that only growing calls human
    # Calibrated again without --grow: the threshold is for plain margins, the growing goes.
    assert cal.main([str(out), "--val", str(sample), "--device", "cpu"]) == 0
    assert "grow" not in load_file(out)


def test_a_damaged_grow_in_a_model_file_is_refused_naming_the_file(sample: Path, tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    from pedscan_data.predict import main as predict_main

    import torch

    model = save_model(net_for(1, width=4, seed=2), tmp_path / "m.pt", threshold=0.5)
    for bad in ({"margin": 1.0}, {"margin": "x", "step_m": 0.2}, {"margin": float("nan"), "step_m": 0.2},
                {"margin": 1.0, "step_m": 0.0}, [1, 2]):
        obj = load_file(model)
        obj["grow"] = bad
        torch.save(obj, tmp_path / "bad.pt")
        assert predict_main([str(tmp_path / "bad.pt"), str(sample), "--out", str(tmp_path / "p")]) == 2
        assert f"{tmp_path / 'bad.pt'}: its grow" in capsys.readouterr().err
        assert not (tmp_path / "p").exists()
