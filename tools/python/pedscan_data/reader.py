"""Lazy reading of pedscan sequence files (``seq_NNNNNN.h5``).

A :class:`Sequence` reads its attributes, beam table, poses and people when opened, and the
per-beam grids only when asked, a frame (or a slice of frames) at a time, through h5py
slicing: a frame read decompresses that frame's chunk of each dataset asked for and nothing
else.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Self

import h5py
import numpy as np

#: The per-beam datasets a sequence may hold, in the order pedscan writes them.
BEAM_FIELDS: tuple[str, ...] = ("range", "xyz", "label", "instance", "velocity", "background/range", "intensity")

#: What :meth:`Sequence.frame` reads when no fields are named.
DEFAULT_FIELDS: tuple[str, ...] = ("range", "label", "instance")


class PedscanError(Exception):
    """A file that is not a pedscan sequence, lacks a dataset asked for, or does not match."""


@dataclass(frozen=True)
class Humans:
    """The people of a sequence: entry k-1 is instance k (N people, T frames)."""

    height_m: np.ndarray
    """f32 [N]"""
    weight_kg: np.ndarray
    """f32 [N]"""
    model: list[str]
    """[N] model names (glTF file stems)"""
    position_m: np.ndarray
    """f64 [T,N,3] world, feet on the floor"""
    heading_rad: np.ndarray
    """f32 [T,N] world"""
    gait_phase: np.ndarray
    """f32 [T,N] in [0, 1), 0 = left heel strike"""
    velocity_mps: np.ndarray
    """f32 [T,N,3] world"""


@dataclass(frozen=True)
class Frame:
    """One frame's per-beam grids ([H,W] or [H,W,3]); a field not read is None."""

    sequence: int
    index: int
    time_s: float
    world_from_sensor: np.ndarray
    range: np.ndarray | None = None
    xyz: np.ndarray | None = None
    label: np.ndarray | None = None
    instance: np.ndarray | None = None
    velocity: np.ndarray | None = None
    background_range: np.ndarray | None = None
    intensity: np.ndarray | None = None


def _attr_int(f: h5py.File, key: str, path: Path) -> int:
    if key not in f.attrs:
        raise PedscanError(f"{path}: not a pedscan sequence (no root attribute {key!r})")
    return int(f.attrs[key])


def _attr_str(f: h5py.File, key: str) -> str:
    value = f.attrs.get(key, "")
    return value.decode() if isinstance(value, bytes) else str(value)


