"""What people look like in labeled scans, by distance: sizes, heights above the ground, legs
hidden, merged instances left out; bad input exits 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pedscan_data.people import main, scan_people

GROUND_Z = -1.73


def upright(centre: tuple[float, float], width: float, z0: float, z1: float, label: int) -> tuple[np.ndarray, np.ndarray]:
    """Points of an upright slab facing the sensor: ``width`` m across, from z0 to z1."""
    c = np.array(centre)
    across = np.array([-c[1], c[0]]) / np.hypot(*c)
    s, z = np.meshgrid(np.linspace(-width / 2, width / 2, 9), np.linspace(z0, z1, 12))
    xy = c + s.reshape(-1, 1) * across
    pts = np.column_stack([xy, z.reshape(-1), np.full(xy.shape[0], 0.3)])
    return pts, np.full(len(pts), label, dtype=np.uint32)


def ground() -> tuple[np.ndarray, np.ndarray]:
    g = np.mgrid[-40:40:0.5, -40:40:0.5].reshape(2, -1).T
    return np.column_stack([g, np.full(len(g), GROUND_Z), np.full(len(g), 0.2)]), np.full(len(g), 40, dtype=np.uint32)


def scene() -> tuple[np.ndarray, np.ndarray]:
    parts = [
        ground(),
        upright((10.0, 0.0), 0.5, GROUND_Z, GROUND_Z + 1.7, 1 << 16 | 30),  # whole, at 10 m
        upright((0.0, -14.0), 0.4, GROUND_Z + 0.9, GROUND_Z + 1.75, 2 << 16 | 254),  # above a car's roof, at 14 m
        upright((-20.0, 0.0), 0.4, GROUND_Z, GROUND_Z + 1.6, 3 << 16 | 30),  # at 20 m
        upright((6.0, 6.0), 0.4, GROUND_Z, GROUND_Z + 1.6, 4 << 16 | 30),  # with the next: one id over 3 m
        upright((6.0, 9.0), 0.4, GROUND_Z, GROUND_Z + 1.6, 4 << 16 | 30),
        upright((-30.0, 0.0), 0.4, GROUND_Z, GROUND_Z + 1.6, 40),  # a post: not a person
    ]
    few = (np.array([[0.0, 25.0, -1.0, 0.1]] * 3), np.full(3, 5 << 16 | 30, dtype=np.uint32))  # 3 points
    parts.append(few)
    return np.concatenate([p[0] for p in parts]).astype(np.float32), np.concatenate([p[1] for p in parts])


def test_each_person_is_measured_from_its_points_and_the_ground_around_it() -> None:
    pts, labels = scene()
    people, merged, few = scan_people(pts, labels)
    assert (merged, few) == (1, 1)
    by_range = {round(p["range_m"]): p for p in people}
    assert sorted(by_range) == [10, 14, 20]
    whole, roof, far = by_range[10], by_range[14], by_range[20]
    assert whole["points"] == 108 and whole["width_m"] == pytest.approx(0.5, rel=0.01)
    assert whole["bottom_m"] == pytest.approx(0.0, abs=1e-6) and whole["top_m"] == pytest.approx(1.7, abs=1e-5)
    assert roof["bottom_m"] == pytest.approx(0.9, abs=1e-5) and roof["height_m"] == pytest.approx(0.85, abs=1e-5)
    assert far["width_m"] == pytest.approx(0.4, rel=0.01)


def test_a_few_stray_points_are_left_out_of_a_person_and_many_make_it_several() -> None:
    from pedscan_data.people import core

    pts, labels = scene()
    people, _, _ = scan_people(pts, labels)
    whole = next(p for p in people if round(p["range_m"]) == 10)
    lab = labels >> 16
    ids, counts = np.unique(lab[np.isin(labels & 0xFFFF, (30, 254))], return_counts=True)
    i = next(i for i, c in zip(ids, counts) if c == whole["points"])
    # 5 points of its id 30 m away (under a tenth of its 108): strays, left out of it.
    stray = (np.array([[0.0, -30.0, -1.0, 0.1]] * 5, dtype=np.float32), np.full(5, i << 16 | 30, dtype=np.uint32))
    p2, l2 = np.concatenate([pts, stray[0]]), np.concatenate([labels, stray[1]])
    again = next(p for p in scan_people(p2, l2)[0] if round(p["range_m"]) == 10)
    assert again == whole
    m = (l2 >> 16) == i
    assert core(p2, m).sum() == whole["points"]
    # 20 (more than a tenth): several people.
    many = (np.array([[0.0, -30.0, -1.0, 0.1]] * 20, dtype=np.float32), np.full(20, i << 16 | 30, dtype=np.uint32))
    p3, l3 = np.concatenate([pts, many[0]]), np.concatenate([labels, many[1]])
    assert core(p3, (l3 >> 16) == i) is None
    assert scan_people(p3, l3)[1] == scan_people(pts, labels)[1] + 1


def test_the_report_bins_people_by_distance_and_counts_hidden_legs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pts, labels = scene()
    seq = tmp_path / "seq"
    (seq / "velodyne").mkdir(parents=True)
    (seq / "labels").mkdir()
    for k in range(2):
        pts.tofile(seq / "velodyne" / f"00000{k}.bin")
        labels.tofile(seq / "labels" / f"00000{k}.label")
    out = tmp_path / "p.json"
    assert main([str(seq), "--json", str(out)]) == 0
    d = json.loads(out.read_text())[0]
    assert (d["scan_count"], d["people"], d["merged"], d["few"]) == (2, 6, 2, 2)
    bins = {(b["min_m"], b["max_m"]): b for b in d["bins"]}
    assert bins[(8.0, 12.0)]["people"] == 2 and bins[(8.0, 12.0)]["legs_hidden"] == 0.0
    assert bins[(12.0, 16.0)]["legs_hidden"] == 1.0 and bins[(12.0, 16.0)]["width_m"] == pytest.approx(0.4, rel=0.01)
    assert bins[(16.0, 24.0)]["people"] == 2 and bins[(32.0, None)]["people"] == 0 and bins[(32.0, None)]["width_m"] is None
    assert "12-16 m" in capsys.readouterr().out
    # A label file of another length, or no labels at all: exit 2, naming the file.
    (seq / "labels" / "000001.label").write_bytes(b"\0" * 8)
    assert main([str(seq)]) == 2
    assert "000001.label" in capsys.readouterr().err
    assert main([str(tmp_path / "nothing")]) == 2
    assert "nothing" in capsys.readouterr().err
