"""The evaluator: perfect and known-corrupt predictions, SemanticKITTI and HDF5 inputs,
and exit 2 with the missing or mismatched files named."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from pedscan_data.evaluate import evaluate, main

BINS = ((0.0, 4.0), (4.0, 8.0), (8.0, np.inf))


def ground_truth(sample: Path) -> dict[str, dict[str, np.ndarray]]:
    """Every sequence's range, label, instance and velocity, read with h5py."""
    out = {}
    for p in sorted(sample.glob("seq_*.h5")):
        with h5py.File(p, "r") as f:
            out[p.name] = {k: f[k][()] for k in ("range", "label", "instance", "velocity")}
            out[p.name]["elevation_deg"] = f["sensor/elevation_deg"][()]
            out[p.name]["azimuth_deg"] = f["sensor/azimuth_deg"][()]
    return out


def write_h5(folder: Path, name: str, label: np.ndarray, velocity: np.ndarray | None = None) -> None:
    folder.mkdir(exist_ok=True)
    with h5py.File(folder / name, "w") as f:
        f["label"] = label
        if velocity is not None:
            f["velocity"] = velocity


def write_kitti(root: Path, sequence: int, t: int, labels: np.ndarray) -> Path:
    """One frame's labels as SemanticKITTI stores them: little-endian uint32 per point."""
    folder = root / "sequences" / f"{sequence:02d}" / "labels"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{t:06d}.label"
    labels.astype("<u4").tofile(path)
    return path


def kitti_from_truth(root: Path, gt: dict[str, dict[str, np.ndarray]], person: int = 30) -> None:
    """Labels equal to the ground truth; returned beams only, row-major; background = 50."""
    for s, name in enumerate(sorted(gt)):
        g = gt[name]
        for t in range(g["range"].shape[0]):
            returned = g["range"][t].ravel() > 0
            cls = np.where(g["label"][t].ravel() == 1, person, 50).astype(np.uint32)
            inst = g["instance"][t].ravel().astype(np.uint32)
            write_kitti(root, s, t, ((inst << 16) | cls)[returned])


