"""Real labeled scans in SemanticKITTI's layout, their projection onto a network's grid, and the
way back from grid cells to points.

**Layout.** A *sequence folder* holds ``velodyne/NNNNNN.bin`` (little-endian float32 ``x y z
remission`` per point, metres, sensor frame) and, to be scored, ``labels/NNNNNN.label`` (uint32
per point in the same order: class in the lower 16 bits, instance in the upper 16). A *dataset
root* holds ``sequences/SS/`` sequence folders. Predictions go, per point in the scan's order,
to ``PRED/predictions/NNNNNN.label`` for a sequence folder and to
``PRED/sequences/SS/predictions/NNNNNN.label`` for a root (semantic-kitti-api's layout).

**Projection.** One implementation, pedscan's: ``pedscan project`` puts each scan on the
sensor's grid exactly as ``pedscan generate`` puts a recorded background there, and writes per
scan the cell of every point (``NNNNNN.cell``, u32, ``row * cols + col``, :data:`NO_CELL` for
a point it drops), the range image and the intensity image (f32 ``rows x cols``, 0 = no
return), with ``grid.json`` saying the grid and the intensity's units. The scans are
projected a chunk at a time (:data:`CHUNK_SCANS`), so a long sequence needs little disk.

**Back to points** (:func:`point_labels`). ``cell``: a point takes its cell's prediction (a
point that lost its cell to a nearer one takes the nearer one's). ``knn``: RangeNet++'s kNN
clean-up (Milioto et al., IROS 2019; ``postproc/KNN.py`` of lidar-bonnetal): each point looks
at the ``search x search`` window of the range image around its cell (its own range in the
centre), takes the ``k`` cells nearest in range, each range difference multiplied by one minus
a normalised Gaussian of ``sigma`` cells over the window, drops those farther than ``cutoff``
metres and lets the rest vote; the window wraps around in azimuth, no-return cells and rows
beyond the grid's edges never vote, cells equally near in range are taken in the window's
order (row by row), and a tied vote is not a person. A point the projection dropped
(outside every row's band, not finite, at the origin) has no cell to look from: 0.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .reader import PedscanError

#: Bytes per point of a ``.bin``: float32 x y z remission.
POINT_BYTES = 16

#: The cell of a point ``pedscan project`` drops.
NO_CELL = 0xFFFFFFFF

#: The class predict writes for a person (SemanticKITTI's ``person``); 0 for everything else.
PERSON_CLASS = 30

#: Scans per ``pedscan project`` call.
CHUNK_SCANS = 64


class ProjectFailed(RuntimeError):
    """``pedscan project`` failed other than on bad input (a crash, a full disk)."""


def checkout_root() -> Path | None:
    """The repository this package sits in (the nearest folder above it holding Cargo.toml
    and data/), or None for an installed copy."""
    for d in Path(__file__).resolve().parents:
        if (d / "Cargo.toml").is_file() and (d / "data").is_dir():
            return d
    return None


def find_pedscan(given: Path | None = None, root: Path | None = None, search_path: bool = True) -> Path:
    """The pedscan binary: ``given`` (``--pedscan``), else ``$PEDSCAN``, else the newer of the
    checkout's ``target/release/pedscan`` and ``target/debug/pedscan`` (``root``, default
    :func:`checkout_root`), else ``pedscan`` on ``PATH`` (when ``search_path``)."""
    if given is not None:
        if not Path(given).is_file():
            raise PedscanError(f"--pedscan {given}: no such file")
        return Path(given)
    env = os.environ.get("PEDSCAN")
    if env:
        if not Path(env).is_file():
            raise PedscanError(f"PEDSCAN={env} is not a file")
        return Path(env)
    root = root if root is not None else checkout_root()
    built = [p for p in (root / "target/release/pedscan", root / "target/debug/pedscan") if p.is_file()] if root else []
    if built:
        return max(built, key=lambda p: p.stat().st_mtime)
    found = shutil.which("pedscan") if search_path else None
    if found:
        return Path(found)
    where = f"under {root / 'target'}" if root else "in this installation"
    raise PedscanError(
        f"no pedscan binary {where}: build it first (cargo build --release), set PEDSCAN to its path"
        + (", give --pedscan BIN or put pedscan on PATH" if search_path else "")
    )


@dataclass(frozen=True)
class ScanSequence:
    """One sequence folder: its scans in file-name order and where its predictions go."""

    folder: Path
    scans: list[Path]
    predictions: Path
    """relative to the predictions' root: ``predictions`` or ``sequences/SS/predictions``"""

    def label_path(self, scan: Path) -> Path:
        return self.folder / "labels" / f"{scan.stem}.label"