class Sequence:
    """One pedscan sequence file, opened read-only.

    The file handle is opened on first data access and reopened in a forked process (a
    PyTorch DataLoader worker), since an HDF5 handle must not be shared across a fork.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self._file: h5py.File | None = None
        self._pid = -1
        try:
            self._load()
        except BaseException:
            self.close()
            raise

    def _load(self) -> None:
        """Reads the attributes, beam table, poses and people; checks the grids' shapes."""
        f = self._h5()
        if "pedscan_version" not in f.attrs:
            raise PedscanError(f"{self.path}: not a pedscan sequence (no pedscan_version attribute)")
        self.version: str = _attr_str(f, "pedscan_version")
        self.index: int = _attr_int(f, "index", self.path)
        self.seed: int = _attr_int(f, "seed", self.path)
        self.frames: int = _attr_int(f, "frames", self.path)
        self.rows: int = _attr_int(f, "rows", self.path)
        self.columns: int = _attr_int(f, "columns", self.path)
        self.sensor: str = _attr_str(f, "sensor")
        self.config: str = _attr_str(f, "config")
        self.provenance: dict[str, str] = dict(
            line.split("=", 1) for line in _attr_str(f, "provenance").splitlines() if "=" in line
        )
        self.fields: tuple[str, ...] = tuple(k for k in BEAM_FIELDS if k in f)
        for key in self.fields:
            shape = f[key].shape
            if shape[:3] != (self.frames, self.rows, self.columns):
                raise PedscanError(
                    f"{self.path}: /{key} has shape {shape}, the attributes say "
                    f"[{self.frames},{self.rows},{self.columns}]"
                )
        self.elevation_deg: np.ndarray = self._small("sensor/elevation_deg")
        self.azimuth_deg: np.ndarray = self._small("sensor/azimuth_deg")
        self.time_s: np.ndarray = self._small("sensor/time_s")
        self.world_from_sensor: np.ndarray = self._small("sensor/world_from_sensor")
        self.humans = Humans(
            height_m=self._small("humans/height_m"),
            weight_kg=self._small("humans/weight_kg"),
            model=[m.decode() if isinstance(m, bytes) else str(m) for m in self._small("humans/model")],
            position_m=self._small("humans/position_m"),
            heading_rad=self._small("humans/heading_rad"),
            gait_phase=self._small("humans/gait_phase"),
            velocity_mps=self._small("humans/velocity_mps"),
        )

    def _h5(self) -> h5py.File:
        """The open file, (re)opened in this process if needed."""
        if self._file is None or self._pid != os.getpid():
            try:
                self._file = h5py.File(self.path, "r")
            except FileNotFoundError:
                raise FileNotFoundError(f"{self.path}: no such file") from None
            except OSError as e:
                raise PedscanError(f"{self.path}: not an HDF5 file ({e})") from e
            self._pid = os.getpid()
        return self._file

    def _small(self, key: str) -> np.ndarray:
        return self.dataset(key)[()]

    def dataset(self, key: str) -> h5py.Dataset:
        """The h5py dataset ``key`` (e.g. ``"range"``, ``"humans/position_m"``), not read."""
        f = self._h5()
        if key not in f or not isinstance(f[key], h5py.Dataset):
            hint = " (not in the --outputs it was written with)" if key in BEAM_FIELDS else ""
            raise PedscanError(f"{self.path}: no dataset /{key}{hint}")
        return f[key]

    def has(self, key: str) -> bool:
        """Whether the per-beam dataset ``key`` was written."""
        return key in self.fields

    def read(self, key: str, frames: int | slice = slice(None)) -> np.ndarray:
        """Frames ``frames`` of the per-beam dataset ``key``; reads only those chunks."""
        if key not in BEAM_FIELDS:
            raise ValueError(f"{key!r} is not a per-beam dataset; one of {', '.join(BEAM_FIELDS)}")
        if isinstance(frames, int) and not -self.frames <= frames < self.frames:
            raise IndexError(f"{self.path}: frame {frames} of {self.frames}")
        return self.dataset(key)[frames]

    def range_digest(self) -> str:
        """SHA-256 of the sequence's ranges (little-endian float32, frame by frame): what a
        prediction file records of the data it was made from, for ``evaluate`` to check."""
        import hashlib

        h = hashlib.sha256()
        for t in range(self.frames):
            h.update(np.ascontiguousarray(self.read("range", t), dtype="<f4").tobytes())
        return h.hexdigest()

    def frame(self, t: int, fields: tuple[str, ...] | None = None) -> Frame:
        """Frame ``t`` with ``fields`` read (default: range, label, instance)."""
        fields = DEFAULT_FIELDS if fields is None else fields
        if not -self.frames <= t < self.frames:
            raise IndexError(f"{self.path}: frame {t} of {self.frames}")
        t %= self.frames
        grids = {key.replace("/", "_"): self.read(key, t) for key in fields}
        return Frame(
            sequence=self.index,
            index=t,
            time_s=float(self.time_s[t]),
            world_from_sensor=self.world_from_sensor[t],
            **grids,
        )

    def iter_frames(self, fields: tuple[str, ...] | None = None) -> Iterator[Frame]:
        """Every frame in order, one read at a time (see :meth:`frame`)."""
        for t in range(self.frames):
            yield self.frame(t, fields)

    def __len__(self) -> int:
        return self.frames

    def __getstate__(self) -> dict[str, object]:
        """Pickles without the file handle (DataLoader workers started by spawn reopen it)."""
        return {**self.__dict__, "_file": None}

    def close(self) -> None:
        """Closes the file; a later read opens it again."""
        if self._file is not None and self._pid == os.getpid():
            self._file.close()
        self._file = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return (
            f"Sequence({str(self.path)!r}, index={self.index}, frames={self.frames}, "
            f"grid={self.rows}x{self.columns}, humans={len(self.humans.model)})"
        )


def sequence_paths(path: str | os.PathLike[str]) -> list[Path]:
    """``path`` itself if a file, else the folder's ``seq_*.h5`` files sorted by name."""
    p = Path(path)
    if p.is_dir():
        found = sorted(p.glob("seq_*.h5"))
        if not found:
            raise PedscanError(f"{p}: no seq_*.h5 files in this folder")
        return found
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or folder")
    return [p]


def open_sequences(path: str | os.PathLike[str]) -> list[Sequence]:
    """The sequences of a pedscan output folder (sorted) or of one sequence file."""
    return [Sequence(p) for p in sequence_paths(path)]
