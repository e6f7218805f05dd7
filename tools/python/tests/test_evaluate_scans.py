"""The evaluator on real scans, per point, SemanticKITTI's way: semantic-kitti-api's person IoU
where no rider is present, ignored classes never counted, the bins, the people found, and
exit 2 naming each mismatched file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pedscan_data.evaluate import evaluate_scans, main

#: SemanticKITTI's classes (semantic-kitti-api's config/semantic-kitti.yaml ``labels``).
KITTI_CLASSES = (0, 1, 10, 11, 13, 15, 16, 18, 20, 30, 31, 32, 40, 44, 48, 49, 50, 51, 52, 60, 70, 71, 72, 80, 81, 99,
                 252, 253, 254, 255, 256, 257, 258, 259)
#: What its learning map sends to "unlabeled" (learning class 0, ignored).
TO_UNLABELED = (0, 1, 52, 99)
RIDERS = (31, 32, 253, 255)


def reference_person_iou(labels: list[np.ndarray], preds: list[np.ndarray]) -> float:
    """semantic-kitti-api's evaluate_semantics.py and auxiliary/np_ioueval.py, followed step by
    step, with the learning map restricted to person (2) against the rest (1) and unlabeled (0,
    the ignored class)."""
    learning_map = {c: (0 if c in TO_UNLABELED else 2 if c in (30, 254) else 1) for c in KITTI_CLASSES}
    maxkey = max(learning_map.keys())
    remap_lut = np.zeros((maxkey + 100), dtype=np.int32)
    remap_lut[list(learning_map.keys())] = list(learning_map.values())
    n_classes, ignore = 3, np.array([0], dtype=np.int64)
    conf_matrix = np.zeros((n_classes, n_classes), dtype=np.int64)
    for label, pred in zip(labels, preds):
        label = remap_lut[label.astype(np.int32).reshape(-1) & 0xFFFF]
        pred = remap_lut[pred.astype(np.int32).reshape(-1) & 0xFFFF]
        idxs = tuple(np.stack((pred, label), axis=0))
        np.add.at(conf_matrix, idxs, 1)
    conf = conf_matrix.copy()
    conf[:, ignore] = 0
    tp = np.diag(conf)
    fp = conf.sum(axis=1) - tp
    fn = conf.sum(axis=0) - tp
    iou = tp / (tp + fp + fn + 1e-15)
    return float(iou[2])


def write_scan(folder: Path, stem: str, xyz: np.ndarray, labels: np.ndarray, pred: np.ndarray | None, pred_root: Path) -> None:
    """One scan (remission 0.5), its labels and, unless None, its predicted labels."""
    for sub in ("velodyne", "labels"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    pts = np.concatenate([xyz, np.full((len(xyz), 1), 0.5)], axis=1).astype("<f4")
    pts.tofile(folder / "velodyne" / f"{stem}.bin")
    labels.astype("<u4").tofile(folder / "labels" / f"{stem}.label")
    if pred is not None:
        pred_root.mkdir(parents=True, exist_ok=True)
        pred.astype("<u4").tofile(pred_root / f"{stem}.label")


def random_scan(rng: np.random.Generator, n: int, classes: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points from 1 to 60 m, labels drawn from ``classes`` with instances 1-4 on people,
    predictions right three times in four."""
    r = rng.uniform(1.0, 60.0, n)
    az = rng.uniform(-np.pi, np.pi, n)
    xyz = np.stack([r * np.cos(az), r * np.sin(az), rng.uniform(-2, 1, n)], axis=1)
    cls = rng.choice(classes, n).astype(np.uint32)
    person = np.isin(cls, (30, 254))
    inst = np.where(person, rng.integers(1, 5, n), 0).astype(np.uint32)
    guess = np.where(rng.random(n) < 0.75, person, ~person)
    return xyz, (inst << 16) | cls, np.where(guess, 30, 0).astype(np.uint32)