def run(capsys: pytest.CaptureFixture[str], *args: str | Path) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_ground_truth_as_prediction_scores_one(sample: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(capsys, sample, sample, "--json", tmp_path / "scores.json")
    assert (code, err) == (0, "")
    report = json.loads((tmp_path / "scores.json").read_text())
    gt = ground_truth(sample)
    humans = sum(np.count_nonzero((g["label"] == 1) & (g["range"] > 0)) for g in gt.values())
    o = report["overall"]
    assert (o["iou"], o["precision"], o["recall"], o["epe_mps"]) == (1.0, 1.0, 1.0, 0.0)
    assert o["human_beams"] == humans and o["fp"] == o["fn"] == 0
    assert o["beams"] == sum(np.count_nonzero(g["range"] > 0) for g in gt.values())
    assert (report["sequences"], report["frames"], report["format"]) == (2, 8, "hdf5")
    assert (report["ground_truth"], report["predictions"], report["from_frame"], report["notes"]) == (str(sample), str(sample), 0, [])
    assert list(report) == ["ground_truth", "predictions", "format", "sequences", "frames", "from_frame", "notes", "overall", "bins",
                            "false_alarms_by_class", "movers_called_human"]
    assert report["false_alarms_by_class"] == [] and report["movers_called_human"] == []  # no false alarm; the hall has no movers
    assert [(b["min_m"], b["max_m"]) for b in report["bins"]] == [(0, 4), (4, 8), (8, None)]
    assert "human IoU 1.0000  precision 1.0000  recall 1.0000" in out
    assert "velocity end-point error on human beams: 0.000 m/s" in out
    for name in ("0-4 m", "4-8 m", "8+ m"):
        assert name in out


def test_known_corruption_gives_the_known_scores(sample: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Every human beam at 8 m or more missed, 50 background beams under 4 m per frame taken
    for human, velocities off by 0.5 m/s along each human beam's own direction and by (3, 0, 0)
    m/s elsewhere: IoU, precision, recall and EPE (over the true human beams alone) follow, and
    the error is all radial (beam directions from the file's angles, as pedscan defines them:
    x forward, y left, z up)."""
    gt = ground_truth(sample)
    preds = tmp_path / "preds"
    human = {b: 0 for b in BINS}
    false_pos = 0
    for name, g in gt.items():
        r, truth = g["range"], (g["label"] == 1) & (g["range"] > 0)
        for b in BINS:
            human[b] += int(np.count_nonzero(truth & (r >= b[0]) & (r < b[1])))
        label = g["label"].copy()
        label[truth & (r >= 8)] = 0
        for t in range(r.shape[0]):
            near_background = np.flatnonzero((r[t] > 0) & (r[t] < 4) & ~truth[t])[:50]
            label[t].flat[near_background] = 1
            false_pos += near_background.size
        el = np.deg2rad(g["elevation_deg"])[:, None]
        az = np.deg2rad(g["azimuth_deg"])[None, :]
        beam = np.stack(np.broadcast_arrays(np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)), -1)
        off = np.where(truth[..., None], 0.5 * beam[None], np.array([3.0, 0.0, 0.0])).astype(np.float32)
        write_h5(preds, name, label, g["velocity"] + off)
    code, out, err = run(capsys, sample, preds, "--json", tmp_path / "scores.json")
    assert (code, err) == (0, "")
    report = json.loads((tmp_path / "scores.json").read_text())
    total, missed = sum(human.values()), human[BINS[2]]
    o = report["overall"]
    assert (o["tp"], o["fp"], o["fn"]) == (total - missed, false_pos, missed)
    assert o["iou"] == pytest.approx((total - missed) / (total + false_pos))
    assert o["precision"] == pytest.approx((total - missed) / (total - missed + false_pos))
    assert o["recall"] == pytest.approx((total - missed) / total)
    assert o["epe_mps"] == pytest.approx(0.5, abs=1e-6)
    along = o["velocity_error_mps"]
    assert along["radial"] == pytest.approx(0.5, abs=1e-6)
    assert along["tangential"] == pytest.approx(0.0, abs=1e-6) and along["up"] == pytest.approx(0.0, abs=1e-6)
    assert along["background_epe"] == pytest.approx(3.0, abs=1e-6)
    near, mid, far = report["bins"]
    assert near["iou"] == pytest.approx(human[BINS[0]] / (human[BINS[0]] + false_pos))
    assert mid["iou"] == 1.0
    assert far["iou"] == 0.0 and far["recall"] == 0.0 and far["precision"] is None
    far_row = next(line for line in out.splitlines() if line.startswith("8+ m"))
    assert "n/a" in far_row  # the 8+ m precision: nothing predicted there


def test_semantickitti_labels(sample: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    gt = ground_truth(sample)
    kitti_from_truth(tmp_path / "kitti", gt)
    code, out, err = run(capsys, sample, tmp_path / "kitti", "--json", tmp_path / "s.json")
    assert (code, err) == (0, "")
    report = json.loads((tmp_path / "s.json").read_text())
    assert report["format"] == "semantickitti" and report["overall"]["iou"] == 1.0
    assert "epe_mps" not in report["overall"] and "end-point" not in out

    # 254 (moving-person) is a person too; every label of sequence 1, frame 2 read back the
    # way SemanticKITTI's loaders do, with its human beams turned into class 50: known FN.
    kitti_from_truth(tmp_path / "moving", gt, person=254)
    path = tmp_path / "moving/sequences/01/labels/000002.label"
    raw = np.fromfile(path, dtype=np.uint32)
    semantic, instance = raw & 0xFFFF, raw >> 16
    assert set(np.unique(semantic)) <= {50, 254} and instance.max() > 0
    write_kitti(tmp_path / "moving", 1, 2, np.where(semantic == 254, 50, semantic))
    missed = int(np.count_nonzero(semantic == 254))
    code, _, _ = run(capsys, sample, tmp_path / "moving", "--json", tmp_path / "m.json")
    o = json.loads((tmp_path / "m.json").read_text())["overall"]
    assert code == 0 and (o["fn"], o["fp"]) == (missed, 0)
    assert o["iou"] == pytest.approx((o["human_beams"] - missed) / o["human_beams"])


def test_missing_or_short_label_files_exit_2_naming_them(sample: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    kitti = tmp_path / "kitti"
    kitti_from_truth(kitti, ground_truth(sample))
    (kitti / "sequences/01/labels/000002.label").unlink()
    code, out, err = run(capsys, sample, kitti)
    assert code == 2 and out == ""
    assert "sequences/01/labels/000002.label: missing" in err

    kitti_from_truth(kitti, ground_truth(sample))
    short = kitti / "sequences/00/labels/000003.label"
    short.write_bytes(short.read_bytes()[:-4])
    write_kitti(kitti, 0, 4, np.zeros(3, np.uint32))
    code, _, err = run(capsys, sample, kitti)
    assert code == 2
    assert "sequences/00/labels/000003.label:" in err and "frame 3 of seq_000000.h5" in err
    assert "sequences/00/labels/000004.label: no such frame" in err

    shutil.rmtree(kitti / "sequences/01")
    code, _, err = run(capsys, sample, kitti)
    assert code == 2 and "sequences/01/labels: missing (sequence 1, 4 frames)" in err

    # A missing first sequence does not stop the check of the next one.
    shutil.rmtree(kitti)
    kitti_from_truth(kitti, ground_truth(sample))
    shutil.rmtree(kitti / "sequences/00")
    write_kitti(kitti, 1, 4, np.zeros(3, np.uint32))
    code, _, err = run(capsys, sample, kitti)
    assert code == 2 and "sequences/00/labels: missing (sequence 0, 4 frames)" in err
    assert "sequences/01/labels/000004.label: no such frame" in err


def test_mismatched_hdf5_predictions_exit_2_naming_them(sample: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    gt = ground_truth(sample)
    preds = tmp_path / "preds"
    write_h5(preds, "seq_000000.h5", gt["seq_000000.h5"]["label"][:3])
    code, _, err = run(capsys, sample, preds)
    assert code == 2
    assert "seq_000000.h5: /label has shape (3, 16, 512)" in err
    assert "seq_000001.h5: missing (sequence 1, 4 frames)" in err
    code, _, err = run(capsys, sample, sample / "seq_000000.h5")
    assert code == 2 and "one prediction file for 2 sequences" in err
    code, _, err = run(capsys, sample / "seq_000000.h5", sample / "seq_000000.h5")
    assert code == 0


def test_predictions_made_from_other_data_exit_2_naming_them(sample: Path, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """A prediction file records the digest of the ranges it was made from (``predict``);
    one made from another sequence of the same shape is refused, not scored."""
    from pedscan_data.reader import Sequence

    gt = ground_truth(sample)
    digests = {}
    for name in gt:
        with Sequence(sample / name) as s:
            digests[name] = s.range_digest()
    assert len(set(digests.values())) == 2
    for swap in (False, True):
        preds = tmp_path / f"preds{int(swap)}"
        for name, other in zip(sorted(gt), sorted(gt)[::-1] if swap else sorted(gt)):
            write_h5(preds, name, gt[name]["label"])
            with h5py.File(preds / name, "a") as f:
                f.attrs["source_range_sha256"] = digests[other]
        code, out, err = run(capsys, sample, preds)
        if swap:
            assert code == 2 and "seq_000000.h5: predictions made from other data than" in err, err
        else:
            assert code == 0, err


def test_label_only_hdf5_predictions_are_scored_without_velocity(
    sample: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Predictions of labels alone (a segmentation network's) score IoU; no velocity error is
    made up for them. The JSON report is indented for reading."""
    for name, g in ground_truth(sample).items():
        write_h5(tmp_path / "preds", name, g["label"])
    code, out, err = run(capsys, sample, tmp_path / "preds", "--json", tmp_path / "s.json")
    assert (code, err) == (0, ""), err
    text = (tmp_path / "s.json").read_text()
    assert text.startswith('{\n  "') and text.endswith("}\n"), text[:40]
    o = json.loads(text)["overall"]
    assert o["iou"] == 1.0 and "epe_mps" not in o and "velocity_error_mps" not in o, o


def test_a_beam_at_a_bins_edge_belongs_to_the_farther_bin() -> None:
    """The bins are [0, 4), [4, 8) and [8, inf) m: a human beam at exactly 4 m is counted in
    the second, one at exactly 8 m in the third; a beam without a return in none."""
    from pedscan_data.evaluate import Report, _score_frame

    report = Report("gt", "pred", "h5")
    range_m = np.array([[0.0, 3.999, 4.0, 7.999, 8.0, 30.0]], np.float32)
    truth = np.ones_like(range_m, bool)
    _score_frame(report, range_m, truth, truth, None, None)
    assert [c.human_beams for c in report.bins] == [1, 2, 2]
    assert [c.tp for c in report.bins] == [1, 2, 2]


def test_beam_axes_are_double_precision_whatever_the_files_dtype() -> None:
    from pedscan_data.evaluate import beam_axes

    el32, az32 = np.array([-30.67, 10.67], np.float32), np.array([0.0, 33.3, 181.7], np.float32)
    axes = beam_axes(el32, az32)
    assert axes.dtype == np.float64
    el, az = np.deg2rad(el32.astype(np.float64)), np.deg2rad(az32.astype(np.float64))
    want = np.array([np.cos(el[1]) * np.cos(az[2]), np.cos(el[1]) * np.sin(az[2]), np.sin(el[1])])
    np.testing.assert_allclose(axes[0, 1, 2], want, rtol=0, atol=1e-15)


def test_velocities_without_ground_truth_velocity_are_noted(
    sample_minimal: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with h5py.File(sample_minimal / "seq_000000.h5", "r") as f:
        label = f["label"][()]
    write_h5(tmp_path, "seq_000000.h5", label, np.zeros(label.shape + (3,), np.float32))
    code, out, _ = run(capsys, sample_minimal, tmp_path)
    assert code == 0
    assert "seq_000000.h5: no /velocity to score the predicted velocities on" in out
    assert "end-point" not in out and "human IoU 1.0000" in out
    # Once per sequence, also when scoring starts after its first frame.
    for k in (0, 1, 2):
        notes = evaluate(sample_minimal, tmp_path, from_frame=k).notes
        assert notes == [f"{sample_minimal / 'seq_000000.h5'}: no /velocity to score the predicted velocities on"], (k, notes)


def test_unknown_format_exits_2(sample: Path, tmp_path: Path) -> None:
    (tmp_path / "labels.txt").write_text("1 0 1\n")
    for predictions in (tmp_path, tmp_path / "labels.txt"):
        done = subprocess.run(
            [sys.executable, "-m", "pedscan_data.evaluate", str(sample), str(predictions)],
            capture_output=True, text=True, check=False,
        )
        assert done.returncode == 2
        assert f"{predictions}: unknown predictions format" in done.stderr


def _report(velocity: bool) -> dict:
    """A scored report as :meth:`Report.as_dict` gives it, with numbers picked by hand."""
    overall = {"beams": 1000, "human_beams": 40, "tp": 30, "fp": 10, "fn": 10,
               "iou": 0.6, "precision": 0.75, "recall": 0.75}
    bins = [
        {"min_m": 0.0, "max_m": 4.0, "iou": 0.8, "precision": 0.9, "recall": 0.88888, "human_beams": 27},
        {"min_m": 4.0, "max_m": 8.0, "iou": 1 / 3, "precision": 0.5, "recall": 0.5, "human_beams": 12},
        {"min_m": 8.0, "max_m": None, "iou": None, "precision": None, "recall": 0.0, "human_beams": 1},
    ]
    if velocity:
        overall["epe_mps"] = 0.12345
        overall["velocity_error_mps"] = {"radial": 0.1, "tangential": 0.05, "up": 0.0125, "background_epe": 1.5}
        for b, e in zip(bins, (0.1, 0.2, None)):
            b["epe_mps"] = e
    return {"sequences": 2, "frames": 3, "format": "h5", "notes": ["a note", "another"],
            "overall": overall, "bins": bins}


def test_the_printed_report_is_the_documented_table() -> None:
    """Every line of the summary `evaluate` prints, written out by hand: counts, rounding to 4
    (velocity 3) places, `n/a` for an undefined score, the bins' names, the columns' widths,
    and the velocity lines and column only when the predictions carry velocity."""
    from pedscan_data.evaluate import format_report

    assert format_report(_report(velocity=False)).split("\n") == [
        "ground truth: 2 sequences, 3 frames, 1000 returned beams, 40 human beams",
        "predictions: h5",
        "human IoU 0.6000  precision 0.7500  recall 0.7500  (TP 30, FP 10, FN 10)",
        "note: a note",
        "note: another",
        "",
        "distance       IoU  precision  recall  human beams",
        "0-4 m       0.8000     0.9000  0.8889           27",
        "4-8 m       0.3333     0.5000  0.5000           12",
        "8+ m           n/a        n/a  0.0000            1",
    ]
    assert format_report(_report(velocity=True)).split("\n") == [
        "ground truth: 2 sequences, 3 frames, 1000 returned beams, 40 human beams",
        "predictions: h5",
        "human IoU 0.6000  precision 0.7500  recall 0.7500  (TP 30, FP 10, FN 10)",
        "note: a note",
        "note: another",
        "velocity end-point error on human beams: 0.123 m/s",
        "  mean |error| along each beam: radial 0.100, tangential 0.050, up 0.013 m/s; "
        "background beams' EPE 1.500 m/s",
        "",
        "distance       IoU  precision  recall  human beams  EPE m/s",
        "0-4 m       0.8000     0.9000  0.8889           27    0.100",
        "4-8 m       0.3333     0.5000  0.5000           12    0.200",
        "8+ m           n/a        n/a  0.0000            1      n/a",
    ]


def test_a_mismatch_names_the_first_twenty_problems_and_counts_the_rest() -> None:
    from pedscan_data.evaluate import MismatchError

    few = MismatchError(["a: missing", "b: 3 frames, not 4"])
    assert str(few) == "predictions do not match the ground truth:\n  a: missing\n  b: 3 frames, not 4"
    assert few.problems == ["a: missing", "b: 3 frames, not 4"]
    many = MismatchError([f"p{k}" for k in range(23)])
    assert str(many) == ("predictions do not match the ground truth:\n  "
                         + "\n  ".join(f"p{k}" for k in range(20)) + "\n  ... and 3 more")
    exactly = MismatchError([f"p{k}" for k in range(20)])
    assert not str(exactly).endswith("more")
    one_over = MismatchError([f"p{k}" for k in range(21)])
    assert str(one_over).endswith("\n  p19\n  ... and 1 more")


def test_beams_labelled_not_scored_count_nowhere(sample: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A ground-truth /label of 255 (a recording's own people) is neither a hit nor a miss: with
    every such beam predicted wrongly, the rest predicted right, the scores are perfect and
    the beams counted are the others."""
    gt_dir, preds = tmp_path / "gt", tmp_path / "preds"
    shutil.copytree(sample, gt_dir)
    returned = not_scored = 0
    for name, g in ground_truth(sample).items():
        label = g["label"].copy()
        ret = g["range"] > 0
        # Some human beams and some background beams of every frame become 255.
        pick = ret & ((g["label"] == 1) | (np.arange(label.size).reshape(label.shape) % 7 == 0))
        pick &= np.arange(label.size).reshape(label.shape) % 2 == 0
        label[pick] = 255
        with h5py.File(gt_dir / name, "a") as f:
            f["label"][...] = label
        write_h5(preds, name, np.where(pick, g["label"] == 0, g["label"] == 1).astype(np.uint8))
        returned += int(ret.sum())
        not_scored += int(pick.sum())
    assert not_scored > 0
    code, _, err = run(capsys, gt_dir, preds, "--json", tmp_path / "s.json")
    assert (code, err) == (0, "")
    o = json.loads((tmp_path / "s.json").read_text())["overall"]
    assert (o["iou"], o["fp"], o["fn"], o["beams"]) == (1.0, 0, 0, returned - not_scored)


def test_false_alarms_by_class_and_movers_called_human(sample: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Background beams made a stroller's and a car's (their /instance after the people's,
    their /class 99 and 10, `/movers/kind` written): with 7 of the stroller's beams a frame
    called human, 3 building beams and 2 no-return beams too, and one stroller beam not scored
    (255, called human), the report counts each kind's scored beams and those called human,
    and the false alarms by class, exactly."""
    gt_dir, preds = tmp_path / "gt", tmp_path / "preds"
    shutil.copytree(sample, gt_dir)
    want = {"stroller": [0, 0], "car": [0, 0]}
    by_class = {99: 0, 50: 0}
    for name, g in ground_truth(sample).items():
        label, instance = g["label"].copy(), g["instance"].copy()
        with h5py.File(gt_dir / name, "a") as f:
            assert "class" in f and "movers" not in f
            cls = f["class"][()]
            n = f["humans/height_m"].shape[0]
            f["movers/kind"] = np.array([b"stroller", b"car"], dtype=h5py.string_dtype())
            human = label == 1
            for t in range(label.shape[0]):
                free = np.flatnonzero((g["range"][t] > 0) & (label[t] == 0) & (cls[t] == 50))
                stroller, car, building = free[:20], free[20:50], free[50:53]
                instance[t].flat[stroller] = n + 1
                instance[t].flat[car] = n + 2
                cls[t].flat[stroller] = 99
                cls[t].flat[car] = 10
                label[t].flat[stroller[0]] = 255  # not scored, whatever is predicted
                human[t].flat[stroller[:8]] = True  # the first of them not scored
                human[t].flat[building] = True
                nothing = np.flatnonzero(g["range"][t] <= 0)[:2]  # no return: never a false alarm
                assert nothing.size == 2
                human[t].flat[nothing] = True
                want["stroller"][0] += 7
                want["stroller"][1] += 19
                want["car"][1] += 30
                by_class[99] += 7
                by_class[50] += 3
            f["instance"][...] = instance
            f["class"][...] = cls
            f["label"][...] = label
        write_h5(preds, name, human.astype(np.uint8))
    code, out, err = run(capsys, gt_dir, preds, "--json", tmp_path / "s.json")
    assert (code, err) == (0, "")
    report = json.loads((tmp_path / "s.json").read_text())
    assert report["overall"]["fp"] == by_class[99] + by_class[50]
    assert [(c["class"], c["name"], c["beams"]) for c in report["false_alarms_by_class"]] == [
        (99, "other-object", by_class[99]), (50, "building", by_class[50])]
    assert sum(c["share"] for c in report["false_alarms_by_class"]) == pytest.approx(1.0)
    assert [(m["kind"], m["called_human"], m["beams"]) for m in report["movers_called_human"]] == [
        ("car", 0, want["car"][1]), ("stroller", want["stroller"][0], want["stroller"][1])]
    s = want["stroller"]
    assert (f"movers' beams called human: car 0 of {want['car'][1]} (0.0 %), stroller {s[0]} of {s[1]} "
            f"({100 * s[0] / s[1]:.1f} %)") in out
    share = 100 * by_class[99] / (by_class[99] + by_class[50])
    assert f"false alarms by true class: other-object {share:.0f} %, building {100 - share:.0f} %" in out