def _root_sequences(path: Path, sub: str) -> list[Path]:
    d = path / "sequences"
    if not d.is_dir():
        return []
    return sorted(p for p in d.iterdir() if p.name.isdigit() and (p / sub).is_dir())


def is_scan_layout(path: Path, labelled: bool = False) -> bool:
    """Whether ``path`` is a sequence folder (``velodyne/``, and ``labels/`` if ``labelled``) or
    a dataset root with such sequences."""
    sub = "labels" if labelled else "velodyne"
    return ((path / "velodyne").is_dir() and (path / sub).is_dir()) or bool(_root_sequences(path, sub))


def bin_files(velodyne: Path) -> list[Path]:
    """The ``.bin`` files of a velodyne folder in file-name order, as ``pedscan project`` takes them."""
    return sorted((p for p in velodyne.iterdir() if p.suffix.lower() == ".bin" and p.is_file()), key=lambda p: p.name)


def scan_sequences(path: Path, labelled: bool = False) -> list[ScanSequence]:
    """The sequences of a sequence folder or dataset root (with ``labelled``, those with
    ``labels/``), each checked by :func:`check_scans`; PedscanError naming what is wrong."""
    if (path / "velodyne").is_dir():
        found = [(path, Path("predictions"))]
    else:
        found = [(p, Path("sequences") / p.name / "predictions") for p in _root_sequences(path, "labels" if labelled else "velodyne")]
    if not found:
        want = "velodyne/ and labels/" if labelled else "velodyne/"
        raise PedscanError(f"{path}: neither a sequence folder holding {want} nor a dataset root with sequences/SS/{want}")
    out = []
    for folder, pred in found:
        if labelled and not (folder / "labels").is_dir():
            raise PedscanError(f"{folder}: no labels/ folder to score against")
        if not (folder / "velodyne").is_dir():
            raise PedscanError(f"{folder / 'velodyne'}: missing (the scans of labels/)")
        out.append(ScanSequence(folder, bin_files(folder / "velodyne"), pred))
    problems = [p for s in out for p in check_scans(s)]
    if problems:
        raise PedscanError("bad scans:\n  " + "\n  ".join(problems[:20]) + (f"\n  ... and {len(problems) - 20} more" if len(problems) > 20 else ""))
    return out


def check_scans(seq: ScanSequence) -> list[str]:
    """What is wrong with a sequence's scans, each problem naming its file: none at all, a size
    that is not whole points, two files of one name, a number missing between the first and
    the last (an N-frame network would take the wrong frames), a label file without its scan."""
    velodyne = seq.folder / "velodyne"
    if not seq.scans:
        return [f"{velodyne}: no .bin scan (velodyne/NNNNNN.bin)"]
    problems = [
        f"{p}: {p.stat().st_size} bytes, not a whole number of {POINT_BYTES}-byte points (float32 x y z remission)"
        for p in seq.scans if p.stat().st_size % POINT_BYTES
    ]
    stems = [p.stem for p in seq.scans]
    problems += [f"{velodyne}: two scans named {a} (.bin and .BIN)" for a, b in zip(stems, stems[1:]) if a == b]
    if all(s.isdigit() for s in stems):
        have = {int(s) for s in stems}
        width = len(stems[0])
        problems += [f"{velodyne / f'{k:0{width}d}.bin'}: missing (the scans run from {stems[0]} to {stems[-1]})"
                     for k in range(min(have), max(have) + 1) if k not in have]
    labels = seq.folder / "labels"
    if labels.is_dir():
        present = set(stems)
        problems += [f"{velodyne / (p.stem + '.bin')}: missing (its labels {p} are there)"
                     for p in sorted(labels.glob("*.label")) if p.stem not in present]
    return problems


