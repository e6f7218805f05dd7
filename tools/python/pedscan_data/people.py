"""What the people of labeled scans look like to the sensor, by distance.

    python -m pedscan_data.people SCANS [SCANS...] [--json FILE]

SCANS is a SemanticKITTI sequence folder or dataset root with ``labels/`` (real scans, or
pedscan's own ``--formats semantickitti`` export). A person is one instance (upper 16 bits of
a label) of class 30 or 254 in one scan. Per distance bin (the median horizontal range of its
points), the people and the medians of: points; width (the points' spread in azimuth times
that range: what a range image shows across); height seen (highest minus lowest point);
lowest and highest point above the ground (the 5th percentile height of the other points
within 3 m, horizontally); and the share whose lowest point is more than 0.5 m above the
ground (legs hidden: behind a parked car, a hedge). A person's points more than 1.5 m from
its median position are strays (a few points labelled with its id elsewhere in the scan, as
SemanticKITTI has) and left out of it. An instance with more than a tenth of its points
strays, or the rest spread over more than 2 m horizontally, is several people under one id:
counted as ``merged`` and left out; so is one of fewer than 5 points (``few``).

Set real scans beside a generated export to see how the two differ (docs/real-data.md).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from collections.abc import Iterator
from typing import Any

import numpy as np

from .evaluate import PERSON_CLASSES
from .reader import PedscanError
from .scans import POINT_BYTES, read_points, read_u32, scan_sequences

#: Distance bins, m (the last open).
BINS_M: tuple[float, ...] = (0.0, 8.0, 12.0, 16.0, 24.0, 32.0)

#: Horizontal radius of the ground around a person, m.
GROUND_RADIUS_M = 3.0

#: Other points the ground estimate needs.
GROUND_POINTS = 10

#: A person whose lowest point is this far above the ground has its legs hidden, m.
LEGS_HIDDEN_M = 0.5

#: An instance spread wider than this is several people, m.
MERGED_M = 2.0

#: A person's points farther than this from its median position are strays, m.
STRAY_M = 1.5

#: An instance with more than this share of strays is several people.
STRAY_SHARE = 0.1

#: Fewer points than this say nothing of a shape.
FEW_POINTS = 5


def person_instances(labels: np.ndarray, keep: np.ndarray | None = None) -> Iterator[np.ndarray]:
    """The points of each person instance (class 30 or 254; among ``keep`` if given), a mask each."""
    cls, inst = labels & 0xFFFF, labels >> 16
    person = np.isin(cls, PERSON_CLASSES) if keep is None else np.isin(cls, PERSON_CLASSES) & keep
    for i in np.unique(inst[person]):
        yield person & (inst == i)


def merged(points: np.ndarray, m: np.ndarray) -> bool:
    """Whether the points ``m`` of one instance spread over more than :data:`MERGED_M` horizontally."""
    return bool(np.ptp(points[m, :2], axis=0).max() > MERGED_M)


def core(points: np.ndarray, m: np.ndarray) -> np.ndarray | None:
    """The points ``m`` of one instance without its strays (farther than :data:`STRAY_M` from
    its median position, horizontally: a few points labelled with its id elsewhere in the
    scan); None where it is several people (strays more than :data:`STRAY_SHARE` of its points,
    or the rest :func:`merged`)."""
    xy = points[:, :2].astype(np.float64)
    centre = np.median(xy[m], axis=0)
    near = m & (np.hypot(*(xy - centre).T) <= STRAY_M)
    if near.sum() < (1.0 - STRAY_SHARE) * m.sum() or merged(points, near):
        return None
    return near


def scan_people(points: np.ndarray, labels: np.ndarray) -> tuple[list[dict[str, float]], int, int]:
    """The people of one scan (dicts of range_m, points, width_m, height_m, bottom_m, top_m; the
    last two NaN without ground around), and the instances merged and with few points."""
    person = np.isin(labels & 0xFFFF, PERSON_CLASSES)
    xy = points[:, :2].astype(np.float64)
    z = points[:, 2].astype(np.float64)
    out: list[dict[str, float]] = []
    spread = few = 0
    for m in person_instances(labels):
        if m.sum() < FEW_POINTS:
            few += 1
            continue
        kept = core(points, m)
        if kept is None:
            spread += 1
            continue
        m = kept
        p = xy[m]
        centre = np.median(p, axis=0)
        horizontal = np.hypot(p[:, 0], p[:, 1])
        rng = float(np.median(horizontal))
        az = np.arctan2(p[:, 1], p[:, 0])
        az = np.angle(np.exp(1j * (az - np.arctan2(centre[1], centre[0]))))  # about the centre, no wrap
        near = ~person & (np.hypot(*(xy - centre).T) < GROUND_RADIUS_M)
        ground = float(np.percentile(z[near], 5)) if near.sum() >= GROUND_POINTS else float("nan")
        out.append({
            "range_m": rng, "points": int(m.sum()), "width_m": float(np.ptp(az) * rng),
            "height_m": float(np.ptp(z[m])), "bottom_m": float(z[m].min() - ground), "top_m": float(z[m].max() - ground),
        })
    return out, spread, few


def summarize(people: list[dict[str, float]]) -> list[dict[str, Any]]:
    """Per distance bin: people and the medians (module docs)."""
    rows = []
    edges = list(BINS_M) + [float("inf")]
    for lo, hi in zip(edges, edges[1:]):
        b = [p for p in people if lo <= p["range_m"] < hi]
        row: dict[str, Any] = {"min_m": lo, "max_m": None if hi == float("inf") else hi, "people": len(b)}
        for key in ("points", "width_m", "height_m", "bottom_m", "top_m"):
            vals = np.array([p[key] for p in b], dtype=np.float64)
            vals = vals[np.isfinite(vals)]
            row[key] = float(np.median(vals)) if vals.size else None
        grounded = [p for p in b if np.isfinite(p["bottom_m"])]
        row["legs_hidden"] = float(np.mean([p["bottom_m"] > LEGS_HIDDEN_M for p in grounded])) if grounded else None
        rows.append(row)
    return rows


def describe(path: Path) -> dict[str, Any]:
    people: list[dict[str, float]] = []
    merged = few = scans = 0
    for seq in scan_sequences(path, labelled=True):
        for scan in seq.scans:
            n = scan.stat().st_size // POINT_BYTES
            got, m, f = scan_people(read_points(scan), read_u32(seq.label_path(scan), n, "labels", scan.name))
            people += got
            merged, few, scans = merged + m, few + f, scans + 1
    return {"scans": str(path), "scan_count": scans, "people": len(people), "merged": merged, "few": few,
            "bins": summarize(people)}


def format_report(d: dict[str, Any]) -> str:
    def f(x: Any, digits: int = 2) -> str:
        return "n/a" if x is None else f"{x:.{digits}f}"

    lines = [f"{d['scans']}: {d['scan_count']} scans, {d['people']} people "
             f"(left out: {d['merged']} instances of several people, {d['few']} of under {FEW_POINTS} points)",
             "distance   people  points  width m  height seen m  lowest m  highest m  legs hidden"]
    for b in d["bins"]:
        name = f"{b['min_m']:g}-{b['max_m']:g} m" if b["max_m"] is not None else f"{b['min_m']:g}+ m"
        lines.append(f"{name:<10} {b['people']:>6}  {f(b['points'], 0):>6}  {f(b['width_m']):>7}  {f(b['height_m']):>13}  "
                     f"{f(b['bottom_m']):>8}  {f(b['top_m']):>9}  {f(b['legs_hidden']):>11}")
    return "\n".join(lines)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m pedscan_data.people", description=__doc__.split("\n\n")[0])
    p.add_argument("scans", type=Path, nargs="+", help="SemanticKITTI sequence folder(s) or dataset root(s) with labels/")
    p.add_argument("--json", type=Path, default=None, help="also write the figures as JSON (a list, one per SCANS)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        reports = [describe(s) for s in args.scans]
    except PedscanError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print("\n\n".join(format_report(r) for r in reports))
    if args.json:
        args.json.write_text(json.dumps(reports, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
