"""Trains the paper's sequence network on pedscan sequences.

    python -m pedscan_data.train DATA [DATA...] --frames N --out RUN [--steps S] [--val DATA2]
                                 [--device auto|cpu|cuda] [--resume]

Several DATA folders (backgrounds, scenarios) pool their sequences: each step draws one of
all of them alike.

The paper's policy (Kim et al. 2020, Section V-B) by default:

- each step draws a random training sequence and a random window of N consecutive frames in
  it (all N frames real: the window ends at frame N-1 or later); the target is the last
  frame's label and velocity; batch size 1;
- Adam, learning rate 1e-3 with the paper's "decay = 1e-3" read as Keras' time decay:
  lr_k = 1e-3 / (1 + 1e-3 k) at step k;
- loss = 10,000 x weighted cross-entropy + 1 x squared velocity error on background beams +
  1,001 x on human beams, each summed over the window's returned beams and divided by their
  number (no-return beams count nowhere); a human beam's cross-entropy weight is the frame's
  background beams / human beams (1 where it has none).

Every deviation is a flag (``--batch``, ``--lr``, ``--decay``, ``--loss-weights``).
Reproducible: step k's window is drawn from (seed, k) alone, so data-loading workers and
``--resume`` change nothing; on CPU a resumed run ends with the same weights as an
uninterrupted one.

RUN gets ``run.json`` (configuration, data, device and versions), ``checkpoint.pt`` every
``--checkpoint-every`` steps (model, optimizer, step), ``model.pt`` (the weights, for
``predict``), ``metrics.jsonl`` (training loss; with ``--val``, IoU per distance bin and the
human velocity end-point error) and ``curves.png``. Exit 0 done, 2 bad input, 130 stopped by
Ctrl-C or SIGTERM (the last checkpoint stays).

``--average-from K``: the run's weights are the mean of the weights after each step past step
K (steps K+1 to the end: stochastic weight averaging over the run's tail, with its decaying
learning rate), so that where the last step happened to land (batch size 1 moves a network
from one step to the next) does not decide the network; validation from then on scores the
mean, and the checkpoint keeps it for ``--resume``.

``--max-minutes M`` bounds one sitting (a batch system's wall-clock limit, a lent GPU): after
the first step that ends past M minutes of training the run checkpoints, validates and
calibrates as at its end, logs ``{"kind": "time_limit", "step": K}`` and exits 0 with step K of
``--steps`` done; ``--resume`` continues it to the end (the model file says which step it is).

On CUDA the run asks PyTorch for deterministic algorithms but only warns where an operation
has none (``CUBLAS_WORKSPACE_CONFIG`` set to ``:4096:8`` unless given); bit-identical
resumption is promised on CPU.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .evaluate import NOT_SCORED
from .reader import PedscanError, Sequence, sequence_paths
from .windows import MIRROR_VELOCITY, backdrop_people, flank_people, widen_people

#: The paper's loss weights: cross-entropy, background velocity, human velocity.
PAPER_LOSS_WEIGHTS = (10_000.0, 1.0, 1_001.0)

#: ``--precision``: the training step's forward pass in float32, or under autocast to bfloat16.
PRECISIONS = ("fp32", "bf16")


@dataclass
class TrainConfig:
    """Everything that fixes the trained weights (``run.json``'s ``config``)."""

    frames: int = 16
    width: int = 16
    intensity: bool = False
    range_change: bool = False
    seed: int = 0
    batch: int = 1
    lr: float = 1e-3
    decay: float = 1e-3
    loss_weights: tuple[float, float, float] = PAPER_LOSS_WEIGHTS
    crop_columns: int = 0
    """0: whole frames; else each window is this many columns at a drawn azimuth (wrapping)"""
    height: bool = False
    """the encoder also sees each return's height (:class:`~pedscan_data.model.NetConfig`'s
    ``elevation_deg``, the training grid's)"""
    class_weight_power: float = 1.0
    """a human beam's cross-entropy weight is (background beams / human beams of the frame) to this
    power: 1 the paper's balance, 0 none"""
    widen_m: float = 0.0
    """each window's people are made wider on either side by a reach drawn in [0, widen_m] m
    (:func:`~pedscan_data.windows.widen_people`); 0: as drawn"""
    flank: float = 0.0
    """each person of a window is given, with this probability, a patch of the frame's own structure
    right beside it (:func:`~pedscan_data.windows.flank_people`); 0: never"""
    backdrop: float = 0.0
    """each person of a window is given, with this probability, a wall 0.5-2 m behind it
    (:func:`~pedscan_data.windows.backdrop_people`); 0: never"""
    mirror: float = 0.0
    """each window is mirrored left for right with this probability: its columns reversed (a
    column's azimuth goes to minus itself: the scene reflected in the sensor's x-z plane) and its
    velocities' y negated; 0: never"""
    precision: str = "fp32"
    """the training step's forward pass: ``fp32``, or ``bf16`` (under autocast to bfloat16: the
    convolutions in bfloat16, the weights, their updates, the loss and validation in float32)"""
    average_from: int | None = None
    """the weights the run gives (``model.pt``, validation, calibration) are the mean of the
    weights after each step past this one (:class:`WeightMean`); None: the last step's"""
    init: dict[str, Any] | None = None
    """the model file the weights started from (name, SHA-256, its step), or None"""
    data: list[dict[str, Any]] = field(default_factory=list)
    """the training sequences: file name, bytes, index, seed"""


def training_paths(folders: list[Path]) -> list[Path]:
    """The sequence files of every training folder (or file), in the order given; one given
    twice is refused (it would weigh twice)."""
    paths: list[Path] = []
    for d in folders:
        paths += sequence_paths(d)
    seen: set[Path] = set()
    for p in paths:
        if p.resolve() in seen:
            raise PedscanError(f"{p}: given twice among the training data")
        seen.add(p.resolve())
    return paths


def describe_data(paths: list[Path]) -> list[dict[str, Any]]:
    out = []
    for p in paths:
        with Sequence(p) as s:
            out.append({"file": p.name, "bytes": p.stat().st_size, "index": s.index, "seed": s.seed, "frames": s.frames})
    return out


class StepWindows:
    """Item i is the i-th training window of the run: a sequence and an end frame drawn from
    ``numpy.random.default_rng([seed, i])`` alone (a map-style dataset: workers and resume do
    not change what step k sees)."""

    def __init__(
        self, sequences: list[Sequence], frames: int, seed: int, intensity: bool, crop_columns: int = 0, widen_m: float = 0.0,
        flank: float = 0.0, backdrop: float = 0.0, mirror: float = 0.0,
    ) -> None:
        self.sequences = sequences
        self.frames = frames
        self.seed = seed
        self.intensity = intensity
        self.crop_columns = crop_columns
        self.widen_m = widen_m
        self.flank = flank
        self.backdrop = backdrop
        self.mirror = mirror

    def pick(self, i: int) -> tuple[int, int]:
        rng = np.random.default_rng([self.seed, i])
        s = int(rng.integers(len(self.sequences)))
        t = int(rng.integers(self.frames - 1, self.sequences[s].frames))
        return s, t

    def __len__(self) -> int:
        return 2**62

    def __getitem__(self, i: int) -> dict[str, Any]:
        import torch

        from .model import input_channels

        s, t = self.pick(i)
        seq = self.sequences[s]
        window = slice(t - self.frames + 1, t + 1)
        r = seq.read("range", window)
        intensity = seq.read("intensity", window) if self.intensity else None
        velocity = seq.read("velocity", t)
        if self.widen_m <= 0 and self.flank <= 0 and self.backdrop <= 0:
            label = seq.read("label", t)
        else:
            # One reach and one patch a person for the window's frames (streams of their own:
            # what step i draws otherwise stays as without them); every frame's labels, the last
            # one's the target.
            reach = float(np.random.default_rng([self.seed, i, 2]).uniform(0.0, self.widen_m)) if self.widen_m > 0 else 0.0
            labels = seq.read("label", window)
            instances = seq.read("instance", window) if self.flank > 0 or self.backdrop > 0 else None
            srcs = []
            for k in range(r.shape[0]):
                r[k], labels[k], src = widen_people(r[k], labels[k], reach)
                if instances is not None:
                    # A grown cell belongs to the person it was grown from.
                    instances[k] = np.take_along_axis(instances[k], src, axis=1)
                srcs.append(src)
            if instances is not None:
                people = np.unique(instances[(labels == 1) & (instances > 0)])
                for k in range(r.shape[0]):
                    if self.flank > 0:
                        r[k], flanked = flank_people(r[k], labels[k], instances[k], self.flank,
                                                     np.random.default_rng([self.seed, i, 3]), people)
                        srcs[k] = np.take_along_axis(srcs[k], flanked, axis=1)
                    if self.backdrop > 0:
                        r[k], labels[k] = backdrop_people(r[k], labels[k], instances[k], self.backdrop,
                                                          np.random.default_rng([self.seed, i, 4]), people)
            src = srcs[-1]
            if intensity is not None:
                for k in range(r.shape[0]):
                    intensity[k] = np.take_along_axis(intensity[k], srcs[k], axis=1)
            label = labels[-1]
            velocity = np.take_along_axis(velocity, src[..., None], axis=1)
        x = input_channels(r, intensity)
        if 0 < self.crop_columns < seq.columns:
            # Columns c0 .. c0 + crop - 1 around the turn, c0 from a stream of its own (the
            # sequence and frame of step i stay those of whole-frame training).
            c0 = int(np.random.default_rng([self.seed, i, 1]).integers(seq.columns))
            cols = (c0 + np.arange(self.crop_columns)) % seq.columns
            r, x, label, velocity = r[..., cols], x[..., cols], label[:, cols], velocity[:, cols]
        if self.mirror > 0 and np.random.default_rng([self.seed, i, 5]).random() < self.mirror:
            # Column c's azimuth is pi (1 - 2 (c + 0.5) / W): reversing the columns sends each
            # to minus itself, the world reflected in the x-z plane, where velocities' y turns.
            r, x, label = r[..., ::-1], np.ascontiguousarray(x[..., ::-1]), np.ascontiguousarray(label[:, ::-1])
            velocity = np.ascontiguousarray(velocity[:, ::-1] * np.array(MIRROR_VELOCITY, dtype=velocity.dtype))
        return {
            "x": torch.from_numpy(x),
            "label": torch.from_numpy(label.astype(np.int64)),
            "velocity": torch.from_numpy(np.ascontiguousarray(velocity.transpose(2, 0, 1))),
            "valid": torch.from_numpy(r[-1] > 0),
            "sequence": s,
            "frame": t,
        }


def paper_loss(
    logits: Any, velocity: Any, label: Any, v_true: Any, valid: Any,
    weights: tuple[float, float, float] = PAPER_LOSS_WEIGHTS, class_weight_power: float = 1.0,
) -> tuple[Any, dict[str, float]]:
    """The paper's loss over a batch; no-return beams (``valid`` False) and not-scored beams
    (``label`` 255, :data:`~pedscan_data.evaluate.NOT_SCORED`: a recorded background's own
    people) count in no term, nor in the class weight.

    A human beam's cross-entropy weighs (background beams / human beams of its frame) to the
    power ``class_weight_power``: the paper's 1 gives both classes the same total weight, which
    where people are 0.6 % of the beams (a street) trains a network that calls far more beams
    human than there are; 0 weighs every beam alike.

    logits [B,2,H,W], velocity and v_true [B,3,H,W], label [B,H,W] (1 human), valid [B,H,W].
    Returns the loss and its three terms (unweighted) for the log.
    """
    import torch
    from torch.nn import functional as F

    valid = valid & (label != NOT_SCORED)
    valid_f = valid.to(logits.dtype)
    human = (label == 1) & valid
    n_valid = valid_f.sum(dim=(1, 2)).clamp(min=1.0)
    n_human = human.to(logits.dtype).sum(dim=(1, 2))
    ratio = (n_valid - n_human) / n_human.clamp(min=1.0)
    class_w = torch.where(n_human > 0, ratio.clamp(min=0.0) ** class_weight_power, torch.ones_like(n_human))
    ce = F.cross_entropy(logits, label.clamp(0, 1), reduction="none")  # [B,H,W]
    w = torch.where(human, class_w[:, None, None], torch.ones_like(ce)) * valid_f
    seg = (w * ce).sum(dim=(1, 2)) / n_valid
    se = (velocity - v_true).square().mean(dim=1)  # mean over x, y, z: [B,H,W]
    bg = (se * (valid & ~human).to(se.dtype)).sum(dim=(1, 2)) / n_valid
    hu = (se * human.to(se.dtype)).sum(dim=(1, 2)) / n_valid
    a, b, c = weights
    loss = (a * seg + b * bg + c * hu).mean()
    return loss, {"ce": seg.mean().item(), "mse_bg": bg.mean().item(), "mse_human": hu.mean().item()}


def window_loss(
    net: Any, x: Any, label: Any, velocity: Any, valid: Any, precision: str,
    weights: tuple[float, float, float], class_weight_power: float,
) -> tuple[Any, dict[str, float]]:
    """The training step's forward pass over windows ``x`` in ``precision`` (``bf16``: under
    autocast to bfloat16) and :func:`paper_loss` on its outputs in float32."""
    import torch

    with torch.autocast(x.device.type, dtype=torch.bfloat16, enabled=precision == "bf16"):
        logits, vel = net(x)
    return paper_loss(logits.float(), vel.float(), label, velocity, valid, weights, class_weight_power)


def validate(
    net: Any, sequences: list[Sequence], device: Any, score_from: int, cuts: tuple[float, ...] = (0.0,)
) -> list[dict[str, Any]]:
    """Per margin cut (0: the softmax's argmax), IoU per distance bin and the human velocity
    EPE on frames ``score_from`` onwards; one pass of the network serves every cut."""
    from .evaluate import Report, _score_frame
    from .predict import after_warm_up, predict_sequence

    reports = [Report("validation", "network", "network", sequences=len(sequences), velocity=True) for _ in cuts]
    net.eval()
    ms: list[float] = []
    for seq in sequences:
        margin, vel, frame_ms = predict_sequence(net, seq, device, first=score_from)
        ms += after_warm_up(frame_ms)
        for t in range(score_from, seq.frames):
            r, label, v = seq.read("range", t), seq.read("label", t), seq.read("velocity", t)
            for cut, report in zip(cuts, reports):
                _score_frame(report, r, label == 1, margin[t] > cut, v, vel[t], scored=label != NOT_SCORED)
                report.frames += 1
    net.train()
    out = []
    for cut, report in zip(cuts, reports):
        d = report.as_dict()
        out.append({"margin": cut, "overall": d["overall"], "bins": d["bins"], "frames": d["frames"],
                    "ms_per_frame": float(np.median(ms))})
    return out


def calibrate(
    net: Any, sequences: list[Sequence], device: Any, score_from: int, mirror: bool = False, grow: bool = False,
) -> dict[str, Any]:
    """The human threshold that maximizes the IoU over the validation beams (frames
    ``score_from`` onwards), found exactly by sorting the beams' margins (``mirror``: the
    margins of mirrored prediction, :func:`~pedscan_data.predict.stream`).

    The paper's class weight (background / human beams, ~25) makes the softmax's argmax call a
    beam human when it is about 1 in 25 likely: recall near 1, precision low. The threshold is
    chosen on validation data, never on the test set.

    ``grow``: region growing is chosen as well (:func:`~pedscan_data.grow.calibrate_grow`) and
    kept where it beats the plain threshold by more than 0.001 IoU (``grow`` in the result, None
    where it does not; the threshold is then for the grown margins).
    """
    from .predict import predict_sequence

    net.eval()
    margins, truth = [], []
    frames = []
    for seq in sequences:
        m, _, _ = predict_sequence(net, seq, device, first=score_from, mirror=mirror)
        for t in range(score_from, seq.frames):
            label, rng = seq.read("label", t), seq.read("range", t)
            ok = (rng > 0) & (label != NOT_SCORED)
            margins.append(m[t][ok])
            truth.append(label[ok] == 1)
            if grow:
                frames.append((m[t], rng, label == 1, ok))
    net.train()
    m, y = np.concatenate(margins).astype(np.float64), np.concatenate(truth)
    if not y.any():
        raise PedscanError("the validation frames hold no human beam: no threshold to calibrate")
    cut, iou = best_cut(m, y)
    called = m > 0
    argmax_iou = int(np.sum(y & called)) / int(np.sum(y | called))
    c = {
        "human_threshold": float(1.0 / (1.0 + np.exp(-cut))), "margin": cut, "mirrored": mirror, "beams": int(len(m)),
        "human_beams": int(y.sum()), "iou_argmax": argmax_iou, "iou_calibrated": iou,
    }
    if grow:
        from .grow import calibrate_grow

        g = calibrate_grow(frames, cut)
        c["grow_tried"] = g["tried"]
        c["grow"] = None
        if g["iou"] > iou + 0.001:
            c["grow"] = {"margin": g["margin"], "step_m": g["step_m"]}
            c.update(human_threshold=float(1.0 / (1.0 + np.exp(-g["cut"]))), margin=g["cut"], iou_calibrated=g["iou"],
                     iou_plain=iou)
    return c


def best_cut(margin: np.ndarray, human: np.ndarray) -> tuple[float, float]:
    """The cut c (within +-15) maximizing the IoU of ``margin > c`` against ``human``, and that
    IoU; exact: the beams sorted by margin, every cut between two distinct margins tried."""
    positives = int(human.sum())
    order = np.argsort(-margin, kind="stable")
    ms, ys = margin[order], human[order]
    tp = np.cumsum(ys)
    iou = tp / (positives + np.cumsum(~ys))  # TP / (TP + FP + FN) when the first k are called human
    cut_ok = np.r_[ms[:-1] > ms[1:], True]  # a cut can fall only between different margins
    k = int(np.argmax(np.where(cut_ok, iou, -1.0)))
    cut = float((ms[k] + ms[k + 1]) / 2) if k + 1 < len(ms) else float(ms[k] - 1.0)
    cut = min(max(cut, -15.0), 15.0)
    called = margin > cut
    return cut, int(np.sum(human & called)) / int(np.sum(human | called))


def calibrate_model(
    model: Path, val: Path | list[Path], device: Any, score_from: int | None, grow: bool = False,
) -> dict[str, Any]:
    """Calibrates a model file's human threshold on validation sequences (one folder or file,
    or several pooled) and writes it in, for the prediction the file asks for (its
    ``mirror``: see :mod:`pedscan_data.predict`), on frames ``score_from`` onwards (None: the
    network's first full window). The record names the sequences by file name, and by folder
    and file name where several folders are pooled. ``grow``: region growing is calibrated as
    well (:func:`calibrate`) and written as the file's ``grow`` (removed where it does not
    help)."""
    from .netio import atomic_save, load_file, load_net
    from .predict import mirrored

    vals = list(val) if isinstance(val, (list, tuple)) else [val]
    net, obj = load_net(model, device)
    if score_from is None:
        score_from = net.cfg.frames - 1
    paths = [p for v in vals for p in sequence_paths(v)]
    seqs = check_sequences(paths, 1, ", ".join(map(str, vals)), net.cfg.intensity)
    c = calibrate(net, seqs, device, score_from, mirror=mirrored(obj, None), grow=grow)
    obj = load_file(model)
    obj["human_threshold"] = c["human_threshold"]
    obj.pop("grow", None)
    if c.get("grow"):
        obj["grow"] = c["grow"]
    names = [s.path.name for s in seqs] if len(vals) == 1 else [f"{s.path.parent.name}/{s.path.name}" for s in seqs]
    obj.setdefault("training", {})["calibration"] = {**c, "score_from": score_from, "val": names}
    atomic_save(obj, model)
    return c


def check_sequences(paths: list[Path], frames: int, what: str, intensity: bool) -> list[Sequence]:
    """Opens the sequences; PedscanError naming every file that cannot give an N-frame window."""
    seqs = [Sequence(p) for p in paths]
    problems = []
    for s in seqs:
        need = ["range", "label", "velocity"] + (["intensity"] if intensity else [])
        missing = [k for k in need if not s.has(k)]
        if missing:
            problems.append(f"{s.path}: no dataset {', '.join('/' + k for k in missing)} (train needs it)")
        if s.frames < frames:
            problems.append(f"{s.path}: {s.frames} frames, shorter than the network's window of {frames}")
        if s.rows % 4 or s.columns % 8:
            problems.append(f"{s.path}: a {s.rows} x {s.columns} grid; the network takes a multiple of 4 rows and of 8 columns")
    if problems:
        raise PedscanError(f"{what}: " + ("\n  ".join([""] + problems) if len(problems) > 1 else problems[0]))
    return seqs


def sensor_of(seqs: list[Sequence]) -> dict[str, Any] | None:
    """The grid the training sequences share, as a model file records it (``predict`` projects
    real scans onto it): the sensor's name, its rows' elevations and its columns; None when
    the sequences were made on different grids."""
    first = seqs[0]
    for s in seqs[1:]:
        if s.columns != first.columns or not np.array_equal(s.elevation_deg, first.elevation_deg):
            return None
    return {"name": first.sensor, "elevation_deg": [float(e) for e in first.elevation_deg], "columns": int(first.columns)}


def plot_curves(metrics: list[dict[str, Any]], path: Path, title: str) -> None:
    """Training loss and validation IoU per bin against steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .netio import save_figure

    train = [m for m in metrics if m["kind"] == "train"]
    val = [m for m in metrics if m["kind"] == "val"]
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.8))
    if train:
        axes[0].plot([m["step"] for m in train], [m["loss"] for m in train])
        axes[0].set_yscale("log")
    axes[0].set(title="training loss", xlabel="step")
    if val:
        steps = [m["step"] for m in val]
        axes[1].plot(steps, [m["overall"]["iou"] or 0 for m in val], "k-", label="all")
        for k, name in enumerate(("0-4 m", "4-8 m", "8+ m")):
            axes[1].plot(steps, [m["bins"][k]["iou"] or 0 for m in val], label=name)
        axes[1].legend()
        axes[2].plot(steps, [m["overall"].get("epe_mps") or 0 for m in val])
    axes[1].set(title="validation IoU (human)", xlabel="step", ylim=(0, 1))
    axes[2].set(title="validation EPE on human beams (m/s)", xlabel="step")
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path)


class Stop(Exception):
    pass


class WeightMean:
    """The running mean of a network's weights after each step past ``after`` (None: never):
    ``mean += (w - mean) / n`` per tensor in float32, in the order of the steps, so a resumed
    run's mean is the uninterrupted one's bit for bit."""

    def __init__(self, net: Any, after: int | None) -> None:
        self.source, self.after = net, after
        self.count = 0
        self.mean: dict[str, Any] = {}
        self._net: Any = None

    def add(self, step: int) -> None:
        if self.after is None or step <= self.after:
            return
        self.count += 1
        for k, v in self.source.state_dict().items():
            v = v.detach()
            if self.count == 1 or not v.is_floating_point():
                self.mean[k] = v.clone()
            else:
                self.mean[k] += (v - self.mean[k]) / self.count
        self._net = None

    def weights(self) -> dict[str, Any] | None:
        """The mean's weights on the CPU, or None before the first step averaged."""
        return {k: v.cpu() for k, v in self.mean.items()} if self.count else None

    def net(self) -> Any:
        """A copy of the network holding the mean (for validation), or None before the first step averaged."""
        if not self.count:
            return None
        if self._net is None:
            import copy

            self._net = copy.deepcopy(self.source)
            self._net.load_state_dict(self.mean)
        return self._net

    def state(self) -> dict[str, Any] | None:
        return {"count": self.count, "mean": self.weights()} if self.count else None

    def load(self, state: dict[str, Any] | None, step: int) -> None:
        """The checkpoint's mean at its ``step``: absent where no step was averaged yet."""
        want = 0 if self.after is None else max(0, step - self.after)
        got = int(state["count"]) if state else 0
        if got != want:
            raise ValueError(f"its weight mean holds {got} steps where step {step} needs {want}")
        if state:
            device = next(iter(self.source.state_dict().values())).device
            self.mean = {k: v.to(device) for k, v in state["mean"].items()}
            if self.mean.keys() != self.source.state_dict().keys():
                raise ValueError("its weight mean is of another network")
        self.count = got


def load_init(path: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """``--init``: what run.json records of the model file (name, SHA-256, its training step),
    and the file."""
    import hashlib

    from .netio import load_file

    obj = load_file(path)
    if "net" not in obj or "state_dict" not in obj:
        raise PedscanError(f"--init {path}: not a pedscan model file (no network or weights)")
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    return {"file": path.name, "sha256": digest, "step": (obj.get("training") or {}).get("step")}, obj


def train(args: argparse.Namespace) -> int:
    import torch

    from .model import NetConfig, SequenceNet, count_parameters, describe
    from .netio import MODEL_FORMAT, RunError, atomic_save, atomic_write_text, environment, load_file, read_json
    from .predict import pick_device

    run: Path = args.out
    cfg = TrainConfig(
        frames=args.frames, width=args.width, intensity=args.intensity, range_change=args.range_change, seed=args.seed,
        batch=args.batch, crop_columns=args.crop_columns,
        lr=args.lr, decay=args.decay, loss_weights=tuple(args.loss_weights), class_weight_power=args.class_weight_power,
        height=args.height, widen_m=args.widen_m, flank=args.flank, backdrop=args.backdrop,
        mirror=args.mirror, precision=args.precision, average_from=args.average_from,
    )
    if cfg.frames < 1 or cfg.batch < 1 or cfg.width < 2:
        raise PedscanError("--frames, --batch must be at least 1 and --width at least 2")
    if cfg.crop_columns < 0 or cfg.crop_columns % 8:
        raise PedscanError(f"--crop-columns {cfg.crop_columns}: a multiple of 8 (the network's), or 0 for whole frames")
    if cfg.range_change and cfg.frames < 2:
        raise PedscanError("--range-change needs --frames 2 or more (a single frame has no range change)")
    if not all(math.isfinite(v) and v >= 0 for v in (cfg.lr, cfg.decay, cfg.class_weight_power, cfg.widen_m, *cfg.loss_weights)):
        raise PedscanError("--lr, --decay, --loss-weights, --class-weight-power and --widen-m must be finite and not negative")
    for flag, value in (("--flank", cfg.flank), ("--backdrop", cfg.backdrop), ("--mirror", cfg.mirror)):
        if not 0.0 <= value <= 1.0:
            raise PedscanError(f"{flag} {value}: a probability, 0 to 1")
    if cfg.average_from is not None and not 0 <= cfg.average_from < args.steps:
        raise PedscanError(f"--average-from {cfg.average_from}: a step from 0 to --steps - 1 ({args.steps - 1})")
    paths = training_paths(args.data)
    seqs = check_sequences(paths, cfg.frames, ", ".join(map(str, args.data)), cfg.intensity)
    val_seqs = check_sequences(sequence_paths(args.val), 1, str(args.val), cfg.intensity) if args.val else []
    score_from = cfg.frames - 1 if args.score_from is None else args.score_from
    for s in val_seqs:
        if s.frames <= score_from:
            raise PedscanError(f"{s.path}: {s.frames} frames, none scored from frame {score_from} (--score-from)")
    cfg.data = describe_data(paths)
    init = load_init(args.init) if args.init is not None else None
    if init is not None:
        cfg.init = init[0]
    if args.max_minutes is not None and not (math.isfinite(args.max_minutes) and args.max_minutes > 0):
        raise PedscanError(f"--max-minutes {args.max_minutes}: not a positive number of minutes")
    device = pick_device(args.device)
    config = json.loads(json.dumps(asdict(cfg)))  # as run.json holds it (tuples become lists)

    ckpt_path = run / "checkpoint.pt"
    metrics_path = run / "metrics.jsonl"
    start = 0
    torch.manual_seed(cfg.seed)
    if device.type == "cuda":
        # cuBLAS is deterministic only with a fixed workspace, which must be set before its first use.
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
        torch.backends.cudnn.benchmark = False
        torch.use_deterministic_algorithms(True, warn_only=True)
    else:
        torch.use_deterministic_algorithms(True)
    sensor = sensor_of(seqs)
    if cfg.height:
        if sensor is None:
            raise PedscanError("--height: the training sequences are on different grids (the height channel needs one)")
        for v in val_seqs:
            if not np.array_equal(v.elevation_deg, np.asarray(sensor["elevation_deg"], dtype=v.elevation_deg.dtype)):
                raise PedscanError(f"--height: {v.path} is on another grid than the training sequences")
    net = SequenceNet(NetConfig(frames=cfg.frames, intensity=cfg.intensity, width=cfg.width, range_change=cfg.range_change,
                                elevation_deg=tuple(sensor["elevation_deg"]) if cfg.height else ())).to(device)
    if init is not None:
        if init[1]["net"] != net.cfg.as_dict():
            diff = sorted(k for k in set(init[1]["net"]) | set(net.cfg.as_dict()) if init[1]["net"].get(k) != net.cfg.as_dict().get(k))
            raise PedscanError(f"--init {args.init}: a network of other options (differs in: {', '.join(diff)}); "
                               "give its flags (--frames, --width, --height, ...)")
        net.load_state_dict(init[1]["state_dict"])
    mean = WeightMean(net, cfg.average_from)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda k: 1.0 / (1.0 + cfg.decay * k))
    if args.resume:
        if not (run / "run.json").is_file():
            raise RunError(f"{run}: no run.json to resume (start it without --resume)")
        before = read_json(run / "run.json")
        # A key added to TrainConfig after the run began holds its default there.
        old = {**{k: v for k, v in json.loads(json.dumps(asdict(TrainConfig()))).items() if k != "data"},
               **before.get("config", {})}
        if old != config:
            diff = sorted(k for k in set(old) | set(config) if old.get(k) != config.get(k))
            raise RunError(f"{run}: a run of another configuration (differs in: {', '.join(diff)}); "
                           "give the same flags and data, or another --out")
        if ckpt_path.exists():
            ck = load_file(ckpt_path)
            try:
                net.load_state_dict(ck["state_dict"])
                opt.load_state_dict(ck["optimizer"])
                sched.load_state_dict(ck["scheduler"])
                torch.set_rng_state(ck["torch_rng"])
                start = int(ck["step"])
                mean.load(ck.get("mean"), start)
            except (KeyError, RuntimeError, ValueError, TypeError) as e:
                raise RunError(f"{ckpt_path}: a damaged checkpoint ({e})") from e
    elif run.exists() and any(run.iterdir()):
        raise RunError(f"{run}: not empty; --resume continues the run in it, or give another --out")
    run.mkdir(parents=True, exist_ok=True)
    env = environment(device)
    if not args.resume or not (run / "run.json").is_file():
        atomic_write_text(run / "run.json", json.dumps({
            "config": config, "val": str(args.val) if args.val else None, "score_from": score_from,
            "parameters": count_parameters(net), "network": describe(net, seqs[0].rows, seqs[0].columns),
            "environment": env,
        }, indent=2) + "\n")
    # Metrics logged after the checkpoint resumed from are dropped: the run writes them again.
    metrics: list[dict[str, Any]] = []
    if metrics_path.exists():
        for line in metrics_path.read_text().splitlines():
            try:
                m = json.loads(line)
            except json.JSONDecodeError:
                continue
            if m.get("step", 0) <= start and start > 0:
                metrics.append(m)
    atomic_write_text(metrics_path, "".join(json.dumps(m) + "\n" for m in metrics))

    data = StepWindows(seqs, cfg.frames, cfg.seed, cfg.intensity, cfg.crop_columns, cfg.widen_m, cfg.flank, cfg.backdrop,
                       cfg.mirror)
    sampler = range(start * cfg.batch, args.steps * cfg.batch)
    loader = torch.utils.data.DataLoader(
        data, batch_size=cfg.batch, sampler=sampler, num_workers=args.workers,
        prefetch_factor=4 if args.workers else None, persistent_workers=False,
    )
    title = f"{run.name}: N={cfg.frames}, {len(seqs)} training sequences"

    def save(step: int) -> None:
        weights = {k: v.detach().cpu() for k, v in net.state_dict().items()}
        training = {"step": step, "config": config, "environment": env, "sensor": sensor}
        if mean.count:
            training["averaged_steps"] = [step - mean.count + 1, step]
        atomic_save({
            "format": MODEL_FORMAT, "net": net.cfg.as_dict(), "state_dict": weights, "optimizer": opt.state_dict(),
            "scheduler": sched.state_dict(), "torch_rng": torch.get_rng_state(), "step": step, "training": training,
            "mean": mean.state(),
        }, ckpt_path)
        atomic_save({"format": MODEL_FORMAT, "net": net.cfg.as_dict(), "state_dict": mean.weights() or weights,
                     "training": training}, run / "model.pt")

    def log(m: dict[str, Any]) -> None:
        metrics.append(m)
        with metrics_path.open("a") as f:
            f.write(json.dumps(m) + "\n")

    stop: list[int] = []
    timed_out = False
    # Ctrl-C, or SIGTERM (a batch system's, or `experiments` passing its own on): exit 130, the last
    # checkpoint kept.
    old_handlers = {sig: signal.signal(sig, lambda *_: stop.append(1)) for sig in (signal.SIGINT, signal.SIGTERM)}
    net.train()
    step = start
    t_start = time.perf_counter()
    t_wait = 0.0
    acc: list[float] = []
    terms: dict[str, float] = {}
    last_log = time.perf_counter()
    try:
        it = iter(loader)
        while step < args.steps:
            if stop:
                raise Stop
            t0 = time.perf_counter()
            try:
                batch = next(it)
            except RuntimeError:
                if stop:  # Ctrl-C reached the loader's worker too
                    raise Stop from None
                raise
            t_wait += time.perf_counter() - t0
            loss, parts = window_loss(
                net, batch["x"].to(device), batch["label"].to(device), batch["velocity"].to(device), batch["valid"].to(device),
                cfg.precision, cfg.loss_weights, cfg.class_weight_power,
            )
            if not torch.isfinite(loss):
                raise PedscanError(f"step {step}: the loss is {float(loss)} (window {batch['sequence'].tolist()}, "
                                   f"frame {batch['frame'].tolist()}); lower --lr")
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            step += 1
            mean.add(step)
            acc.append(loss.item())
            for k, v in parts.items():
                terms[k] = terms.get(k, 0.0) + v
            done = step - start
            rate = done / (time.perf_counter() - t_start)
            if not args.quiet and (time.perf_counter() - last_log > 1.0 or step == args.steps):
                last_log = time.perf_counter()
                bar = int(30 * step / args.steps)
                eta = (args.steps - step) / rate if rate > 0 else 0
                print(f"\r[{'#' * bar}{'.' * (30 - bar)}] {step}/{args.steps} {rate:.2f} steps/s "
                      f"loss {np.mean(acc[-50:]):.4g} data wait {100 * t_wait / (time.perf_counter() - t_start):.0f}% "
                      f"eta {eta / 60:.0f} min ", end="", file=sys.stderr)
            if args.max_minutes is not None and time.perf_counter() - t_start > 60 * args.max_minutes:
                timed_out = True
            last = step == args.steps or timed_out
            if step % args.log_every == 0 or last:
                log({"kind": "train", "step": step, "loss": float(np.mean(acc)),
                     **{k: v / len(acc) for k, v in terms.items()}, "lr": sched.get_last_lr()[0],
                     "steps_per_s": rate, "data_wait_share": t_wait / (time.perf_counter() - t_start),
                     "wall_s": time.perf_counter() - t_start})
                acc, terms = [], {}
            if val_seqs and (step % args.val_every == 0 or last):
                averaged = mean.net()
                v = validate(averaged if averaged is not None else net, val_seqs, device, score_from)[0]
                log({"kind": "val", "step": step, **v, **({"weights": "mean"} if mean.count else {})})
                if not args.quiet:
                    o = v["overall"]
                    print(f"\n  step {step}: validation IoU {o['iou'] or 0:.4f} "
                          f"({' / '.join(format(b['iou'] or 0, '.3f') for b in v['bins'])} at 0-4/4-8/8+ m), "
                          f"EPE {o['epe_mps'] or 0:.3f} m/s", file=sys.stderr)
            if step % args.checkpoint_every == 0 or last:
                save(step)
                plot_curves(metrics, run / "curves.png", title)
            if timed_out and step < args.steps:
                log({"kind": "time_limit", "step": step, "steps": args.steps, "max_minutes": args.max_minutes})
                break
            if step == args.stop_at_step:
                stop.append(1)
    except Stop:
        print(f"\nstopped at step {step}; the checkpoint of step "
              f"{load_file(ckpt_path)['step'] if ckpt_path.exists() else 0} stays (--resume continues)", file=sys.stderr)
        return 130
    finally:
        for sig, handler in old_handlers.items():
            signal.signal(sig, handler)
    if start == args.steps and not (run / "model.pt").exists():
        save(step)
    if val_seqs and not args.no_calibrate and start < args.steps:
        c = calibrate_model(run / "model.pt", args.val, device, score_from)
        log({"kind": "calibration", "step": step, **c})
        if not args.quiet:
            print(f"\n  human threshold {c['human_threshold']:.4f} (calibrated on validation): IoU "
                  f"{c['iou_argmax']:.4f} at the argmax -> {c['iou_calibrated']:.4f}", file=sys.stderr)
    if not args.quiet:
        print(file=sys.stderr)
    if timed_out and step < args.steps:
        print(f"{run}: {step} of {args.steps} steps in the --max-minutes {args.max_minutes:g} budget; "
              f"model {run / 'model.pt'} (step {step}); --resume continues")
    else:
        print(f"{run}: {step} steps; model {run / 'model.pt'}")
    return 0


def bench_loader(args: argparse.Namespace) -> int:
    """Windows per second the loader delivers alone (no training), with the run's workers."""
    import torch

    seqs = check_sequences(training_paths(args.data), args.frames, ", ".join(map(str, args.data)), args.intensity)
    data = StepWindows(seqs, args.frames, args.seed, args.intensity)
    n = args.bench_loader
    loader = torch.utils.data.DataLoader(
        data, batch_size=1, sampler=range(n + 8), num_workers=args.workers, prefetch_factor=4 if args.workers else None
    )
    it = iter(loader)
    for _ in range(8):
        next(it)
    t0 = time.perf_counter()
    for _ in range(n):
        next(it)
    rate = n / (time.perf_counter() - t0)
    print(json.dumps({"frames": args.frames, "workers": args.workers, "windows_per_s": rate}))
    return 0


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m pedscan_data.train", description=__doc__.split("\n\n")[0])
    p.add_argument("data", type=Path, nargs="+",
                   help="pedscan output folder(s) with the training sequences; each step draws one of all their "
                   "sequences alike (several backgrounds: one folder each)")
    p.add_argument("--frames", type=int, required=True, help="N, frames per window (1, 2, 4, 8, 16)")
    p.add_argument("--out", type=Path, help="run folder")
    p.add_argument("--steps", type=int, default=4000, help="training steps (default 4000)")
    p.add_argument("--val", type=Path, help="pedscan output folder with validation sequences")
    p.add_argument("--device", default="auto", help="auto | cpu | cuda (default auto)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--width", type=int, default=16, help="channels of the encoder's first layer (default 16)")
    p.add_argument("--intensity", action="store_true", help="also take the return intensity as input")
    p.add_argument("--range-change", action="store_true",
                   help="the decoder also sees each beam's range change against the earlier frames, and the "
                        "velocity branch the whole scan's (not in the paper; N >= 2)")
    p.add_argument("--height", action="store_true",
                   help="the encoder also sees each return's height, range x sin(its row's elevation) (not in the paper)")
    p.add_argument("--batch", type=int, default=1, help="windows per step (paper: 1)")
    p.add_argument("--crop-columns", type=int, default=0, metavar="W",
                   help="train on W columns of each window at a drawn azimuth (a multiple of 8; a step costs about "
                        "W / columns of a whole frame's; validation and prediction stay whole); 0: whole frames (paper)")
    p.add_argument("--lr", type=float, default=1e-3, help="Adam learning rate (paper: 1e-3)")
    p.add_argument("--decay", type=float, default=1e-3, help="time decay: lr / (1 + decay * step) (paper: 1e-3)")
    p.add_argument("--loss-weights", type=float, nargs=3, default=list(PAPER_LOSS_WEIGHTS),
                   metavar=("CE", "BG", "HUMAN"), help="paper: 10000 1 1001")
    p.add_argument("--class-weight-power", type=float, default=1.0, metavar="P",
                   help="a human beam's cross-entropy weight is (background / human beams of its frame) to the power P "
                   "(paper: 1, both classes weigh alike; 0: every beam alike)")
    p.add_argument("--widen-m", type=float, default=0.0, metavar="M",
                   help="make each window's people wider on either side by up to M metres, drawn per window, as clothes "
                   "and carried things make real people (not in the paper; default 0)")
    p.add_argument("--flank", type=float, default=0.0, metavar="P",
                   help="give each person, with probability P, a patch of the frame's own structure right beside it, "
                   "standing 0.05-0.5 m behind the person, as real people stand in stalls and doorways (not in the "
                   "paper; default 0)")
    p.add_argument("--backdrop", type=float, default=0.0, metavar="P",
                   help="give each person, with probability P, a wall 0.5-2 m behind it reaching past its sides, as "
                   "real people stand before stalls, shop fronts and parked cars (not in the paper; default 0)")
    p.add_argument("--mirror", type=float, default=0.0, metavar="P",
                   help="mirror each window left for right with probability P (columns reversed, velocities' y "
                   "negated): streets seen with traffic on the other side (not in the paper; default 0)")
    p.add_argument("--precision", choices=PRECISIONS, default="fp32",
                   help="the training step's forward pass: fp32 (default), or bf16 under autocast (0.5-0.75 of "
                   "fp32's step time on a CPU with AVX-512 BF16; --bench-step measures it; validation stays fp32)")
    p.add_argument("--average-from", type=int, default=None, metavar="K",
                   help="the run's weights (model.pt, validation, calibration) are the mean of those after each step "
                   "past step K (not in the paper; default: the last step's)")
    p.add_argument("--init", type=Path, default=None, metavar="MODEL",
                   help="start from the weights of this model file (the same network options; fine-tuning)")
    p.add_argument("--workers", type=int, default=1, help="data-loading processes (default 1; 0: in the trainer)")
    p.add_argument("--val-every", type=int, default=500)
    p.add_argument("--checkpoint-every", type=int, default=250)
    p.add_argument("--log-every", type=int, default=50)
    p.add_argument("--score-from", type=int, help="validation scores frames from this one (default N-1)")
    p.add_argument("--no-calibrate", action="store_true",
                   help="keep the softmax's argmax (by default, with --val, the human threshold that "
                   "maximizes validation IoU is written into model.pt at the end)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--stop-at-step", type=int, metavar="K",
                   help="stop after step K as Ctrl-C would (exit 130; --resume continues): for tests of resuming")
    p.add_argument("--max-minutes", type=float, metavar="M",
                   help="end this sitting after M minutes of training: checkpoint, validate, calibrate, exit 0 "
                        "(--resume continues to --steps)")
    p.add_argument("--bench-loader", type=int, metavar="WINDOWS", help="only time the loader over this many windows")
    p.add_argument("--bench-step", type=int, metavar="STEPS",
                   help="only time the training step on the data's grid in each --precision, interleaved (5 rounds of STEPS)")
    return p


def bench_step(args: argparse.Namespace) -> int:
    """Seconds per training step (forward, loss, backward, Adam) of the run's network on the CPU, on the first
    training sequence's grid (``--crop-columns`` wide where given) in each ``--precision``,
    the precisions interleaved, 5 rounds of ``args.bench_step`` steps: the medians and their
    ratio to fp32's. Random inputs and labels: the step's cost does not depend on them."""
    import statistics

    import torch

    from .model import NetConfig, SequenceNet

    if args.bench_step < 1:
        raise PedscanError(f"--bench-step {args.bench_step}: at least one step a round")
    seqs = check_sequences(training_paths(args.data), args.frames, ", ".join(map(str, args.data)), args.intensity)
    rows, cols = seqs[0].rows, args.crop_columns or seqs[0].columns
    torch.manual_seed(args.seed)
    x = torch.rand(args.batch, args.frames, 3 if args.intensity else 2, rows, cols)
    label = (torch.rand(args.batch, rows, cols) < 0.01).long()
    velocity, valid = torch.zeros(args.batch, 3, rows, cols), torch.ones(args.batch, rows, cols, dtype=torch.bool)
    steps = {}
    for precision in PRECISIONS:
        net = SequenceNet(NetConfig(frames=args.frames, intensity=args.intensity, width=args.width, range_change=args.range_change,
                                    elevation_deg=tuple(float(e) for e in seqs[0].elevation_deg) if args.height else ()))
        opt = torch.optim.Adam(net.parameters(), lr=args.lr)

        def step(net=net, opt=opt, precision=precision) -> None:
            loss = window_loss(net, x, label, velocity, valid, precision, PAPER_LOSS_WEIGHTS, 1.0)[0]
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
        step()
        steps[precision] = step
    times: dict[str, list[float]] = {p: [] for p in PRECISIONS}
    for _ in range(5):
        for p, step in steps.items():
            t0 = time.perf_counter()
            for _ in range(args.bench_step):
                step()
            times[p].append((time.perf_counter() - t0) / args.bench_step)
    med = {p: statistics.median(t) for p, t in times.items()}
    print(json.dumps({"frames": args.frames, "grid": [rows, cols], "batch": args.batch, "threads": torch.get_num_threads(),
                      "s_per_step": med, "ratio_to_fp32": {p: m / med["fp32"] for p, m in med.items()}}))
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        if args.bench_loader:
            return bench_loader(args)
        if args.bench_step is not None:
            return bench_step(args)
        if args.out is None:
            parser().error("--out RUN is needed")
        if args.steps < 0:
            raise PedscanError(f"--steps {args.steps}: not a number of steps")
        return train(args)
    except (PedscanError, FileNotFoundError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