def read_points(path: Path) -> np.ndarray:
    """A ``.bin`` scan: f32 [n, 4] (x, y, z, remission)."""
    data = np.fromfile(path, dtype="<f4")
    if data.size % 4:
        raise PedscanError(f"{path}: not a whole number of {POINT_BYTES}-byte points")
    return data.reshape(-1, 4)


def point_range(points: np.ndarray) -> np.ndarray:
    """Each point's distance from the sensor, f32, computed as ``pedscan project`` does (in f64)."""
    xyz = points[:, :3].astype(np.float64)
    return np.sqrt((xyz * xyz).sum(axis=1)).astype(np.float32)


def count_problem(path: Path, count: int, what: str, of: str) -> str | None:
    """What is wrong with a file of one u32 per point (labels, predictions, cells) that should
    hold ``count`` of them, naming it; None when nothing is."""
    size = path.stat().st_size
    if size == 4 * count:
        return None
    return f"{path}: {size // 4 if size % 4 == 0 else f'{size} bytes, not whole'} {what}, {of} has {count} points"


def read_u32(path: Path, count: int, what: str, of: str) -> np.ndarray:
    """One little-endian u32 per point; PedscanError (:func:`count_problem`) for another count."""
    problem = count_problem(path, count, what, of)
    if problem:
        raise PedscanError(problem)
    return np.fromfile(path, dtype="<u4")


# --- pedscan project -----------------------------------------------------------------------


@dataclass(frozen=True)
class Grid:
    """What ``grid.json`` says: the grid and its scans' counts."""

    folder: Path
    sensor: str
    rows: int
    cols: int
    intensity_units: str
    scans: list[dict[str, Any]]


@dataclass(frozen=True)
class ProjectedScan:
    """One scan on the grid."""

    file: Path
    """the ``.bin``"""
    cells: np.ndarray
    """u32 [points]: the cell of each point, :data:`NO_CELL` where dropped"""
    range_m: np.ndarray
    """f32 [rows, cols], 0 = no return"""
    intensity: np.ndarray
    """f32 [rows, cols], in ``Grid.intensity_units``"""
    stats: dict[str, Any]
    """its entry in ``grid.json``: points, kept, outside_band, replaced"""


def read_grid(folder: Path, scans: list[Path]) -> Grid:
    """``grid.json`` of a ``pedscan project`` output for ``scans``; PedscanError naming the file
    when it is not what ``project`` writes."""
    path = folder / "grid.json"
    try:
        g = json.loads(path.read_text())
        grid = Grid(folder, str(g["sensor"]), int(g["rows"]), int(g["cols"]), str(g["intensity_units"]), list(g["scans"]))
        files = [str(s["file"]) for s in grid.scans]
        counts = [int(s["points"]) for s in grid.scans]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise PedscanError(f"{path}: not the grid.json of pedscan project ({type(e).__name__}: {e})") from e
    if grid.rows < 1 or grid.cols < 1:
        raise PedscanError(f"{path}: a {grid.rows} x {grid.cols} grid")
    if files != [p.name for p in scans]:
        raise PedscanError(f"{path}: lists {len(files)} scans, not the {len(scans)} given ({', '.join(files[:3])} ...)")
    for p, n in zip(scans, counts):
        if n * POINT_BYTES != p.stat().st_size:
            raise PedscanError(f"{path}: {p.name} has {n} points, the file {p.stat().st_size // POINT_BYTES}")
    return grid


def read_projected(grid: Grid, k: int, scan: Path) -> ProjectedScan:
    """Scan ``k`` of a projection, its three files checked against the grid and the scan."""
    stem = grid.folder / scan.stem
    n = int(grid.scans[k]["points"])
    cells = read_u32(stem.with_suffix(".cell"), n, "cells", scan.name)
    images = []
    for ext in (".range", ".intensity"):
        p = stem.with_suffix(ext)
        if p.stat().st_size != 4 * grid.rows * grid.cols:
            raise PedscanError(f"{p}: {p.stat().st_size} bytes, not a {grid.rows} x {grid.cols} f32 image")
        images.append(np.fromfile(p, dtype="<f4").reshape(grid.rows, grid.cols))
    bad = (cells != NO_CELL) & (cells >= grid.rows * grid.cols)
    if bad.any():
        raise PedscanError(f"{stem.with_suffix('.cell')}: cell {int(cells[bad][0])} outside the {grid.rows} x {grid.cols} grid")
    return ProjectedScan(scan, cells, images[0], images[1], grid.scans[k])


