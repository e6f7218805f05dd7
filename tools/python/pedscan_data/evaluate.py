"""Scores human segmentation (and velocity) predictions against pedscan ground truth, or
per-point predictions against SemanticKITTI's labeled scans.

    python -m pedscan_data.evaluate GROUND_TRUTH PREDICTIONS [--json FILE] [--from-frame K]

**pedscan ground truth.** GROUND_TRUTH is a pedscan output folder or one sequence file.
PREDICTIONS is either

- SemanticKITTI labels: ``PREDICTIONS/sequences/SS/labels/NNNNNN.label`` (SS the sequence
  index, at least two digits; NNNNNN the frame), uint32 per returned beam in row-major grid
  order, no-return beams skipped, ``instance << 16 | class``; class 30 or 254 = person; or
- HDF5 files named like the ground truth's (a folder, or one file against one sequence) with
  ``/label`` [T,H,W] (nonzero = human) and optionally ``/velocity`` [T,H,W,3] (m/s).

Prints the human IoU, precision and recall over all returned beams and in the paper's
distance bins (0-4, 4-8, 8+ m; no-return beams excluded), and the velocity end-point error
on the ground truth's human beams when the predictions carry velocities. A beam whose
ground-truth ``/label`` is 255 (:data:`NOT_SCORED`: a recording's own people) is not scored.
Where the ground truth has ``/class``, the false alarms by their true SemanticKITTI class;
where it has a built-in world's movers (``/movers/kind``), each kind's scored beams and how
many of them are called human (a stroller taken for its pusher, a car for a person).

**Labeled scans, per point.** GROUND_TRUTH is a SemanticKITTI sequence folder (``velodyne/``
and ``labels/``) or a dataset root (``sequences/SS/labels/``); PREDICTIONS what
``pedscan_data.predict`` writes for it: ``PRED/predictions/NNNNNN.label`` (or that folder
itself) for a sequence folder, ``PRED/sequences/SS/predictions/NNNNNN.label`` for a root (also
semantic-kitti-api's layout), uint32 per point in the scan's order. SemanticKITTI's
convention: the ground truth's person is class 30 or 254 (lower 16 bits); not scored are the
classes semantic-kitti-api's learning map makes "unlabeled" (0, 1, 52, 99) and riders (31,
32, 253, 255: a person on a vehicle is neither a hit nor a false alarm for a pedestrian
network). Where no rider is present the person IoU is semantic-kitti-api's. Prints person
IoU, precision and recall overall and by the point's range (the paper's 0-4, 4-8, 8+ m and
the street's 8-16, 16-32, 32+ m), false-alarm points per scan, and the people found (half or
more of their points called person) and missed: a person is one scan's person points of one
nonzero instance (upper 16 bits), in the bin of their median range; and the people found by
what stands just behind them (the labelled class with the most points 0-2 m behind them along
the line of sight, within 0.8 m of it, 0.2-2 m above their feet, ground left out; "nothing"
where none), where the surroundings, not the person, decide. Every file is checked before any
is scored.

Exit 0 when scored, 2 when the predictions do not match the ground truth (every missing or
mismatched file named) or a file is not what its layout says.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from .reader import PedscanError, Sequence, open_sequences
from .scans import POINT_BYTES, ScanSequence, count_problem, is_scan_layout, point_range, read_points, read_u32, scan_sequences

#: Distance bins of the paper, metres: [min, max).
BINS: tuple[tuple[float, float], ...] = ((0.0, 4.0), (4.0, 8.0), (8.0, math.inf))

#: SemanticKITTI classes that count as a person: person and moving-person.
PERSON_CLASSES: tuple[int, ...] = (30, 254)

#: A pedscan ``/label`` that is not scored (a recording's own people): neither hit nor miss.
NOT_SCORED = 255


class MismatchError(PedscanError):
    """The predictions do not cover the ground truth's frames (each problem named)."""

    def __init__(self, problems: list[str]) -> None:
        self.problems = problems
        shown = problems[:20]
        more = f"\n  ... and {len(problems) - 20} more" if len(problems) > 20 else ""
        super().__init__(
            "predictions do not match the ground truth:\n  " + "\n  ".join(shown) + more
        )


