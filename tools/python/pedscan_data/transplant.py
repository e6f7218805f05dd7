"""Is it the people or what stands around them? A network's response to real and generated
people, each in its own scan and transplanted into the other's.

    python -m pedscan_data.transplant MODEL REAL GENERATED [--columns 8] [--range 8 24] [--json FILE]

REAL and GENERATED are labeled scans in SemanticKITTI's layout (a sequence folder or dataset
root with ``labels/``: real scans, and pedscan's ``--formats semantickitti`` export of the
world the network was trained on). Both are put on the model's grid by ``pedscan project``, as
``predict`` does, and each scan is seen alone (an N-frame network sees it as a still scene).
A person is one instance of class 30 or 254 in one scan whose median range lies in
``--range``, with at least 20 cells and spread over at most 2 m, its strays left out
(:mod:`pedscan_data.people`).

Per person the median human margin (logit of human minus background, over its cells; as
``predict`` gives it: mirrored and grown where the model file asks) and whether it exceeds
the model's threshold (found), in four settings:

- ``real``: real people in their scans; ``generated``: generated people in theirs;
- ``real in generated``: a real person's columns, ``--columns`` either side of it, every row,
  put into a generated scan at the same columns (its k-th scan for the k-th person, cycling);
- ``generated in real``: the other way round;
- ``real, backdrop pushed back`` and ``generated, backdrop pushed back``: the people in their
  own scans with their backdrop moved 8 m farther: the cells of their rows, ``BACKDROP_COLUMNS``
  either side of their centre, that are not theirs and hold a return 0-2 m behind their median
  range (a stall's back wall, a shop front, a parked car).

Beside the settings, the backdrop share of each side: per person, the share of those cells
(its rows, ``BACKDROP_COLUMNS`` either side, not its own) holding a return 0-2 m behind it;
their mean over the people.

- ``real, alone`` and ``generated, alone``: the people in their own scans with every other
  return taken out but the ground's (SemanticKITTI's road, parking, sidewalk, other ground and
  terrain: ``GROUND_CLASSES``), so nothing stands around them;
- ``real, alone, a quarter narrower`` and the same for the generated: alone, and in each of
  their rows the outer eighth of their cells at either side taken out too (``NARROWER``), as
  if they were a quarter narrower (0.53 m across becomes 0.40 m).

When a real person is missed in its own scan and found among generated surroundings (and a
generated one missed among real surroundings), the surroundings decide, not the person's own
shape; ``--columns 0`` moves the people's columns alone. When one is missed alone and found
alone but narrower, its width decides.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from .people import core, person_instances
from .reader import PedscanError
from .scans import NO_CELL, POINT_BYTES, find_pedscan, projected_scans, read_points, read_u32, scan_sequences, sensor_argument

#: A person needs this many cells of the grid.
MIN_CELLS = 20

#: Columns either side of a person's centre where its backdrop is looked for (1 m at 14 m on
#: a 2,048-column grid).
BACKDROP_COLUMNS = 16

#: Returns this far behind a person's median range are its backdrop, m.
BACKDROP_M = (0.0, 2.0)

#: How much farther ``backdrop pushed back`` moves them, m.
BACKDROP_PUSH_M = 8.0

#: SemanticKITTI's ground classes (road, parking, sidewalk, other ground, terrain): what a
#: person ``alone`` keeps around it.
GROUND_CLASSES = (40, 44, 48, 49, 72)

#: The share of a person's cells in each of its rows that ``a quarter narrower`` takes out, half
#: at either side.
NARROWER = 0.25

#: People taken from each side at most (the first in file order).
MAX_PEOPLE = 200


def centre_column(col: np.ndarray, cols: int) -> int:
    """The circular mean of columns (a person across the turn's seam keeps its place)."""
    return int(np.round(np.angle(np.exp(2j * np.pi * col / cols).mean()) / (2 * np.pi) * cols)) % cols


def grid_people(points: np.ndarray, labels: np.ndarray, cells: np.ndarray, range_m: np.ndarray,
                band: tuple[float, float]) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The people of one projected scan: (rows, columns, median range) of each one's cells."""
    cols = range_m.shape[1]
    out = []
    for m in person_instances(labels, cells != NO_CELL):
        m = core(points, m)
        if m is None:
            continue
        c = np.unique(cells[m].astype(np.int64))
        if len(c) < MIN_CELLS:
            continue
        r, col = np.divmod(c, cols)
        if np.ptp((col - centre_column(col, cols) + cols // 2) % cols) > cols // 4:
            continue
        d = float(np.median(range_m[r, col]))
        if band[0] <= d < band[1]:
            out.append((r, col, d))
    return out


def backdrop(image: np.ndarray, rows: np.ndarray, cols: np.ndarray, range_m: float) -> tuple[np.ndarray, int]:
    """A person's backdrop cells in ``image`` (a mask) and how many cells were looked at: of
    its rows, ``BACKDROP_COLUMNS`` either side of its centre, those not its own; the backdrop
    those holding a return ``BACKDROP_M`` behind its median range."""
    w = image.shape[1]
    near = np.zeros(image.shape, bool)
    near[rows.min():rows.max() + 1, (centre_column(cols, w) + np.arange(-BACKDROP_COLUMNS, BACKDROP_COLUMNS + 1)) % w] = True
    near[rows, cols] = False
    behind = image - range_m
    return near & (image > 0) & (behind >= BACKDROP_M[0]) & (behind < BACKDROP_M[1]), int(near.sum())


def alone(image: np.ndarray, ground: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """``image`` with every return taken out (0) but the person's cells and the ground's."""
    out = np.where(ground, image, 0.0).astype(image.dtype)
    out[rows, cols] = image[rows, cols]
    return out


def narrower(rows: np.ndarray, cols: np.ndarray, width: int) -> np.ndarray:
    """Which of a person's cells stay when it is made narrower: in each of its rows, the outer
    ``NARROWER / 2`` of its cells (by column, counted from its centre across the seam) at
    either side go."""
    rel = (cols - centre_column(cols, width) + width // 2) % width
    keep = np.ones(len(rows), bool)
    for r in np.unique(rows):
        at = np.nonzero(rows == r)[0]
        k = int(round(len(at) * NARROWER / 2))
        if k:
            order = at[np.argsort(rel[at], kind="stable")]
            keep[order[:k]] = keep[order[-k:]] = False
    return keep


def collect(binary: Path, scans: Path, work: Path, sensor: str, band: tuple[float, float]) -> tuple[list[np.ndarray], list[np.ndarray], list[tuple[int, np.ndarray, np.ndarray, float]]]:
    """The range images of every scan, their ground cells (``GROUND_CLASSES``), and (scan
    index, rows, columns, range) of their people."""
    images: list[np.ndarray] = []
    grounds: list[np.ndarray] = []
    people: list[tuple[int, np.ndarray, np.ndarray, float]] = []
    for seq in scan_sequences(scans, labelled=True):
        for _, p in projected_scans(binary, seq, work, sensor):
            n = p.file.stat().st_size // POINT_BYTES
            labels = read_u32(seq.label_path(p.file), n, "labels", p.file.name)
            for r, c, d in grid_people(read_points(p.file), labels, p.cells, p.range_m, band):
                if len(people) < MAX_PEOPLE:
                    people.append((len(images), r, c, d))
            ground = np.zeros(p.range_m.shape, bool)
            on = p.cells != NO_CELL
            ground.flat[p.cells[on].astype(np.int64)] = np.isin(labels[on] & 0xFFFF, GROUND_CLASSES)
            images.append(p.range_m)
            grounds.append(ground)
    return images, grounds, people


def transplant(model: Path, real: Path, generated: Path, columns: int = 8, band: tuple[float, float] = (8.0, 24.0),
               pedscan: Path | None = None) -> dict[str, Any]:
    """The four settings' people, median margins and shares found (module docs)."""
    from .grow import as_predicted, model_grow
    from .model import input_channels
    from .netio import load_net
    from .predict import human_margin, mirrored, model_sensor, stream

    net, obj = load_net(model, "cpu")
    cut = human_margin(obj)
    mirror = mirrored(obj, None)  # the margins `predict` would give: mirrored where the file asks,
    grow = model_grow(obj, model)  # grown where it asks
    spec = model_sensor(obj)
    if spec is None:
        raise PedscanError(f"{model}: the model file does not say which sensor's grid it was trained on")
    binary = find_pedscan(pedscan)
    with tempfile.TemporaryDirectory(prefix="pedscan-transplant-") as tmp:
        sensor = sensor_argument(spec, Path(tmp))
        real_img, real_ground, real_people = collect(binary, real, Path(tmp) / "real", sensor, band)
        gen_img, gen_ground, gen_people = collect(binary, generated, Path(tmp) / "generated", sensor, band)
    if not real_people or not gen_people:
        empty = real if not real_people else generated
        raise PedscanError(f"{empty}: no person at {band[0]:g}-{band[1]:g} m with {MIN_CELLS} cells or more")

    def margin(r: np.ndarray) -> np.ndarray:
        return as_predicted(next(stream(net, [input_channels(r)], "cpu", mirror=mirror))[1], r, grow)

    def moved(source: list[np.ndarray], people: list[tuple[int, np.ndarray, np.ndarray, float]], target: list[np.ndarray]) -> list[float]:
        out = []
        for k, (s, r, c, _) in enumerate(people):
            image = target[k % len(target)].copy()
            w = image.shape[1]
            cols = (centre_column(c, w) + np.arange(-columns, columns + 1)) % w
            image[:, cols] = source[s][:, cols]
            image[r, c] = source[s][r, c]
            out.append(float(np.median(margin(image)[r, c])))
        return out

    def own(images: list[np.ndarray], people: list[tuple[int, np.ndarray, np.ndarray, float]]) -> list[float]:
        cache: dict[int, np.ndarray] = {}
        out = []
        for s, r, c, _ in people:
            if s not in cache:
                cache[s] = margin(images[s])
            out.append(float(np.median(cache[s][r, c])))
        return out

    # Each person's backdrop (mask, cells looked at), found once for both uses below.
    real_bd = [backdrop(real_img[s], r, c, d) for s, r, c, d in real_people]
    gen_bd = [backdrop(gen_img[s], r, c, d) for s, r, c, d in gen_people]

    def pushed(images: list[np.ndarray], people: list[tuple[int, np.ndarray, np.ndarray, float]],
               backdrops: list[tuple[np.ndarray, int]]) -> list[float]:
        out = []
        for (s, r, c, _), (mask, _) in zip(people, backdrops):
            image = images[s].copy()
            image[mask] += BACKDROP_PUSH_M
            out.append(float(np.median(margin(image)[r, c])))
        return out

    def by_itself(images: list[np.ndarray], grounds: list[np.ndarray], people: list[tuple[int, np.ndarray, np.ndarray, float]],
                  thinner: bool) -> list[float]:
        out = []
        for s, r, c, _ in people:
            image = alone(images[s], grounds[s], r, c)
            if thinner:
                keep = narrower(r, c, image.shape[1])
                image[r[~keep], c[~keep]] = 0.0
                r, c = r[keep], c[keep]
            out.append(float(np.median(margin(image)[r, c])))
        return out

    def share(backdrops: list[tuple[np.ndarray, int]]) -> float:
        return float(np.mean([mask.sum() / max(looked, 1) for mask, looked in backdrops]))

    settings = {
        "real": own(real_img, real_people),
        "generated": own(gen_img, gen_people),
        "real in generated": moved(real_img, real_people, gen_img),
        "generated in real": moved(gen_img, gen_people, real_img),
        "real, backdrop pushed back": pushed(real_img, real_people, real_bd),
        "generated, backdrop pushed back": pushed(gen_img, gen_people, gen_bd),
        "real, alone": by_itself(real_img, real_ground, real_people, False),
        "generated, alone": by_itself(gen_img, gen_ground, gen_people, False),
        "real, alone, a quarter narrower": by_itself(real_img, real_ground, real_people, True),
        "generated, alone, a quarter narrower": by_itself(gen_img, gen_ground, gen_people, True),
    }
    return {
        "model": str(model), "real": str(real), "generated": str(generated), "columns": columns, "range_m": list(band),
        "threshold_margin": cut,
        "backdrop_share": {"real": share(real_bd), "generated": share(gen_bd)},
        "settings": {k: {"people": len(v), "median_margin": float(np.median(v)), "found": float(np.mean(np.array(v) > cut))}
                     for k, v in settings.items()},
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m pedscan_data.transplant", description=__doc__.split("\n\n")[0])
    p.add_argument("model", type=Path, help="model file (.pt) or run folder")
    p.add_argument("real", type=Path, help="real labeled scans (SemanticKITTI layout)")
    p.add_argument("generated", type=Path, help="generated labeled scans (pedscan's semantickitti export)")
    p.add_argument("--columns", type=int, default=8, help="columns of surroundings moved with a person, either side (default 8)")
    p.add_argument("--range", type=float, nargs=2, default=(8.0, 24.0), metavar=("MIN", "MAX"), help="people at these ranges, m")
    p.add_argument("--pedscan", type=Path, default=None, help="the pedscan binary (default: $PEDSCAN, the checkout's, PATH)")
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args(argv)
    if args.columns < 0 or not (0 <= args.range[0] < args.range[1]):
        print("error: --columns must not be negative and --range MIN MAX must rise from 0 or more", file=sys.stderr)
        return 2
    try:
        d = transplant(args.model, args.real, args.generated, args.columns, tuple(args.range), args.pedscan)
    except PedscanError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"people at {d['range_m'][0]:g}-{d['range_m'][1]:g} m, {d['columns']} columns either side moved with each; "
          f"threshold margin {d['threshold_margin']:.2f}")
    print("setting                                 people  median margin  found")
    for k, v in d["settings"].items():
        print(f"{k:<39} {v['people']:>6}  {v['median_margin']:>13.2f}  {v['found']:>5.2f}")
    b = d["backdrop_share"]
    print(f"backdrop (their rows, {BACKDROP_COLUMNS} columns either side, a return {BACKDROP_M[0]:g}-{BACKDROP_M[1]:g} m "
          f"behind them): real {b['real']:.2f}, generated {b['generated']:.2f} of the cells")
    if args.json:
        args.json.write_text(json.dumps(d, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