def run_project(pedscan: Path, scans: list[Path], work: Path, sensor: str) -> Grid:
    """``pedscan project`` of ``scans`` (one velodyne folder's files) into ``work/grid``.

    The scans are linked into ``work/in/velodyne`` so that any subset can be projected; a
    message from ``project`` names the user's files, not the links."""
    src = work / "in" / "velodyne"
    if work.exists():
        shutil.rmtree(work)
    src.mkdir(parents=True)
    for p in scans:
        (src / p.name).symlink_to(p.resolve())
    out = work / "grid"
    cmd = [str(pedscan), "project", str(src.parent), "--out", str(out), "--sensor", sensor]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    message = done.stderr.strip().replace(str(src), str(scans[0].parent)).replace(str(src.parent), str(scans[0].parent.parent))
    if done.returncode == 2 and "unrecognized subcommand" in done.stderr:
        raise PedscanError(f"{pedscan}: a build without `pedscan project`; build a newer one (cargo build --release) or give --pedscan BIN")
    if done.returncode == 2:
        raise PedscanError(message.removeprefix("error: ").removeprefix("Error: "))
    if done.returncode != 0:
        raise ProjectFailed(f"{' '.join(cmd)} exited {done.returncode}:\n{message}")
    return read_grid(out, scans)


def projected_scans(pedscan: Path, seq: ScanSequence, work: Path, sensor: str, chunk: int | None = None) -> Iterator[tuple[Grid, ProjectedScan]]:
    """Every scan of ``seq`` on the grid, in order, projected ``chunk`` (default
    :data:`CHUNK_SCANS`) scans at a time."""
    chunk = chunk or CHUNK_SCANS
    for k0 in range(0, len(seq.scans), chunk):
        part = seq.scans[k0 : k0 + chunk]
        grid = run_project(pedscan, part, work, sensor)
        for k, scan in enumerate(part):
            yield grid, read_projected(grid, k, scan)
    if work.exists():
        shutil.rmtree(work)


def sensor_argument(spec: Any, work: Path) -> str:
    """What ``--sensor`` gets for a model file's ``sensor``: a preset's or file's name as is;
    a table (``name``, ``elevation_deg``, ``columns``, ...) written as a sensor TOML file."""
    if isinstance(spec, str):
        return spec
    if isinstance(spec, dict) and "elevation_deg" in spec and "columns" in spec:
        lines = []
        for key, value in spec.items():
            if isinstance(value, str):
                lines.append(f"{key} = {json.dumps(value)}")
            elif isinstance(value, (list, tuple, np.ndarray)):
                lines.append(f"{key} = [{', '.join(repr(float(v)) for v in value)}]")
            elif isinstance(value, bool) or value is None:
                raise PedscanError(f"the model's sensor table: {key} = {value!r} is not a sensor file's value")
            else:
                lines.append(f"{key} = {value!r}")
        work.mkdir(parents=True, exist_ok=True)
        path = work / "sensor.toml"
        path.write_text("\n".join(lines) + "\n")
        return str(path)
    raise PedscanError(f"the model's sensor {spec!r}: neither a name nor a table with elevation_deg and columns")


# --- back to points ------------------------------------------------------------------------