class KittiPredictions:
    """``ROOT/sequences/SS/labels/NNNNNN.label`` files."""

    format = "semantickitti"

    def __init__(self, root: Path) -> None:
        self.root = root

    def path(self, seq: Sequence, t: int) -> Path:
        return self.root / "sequences" / f"{seq.index:02d}" / "labels" / f"{t:06d}.label"

    def check(self, sequences: list[Sequence]) -> list[str]:
        problems = []
        for seq in sequences:
            folder = self.path(seq, 0).parent
            if not folder.is_dir():
                problems.append(f"{folder}: missing (sequence {seq.index}, {seq.frames} frames)")
                continue
            expected = {self.path(seq, t).name for t in range(seq.frames)}
            present = {p.name for p in folder.glob("*.label")}
            problems += [f"{folder / n}: missing" for n in sorted(expected - present)]
            problems += [
                f"{folder / n}: no such frame (sequence {seq.index} has {seq.frames} frames)"
                for n in sorted(present - expected)
            ]
        return problems

    def available(self, seq: Sequence, t: int) -> bool:
        return self.path(seq, t).is_file()

    def human(self, seq: Sequence, t: int, range_m: np.ndarray) -> np.ndarray:
        path = self.path(seq, t)
        values = np.fromfile(path, dtype="<u4")
        returned = range_m.ravel() > 0
        n = int(np.count_nonzero(returned))
        if values.size != n:
            raise MismatchError(
                [f"{path}: {values.size} labels, frame {t} of {seq.path.name} has {n} returned beams"]
            )
        grid = np.zeros(returned.size, dtype=bool)
        grid[returned] = np.isin(values & 0xFFFF, PERSON_CLASSES)
        return grid.reshape(range_m.shape)

    def velocity(self, seq: Sequence, t: int) -> np.ndarray | None:
        return None


class H5Predictions:
    """HDF5 files with ``/label`` (and optionally ``/velocity``), named like the ground truth."""

    format = "hdf5"

    def __init__(self, root: Path) -> None:
        self.root = root
        self._open: dict[Path, h5py.File] = {}
        self._usable: set[Path] = set()

    def path(self, seq: Sequence) -> Path:
        return self.root / seq.path.name if self.root.is_dir() else self.root

    def _file(self, seq: Sequence) -> h5py.File:
        p = self.path(seq)
        if p not in self._open:
            self._open[p] = h5py.File(p, "r")
        return self._open[p]

    def check(self, sequences: list[Sequence]) -> list[str]:
        if not self.root.is_dir() and len(sequences) != 1:
            return [
                (
                    f"{self.root}: one prediction file for {len(sequences)} sequences; give a "
                    "folder of files named like the ground truth's"
                )
            ]
        problems = []
        for seq in sequences:
            p = self.path(seq)
            grid = (seq.frames, seq.rows, seq.columns)
            if not p.is_file():
                problems.append(f"{p}: missing (sequence {seq.index}, {seq.frames} frames)")
                continue
            try:
                f = self._file(seq)
            except OSError as e:
                problems.append(f"{p}: not an HDF5 file ({e})")
                continue
            if "label" not in f:
                problems.append(f"{p}: no /label dataset")
            elif f["label"].shape != grid:
                problems.append(f"{p}: /label has shape {f['label'].shape}, {seq.path.name} is {list(grid)}")
            if "velocity" in f and f["velocity"].shape != grid + (3,):
                problems.append(
                    f"{p}: /velocity has shape {f['velocity'].shape}, {seq.path.name} is {list(grid + (3,))}"
                )
            elif "label" in f and f["label"].shape == grid:
                made_from = f.attrs.get("source_range_sha256")
                if isinstance(made_from, bytes):
                    made_from = made_from.decode("ascii", "replace")
                if made_from is not None and str(made_from) != seq.range_digest():
                    problems.append(f"{p}: predictions made from other data than {seq.path} (its ranges differ)")
                else:
                    self._usable.add(p)
        return problems

    def available(self, seq: Sequence, t: int) -> bool:
        return self.path(seq) in self._usable

    def human(self, seq: Sequence, t: int, range_m: np.ndarray) -> np.ndarray:
        return self._file(seq)["label"][t] != 0

    def velocity(self, seq: Sequence, t: int) -> np.ndarray | None:
        f = self._file(seq)
        return f["velocity"][t] if "velocity" in f else None


def open_predictions(path: Path) -> KittiPredictions | H5Predictions:
    """The predictions' format, from their layout; PedscanError when neither."""
    if (path / "sequences").is_dir():
        return KittiPredictions(path)
    if (path.is_file() and path.suffix == ".h5") or (path.is_dir() and any(path.glob("*.h5"))):
        return H5Predictions(path)
    raise PedscanError(
        f"{path}: unknown predictions format (neither a sequences/SS/labels/ folder of "
        "SemanticKITTI .label files nor HDF5 files named like the ground truth)"
    )


def _ratio(a: float, b: float) -> float | None:
    return a / b if b else None


