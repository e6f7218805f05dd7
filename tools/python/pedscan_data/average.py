"""Averages the weights of trained networks into one model file (a uniform "model soup").

    python -m pedscan_data.average MODEL MODEL [MODEL...] --out FILE --val DATA [DATA...]
                                   [--score-from K] [--[no-]mirror] [--device auto|cpu|cuda]

Networks fine-tuned from one file (runs of ``train --init`` from it, or one from another) often
lie in one basin of the loss, where the mean of their weights predicts better than each of
them (Izmailov et al. 2018, stochastic weight averaging; Wortsman et al. 2022, model soups).
The network has no batch normalization, so the mean of its weights is the whole model; what
is its own is the human threshold, calibrated on DATA (validation sequences, several folders
pooled; never a test set) as ``train`` calibrates, for the prediction the file asks for (one pass or mirrored).

The files must describe one network (the same ``net``: frames, width, inputs, rows'
elevations) on one grid (``sensor``), with the same weights' names and shapes, all finite;
each weight of FILE is their mean (summed in float64). FILE records ``training.averaged``
(each file's name, SHA-256 and training step), the grid, the calibration, where it was made,
and the files' licences, each once. ``mirror``: the files' own where they agree, else
``--mirror`` / ``--no-mirror`` must say. Exit 0 written, 2 bad input (the file named);
FILE is written only complete.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path
from typing import Any

from .reader import PedscanError


def averaged(models: list[Path], mirror: bool | None = None) -> dict[str, Any]:
    """The model file of the mean of ``models``' weights, not yet calibrated; PedscanError
    naming the file that cannot take part."""
    import torch

    from .netio import load_file
    from .predict import model_sensor

    if len(models) < 2:
        raise PedscanError("average: two model files or more (one is its own average)")
    if len(set(Path(m).resolve() for m in models)) < len(models):
        raise PedscanError("average: a model file given twice (weight it by training it again, not by naming it twice)")
    objs = []
    for m in models:
        obj = load_file(Path(m))
        if not isinstance(obj.get("net"), dict) or not isinstance(obj.get("state_dict"), dict):
            raise PedscanError(f"{m}: not a pedscan model file (no network or weights)")
        objs.append(obj)
    first, ref = objs[0], objs[0]["state_dict"]
    for m, obj in zip(models, objs):
        if obj["net"] != first["net"]:
            diff = sorted(k for k in set(obj["net"]) | set(first["net"]) if obj["net"].get(k) != first["net"].get(k))
            raise PedscanError(f"{m}: another network than {models[0]} (differs in: {', '.join(diff)})")
        if model_sensor(obj) != model_sensor(first):
            raise PedscanError(f"{m}: trained on another grid than {models[0]}")
        sd = obj["state_dict"]
        if set(sd) != set(ref) or any(tuple(sd[k].shape) != tuple(ref[k].shape) for k in ref):
            raise PedscanError(f"{m}: its weights' names or shapes differ from {models[0]}'s")
        bad = [k for k, v in sd.items() if v.is_floating_point() and not bool(torch.isfinite(v).all())]
        if bad:
            raise PedscanError(f"{m}: weights that are not finite ({', '.join(bad[:3])})")
    mirrors = {bool(o.get("mirror", False)) for o in objs}
    if mirror is None:
        if len(mirrors) > 1:
            raise PedscanError("average: the files disagree on predicting mirrored; say --mirror or --no-mirror")
        mirror = mirrors.pop()
    state = {}
    for k, v in ref.items():
        if v.is_floating_point():
            total = sum(o["state_dict"][k].to(torch.float64) for o in objs)
            state[k] = (total / len(objs)).to(v.dtype)
        else:  # a counter or an index: the files agree or the mean means nothing
            if any(not torch.equal(o["state_dict"][k], v) for o in objs):
                raise PedscanError(f"average: the files differ in {k}, which is not a weight to average")
            state[k] = v.clone()
    training: dict[str, Any] = {
        "averaged": [
            {"file": Path(m).name, "sha256": hashlib.sha256(Path(m).read_bytes()).hexdigest(),
             "step": (o.get("training") or {}).get("step")}
            for m, o in zip(models, objs)
        ],
    }
    sensor = model_sensor(first)
    if sensor is not None:
        training["sensor"] = sensor
    units = {str(o.get("intensity_units", (o.get("training") or {}).get("intensity_units"))) for o in objs}
    if len(units) == 1 and "None" not in units:
        training["intensity_units"] = units.pop()
    out: dict[str, Any] = {"format": first["format"], "net": first["net"], "state_dict": state, "training": training,
                           "mirror": mirror}
    licences = list(dict.fromkeys(str(o["licence"]) for o in objs if o.get("licence")))
    if licences:
        out["licence"] = " | ".join(licences)
    return out


def run(args: argparse.Namespace) -> int:
    from .calibrate import check_arguments, write_calibrated
    from .netio import atomic_save, environment
    from .predict import pick_device

    out = check_arguments(args)
    obj = averaged([Path(m) for m in args.models], args.mirror)
    obj["training"]["environment"] = environment(pick_device(args.device))
    c = write_calibrated(lambda tmp: atomic_save(obj, tmp), out, args)
    print(f"{out}: the mean of {len(args.models)} networks; human threshold {c['human_threshold']:.4f} "
          f"(calibrated on {', '.join(args.val)}{', mirrored' if c['mirrored'] else ''}: IoU {c['iou_calibrated']:.4f})")
    return 0


def parser() -> argparse.ArgumentParser:
    from .calibrate import add_arguments

    p = argparse.ArgumentParser(prog="python -m pedscan_data.average", description=__doc__.split("\n\n")[0])
    p.add_argument("models", nargs="+", metavar="MODEL", help="model files of one network (two or more)")
    p.add_argument("--out", required=True, metavar="FILE", help="the averaged model file")
    p.add_argument("--mirror", action=argparse.BooleanOptionalAction, default=None,
                   help="whether the file predicts mirrored (default: as the files do, where they agree)")
    p.add_argument("--val", required=True, nargs="+", metavar="DATA",
                   help="validation sequences (pedscan output folders or files, pooled) to calibrate its threshold on")
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
