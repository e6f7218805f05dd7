"""Calibrates a model file's human threshold on validation sequences.

    python -m pedscan_data.calibrate MODEL --val DATA [DATA...] [--out FILE] [--score-from K]
                                     [--grow] [--device auto|cpu|cuda]

The threshold that maximizes the IoU over the validation beams, found exactly as ``train``
finds it at the end of a run (:func:`~pedscan_data.train.calibrate`), for the prediction the
file makes (one pass, or mirrored where its ``mirror`` says so). Several DATA folders are
pooled: generated streets with generated people composited into recorded streets, say, so
that the threshold is chosen on data nearer the real scans it will meet. Validation data is
generated data, never a test set. MODEL is rewritten in place, or the result written to
``--out``; the file records the calibration (``training.calibration``: the figures and the
sequences). With ``--grow`` region growing from confident beams is chosen as well
(:mod:`pedscan_data.grow`: a lower cut and a range step, the threshold then for the grown
margins) and kept where it raises the validation IoU by more than 0.001; without it, a
file's growing is removed (its new threshold is for plain margins). Exit 0 done, 2 bad input
(the input named); nothing is written on failure.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .reader import PedscanError, sequence_paths


def check_arguments(args: argparse.Namespace) -> Path:
    """The checks a calibrating command makes before it reads anything big (``--val``,
    ``--score-from``, ``--out``); the file to write."""
    if args.score_from is not None and args.score_from < 0:
        raise PedscanError(f"--score-from {args.score_from}: not a frame index")
    for v in args.val:
        try:
            sequence_paths(v)
        except (PedscanError, FileNotFoundError) as e:
            raise PedscanError(f"--val {e}") from e
    out = Path(args.out)
    if out.is_dir():
        raise PedscanError(f"--out {out}: a folder (a model file is wanted)")
    return out


def write_calibrated(save: Callable[[Path], None], out: Path, args: argparse.Namespace) -> dict[str, Any]:
    """A model file that ``save`` writes, calibrated on ``args.val`` (pooled) and moved to
    ``out`` only once complete; on failure nothing is left (an earlier ``out`` stays)."""
    from .predict import pick_device
    from .train import calibrate_model

    device = pick_device(args.device)
    tmp = out.with_name(out.name + ".calibrating")
    try:
        save(tmp)
        c = calibrate_model(tmp, [Path(v) for v in args.val], device, args.score_from, grow=args.grow)
        os.replace(tmp, out)
    finally:
        if tmp.exists():
            tmp.unlink()
    return c


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments a calibrating command shares besides its ``--val``: ``--score-from``,
    ``--grow``, ``--device``."""
    p.add_argument("--score-from", type=int, metavar="K", help="calibrate on frames K onwards (default: the network's frames - 1)")
    p.add_argument("--grow", action="store_true",
                   help="also choose region growing from confident beams (a lower cut and a range step), kept where it helps")
    p.add_argument("--device", default="auto", help="auto | cpu | cuda (default auto)")


def run(args: argparse.Namespace) -> int:
    from .netio import load_file

    model = Path(args.model)
    load_file(model)  # a missing or damaged file is named before anything else
    args.out = args.out or str(model)
    out = check_arguments(args)
    c = write_calibrated(lambda tmp: shutil.copyfile(model, tmp), out, args)
    print(f"{out}: human threshold {c['human_threshold']:.4f} (calibrated on {c['beams']} beams of "
          f"{len(args.val)} folder{'s' if len(args.val) > 1 else ''}{', mirrored' if c['mirrored'] else ''}: "
          f"IoU {c['iou_argmax']:.4f} at the argmax -> {c['iou_calibrated']:.4f})")
    if args.grow:
        g = c.get("grow")
        print(f"{out}: growing from margin {g['margin']:.3f} over range steps < {g['step_m']} m "
              f"(IoU {c['iou_plain']:.4f} without)" if g else f"{out}: growing does not help; not kept")
    return 0


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m pedscan_data.calibrate", description=__doc__.split("\n\n")[0])
    p.add_argument("model", metavar="MODEL", help="a model file (rewritten in place unless --out)")
    p.add_argument("--out", metavar="FILE", help="write the calibrated model here instead")
    p.add_argument("--val", required=True, nargs="+", metavar="DATA",
                   help="validation sequences (pedscan output folders or files), pooled")
    add_arguments(p)
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return run(args)
    except (PedscanError, FileNotFoundError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