@dataclass
class Counts:
    """Beam counts of one distance bin."""

    beams: int = 0
    human_beams: int = 0
    tp: int = 0
    fp: int = 0
    fn: int = 0
    epe_sum: float = 0.0
    epe_beams: int = 0
    #: Sums over the human beams of |error| along each beam's radial, tangential and up axes.
    radial_sum: float = 0.0
    tangential_sum: float = 0.0
    up_sum: float = 0.0
    axis_beams: int = 0
    #: EPE summed over the returned background beams (the sensor's own motion seen in them).
    background_epe_sum: float = 0.0
    background_beams: int = 0

    def add(self, other: Counts) -> None:
        for k in self.__dataclass_fields__:
            setattr(self, k, getattr(self, k) + getattr(other, k))

    def scores(self, velocity: bool) -> dict[str, Any]:
        out: dict[str, Any] = {
            "iou": _ratio(self.tp, self.tp + self.fp + self.fn),
            "precision": _ratio(self.tp, self.tp + self.fp),
            "recall": _ratio(self.tp, self.tp + self.fn),
            "beams": self.beams,
            "human_beams": self.human_beams,
            "tp": self.tp,
            "fp": self.fp,
            "fn": self.fn,
        }
        if velocity:
            out["epe_mps"] = _ratio(self.epe_sum, self.epe_beams)
            out["velocity_error_mps"] = {
                "radial": _ratio(self.radial_sum, self.axis_beams),
                "tangential": _ratio(self.tangential_sum, self.axis_beams),
                "up": _ratio(self.up_sum, self.axis_beams),
                "background_epe": _ratio(self.background_epe_sum, self.background_beams),
            }
        return out


@dataclass
class Report:
    """What :func:`evaluate` found; :meth:`as_dict` is the ``--json`` content."""

    ground_truth: str
    predictions: str
    format: str
    sequences: int = 0
    frames: int = 0
    velocity: bool = False
    notes: list[str] = field(default_factory=list)
    from_frame: int = 0
    bins: list[Counts] = field(default_factory=lambda: [Counts() for _ in BINS])
    #: False-alarm beams by their true SemanticKITTI class (``/class``, where it was written).
    false_alarm_classes: dict[int, int] = field(default_factory=dict)
    #: A built-in world's movers' scored beams by kind (``/movers/kind``): [called human, beams].
    movers: dict[str, list[int]] = field(default_factory=dict)

    def add_breakdown(self, seq: Sequence, kinds: list[str], t: int, range_m: np.ndarray, label: np.ndarray,
                      human: np.ndarray) -> None:
        """Frame ``t``'s false alarms by true class, and its movers' beams called human, by kind
        (``kinds``: :func:`mover_kinds`)."""
        scored = (range_m > 0) & (label != NOT_SCORED)
        f = seq.dataset("range").file
        if "class" in f:
            cls = f["class"][t]
            for k, n in zip(*np.unique(cls[human & scored & (label != 1)], return_counts=True)):
                self.false_alarm_classes[int(k)] = self.false_alarm_classes.get(int(k), 0) + int(n)
        if kinds:
            instance = seq.read("instance", t)
            first = len(seq.humans.model) + 1
            for j, kind in enumerate(kinds):
                mine = scored & (instance == first + j)
                tally = self.movers.setdefault(kind, [0, 0])
                tally[0] += int(np.count_nonzero(mine & human))
                tally[1] += int(np.count_nonzero(mine))

    def as_dict(self) -> dict[str, Any]:
        total = Counts()
        for c in self.bins:
            total.add(c)
        return {
            "ground_truth": self.ground_truth,
            "predictions": self.predictions,
            "format": self.format,
            "sequences": self.sequences,
            "frames": self.frames,
            "from_frame": self.from_frame,
            "notes": self.notes,
            "overall": total.scores(self.velocity),
            "bins": [
                {"min_m": lo, "max_m": None if math.isinf(hi) else hi, **c.scores(self.velocity)}
                for (lo, hi), c in zip(BINS, self.bins)
            ],
            "false_alarms_by_class": [
                {"class": k, "name": CLASS_NAMES.get(k, str(k)), "beams": n, "share": n / total.fp}
                for k, n in sorted(self.false_alarm_classes.items(), key=lambda kv: (-kv[1], kv[0]))
            ],
            "movers_called_human": [
                {"kind": k, "beams": n, "called_human": c, "share": _ratio(c, n)}
                for k, (c, n) in sorted(self.movers.items())
            ],
        }


def beam_axes(elevation_deg: np.ndarray, azimuth_deg: np.ndarray) -> np.ndarray:
    """[3, H, W, 3]: each beam's radial (outward), tangential (towards larger azimuth) and
    up unit vectors in the sensor frame, for the velocity error along each."""
    el = np.deg2rad(np.asarray(elevation_deg, np.float64))[:, None]
    az = np.deg2rad(np.asarray(azimuth_deg, np.float64))[None, :]
    el, az = np.broadcast_arrays(el, az)
    radial = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1)
    tangential = np.stack([-np.sin(az), np.cos(az), np.zeros_like(az)], -1)
    up = np.cross(radial, tangential)
    return np.stack([radial, tangential, up])


