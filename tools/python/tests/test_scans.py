"""Real scans' side of the package: the layout found and checked, ``pedscan project``'s files
read (and refused when they are not what it writes), the binary found, and the way back from
cells to points, cell by cell and by RangeNet++'s kNN vote."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from pedscan_data.reader import PedscanError
from pedscan_data.scans import (
    NO_CELL, Knn, ScanSequence, cell_labels, check_scans, find_pedscan, knn_labels, point_labels, read_grid, read_projected,
    scan_sequences, sensor_argument,
)


def write_bin(path: Path, points: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    np.asarray(points, "<f4").reshape(-1, 4).tofile(path)
    return path


def test_the_layouts_are_told_apart_and_every_bad_scan_named(tmp_path: Path) -> None:
    one = tmp_path / "seq"
    for k in (0, 1, 2):
        write_bin(one / "velodyne" / f"{k:06d}.bin", np.ones((3, 4)))
    (s,) = scan_sequences(one)
    assert (s.folder, [p.name for p in s.scans], s.predictions) == (one, ["000000.bin", "000001.bin", "000002.bin"], Path("predictions"))
    root = tmp_path / "root"
    for ss in ("08", "03"):
        write_bin(root / "sequences" / ss / "velodyne" / "000000.bin", np.ones((2, 4)))
    (root / "sequences" / "notes").mkdir()
    got = scan_sequences(root)
    assert [(x.folder.name, str(x.predictions)) for x in got] == [("03", "sequences/03/predictions"), ("08", "sequences/08/predictions")]
    with pytest.raises(PedscanError, match="neither a sequence folder holding velodyne/ and labels/"):
        scan_sequences(root, labelled=True)
    # Every problem at once, each naming its file: a partial point, a gap in the numbering,
    # labels without their scan.
    (one / "velodyne" / "000001.bin").write_bytes(b"\0" * 17)
    (one / "velodyne" / "000002.bin").rename(one / "velodyne" / "000004.bin")
    (one / "labels").mkdir()
    (one / "labels" / "000009.label").write_bytes(b"")
    with pytest.raises(PedscanError) as e:
        scan_sequences(one)
    msg = str(e.value)
    assert f"{one / 'velodyne/000001.bin'}: 17 bytes, not a whole number of 16-byte points" in msg
    for k in (2, 3):
        assert f"{one / 'velodyne' / f'00000{k}.bin'}: missing (the scans run from 000000 to 000004)" in msg
    assert f"{one / 'velodyne/000009.bin'}: missing (its labels {one / 'labels/000009.label'} are there)" in msg
    empty = tmp_path / "empty"
    (empty / "velodyne").mkdir(parents=True)
    assert check_scans(ScanSequence(empty, [], Path("predictions"))) == [
        f"{empty / 'velodyne'}: no .bin scan (velodyne/NNNNNN.bin)"
    ]


def write_projection(folder: Path, scans: list[Path], rows: int, cols: int, cells: list[np.ndarray]) -> None:
    """A projection's files as ``pedscan project`` documents them."""
    folder.mkdir(parents=True, exist_ok=True)
    entries = []
    for scan, c in zip(scans, cells):
        n = scan.stat().st_size // 16
        entries.append({"file": scan.name, "points": n, "kept": n, "outside_band": 0, "replaced": 0})
        np.asarray(c, "<u4").tofile(folder / f"{scan.stem}.cell")
        np.arange(rows * cols, dtype="<f4").tofile(folder / f"{scan.stem}.range")
        np.full(rows * cols, 0.5, "<f4").tofile(folder / f"{scan.stem}.intensity")
    grid = {"sensor": "s", "rows": rows, "cols": cols, "intensity_units": "remission", "ring_mapped": False, "scans": entries}
    (folder / "grid.json").write_text(json.dumps(grid))


