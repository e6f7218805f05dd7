"""Runs a trained network over pedscan sequences or real scans and writes its predictions.

    python -m pedscan_data.predict MODEL DATA --out PRED [--format h5|semantickitti]
                                    [--device auto|cpu|cuda] [--export-onnx FILE] [--[no-]mirror]
    python -m pedscan_data.predict MODEL SCANS --out PRED [--sensor NAME|FILE.toml]
                                    [--pedscan BIN] [--per-point knn|cell] [--knn K,S,SIGMA,CUT]

MODEL is a run folder (its ``model.pt``) or a model file.

**pedscan sequences.** DATA is a pedscan output folder or one sequence file. Per sequence,
PRED gets an HDF5 file named like the ground truth with ``/label`` u8 [T,H,W] (1 human) and
``/velocity`` f32 [T,H,W,3] (m/s, sensor frame), so ``python -m pedscan_data.evaluate DATA
PRED`` scores it unchanged; or, with ``--format semantickitti``,
``PRED/sequences/SS/labels/NNNNNN.label`` (uint32 per returned beam, class 30 person / 0
unlabeled) and ``PRED/sequences/SS/velocity/NNNNNN.bin`` (f32 x y z per returned beam).

**Real scans, per point.** SCANS is a SemanticKITTI sequence folder (``velodyne/NNNNNN.bin``)
or a dataset root (``sequences/SS/velodyne/``); see :mod:`pedscan_data.scans`. Each scan is
put on the model's sensor grid by ``pedscan project`` (the projection ``generate`` gives a
recorded background; the binary is ``--pedscan``, else ``$PEDSCAN``, else this checkout's
build, else ``PATH``), the network predicts on the grid, and each point gets a label back
(``--per-point``: RangeNet++'s kNN vote, the default, or its cell's): uint32 per point in the
scan's order, 30 person / 0 not, in ``PRED/predictions/NNNNNN.label`` (a sequence folder) or
``PRED/sequences/SS/predictions/NNNNNN.label`` (a root), semantic-kitti-api's layout, with
``PRED/predict.json`` saying how. The grid is ``--sensor``, else the model file's ``sensor``.
An N-frame network takes the scans in file order as its frames. Every scan is checked before
anything is projected, and PRED is written in a temporary sibling and moved into place: on
bad input (exit 2, the file named) nothing is written.

**Streaming.** Each frame is encoded once; frame t is decoded from the features of frames
t-N+1 .. t. A frame with fewer than N-1 predecessors (the first N-1 of a sequence) is decoded
with the first frame's features repeated in place of the missing ones, as a robot that has
just started would; the files record ``full_window_from = N-1``, and training and the
experiments score only frames from there on (``evaluate --from-frame``).

**Mirrored.** With ``--mirror`` each frame also goes through the network mirrored left for
right and the two passes' outputs are averaged (:func:`stream`; twice the time); without
``--mirror`` or ``--no-mirror``, as the model file's ``mirror`` says (the prediction its
threshold was chosen for). The files record ``mirrored``.

**Grown.** Where the model file has ``grow`` (``calibrate --grow``), a beam is human where the
highest margin of its component of confident-enough neighbours exceeds the threshold
(:mod:`pedscan_data.grow`); the HDF5 files record it as ``grow`` (JSON), ``predict.json`` too.

``--export-onnx FILE`` writes the network (input [B, N, C, H, W]; outputs ``logits``
[B,2,H,W] and ``velocity`` [B,3,H,W]) for ONNX Runtime, checked against PyTorch on a random
window within 1e-4 + 1e-4 x |PyTorch's value| before the file is kept.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import tempfile
import time
import warnings
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from .grow import human_mask, model_grow
from .reader import PedscanError, Sequence, open_sequences
from .scans import (
    Grid, Knn, ProjectedScan, ProjectFailed, find_pedscan, is_scan_layout, move_into_place, point_labels,
    projected_scans, read_points, scan_sequences, sensor_argument,
)
from .windows import MIRROR_VELOCITY

#: How points take the grid's predictions by default: ``knn`` or ``cell``. (Measured on
#: generated scans: see :func:`predict_scans`.)
PER_POINT = "knn"


def _torch():
    import torch

    return torch


def pick_device(name: str) -> Any:
    torch = _torch()
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise PedscanError(f"--device {name}: no CUDA device is available (try --device cpu)")
    return torch.device(name)


def sequence_inputs(seq: Sequence, intensity: bool, frames: slice = slice(None)) -> np.ndarray:
    """The network's input channels of a sequence's frames: f32 [T, C, H, W]."""
    from .model import input_channels

    if intensity and not seq.has("intensity"):
        raise PedscanError(f"{seq.path}: no dataset /intensity, which this network takes as input")
    r = seq.read("range", frames)
    i = seq.read("intensity", frames) if intensity else None
    return input_channels(r, i)


def stream(
    net: Any, frames: Iterable[np.ndarray], device: Any, first: int = 0, mirror: bool = False,
) -> Iterator[tuple[int, Any, Any, float]]:
    """Streams ``net`` over ``frames`` (each the inputs f32 [C,H,W] of one frame, in order):
    per frame t, (t, human margin f32 [H,W], velocity f32 [H,W,3], ms), the margin and velocity
    None before ``first``.

    Each frame is encoded once (frames before ``first`` too: the later ones need them); a
    frame with fewer than N-1 predecessors uses frame 0's features in place of the missing ones.

    ``mirror``: every frame also goes through the network mirrored left for right (its columns
    reversed: column c's azimuth pi (1 - 2 (c + 0.5) / W) goes to minus itself, the world
    reflected in the sensor's x-z plane), and the outputs are the means of the two passes, the
    mirrored one reversed back (its velocities' y negated back).
    """
    torch = _torch()
    n = net.cfg.frames
    passes = 2 if mirror else 1
    feats: list[list[Any]] = [[] for _ in range(passes)]  # per pass, on the device: (inputs, features) of the last N frames
    for t, frame in enumerate(frames):
        start = time.perf_counter()
        margin = velocity = None
        with torch.inference_mode():
            x = torch.from_numpy(frame)[None].to(device)
            outs = []
            for k in range(passes):
                xk = x.flip(-1) if k else x
                s1, s2, f = net.encode(xk)
                feats[k].append((xk, f))
                if len(feats[k]) > n:
                    feats[k].pop(0)
                if t >= first:
                    window = [feats[k][0]] * (n - len(feats[k])) + feats[k]
                    logits, vel = net.decode(
                        s1, s2, torch.stack([e[1] for e in window], dim=1), torch.stack([e[0] for e in window], dim=1)
                    )
                    m, v = logits[0, 1] - logits[0, 0], vel[0]
                    if k:
                        m, v = m.flip(-1), v.flip(-1) * torch.tensor(MIRROR_VELOCITY, dtype=v.dtype, device=v.device)[:, None, None]
                    outs.append((m, v))
            if outs:
                margin = (sum(m for m, _ in outs) / passes).to("cpu").numpy()
                velocity = (sum(v for _, v in outs) / passes).permute(1, 2, 0).to("cpu").numpy()
        yield t, margin, velocity, (time.perf_counter() - start) * 1e3


def predict_sequence(
    net: Any, seq: Sequence, device: Any, first: int = 0, chunk: int = 8, mirror: bool = False,
) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """Streams ``net`` over ``seq`` (:func:`stream`): the human margin f32 [T,H,W] (logit of
    human minus logit of background; human where it exceeds the model's threshold,
    :func:`human_margin`), velocity f32 [T,H,W,3] and ms per frame.

    Frames before ``first`` are encoded (the later ones need them) but not decoded; their
    outputs stay 0. Inputs are read ``chunk`` frames at a time.
    """

    def inputs() -> Iterator[np.ndarray]:
        for t0 in range(0, seq.frames, chunk):
            yield from sequence_inputs(seq, net.cfg.intensity, slice(t0, min(t0 + chunk, seq.frames)))

    margin = np.zeros((seq.frames, seq.rows, seq.columns), dtype=np.float32)
    velocity = np.zeros((seq.frames, seq.rows, seq.columns, 3), dtype=np.float32)
    ms: list[float] = []
    for t, m, v, frame_ms in stream(net, inputs(), device, first, mirror):
        if m is not None:
            margin[t], velocity[t] = m, v
        ms.append(frame_ms)
    return margin, velocity, ms


def human_margin(model: dict[str, Any]) -> float:
    """The margin above which a beam is human: log(p / (1 - p)) of the model file's
    ``human_threshold`` p (0.5, the softmax's argmax, unless calibrated on validation data)."""
    p = float(model.get("human_threshold", 0.5))
    return math.log(p / (1.0 - p))


def mirrored(model: dict[str, Any], asked: bool | None) -> bool:
    """Whether to predict mirrored (:func:`stream`): as asked, else as the model file's
    ``mirror`` says (how its threshold is meant to be used)."""
    return bool(model.get("mirror", False)) if asked is None else asked


def write_h5(path: Path, labels: np.ndarray, velocity: np.ndarray, attrs: dict[str, Any]) -> None:
    """One prediction file, under a temporary name until complete."""
    tmp = path.with_name(path.name + ".tmp")
    t, h, w = labels.shape
    with h5py.File(tmp, "w") as f:
        f.create_dataset("label", data=labels, chunks=(1, h, w), compression="gzip", compression_opts=1, shuffle=True)
        f.create_dataset(
            "velocity", data=velocity, chunks=(1, h, w, 3), compression="gzip", compression_opts=1, shuffle=True
        )
        for k, v in attrs.items():
            f.attrs[k] = v
    os.replace(tmp, path)


def write_kitti(root: Path, seq: Sequence, labels: np.ndarray, velocity: np.ndarray) -> None:
    """SemanticKITTI labels (and velocities) of one sequence, one file per frame, each renamed
    into place when complete."""
    base = root / "sequences" / f"{seq.index:02d}"
    (base / "labels").mkdir(parents=True, exist_ok=True)
    (base / "velocity").mkdir(parents=True, exist_ok=True)
    for t in range(seq.frames):
        returned = seq.read("range", t).ravel() > 0
        cls = np.where(labels[t].ravel()[returned] != 0, 30, 0).astype("<u4")
        vel = velocity[t].reshape(-1, 3)[returned].astype("<f4")
        for path, data in ((base / "labels" / f"{t:06d}.label", cls), (base / "velocity" / f"{t:06d}.bin", vel)):
            tmp = path.with_name(path.name + ".tmp")
            data.tofile(tmp)
            os.replace(tmp, path)


def export_onnx(
    net: Any, path: Path, rows: int, columns: int, atol: float = 1e-4, human_threshold: float = 0.5,
    mirror: bool = False, grow: dict[str, Any] | None = None, rtol: float = 1e-4,
) -> float:
    """Writes the network as ONNX and checks ONNX Runtime against PyTorch on a random window,
    each output within ``atol`` + ``rtol`` x its PyTorch value (float32's rounding grows with
    the logits); returns the largest difference. The file appears only once it is checked. Its metadata
    ``human_threshold`` is the softmax probability above which a beam is human, ``mirror``
    ("true" or "false") whether that threshold is for the mean of the frame's and the mirrored
    frame's outputs (:func:`stream`), which a caller of the file then computes; with ``grow``
    (a model file's) also ``grow_margin`` and ``grow_step_m``, the region growing the threshold
    is for (:mod:`pedscan_data.grow`)."""
    torch = _torch()
    import onnxruntime as ort

    cfg = net.cfg
    net = net.to("cpu").eval()
    g = torch.Generator().manual_seed(0)
    rng = torch.rand(1, cfg.frames, 1, rows, columns, generator=g) * 30.0
    valid = (torch.rand(1, cfg.frames, 1, rows, columns, generator=g) > 0.1).float()
    chans = [rng * valid / 10.0, valid]
    if cfg.intensity:
        chans.append(torch.rand(1, cfg.frames, 1, rows, columns, generator=g) * valid)
    x = torch.cat(chans, dim=2)
    tmp = path.with_name(path.name + ".tmp")
    with warnings.catch_warnings():  # the tracer's notes on shape checks it folds into constants
        warnings.simplefilter("ignore")
        torch.onnx.export(
            net, (x,), str(tmp), input_names=["input"], output_names=["logits", "velocity"],
            dynamic_axes={"input": {0: "batch"}, "logits": {0: "batch"}, "velocity": {0: "batch"}},
            opset_version=17, dynamo=False,
        )
    import onnx

    m = onnx.load(str(tmp))
    onnx.helper.set_model_props(m, {
        "human_threshold": repr(float(human_threshold)), "frames": str(cfg.frames),
        "inputs": "range/10m, valid" + (", intensity" if cfg.intensity else ""),
        "range_change": str(cfg.range_change).lower(), "mirror": str(bool(mirror)).lower(),
        **({"grow_margin": repr(float(grow["margin"])), "grow_step_m": repr(float(grow["step_m"]))} if grow else {}),
    })
    onnx.save(m, str(tmp))
    with torch.no_grad():
        ref = [o.numpy() for o in net(x)]
    sess = ort.InferenceSession(str(tmp), providers=["CPUExecutionProvider"])
    out = sess.run(None, {"input": x.numpy()})
    diff = max(float(np.max(np.abs(a - b))) for a, b in zip(ref, out))
    if not all(bool(np.all(np.abs(a - b) <= atol + rtol * np.abs(a))) for a, b in zip(ref, out)):
        tmp.unlink(missing_ok=True)
        raise PedscanError(
            f"{path}: ONNX Runtime differs from PyTorch by {diff:.3g} (> {atol:g} + {rtol:g} x |PyTorch's|); not written"
        )
    os.replace(tmp, path)
    return diff


def after_warm_up(ms: list[float]) -> list[float]:
    """A sequence's per-frame times without its first, which pays for warm-up, unless it is
    the only one."""
    return ms[1:] if len(ms) > 1 else ms


def predict(
    model: str | os.PathLike[str], data: str | os.PathLike[str], out: Path, fmt: str = "h5",
    device: str = "auto", first: int = 0, quiet: bool = False, mirror: bool | None = None,
) -> dict[str, Any]:
    """Predicts every sequence of ``data`` into ``out`` (``mirror``: see :func:`stream`; None:
    as the model file asks, :func:`mirrored`); returns timing figures."""
    from .netio import load_net

    dev = pick_device(device)
    net, obj = load_net(model, dev)
    mirror = mirrored(obj, mirror)
    cut, grow = human_margin(obj), model_grow(obj, model)
    sequences = open_sequences(data)
    for seq in sequences:
        if net.cfg.intensity and not seq.has("intensity"):
            raise PedscanError(f"{seq.path}: no dataset /intensity, which this network takes as input")
        if seq.rows % 4 or seq.columns % 8:
            raise PedscanError(
                f"{seq.path}: a {seq.rows} x {seq.columns} grid; the network takes a multiple of 4 rows and of 8 columns"
            )
        check_height_rows(net, model, seq.rows, str(seq.path))
    out.mkdir(parents=True, exist_ok=True)
    all_ms: list[float] = []
    for k, seq in enumerate(sequences):
        margin, velocity, ms = predict_sequence(net, seq, dev, first=first, mirror=mirror)
        if grow:
            labels = np.stack([human_mask(margin[t], seq.read("range", t), cut, grow) for t in range(seq.frames)])
        else:
            labels = margin > cut
        labels = labels.astype(np.uint8)
        all_ms += after_warm_up(ms)
        if fmt == "h5":
            write_h5(
                out / seq.path.name, labels, velocity,
                {"frames_seen": net.cfg.frames, "full_window_from": net.cfg.frames - 1,
                 "human_threshold": float(obj.get("human_threshold", 0.5)), "model": Path(model).name,
                 "mirrored": int(mirror), "source_range_sha256": seq.range_digest(),
                 **({"grow": json.dumps(grow)} if grow else {})},
            )
        else:
            write_kitti(out, seq, labels, velocity)
        if not quiet:
            print(f"\r{k + 1}/{len(sequences)} sequences, {np.median(all_ms):.1f} ms per frame", end="", file=sys.stderr)
    if not quiet:
        print(file=sys.stderr)
    return {"sequences": len(sequences), "ms_per_frame_median": float(np.median(all_ms)) if all_ms else None}


def model_sensor(obj: dict[str, Any]) -> Any:
    """The sensor a model file says it was trained on (``sensor``: a preset's name or a table
    with ``elevation_deg`` and ``columns``), or None."""
    return obj.get("sensor", obj.get("training", {}).get("sensor"))


def check_height_rows(net: Any, model: Any, rows: int, what: str) -> None:
    """Refuses ``what``'s grid of ``rows`` rows where the network's height channel is for
    another (its row elevations)."""
    if net.cfg.elevation_deg and rows != len(net.cfg.elevation_deg):
        raise PedscanError(f"{what}: {rows} rows; {model} sees heights on a grid of {len(net.cfg.elevation_deg)} rows")


def check_grid(grid: Grid, net: Any, obj: dict[str, Any], model: Any) -> list[str]:
    """Refuses a grid the network cannot take or whose intensity is not in the units it was
    trained on; the notes to print (units the model file does not record)."""
    if grid.rows % 4 or grid.cols % 8:
        raise PedscanError(
            f"--sensor {grid.sensor}: a {grid.rows} x {grid.cols} grid; the network takes a multiple of 4 rows and of 8 columns"
        )
    check_height_rows(net, model, grid.rows, f"--sensor {grid.sensor}")
    if not net.cfg.intensity:
        return []
    trained = obj.get("intensity_units", obj.get("training", {}).get("intensity_units"))
    if trained is None:
        return [f"{model}: the model file does not say its intensity's units; the scans' are {grid.intensity_units}"]
    if trained != grid.intensity_units:
        raise PedscanError(
            f"{model}: a network trained on intensity in {trained}, the scans' intensity is {grid.intensity_units}"
        )
    return []


def predict_scans(
    model: str | os.PathLike[str], scans: Path, out: Path, sensor: str | None = None, pedscan: Path | None = None,
    knn: Knn | None = Knn(), device: str = "auto", quiet: bool = False, mirror: bool | None = None,
) -> dict[str, Any]:
    """Predicts every scan of a SemanticKITTI sequence folder or dataset root, per point, into
    ``out`` (module docs; ``knn`` None: each point takes its cell's prediction). Returns what
    ``PRED/predict.json`` records: counts, timing, notes."""
    from .model import input_channels
    from .netio import load_net

    sequences = scan_sequences(scans)
    binary = find_pedscan(pedscan)
    if out.exists() and not out.is_dir():
        raise PedscanError(f"--out {out}: not a folder")
    dev = pick_device(device)
    net, obj = load_net(model, dev)
    cut, grow = human_margin(obj), model_grow(obj, model)
    mirror = mirrored(obj, mirror)
    spec = sensor if sensor is not None else model_sensor(obj)
    notes = []
    if sensor is not None and model_sensor(obj) not in (None, sensor):
        notes.append(f"--sensor {sensor} in place of the model file's sensor {model_sensor(obj)!r}")
    if spec is None:
        raise PedscanError(f"{model}: the model file does not say which sensor's grid it was trained on; give --sensor NAME|FILE.toml")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    work = tmp / ".work"
    record: dict[str, Any] = {
        "model": Path(model).name, "scans": str(scans), "frames_seen": net.cfg.frames,
        "full_window_from": net.cfg.frames - 1, "human_threshold": float(obj.get("human_threshold", 0.5)),
        "per_point": "cell" if knn is None else "knn", "mirrored": mirror, "grow": grow,
        "knn": None if knn is None else {"k": knn.k, "search": knn.search, "sigma": knn.sigma, "cutoff_m": knn.cutoff_m},
        "sequences": [], "notes": notes,
    }
    start = time.perf_counter()
    all_ms: list[float] = []
    done = 0
    total = sum(len(s.scans) for s in sequences)
    try:
        sensor_arg = sensor_argument(spec, work)
        for seq in sequences:
            folder = tmp / seq.predictions
            folder.mkdir(parents=True)
            held: list[ProjectedScan] = []
            counts = {"scans": 0, "points": 0, "kept": 0, "replaced": 0, "outside_band": 0}

            def inputs() -> Iterator[np.ndarray]:
                for grid, p in projected_scans(binary, seq, work / "project", sensor_arg):
                    if counts["scans"] == 0:
                        record["notes"] += [n for n in check_grid(grid, net, obj, model) if n not in record["notes"]]
                        record.update(sensor=grid.sensor, rows=grid.rows, cols=grid.cols, intensity_units=grid.intensity_units)
                    for key in ("points", "kept", "replaced", "outside_band"):
                        counts[key] += int(p.stats.get(key, 0))
                    counts["scans"] += 1
                    held.append(p)
                    yield input_channels(p.range_m, p.intensity if net.cfg.intensity else None)

            ms: list[float] = []
            for _, margin, _, frame_ms in stream(net, inputs(), dev, mirror=mirror):
                p = held.pop(0)
                labels = point_labels(human_mask(margin, p.range_m, cut, grow), p.range_m, p.cells, read_points(p.file), knn)
                labels.tofile(folder / f"{p.file.stem}.label")
                ms.append(frame_ms)
                done += 1
                if not quiet:
                    print(f"\r{done}/{total} scans, {np.median(ms):.0f} ms per frame", end="", file=sys.stderr)
            all_ms += after_warm_up(ms)
            record["sequences"].append({"folder": str(seq.folder), "predictions": str(seq.predictions), **counts})
        record["seconds"] = time.perf_counter() - start
        record["ms_per_frame_median"] = float(np.median(all_ms)) if all_ms else None
        shutil.rmtree(work, ignore_errors=True)
        (tmp / "predict.json").write_text(json.dumps(record, indent=2) + "\n")
        move_into_place(tmp, out, [s.predictions for s in sequences] + [Path("predict.json")])
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if not quiet:
        print(file=sys.stderr)
        for note in record["notes"]:
            print(f"note: {note}", file=sys.stderr)
    return record


def main(argv: list[str] | None = None) -> int:
    """The command line; returns the exit code (0 written, 1 failed, 2 bad input)."""
    parser = argparse.ArgumentParser(prog="python -m pedscan_data.predict", description=__doc__.split("\n\n")[0])
    parser.add_argument("model", type=Path, help="run folder or model file (.pt)")
    parser.add_argument(
        "data", type=Path, nargs="?",
        help="pedscan output folder or sequence file; or SemanticKITTI scans: a sequence folder (velodyne/) "
        "or a dataset root (sequences/SS/velodyne/)",
    )
    parser.add_argument("--out", type=Path, help="folder for the predictions")
    parser.add_argument("--format", choices=("h5", "semantickitti"), help="for pedscan data (default h5)")
    parser.add_argument("--device", default="auto", help="auto | cpu | cuda (default auto)")
    parser.add_argument("--export-onnx", type=Path, metavar="FILE", help="write the network as ONNX")
    parser.add_argument("--onnx-grid", default="32x1024", metavar="HxW", help="grid of the ONNX check (default 32x1024)")
    parser.add_argument("--sensor", metavar="NAME|FILE.toml", help="scans: the grid to project on (default: the model file's)")
    parser.add_argument("--pedscan", type=Path, metavar="BIN", help="scans: the pedscan binary (default: $PEDSCAN, this checkout's build, PATH)")
    parser.add_argument(
        "--per-point", choices=("knn", "cell"), default=PER_POINT,
        help=f"scans: a point's label from RangeNet++'s kNN vote or its cell's (default {PER_POINT})",
    )
    parser.add_argument("--knn", default="5,5,1,1", metavar="K,SEARCH,SIGMA,CUTOFF_M",
                        help="scans: the kNN vote's neighbours, window, Gaussian sigma (cells) and range cutoff (default 5,5,1,1)")
    parser.add_argument("--mirror", action=argparse.BooleanOptionalAction, default=None,
                        help="also run each frame mirrored left for right and average the two passes (twice the time); "
                        "default: as the model file says (the prediction its threshold was chosen for)")
    args = parser.parse_args(argv)
    from .netio import load_net

    try:
        if args.export_onnx is not None:
            net, obj = load_net(args.model)
            h, w = (int(v) for v in args.onnx_grid.lower().split("x"))
            diff = export_onnx(net, args.export_onnx, h, w, human_threshold=float(obj.get("human_threshold", 0.5)),
                               mirror=mirrored(obj, None), grow=model_grow(obj, args.model))
            print(f"wrote {args.export_onnx} (ONNX Runtime against PyTorch: max difference {diff:.2g})")
            if args.data is None:
                return 0
        if args.data is None or args.out is None:
            parser.error("DATA and --out are needed to predict (or give --export-onnx FILE alone)")
        if is_scan_layout(args.data):
            if args.format is not None:
                raise PedscanError(f"--format {args.format}: for pedscan data; scans are written per point in SemanticKITTI's layout")
            knn = Knn.parse(args.knn) if args.per_point == "knn" else None
            rec = predict_scans(args.model, args.data, args.out, args.sensor, args.pedscan, knn, args.device,
                                mirror=args.mirror)
            scans = sum(s["scans"] for s in rec["sequences"])
            print(f"wrote {scans} scans' predictions to {args.out} in {rec['seconds']:.1f} s; "
                  f"{rec['ms_per_frame_median']:.1f} ms per frame (median)")
            return 0
        if args.out.exists() and args.out.resolve() == args.data.resolve():
            raise PedscanError(f"--out {args.out}: the same folder as the data; give another")
        res = predict(args.model, args.data, args.out, args.format or "h5", args.device, mirror=args.mirror)
    except (PedscanError, FileNotFoundError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except ProjectFailed as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    print(f"wrote {res['sequences']} sequences to {args.out}; {res['ms_per_frame_median']:.1f} ms per frame (median)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