def _score_frame(
    report: Report, range_m: np.ndarray, truth: np.ndarray, human: np.ndarray,
    v_true: np.ndarray | None, v_pred: np.ndarray | None, axes: np.ndarray | None = None,
    scored: np.ndarray | None = None,
) -> None:
    """Adds one frame's beams to the report's bins (``axes``: :func:`beam_axes`); only the
    returned beams where ``scored`` (default: all; pedscan's: ``/label != NOT_SCORED``)."""
    returned = range_m > 0 if scored is None else (range_m > 0) & scored
    error = along = None
    if v_true is not None and v_pred is not None:
        diff = v_pred.astype(np.float64) - v_true
        error = np.linalg.norm(diff, axis=-1)
        if axes is not None:
            along = np.abs(np.einsum("hwc,ahwc->ahw", diff, axes))
    for (lo, hi), c in zip(BINS, report.bins):
        inside = returned & (range_m >= lo) & (range_m < hi)
        t, p = truth & inside, human & inside
        c.beams += int(np.count_nonzero(inside))
        c.human_beams += int(np.count_nonzero(t))
        c.tp += int(np.count_nonzero(t & p))
        c.fp += int(np.count_nonzero(p & ~t))
        c.fn += int(np.count_nonzero(t & ~p))
        if error is not None:
            c.epe_sum += float(error[t].sum())
            c.epe_beams += int(np.count_nonzero(t))
            background = inside & ~truth
            c.background_epe_sum += float(error[background].sum())
            c.background_beams += int(np.count_nonzero(background))
            if along is not None:
                c.radial_sum += float(along[0][t].sum())
                c.tangential_sum += float(along[1][t].sum())
                c.up_sum += float(along[2][t].sum())
                c.axis_beams += int(np.count_nonzero(t))


def mover_kinds(seq: Sequence) -> list[str]:
    """The sequence's movers' kinds (``/movers/kind``; mover j is instance N + 1 + j); none
    without movers or without ``/instance`` to find their beams by."""
    f = seq.dataset("range").file
    if "movers/kind" not in f or not seq.has("instance"):
        return []
    return [k.decode() if isinstance(k, bytes) else str(k) for k in f["movers/kind"][()]]


def evaluate(ground_truth: str | Path, predictions: str | Path, from_frame: int = 0) -> Report:
    """Scores ``predictions`` against ``ground_truth`` on frames ``from_frame`` onwards.

    Raises PedscanError for ground truth that is not pedscan's or predictions of an unknown
    format, MismatchError (naming every missing or mismatched file and frame, all of them at
    once) when the predictions do not match the ground truth's frames.
    """
    sequences = open_sequences(ground_truth)
    preds = open_predictions(Path(predictions))
    problems = preds.check(sequences)
    report = Report(str(ground_truth), str(predictions), preds.format, sequences=len(sequences))
    report.from_frame = from_frame
    for seq in sequences:
        axes = beam_axes(seq.elevation_deg, seq.azimuth_deg)
        kinds = mover_kinds(seq)
        noted = False
        for t in range(from_frame, seq.frames):
            if not preds.available(seq, t):
                continue
            range_m = seq.read("range", t)
            try:
                human = preds.human(seq, t, range_m)
            except MismatchError as e:
                problems += e.problems
                continue
            v_pred = preds.velocity(seq, t)
            v_true = seq.read("velocity", t) if v_pred is not None and seq.has("velocity") else None
            if v_pred is not None and v_true is None and not noted:
                report.notes.append(f"{seq.path}: no /velocity to score the predicted velocities on")
                noted = True
            report.velocity |= v_true is not None
            label = seq.read("label", t)
            _score_frame(report, range_m, label == 1, human, v_true, v_pred, axes, label != NOT_SCORED)
            report.add_breakdown(seq, kinds, t, range_m, label, human)
            report.frames += 1
    if problems:
        raise MismatchError(problems)
    return report


# --- real scans, per point ------------------------------------------------------------------

#: Scan mode's bins beyond the paper's: people in the street are far.
STREET_BINS: tuple[tuple[float, float], ...] = ((8.0, 16.0), (16.0, 32.0), (32.0, math.inf))

#: SemanticKITTI classes semantic-kitti-api's learning map sends to "unlabeled" (unlabeled,
#: outlier, other-structure, other-object): never scored.
UNLABELED_CLASSES: tuple[int, ...] = (0, 1, 52, 99)

#: Riders (bicyclist, motorcyclist, and moving): a person on a vehicle is neither a hit nor a
#: false alarm for a pedestrian network. Never scored.
RIDER_CLASSES: tuple[int, ...] = (31, 32, 253, 255)


#: What stands behind a person (:meth:`ScanReport.add_scan`): the labelled points this far
#: behind the person's centre along the line of sight (m), within ``BEHIND_ACROSS_M`` of that
#: line and ``BEHIND_UP_M`` above the person's lowest point, the ground's classes (road,
#: parking, sidewalk, other-ground, lane-marking, terrain), people, riders, unlabeled and
#: outlier points left out.
BEHIND_ALONG_M: tuple[float, float] = (0.0, 2.0)
BEHIND_ACROSS_M: float = 0.8
BEHIND_UP_M: tuple[float, float] = (0.2, 2.0)
GROUND_CLASSES: tuple[int, ...] = (40, 44, 48, 49, 60, 72)
#: Unlabeled and outlier points say nothing of what stands there.
UNKNOWN_CLASSES: tuple[int, ...] = (0, 1)