def test_a_projection_is_read_as_documented_and_refused_when_it_is_not(tmp_path: Path) -> None:
    scans = [write_bin(tmp_path / "v" / f"00000{k}.bin", np.ones((3, 4))) for k in (0, 1)]
    out = tmp_path / "grid"
    write_projection(out, scans, 2, 4, [[0, 7, NO_CELL], [1, 1, 1]])
    grid = read_grid(out, scans)
    assert (grid.sensor, grid.rows, grid.cols, grid.intensity_units) == ("s", 2, 4, "remission")
    p = read_projected(grid, 0, scans[0])
    assert p.cells.tolist() == [0, 7, NO_CELL] and p.range_m.shape == (2, 4) and p.range_m[1, 3] == 7.0
    assert p.intensity.dtype == np.float32 and p.stats["points"] == 3
    # Another scan list, a count that is not the file's, a short cell file, a cell off the grid,
    # a short image, broken JSON: each refused, naming the file.
    with pytest.raises(PedscanError, match="lists 2 scans, not the 1 given"):
        read_grid(out, scans[:1])
    g = json.loads((out / "grid.json").read_text())
    g["scans"][1]["points"] = 4
    (out / "grid.json").write_text(json.dumps(g))
    with pytest.raises(PedscanError, match=f"{out / 'grid.json'}: 000001.bin has 4 points, the file 3"):
        read_grid(out, scans)
    write_projection(out, scans, 2, 4, [[0, 7], [1, 1, 8]])
    grid = read_grid(out, scans)
    with pytest.raises(PedscanError, match=f"{out / '000000.cell'}: 2 cells, 000000.bin has 3 points"):
        read_projected(grid, 0, scans[0])
    with pytest.raises(PedscanError, match=f"{out / '000001.cell'}: cell 8 outside the 2 x 4 grid"):
        read_projected(grid, 1, scans[1])
    write_projection(out, scans, 2, 4, [[0, 7, 1], [1, 1, 1]])
    (out / "000000.range").write_bytes(b"\0" * 12)
    with pytest.raises(PedscanError, match=f"{out / '000000.range'}: 12 bytes, not a 2 x 4 f32 image"):
        read_projected(read_grid(out, scans), 0, scans[0])
    (out / "grid.json").write_text("{")
    with pytest.raises(PedscanError, match=f"{out / 'grid.json'}: not the grid.json of pedscan project"):
        read_grid(out, scans)


def test_the_binary_is_found_as_the_tests_find_it_then_on_the_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("PEDSCAN", raising=False)
    monkeypatch.setenv("PATH", str(tmp_path / "bin"))
    with pytest.raises(PedscanError, match="build it first .* or put pedscan on PATH"):
        find_pedscan(root=tmp_path)
    (tmp_path / "bin").mkdir()
    on_path = tmp_path / "bin" / "pedscan"
    on_path.write_text("#!/bin/sh\n")
    on_path.chmod(0o755)
    assert find_pedscan(root=tmp_path) == on_path
    with pytest.raises(PedscanError, match="build it first"):
        find_pedscan(root=tmp_path, search_path=False)
    (tmp_path / "target/release").mkdir(parents=True)
    (tmp_path / "target/release/pedscan").write_text("")
    assert find_pedscan(root=tmp_path) == tmp_path / "target/release/pedscan"
    monkeypatch.setenv("PEDSCAN", str(on_path))
    assert find_pedscan(root=tmp_path) == on_path
    assert find_pedscan(tmp_path / "target/release/pedscan", root=tmp_path) == tmp_path / "target/release/pedscan"
    with pytest.raises(PedscanError, match=f"--pedscan {tmp_path / 'none'}: no such file"):
        find_pedscan(tmp_path / "none")


def test_a_models_sensor_table_becomes_a_sensor_file(tmp_path: Path) -> None:
    table = {"name": "t4", "elevation_deg": np.array([3.0, 1.0, -1.0, -3.0]), "columns": 64, "max_range_m": 20.0}
    path = sensor_argument(table, tmp_path / "w")
    got = tomllib.loads(Path(path).read_text())
    assert got == {"name": "t4", "elevation_deg": [3.0, 1.0, -1.0, -3.0], "columns": 64, "max_range_m": 20.0}
    assert sensor_argument("hdl64e", tmp_path) == "hdl64e"
    for bad in ({"columns": 3}, 7, {"elevation_deg": [1.0], "columns": 8, "rate_hz": None}):
        with pytest.raises(PedscanError, match="the model's sensor"):
            sensor_argument(bad, tmp_path / "x")