def run(capsys: pytest.CaptureFixture[str], *args: str | Path) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_the_person_iou_is_semantic_kitti_apis_where_no_rider_is(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(7)
    no_riders = tuple(c for c in KITTI_CLASSES if c not in RIDERS) + (30, 30, 254)
    root, pred = tmp_path / "kitti", tmp_path / "pred"
    labels, preds = [], []
    for ss, scans in (("00", 3), ("05", 2)):
        for k in range(scans):
            xyz, lab, p = random_scan(rng, 2000, no_riders)
            p[rng.random(p.size) < 0.01] = 254  # a moving person predicted is a person too
            write_scan(root / "sequences" / ss, f"{k:06d}", xyz, lab, p, pred / "sequences" / ss / "predictions")
            labels.append(lab)
            preds.append(p)
    code, out, err = run(capsys, root, pred, "--json", tmp_path / "s.json")
    assert (code, err) == (0, ""), err
    d = json.loads((tmp_path / "s.json").read_text())
    assert d["overall"]["iou"] == pytest.approx(reference_person_iou(labels, preds), rel=1e-12)
    assert (d["format"], d["sequences"], d["scans"], d["points"]) == ("semantickitti-points", 2, 5, 10000)
    assert d["not_scored"]["rider"] == 0 and d["not_scored"]["unlabeled"] > 0
    assert f"person IoU {d['overall']['iou']:.4f}" in out
    # Scans from the second onwards of each sequence: the reference on those alone.
    d = evaluate_scans(root, pred, from_frame=1).as_dict()
    assert d["scans"] == 3
    assert d["overall"]["iou"] == pytest.approx(reference_person_iou(labels[1:3] + labels[4:], preds[1:3] + preds[4:]), rel=1e-12)


def test_ignored_classes_never_count_and_a_planted_mislabel_changes_the_score(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    xyz, lab, pred = random_scan(rng, 3000, KITTI_CLASSES + (30,) * 5)
    seq = tmp_path / "seq"
    write_scan(seq, "000000", xyz, lab, pred, tmp_path / "pred" / "predictions")
    base = evaluate_scans(seq, tmp_path / "pred").as_dict()
    ignored = np.isin(lab & 0xFFFF, TO_UNLABELED + RIDERS)
    assert base["not_scored"] == {"unlabeled": int(np.isin(lab & 0xFFFF, TO_UNLABELED).sum()),
                                  "rider": int(np.isin(lab & 0xFFFF, RIDERS).sum())}
    assert base["overall"]["points"] == 3000 - int(ignored.sum())
    # Every ignored point predicted the other way: nothing changes.
    flipped = np.where(ignored, np.where(pred == 30, 0, 30), pred).astype(np.uint32)
    write_scan(seq, "000000", xyz, lab, flipped, tmp_path / "pred" / "predictions")
    assert evaluate_scans(seq, tmp_path / "pred").as_dict() == base
    # One scored background point called a person: one more false alarm, the IoU falls to the
    # value it must.
    o = base["overall"]
    k = int(np.flatnonzero(~ignored & (pred == 0) & ~np.isin(lab & 0xFFFF, (30, 254)))[0])
    planted = flipped.copy()
    planted[k] = 30
    write_scan(seq, "000000", xyz, lab, planted, tmp_path / "pred" / "predictions")
    got = evaluate_scans(seq, tmp_path / "pred").as_dict()["overall"]
    assert (got["tp"], got["fp"], got["fn"]) == (o["tp"], o["fp"] + 1, o["fn"])
    assert got["iou"] == pytest.approx(o["tp"] / (o["tp"] + o["fp"] + 1 + o["fn"]))
    assert got["false_alarm_points_per_scan"] == o["fp"] + 1


def test_bins_false_alarms_and_people_found_by_instance(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two scans. Scan 0: person 1, ten points at 5 m, six called (found); person 2, four points
    at 20 m, one called (missed); two background points called at 3 and 40 m; a rider called.
    Scan 1: person 1 again (another person: instances are per scan), two points at 10 m, one
    called (half: found); person 0 points (no instance) at 50 m are scored but are nobody."""
    seq, pred = tmp_path / "seq", tmp_path / "pred" / "predictions"

    def along_x(r: list[float]) -> np.ndarray:
        return np.stack([np.array(r), np.zeros(len(r)), np.zeros(len(r))], axis=1)

    r0 = [5.0] * 10 + [20.0] * 4 + [3.0, 40.0, 7.0, 12.0]
    lab0 = np.array([1 << 16 | 30] * 10 + [2 << 16 | 254] * 4 + [50, 40, 31 | 3 << 16, 70], np.uint32)
    p0 = np.array([30] * 6 + [0] * 4 + [30] + [0] * 3 + [30, 30, 30, 0], np.uint32)
    write_scan(seq, "000000", along_x(r0), lab0, p0, pred)
    r1 = [10.0, 10.0, 50.0, 50.0]
    lab1 = np.array([1 << 16 | 30, 1 << 16 | 30, 30, 30], np.uint32)
    p1 = np.array([30, 0, 30, 0], np.uint32)
    write_scan(seq, "000001", along_x(r1), lab1, p1, pred)
    code, out, err = run(capsys, seq, tmp_path / "pred", "--json", tmp_path / "s.json")
    assert (code, err) == (0, "")
    d = json.loads((tmp_path / "s.json").read_text())
    o = d["overall"]
    assert (o["points"], o["person_points"], o["tp"], o["fp"], o["fn"]) == (21, 18, 9, 2, 9)
    assert (o["people"], o["people_found"], o["people_missed"], o["false_alarm_points_per_scan"]) == (3, 2, 1, 1.0)
    assert d["not_scored"] == {"unlabeled": 0, "rider": 1}
    paper = {(b["min_m"], b["max_m"]): b for b in d["bins"]}
    street = {(b["min_m"], b["max_m"]): b for b in d["street_bins"]}
    assert list(paper) == [(0, 4), (4, 8), (8, None)] and list(street) == [(8, 16), (16, 32), (32, None)]
    assert (paper[(0, 4)]["fp"], paper[(0, 4)]["person_points"], paper[(0, 4)]["iou"]) == (1, 0, 0.0)
    assert (paper[(4, 8)]["tp"], paper[(4, 8)]["fn"], paper[(4, 8)]["people"], paper[(4, 8)]["people_found"]) == (6, 4, 1, 1)
    assert (paper[(8, None)]["people"], paper[(8, None)]["people_found"], paper[(8, None)]["points"]) == (2, 1, 10)
    assert (street[(8, 16)]["people_found"], street[(8, 16)]["tp"], street[(8, 16)]["fn"]) == (1, 1, 1)
    assert (street[(16, 32)]["people"], street[(16, 32)]["people_found"], street[(16, 32)]["recall"]) == (1, 0, 0.25)
    assert (street[(32, None)]["people"], street[(32, None)]["fp"], street[(32, None)]["tp"]) == (0, 1, 1)
    assert street[(32, None)]["false_alarm_points_per_scan"] == 0.5
    lines = out.splitlines()
    assert lines[0] == "ground truth: 1 sequences, 2 scans, 22 points (21 scored; not scored: 0 unlabeled, 1 rider)"
    assert "people found 2 of 3 (half or more of their points)" in lines[3]
    assert lines[5].split() == ["distance", "IoU", "precision", "recall", "person", "points", "people", "found", "FA/scan"]
    assert lines[7].split() == ["4-8", "m", "0.6000", "1.0000", "0.6000", "10", "1/1", "0.0"]
    assert [ln.split()[0] for ln in lines[6:12]] == ["0-4", "4-8", "8+", "8-16", "16-32", "32+"]
    # The false alarms by their true class: a building at 3 m and road at 40 m (scan 0).
    assert d["false_alarms_by_class"] == [{"class": 40, "name": "road", "points": 1, "share": 0.5},
                                          {"class": 50, "name": "building", "points": 1, "share": 0.5}]
    assert lines[12] == "false alarms by true class: road 50 %, building 50 %"


def test_people_are_counted_by_what_stands_behind_them(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A person found with a wall 1 m behind them (a fence in front does not count), one
    missed with nothing behind: only the sidewalk under the space behind them and a bin beside
    it, 1.5 m off their line of sight."""
    seq, pred = tmp_path / "seq", tmp_path / "pred" / "predictions"
    column = lambda x, y, z0, z1, n: np.stack([np.full(n, x), np.full(n, y), np.linspace(z0, z1, n)], axis=1)
    parts = [
        (column(10.0, 0.0, -1.7, 0.0, 12), 1 << 16 | 30, 30),   # person A, found
        (column(11.0, 0.1, -1.4, 0.0, 6), 50, 0),               # a building 1 m behind A
        (column(9.0, 0.0, -1.5, -0.5, 4), 51, 0),               # a fence 1 m before A
        (column(0.0, 12.0, -1.7, 0.0, 12), 2 << 16 | 30, 0),    # person B, missed
        (column(0.0, 13.0, -1.7, -1.7, 2), 48, 0),              # sidewalk behind B
        (column(1.5, 13.0, -1.4, -0.6, 3), 99, 0),              # a bin 1.5 m off B's line of sight
    ]
    xyz = np.concatenate([p[0] for p in parts])
    labels = np.concatenate([np.full(len(p[0]), p[1], np.uint32) for p in parts])
    predicted = np.concatenate([np.full(len(p[0]), p[2], np.uint32) for p in parts])
    write_scan(seq, "000000", xyz, labels, predicted, pred)
    code, out, err = run(capsys, seq, tmp_path / "pred", "--json", tmp_path / "b.json")
    assert (code, err) == (0, "")
    d = json.loads((tmp_path / "b.json").read_text())
    assert d["people_by_what_stands_behind"] == [{"class": 0, "name": "nothing", "people": 1, "found": 0},
                                                 {"class": 50, "name": "building", "people": 1, "found": 1}]
    assert out.splitlines()[-1] == "people found by what stands 0-2 m behind them: nothing 0/1, building 1/1"


def test_mismatched_or_bad_files_exit_2_naming_each_and_write_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(1)
    seq, pred = tmp_path / "seq", tmp_path / "pred" / "predictions"
    for k in range(3):
        xyz, lab, p = random_scan(rng, 50, (30, 40, 50))
        write_scan(seq, f"{k:06d}", xyz, lab, p, pred)
    report = tmp_path / "s.json"
    # Labels of another length, a short prediction, a missing one, one with no scan: all named.
    (seq / "labels/000000.label").write_bytes(b"\0" * 4 * 49)
    (pred / "000001.label").write_bytes(b"\0" * 6)
    (pred / "000002.label").unlink()
    (pred / "000007.label").write_bytes(b"")
    code, out, err = run(capsys, seq, tmp_path / "pred", "--json", report)
    assert code == 2 and out == "" and not report.exists()
    assert f"{seq / 'labels/000000.label'}: 49 labels, {seq / 'velodyne/000000.bin'} has 50 points" in err
    assert f"{pred / '000001.label'}: 6 bytes, not whole predicted labels" in err
    assert f"{pred / '000002.label'}: missing" in err
    assert f"{pred / '000007.label'}: no such scan in {seq / 'velodyne'}" in err
    # A scan that is not whole points; a missing scan (labels without it).
    (seq / "velodyne/000001.bin").write_bytes(b"\0" * 33)
    (seq / "labels/000009.label").write_bytes(b"")
    code, _, err = run(capsys, seq, tmp_path / "pred")
    assert code == 2
    assert f"{seq / 'velodyne/000001.bin'}: 33 bytes, not a whole number of 16-byte points" in err
    assert f"{seq / 'velodyne/000009.bin'}: missing (its labels" in err
    # Predictions given as the predictions folder itself are found; scans without labels refused.
    (seq / "velodyne/000001.bin").write_bytes(b"\0" * 16 * 50)
    (seq / "labels/000009.label").unlink()
    (seq / "labels/000000.label").write_bytes(b"\0" * 4 * 50)
    (pred / "000001.label").write_bytes(b"\0" * 4 * 50)
    (pred / "000007.label").unlink()
    xyz, lab, p = random_scan(rng, 50, (30, 40))
    write_scan(seq, "000002", xyz, lab, p, pred)
    code, out, err = run(capsys, seq, pred)
    assert (code, err) == (0, ""), err
    (tmp_path / "bare/velodyne").mkdir(parents=True)
    code, _, err = run(capsys, tmp_path / "bare", pred)
    assert code == 2 and f"{tmp_path / 'bare'}: scans without labels/ to score against" in err


def test_the_picture_shows_the_scan_with_most_people_in_its_colours(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--png draws the scored scan with the most person points: each kind of point in its
    colour (hits green, misses red, false alarms orange); refused for pedscan outputs."""
    from PIL import Image

    seq, pred = tmp_path / "seq", tmp_path / "pred" / "predictions"
    x = np.linspace(5.0, 20.0, 400)
    xyz = np.stack([x, np.zeros_like(x), np.full_like(x, -1.0)], axis=1)
    few = np.where(np.arange(400) < 20, 30, 40)
    many = np.where(np.arange(400) < 200, 30, 40)
    write_scan(seq, "000000", xyz, few, few, pred)
    called = np.where((np.arange(400) < 100) | (np.arange(400) >= 390), 30, 0)  # hits, misses, false alarms
    write_scan(seq, "000001", xyz, many, called, pred)
    png = tmp_path / "scan.png"
    assert main([str(seq), str(tmp_path / "pred"), "--png", str(png)]) == 0
    assert "000001.bin" in capsys.readouterr().out.splitlines()[-1]
    rgb = np.asarray(Image.open(png).convert("RGB")).reshape(-1, 3).astype(int)
    for colour in ((0x1A, 0x98, 0x50), (0xD7, 0x30, 0x27), (0xFD, 0x8D, 0x3C)):
        assert (np.abs(rgb - colour).sum(axis=1) < 12).sum() > 20, colour
    assert main([str(tmp_path / "pred"), str(tmp_path / "pred"), "--png", str(tmp_path / "no.png")]) == 2
    assert not (tmp_path / "no.png").exists()