def behind_class(xyz: np.ndarray, cls: np.ndarray, person: np.ndarray) -> int:
    """The SemanticKITTI class with the most points behind the person whose points ``person``
    marks (see ``BEHIND_ALONG_M``), 0 where nothing stands there. ``xyz`` f32 [n, 3] in the
    sensor's frame, ``cls`` each point's class."""
    centre = xyz[person, :2].astype(np.float64).mean(axis=0)
    d = float(np.hypot(*centre))
    if d <= 0.0:
        return 0
    u = centre / d
    q = xyz[:, :2].astype(np.float64)
    along = q @ u - d
    across = np.abs(q @ np.array([-u[1], u[0]]))
    z0 = float(xyz[person, 2].min())
    up = xyz[:, 2] - z0
    there = ((along >= BEHIND_ALONG_M[0]) & (along < BEHIND_ALONG_M[1]) & (across < BEHIND_ACROSS_M)
             & (up >= BEHIND_UP_M[0]) & (up < BEHIND_UP_M[1])
             & ~np.isin(cls, GROUND_CLASSES + PERSON_CLASSES + RIDER_CLASSES + UNKNOWN_CLASSES) & ~person)
    if not there.any():
        return 0
    classes, counts = np.unique(cls[there], return_counts=True)
    return int(classes[np.argmax(counts)])


#: SemanticKITTI's class names (its semantic-kitti.yaml), for the false alarms by class.
CLASS_NAMES: dict[int, str] = {
    0: "unlabeled", 1: "outlier", 10: "car", 11: "bicycle", 13: "bus", 15: "motorcycle", 16: "on-rails", 18: "truck",
    20: "other-vehicle", 30: "person", 31: "bicyclist", 32: "motorcyclist", 40: "road", 44: "parking", 48: "sidewalk",
    49: "other-ground", 50: "building", 51: "fence", 52: "other-structure", 60: "lane-marking", 70: "vegetation",
    71: "trunk", 72: "terrain", 80: "pole", 81: "traffic-sign", 99: "other-object", 252: "moving-car",
    253: "moving-bicyclist", 254: "moving-person", 255: "moving-motorcyclist", 256: "moving-on-rails", 257: "moving-bus",
    258: "moving-truck", 259: "moving-other-vehicle",
}


@dataclass
class PointCounts:
    """Point counts of one distance bin (or of all points)."""

    points: int = 0
    person_points: int = 0
    tp: int = 0
    fp: int = 0
    fn: int = 0
    #: People (a scan's person points of one nonzero instance), placed by their median range.
    people: int = 0
    people_found: int = 0

    def add(self, inside: np.ndarray, truth: np.ndarray, human: np.ndarray) -> None:
        t, p = truth & inside, human & inside
        self.points += int(np.count_nonzero(inside))
        self.person_points += int(np.count_nonzero(t))
        self.tp += int(np.count_nonzero(t & p))
        self.fp += int(np.count_nonzero(p & ~t))
        self.fn += int(np.count_nonzero(t & ~p))

    def scores(self, scans: int) -> dict[str, Any]:
        return {
            "iou": _ratio(self.tp, self.tp + self.fp + self.fn),
            "precision": _ratio(self.tp, self.tp + self.fp),
            "recall": _ratio(self.tp, self.tp + self.fn),
            "points": self.points, "person_points": self.person_points, "tp": self.tp, "fp": self.fp, "fn": self.fn,
            "false_alarm_points_per_scan": _ratio(self.fp, scans),
            "people": self.people, "people_found": self.people_found, "people_missed": self.people - self.people_found,
        }