def reference_knn(person: np.ndarray, range_m: np.ndarray, cells: np.ndarray, point_range: np.ndarray, knn: Knn) -> np.ndarray:
    """RangeNet++'s postproc/KNN.py read point by point, with pedscan's grid: the window wraps
    around in azimuth, rows beyond the edges and no-return cells are infinitely far, neighbours
    equally near are taken in window order (a stable sort), and a tied vote is not a person."""
    h, w = person.shape
    half = knn.search // 2
    coords = [(dr, dc) for dr in range(-half, half + 1) for dc in range(-half, half + 1)]
    var = knn.sigma**2
    g = np.array([math.exp(-(dr * dr + dc * dc) / (2 * var)) / (2 * math.pi * var) for dr, dc in coords])
    inv = 1.0 - g / g.sum()
    out = []
    for cell, r in zip(cells, point_range):
        if cell == NO_CELL:
            out.append(False)
            continue
        row, col = divmod(int(cell), w)
        cand = []
        for (dr, dc), weight in zip(coords, inv):
            rr, cc = row + dr, (col + dc) % w
            if (dr, dc) == (0, 0):
                nb = r
            elif 0 <= rr < h and range_m[rr, cc] > 0:
                nb = range_m[rr, cc]
            else:
                nb = math.inf
            label = bool(person[min(max(rr, 0), h - 1), cc])
            cand.append((abs(nb - r) * np.float32(weight), label))
        cand.sort(key=lambda x: x[0])
        votes = [label for d, label in cand[: knn.k] if d <= knn.cutoff_m]
        out.append(sum(votes) > len(votes) - sum(votes))
    return np.array(out)


@pytest.mark.parametrize("knn", [Knn(), Knn(3, 3, 0.5, 0.3), Knn(7, 5, 2.0, 2.0)])
def test_the_knn_vote_is_rangenets_point_by_point(knn: Knn) -> None:
    rng = np.random.default_rng(knn.k)
    h, w = 6, 16
    # Ranges on a few distinct levels so that ties and the cutoff both matter; some holes.
    range_m = rng.choice([0.0, 4.0, 4.5, 9.0, 9.2], size=(h, w)).astype(np.float32)
    person = rng.random((h, w)) < 0.4
    cells = rng.integers(0, h * w, 300).astype(np.uint32)
    cells[::17] = NO_CELL
    r = np.where(rng.random(300) < 0.5, range_m.ravel()[cells % (h * w)], rng.uniform(3.0, 10.0, 300)).astype(np.float32)
    r[r == 0] = 6.0
    got = knn_labels(person, range_m, cells, r, knn)
    np.testing.assert_array_equal(got, reference_knn(person, range_m, cells, r, knn))
    assert got.any() and not got.all()


def test_a_point_behind_a_person_takes_what_it_is_near_in_range() -> None:
    """A person (cells at 5 m) in front of a wall (10 m): a wall point that lost its cell to the
    person's nearer return takes the person's label by cell and the wall's by kNN; a point of
    the person stays a person; the window wraps from column 0 to the last; a dropped point is 0."""
    h, w = 5, 12
    range_m = np.full((h, w), 10.0, np.float32)
    person = np.zeros((h, w), bool)
    range_m[1:4, 0:3] = 5.0
    person[1:4, 0:3] = True
    range_m[1:4, 10:12] = 5.0
    person[1:4, 10:12] = True
    cells = np.array([2 * w + 1, 2 * w + 1, 2 * w + 0, 2 * w + 6, NO_CELL], np.uint32)
    r = np.array([10.0, 5.05, 5.0, 10.0, 5.0], np.float32)
    by_cell = cell_labels(person, cells)
    by_knn = knn_labels(person, range_m, cells, r, Knn())
    assert by_cell.tolist() == [True, True, True, False, False]
    assert by_knn.tolist() == [False, True, True, False, False]
    pts = np.zeros((5, 4), np.float32)
    pts[:, 0] = r
    assert point_labels(person, range_m, cells, pts, None).tolist() == [30, 30, 30, 0, 0]
    assert point_labels(person, range_m, cells, pts, Knn()).dtype == np.dtype("<u4")


def test_knn_settings_are_checked_and_parsed() -> None:
    assert Knn.parse("5,5,1,1") == Knn()
    assert Knn.parse("3,3,0.5,0") == Knn(3, 3, 0.5, 0.0)
    for bad, msg in (("5,4,1,1", "not an odd number"), ("26,5,1,1", "not between 1 and the window's 25"),
                     ("5,5,0,1", "sigma must be positive"), ("5,5,1", "not K,SEARCH,SIGMA,CUTOFF_M"),
                     ("a,5,1,1", "not K,SEARCH,SIGMA,CUTOFF_M")):
        with pytest.raises(PedscanError, match=msg):
            Knn.parse(bad)
    weights = Knn().weights()
    assert weights.shape == (25,) and weights.argmin() == 12
    assert float(weights.sum()) == pytest.approx(24.0)