@dataclass(frozen=True)
class Knn:
    """RangeNet++'s kNN clean-up (its defaults: 5 neighbours in a 5 x 5 window, sigma 1 cell, 1 m cutoff)."""

    k: int = 5
    search: int = 5
    sigma: float = 1.0
    cutoff_m: float = 1.0

    def __post_init__(self) -> None:
        if self.search < 1 or self.search % 2 == 0:
            raise PedscanError(f"kNN search window {self.search}: not an odd number of cells")
        if not 1 <= self.k <= self.search * self.search:
            raise PedscanError(f"kNN k = {self.k}: not between 1 and the window's {self.search * self.search} cells")
        if not (self.sigma > 0 and math.isfinite(self.sigma) and self.cutoff_m >= 0):
            raise PedscanError(f"kNN sigma {self.sigma}, cutoff {self.cutoff_m} m: sigma must be positive, the cutoff not negative")

    @classmethod
    def parse(cls, text: str) -> Knn:
        """``K,SEARCH,SIGMA,CUTOFF_M`` (e.g. ``5,5,1,1``)."""
        parts = text.split(",")
        try:
            if len(parts) != 4:
                raise ValueError("four values")
            return cls(int(parts[0]), int(parts[1]), float(parts[2]), float(parts[3]))
        except ValueError as e:
            raise PedscanError(f"--knn {text}: not K,SEARCH,SIGMA,CUTOFF_M ({e})") from e

    def weights(self) -> np.ndarray:
        """One minus the normalised Gaussian over the window, row-major: f32 [search * search]."""
        c = np.arange(self.search) - (self.search - 1) / 2
        g = np.exp(-(c[:, None] ** 2 + c[None, :] ** 2) / (2 * self.sigma**2))
        return (1.0 - g / g.sum()).astype(np.float32).ravel()


def cell_labels(person: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Each point's cell's prediction (False for a dropped point): bool [points]."""
    out = np.zeros(cells.shape, dtype=bool)
    kept = cells != NO_CELL
    out[kept] = person.ravel()[cells[kept].astype(np.int64)]
    return out


def knn_labels(person: np.ndarray, range_m: np.ndarray, cells: np.ndarray, range_of_point: np.ndarray, knn: Knn) -> np.ndarray:
    """RangeNet++'s kNN vote of each point (module docs): bool [points]."""
    h, w = person.shape
    kept = np.flatnonzero(cells != NO_CELL)
    cell = cells[kept].astype(np.int64)
    row, col = cell // w, cell % w
    r = range_of_point[kept].astype(np.float32)
    ranges = np.where(range_m > 0, range_m, np.inf).astype(np.float32).ravel()
    flat = person.ravel()
    half = knn.search // 2
    weight = knn.weights()
    dist = np.empty((kept.size, knn.search * knn.search), dtype=np.float32)
    vote = np.empty(dist.shape, dtype=bool)
    j = 0
    for dr in range(-half, half + 1):
        rr = row + dr
        inside = (rr >= 0) & (rr < h)
        idx = np.clip(rr, 0, h - 1) * w + (col + np.arange(-half, half + 1)[:, None]) % w
        for m, dc in enumerate(range(-half, half + 1)):
            nb = r if dr == dc == 0 else np.where(inside, ranges[idx[m]], np.float32(np.inf))
            dist[:, j] = np.abs(nb - r) * weight[j]
            vote[:, j] = flat[idx[m]]
            j += 1
    nearest = np.argsort(dist, axis=1, kind="stable")[:, : knn.k]
    d = np.take_along_axis(dist, nearest, axis=1)
    v = np.take_along_axis(vote, nearest, axis=1)
    counts = np.isfinite(d) if knn.cutoff_m <= 0 else d <= knn.cutoff_m
    yes = np.count_nonzero(counts & v, axis=1)
    no = np.count_nonzero(counts & ~v, axis=1)
    out = np.zeros(cells.shape, dtype=bool)
    out[kept] = yes > no
    return out


def point_labels(person: np.ndarray, range_m: np.ndarray, cells: np.ndarray, points: np.ndarray, knn: Knn | None) -> np.ndarray:
    """Per point, SemanticKITTI's uint32: :data:`PERSON_CLASS` or 0; by cell, or by kNN if given."""
    human = cell_labels(person, cells) if knn is None else knn_labels(person, range_m, cells, point_range(points), knn)
    return np.where(human, PERSON_CLASS, 0).astype("<u4")


def move_into_place(tmp: Path, out: Path, parts: list[Path]) -> None:
    """Moves ``parts`` (relative paths) of the finished ``tmp`` into ``out``, each replacing what
    was there, then removes ``tmp``. ``out`` not there yet: ``tmp`` becomes it."""
    if not out.exists():
        os.replace(tmp, out)
        return
    for k, part in enumerate(parts):
        target = out / part
        target.parent.mkdir(parents=True, exist_ok=True)
        if target.exists() or target.is_symlink():
            old = tmp / f".old-{k}"
            os.replace(target, old)
        os.replace(tmp / part, target)
    shutil.rmtree(tmp)