@dataclass
class ScanReport:
    """What :func:`evaluate_scans` found; :meth:`as_dict` is the ``--json`` content."""

    ground_truth: str
    predictions: str
    sequences: int = 0
    scans: int = 0
    from_frame: int = 0
    points: int = 0
    unlabeled_points: int = 0
    rider_points: int = 0
    overall: PointCounts = field(default_factory=PointCounts)
    bins: list[PointCounts] = field(default_factory=lambda: [PointCounts() for _ in BINS + STREET_BINS])
    #: False-alarm points by their true SemanticKITTI class.
    false_alarm_classes: dict[int, int] = field(default_factory=dict)
    #: People by what stands behind them (:func:`behind_class`; 0: nothing): [found, people].
    behind: dict[int, list[int]] = field(default_factory=dict)

    def add_scan(self, range_m: np.ndarray, truth_labels: np.ndarray, predicted: np.ndarray,
                 xyz: np.ndarray | None = None) -> None:
        """One scan: its points' ranges (m), ground-truth and predicted SemanticKITTI labels,
        and their positions f32 [n, 3] (the people by what stands behind them; none without)."""
        cls = truth_labels & 0xFFFF
        unlabeled, rider = np.isin(cls, UNLABELED_CLASSES), np.isin(cls, RIDER_CLASSES)
        scored = ~(unlabeled | rider)
        truth = np.isin(cls, PERSON_CLASSES) & scored
        human = np.isin(predicted & 0xFFFF, PERSON_CLASSES) & scored
        self.scans += 1
        self.points += int(range_m.size)
        self.unlabeled_points += int(np.count_nonzero(unlabeled))
        self.rider_points += int(np.count_nonzero(rider))
        self.overall.add(scored, truth, human)
        for (lo, hi), c in zip(BINS + STREET_BINS, self.bins):
            c.add(scored & (range_m >= lo) & (range_m < hi), truth, human)
        for k, n in zip(*np.unique(cls[human & ~truth], return_counts=True)):
            self.false_alarm_classes[int(k)] = self.false_alarm_classes.get(int(k), 0) + int(n)
        instance = truth_labels >> 16
        person = truth & (instance != 0)
        ids, which = np.unique(instance[person], return_inverse=True)
        hits = np.bincount(which, weights=human[person], minlength=ids.size)
        sizes = np.bincount(which, minlength=ids.size)
        r = range_m[person]
        for k in range(ids.size):
            found = int(2 * hits[k] >= sizes[k])
            middle = float(np.median(r[which == k]))
            self.overall.people += 1
            self.overall.people_found += found
            if xyz is not None:
                mine = np.zeros(person.shape, bool)
                mine[np.flatnonzero(person)[which == k]] = True
                tally = self.behind.setdefault(behind_class(xyz, cls, mine), [0, 0])
                tally[0] += found
                tally[1] += 1
            for (lo, hi), c in zip(BINS + STREET_BINS, self.bins):
                if lo <= middle < hi:
                    c.people += 1
                    c.people_found += found

    def as_dict(self) -> dict[str, Any]:
        def binned(pairs: tuple[tuple[float, float], ...], counts: list[PointCounts]) -> list[dict[str, Any]]:
            return [{"min_m": lo, "max_m": None if math.isinf(hi) else hi, **c.scores(self.scans)}
                    for (lo, hi), c in zip(pairs, counts)]

        return {
            "ground_truth": self.ground_truth,
            "predictions": self.predictions,
            "format": "semantickitti-points",
            "sequences": self.sequences,
            "scans": self.scans,
            "from_frame": self.from_frame,
            "points": self.points,
            "not_scored": {"unlabeled": self.unlabeled_points, "rider": self.rider_points},
            "overall": self.overall.scores(self.scans),
            "bins": binned(BINS, self.bins[: len(BINS)]),
            "street_bins": binned(STREET_BINS, self.bins[len(BINS):]),
            "false_alarms_by_class": [
                {"class": k, "name": CLASS_NAMES.get(k, str(k)), "points": n, "share": n / self.overall.fp}
                for k, n in sorted(self.false_alarm_classes.items(), key=lambda kv: (-kv[1], kv[0]))
            ],
            "people_by_what_stands_behind": [
                {"class": k, "name": "nothing" if k == 0 else CLASS_NAMES.get(k, str(k)), "people": n, "found": f}
                for k, (f, n) in sorted(self.behind.items(), key=lambda kv: (-kv[1][1], kv[0]))
            ],
        }


def scan_predictions(seq: ScanSequence, predictions: Path) -> Path:
    """The folder of a sequence's predicted labels: ``PRED/predictions`` (or PRED itself, when
    it holds the .label files) for a sequence folder, ``PRED/sequences/SS/predictions`` in a root."""
    folder = predictions / seq.predictions
    if seq.predictions == Path("predictions") and not folder.is_dir() and any(predictions.glob("*.label")):
        return predictions
    return folder


def evaluate_scans(ground_truth: str | Path, predictions: str | Path, from_frame: int = 0) -> ScanReport:
    """Scores per-point predictions of SemanticKITTI scans (a sequence folder or a dataset root
    with labels) on scans ``from_frame`` onwards of each sequence, SemanticKITTI's way (module
    docs). Every file is checked before any is scored: MismatchError names each missing file
    and each file of another length; PedscanError a scan that is not whole points or missing."""
    sequences = scan_sequences(Path(ground_truth), labelled=True)
    report = ScanReport(str(ground_truth), str(predictions), sequences=len(sequences), from_frame=from_frame)
    problems: list[str] = []
    work: list[tuple[Path, Path, Path, int]] = []
    for seq in sequences:
        folder = scan_predictions(seq, Path(predictions))
        if not folder.is_dir():
            problems.append(f"{folder}: missing ({len(seq.scans)} scans of {seq.folder})")
            continue
        stems = {p.stem for p in seq.scans}
        problems += [f"{p}: no such scan in {seq.folder / 'velodyne'}" for p in sorted(folder.glob("*.label")) if p.stem not in stems]
        for scan in seq.scans[from_frame:]:
            n = scan.stat().st_size // POINT_BYTES
            found = [
                f"{path}: missing" if not path.is_file() else count_problem(path, n, what, str(scan))
                for path, what in ((seq.label_path(scan), "labels"), (folder / f"{scan.stem}.label", "predicted labels"))
            ]
            problems += [f for f in found if f]
            if not any(found):
                work.append((scan, seq.label_path(scan), folder / f"{scan.stem}.label", n))
    if problems:
        raise MismatchError(problems)
    for scan, labels, predicted, n in work:
        points = read_points(scan)
        report.add_scan(point_range(points), read_u32(labels, n, "labels", scan.name),
                        read_u32(predicted, n, "predicted labels", scan.name), points[:, :3])
    return report


