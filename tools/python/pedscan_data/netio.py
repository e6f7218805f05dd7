"""Model files, run folders and the environment a run records (shared by train, predict and
the experiments).

A **model file** (``model.pt``) is a plain dict saved with ``torch.save`` and read back with
``torch.load(weights_only=True)`` (no pickled code runs): ``format``, ``net`` (the
:class:`~pedscan_data.model.NetConfig`), ``state_dict``, and ``training`` (how it was made).
A **run folder** holds ``run.json`` (the configuration), ``checkpoint.pt`` (model, optimizer
and the step), ``model.pt`` (the latest weights), ``metrics.jsonl`` and ``curves.png``.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import warnings
from pathlib import Path
from typing import Any

from .reader import PedscanError

MODEL_FORMAT = "pedscan-net/1"


class RunError(PedscanError):
    """A model, checkpoint or run folder that cannot be used (named in the message)."""


def environment(device: Any) -> dict[str, Any]:
    """What a run records about where it ran: device, versions, threads."""
    import h5py
    import numpy
    import torch

    dev = str(device)
    name = platform.processor() or platform.machine()
    if dev.startswith("cuda"):
        name = torch.cuda.get_device_name(device)
    return {
        "device": dev,
        "device_name": name,
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "python": sys.version.split()[0],
        "torch": str(torch.__version__),
        "numpy": numpy.__version__,
        "h5py": h5py.__version__,
        "platform": platform.platform(),
    }


def atomic_save(obj: Any, path: Path) -> None:
    """``torch.save`` to a temporary name, then rename: a reader never sees half a file."""
    import torch

    tmp = path.with_name(path.name + ".tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def save_figure(fig: Any, path: Path) -> None:
    """A matplotlib figure as PNG under a temporary name, renamed when written; closes it."""
    import matplotlib.pyplot as plt

    tmp = path.with_name(path.name + ".tmp.png")
    fig.savefig(tmp, dpi=80)
    plt.close(fig)
    os.replace(tmp, path)


def load_file(path: Path) -> dict[str, Any]:
    """A model file or checkpoint, read without running pickled code; RunError if unreadable."""
    import torch

    if not path.is_file():
        raise RunError(f"{path}: no such file")
    # What torch warns while failing on a damaged file (e.g. "Detected pickle protocol 4") is
    # noise before the error below; a file that loads gets its warnings as usual.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            obj = torch.load(path, map_location="cpu", weights_only=True)
        except Exception as e:  # torch raises many types for a damaged file
            raise RunError(f"{path}: not a readable pedscan model or checkpoint ({type(e).__name__}: {e})") from e
    for w in caught:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    if not isinstance(obj, dict) or obj.get("format") != MODEL_FORMAT:
        raise RunError(f"{path}: not a pedscan model or checkpoint (format is not {MODEL_FORMAT!r})")
    return obj


def load_net(path: str | os.PathLike[str], device: Any = "cpu") -> tuple[Any, dict[str, Any]]:
    """The network of a model file or of a run folder (its ``model.pt``), in eval mode."""
    from .model import NetConfig, SequenceNet

    p = Path(path)
    if p.is_dir():
        if not (p / "model.pt").is_file():
            raise RunError(f"{p}: a folder without model.pt (not a training run, or one that has not saved yet)")
        p = p / "model.pt"
    obj = load_file(p)
    try:
        cfg = NetConfig(**obj["net"])
        net = SequenceNet(cfg)
        net.load_state_dict(obj["state_dict"])
    except (KeyError, TypeError, RuntimeError, ValueError) as e:
        raise RunError(f"{p}: the weights do not fit the network it describes ({e})") from e
    net.to(device).eval()
    return net, obj


def read_json(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise RunError(f"{path}: unreadable ({e})") from e