def draw_scan(ground_truth: str | Path, predictions: str | Path, png: Path, from_frame: int = 0) -> str:
    """A top view of the scored scan with the most person points: hits (person called person)
    green, misses red, false alarms orange, points not scored light blue, the rest grey; beside
    it, the same around the people. Returns which scan it drew."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .netio import save_figure

    best: tuple[int, Path, Path, Path] | None = None
    for seq in scan_sequences(Path(ground_truth), labelled=True):
        folder = scan_predictions(seq, Path(predictions))
        for scan in seq.scans[from_frame:]:
            n = scan.stat().st_size // POINT_BYTES
            people = int(np.isin(read_u32(seq.label_path(scan), n, "labels", scan.name) & 0xFFFF, PERSON_CLASSES).sum())
            if best is None or people > best[0]:
                best = (people, scan, seq.label_path(scan), folder / f"{scan.stem}.label")
    if best is None:
        raise PedscanError(f"{ground_truth}: no scan to draw")
    _, scan, labels, predicted = best
    points = read_points(scan)
    n = len(points)
    truth = read_u32(labels, n, "labels", scan.name) & 0xFFFF
    called = np.isin(read_u32(predicted, n, "predicted labels", scan.name) & 0xFFFF, PERSON_CLASSES)
    person = np.isin(truth, PERSON_CLASSES)
    ignored = np.isin(truth, UNLABELED_CLASSES + RIDER_CLASSES)
    kinds = [
        ("background", ~person & ~called & ~ignored, "#b0b0b0", 0.3),
        ("not scored", ignored, "#9ecae1", 0.5),
        ("hit", person & called & ~ignored, "#1a9850", 4.0),
        ("miss", person & ~called & ~ignored, "#d73027", 4.0),
        ("false alarm", ~person & called & ~ignored, "#fd8d3c", 4.0),
    ]
    fig, axes = plt.subplots(1, 2, figsize=(14, 7))
    around = points[person | (called & ~ignored)]
    centre = np.median(around[:, :2], axis=0) if len(around) else np.zeros(2)
    for ax, half, title in ((axes[0], 45.0, "within 45 m"), (axes[1], 12.0, "around the people")):
        c = np.zeros(2) if ax is axes[0] else centre
        for name, mask, colour, size in kinds:
            ax.scatter(points[mask, 0], points[mask, 1], s=size, c=colour, linewidths=0,
                       label=f"{name} ({int(mask.sum())})" if ax is axes[0] else None)
        ax.plot([0], [0], "k^", markersize=8)
        ax.set_xlim(c[0] - half, c[0] + half)
        ax.set_ylim(c[1] - half, c[1] + half)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m, forward)")
        ax.set_ylabel("y (m, left)")
        ax.set_title(f"{scan.parent.parent.name}/{scan.name}: {title}")
    axes[0].legend(loc="lower left", markerscale=3, fontsize=9)
    fig.tight_layout()
    save_figure(fig, png)
    return str(scan)


def format_scan_report(d: dict[str, Any]) -> str:
    """The printed summary of :meth:`ScanReport.as_dict`."""
    o, skip = d["overall"], d["not_scored"]
    lines = [
        (f"ground truth: {d['sequences']} sequences, {d['scans']} scans, {d['points']} points "
         f"({o['points']} scored; not scored: {skip['unlabeled']} unlabeled, {skip['rider']} rider)"),
        f"predictions: {d['format']}",
        (f"person IoU {_fmt(o['iou'])}  precision {_fmt(o['precision'])}  recall {_fmt(o['recall'])}  "
         f"(TP {o['tp']}, FP {o['fp']}, FN {o['fn']})"),
        (f"false alarms {_fmt(o['false_alarm_points_per_scan'], 1)} points per scan; people found "
         f"{o['people_found']} of {o['people']} (half or more of their points)"),
        "",
        f"{'distance':<10}{'IoU':>8}{'precision':>11}{'recall':>8}{'person points':>15}{'people found':>14}{'FA/scan':>9}",
    ]
    for b in d["bins"] + d["street_bins"]:
        name = f"{b['min_m']:g}-{b['max_m']:g} m" if b["max_m"] is not None else f"{b['min_m']:g}+ m"
        people = f"{b['people_found']}/{b['people']}"
        lines.append(f"{name:<10}{_fmt(b['iou']):>8}{_fmt(b['precision']):>11}{_fmt(b['recall']):>8}"
                     f"{b['person_points']:>15}{people:>14}{_fmt(b['false_alarm_points_per_scan'], 1):>9}")
    if d["false_alarms_by_class"]:
        lines.append("false alarms by true class: " + ", ".join(f"{c['name']} {100 * c['share']:.0f} %"
                                                                for c in d["false_alarms_by_class"][:8]))
    if d.get("people_by_what_stands_behind"):
        lines.append("people found by what stands 0-2 m behind them: " + ", ".join(
            f"{c['name']} {c['found']}/{c['people']}" for c in d["people_by_what_stands_behind"]))
    return "\n".join(lines)


def _fmt(x: float | None, digits: int = 4) -> str:
    return "n/a" if x is None else f"{x:.{digits}f}"


def format_report(d: dict[str, Any]) -> str:
    """The printed summary of :meth:`Report.as_dict`."""
    o = d["overall"]
    velocity = "epe_mps" in o
    lines = [
        (
            f"ground truth: {d['sequences']} sequences, {d['frames']} frames, "
            f"{o['beams']} returned beams, {o['human_beams']} human beams"
        ),
        f"predictions: {d['format']}",
        (
            f"human IoU {_fmt(o['iou'])}  precision {_fmt(o['precision'])}  "
            f"recall {_fmt(o['recall'])}  (TP {o['tp']}, FP {o['fp']}, FN {o['fn']})"
        ),
    ]
    lines += [f"note: {n}" for n in d["notes"]]
    if velocity:
        lines.append(f"velocity end-point error on human beams: {_fmt(o['epe_mps'], 3)} m/s")
        v = o["velocity_error_mps"]
        lines.append(
            f"  mean |error| along each beam: radial {_fmt(v['radial'], 3)}, tangential "
            f"{_fmt(v['tangential'], 3)}, up {_fmt(v['up'], 3)} m/s; background beams' EPE "
            f"{_fmt(v['background_epe'], 3)} m/s"
        )
    header = f"{'distance':<10}{'IoU':>8}{'precision':>11}{'recall':>8}{'human beams':>13}"
    lines += ["", header + (f"{'EPE m/s':>9}" if velocity else "")]
    for b in d["bins"]:
        name = f"{b['min_m']:g}-{b['max_m']:g} m" if b["max_m"] is not None else f"{b['min_m']:g}+ m"
        row = (
            f"{name:<10}{_fmt(b['iou']):>8}{_fmt(b['precision']):>11}{_fmt(b['recall']):>8}"
            f"{b['human_beams']:>13}"
        )
        lines.append(row + (f"{_fmt(b['epe_mps'], 3):>9}" if velocity else ""))
    if d.get("false_alarms_by_class"):
        lines.append("false alarms by true class: " + ", ".join(f"{c['name']} {100 * c['share']:.0f} %"
                                                                for c in d["false_alarms_by_class"][:8]))
    if d.get("movers_called_human"):
        lines.append("movers' beams called human: " + ", ".join(
            f"{m['kind']} {m['called_human']} of {m['beams']}"
            + (f" ({100 * m['share']:.1f} %)" if m["share"] is not None else "")
            for m in d["movers_called_human"]))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """The command line; returns the exit code (0 scored, 2 bad or mismatched input)."""
    parser = argparse.ArgumentParser(
        prog="python -m pedscan_data.evaluate",
        description="Human IoU, precision, recall (and velocity EPE) of predictions "
        "against pedscan ground truth or SemanticKITTI's labeled scans.",
    )
    parser.add_argument(
        "ground_truth", type=Path,
        help="pedscan output folder or sequence file; or labeled scans: a SemanticKITTI sequence folder "
        "(velodyne/, labels/) or dataset root (sequences/SS/labels/)",
    )
    parser.add_argument(
        "predictions", type=Path,
        help="SemanticKITTI folder or HDF5 file(s); for scans, predict's folder (predictions/ or sequences/SS/predictions/)",
    )
    parser.add_argument("--json", type=Path, metavar="FILE", help="also write the scores as JSON")
    parser.add_argument("--png", type=Path, metavar="FILE",
                        help="scans: also draw the scan with the most person points from above (hits, misses, "
                        "false alarms)")
    parser.add_argument(
        "--from-frame", type=int, default=0, metavar="K",
        help="score frames K onwards of each sequence (an N-frame network's full windows: K = N-1)",
    )
    args = parser.parse_args(argv)
    try:
        if args.from_frame < 0:
            raise PedscanError(f"--from-frame {args.from_frame}: not a frame index")
        if is_scan_layout(args.ground_truth, labelled=True):
            report = evaluate_scans(args.ground_truth, args.predictions, args.from_frame).as_dict()
            text = format_scan_report(report)
            if args.png is not None:
                text += f"\nwrote {args.png} ({draw_scan(args.ground_truth, args.predictions, args.png, args.from_frame)})"
        elif args.png is not None:
            raise PedscanError("--png draws labeled scans; a pedscan output has `pedscan stats` and --png of generate")
        elif is_scan_layout(args.ground_truth):
            raise PedscanError(f"{args.ground_truth}: scans without labels/ to score against")
        else:
            report = evaluate(args.ground_truth, args.predictions, args.from_frame).as_dict()
            text = format_report(report)
    except (PedscanError, FileNotFoundError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(text)
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
