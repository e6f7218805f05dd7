"""N-frame windows for training, after Kim et al. (IEEE Access 2020).

A window is the range images of N consecutive frames of one sequence, with the last frame's
labels and velocities as the targets; windows never cross sequence boundaries.
:class:`WindowDataset` returns numpy arrays and needs nothing beyond numpy and h5py;
:class:`TorchWindowDataset` wraps it for a PyTorch ``DataLoader`` and imports torch only
when built.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from .evaluate import NOT_SCORED
from .reader import PedscanError, Sequence, open_sequences


def class_weight(label: np.ndarray, range_m: np.ndarray) -> float:
    """The paper's human class weight for one frame: background beams / human beams.

    Only beams with a return count (``range_m > 0``), and not the not-scored ones (``label``
    255: a recorded background's own people). A frame without a human beam gets 1.0, so a
    weighted loss stays unweighted there.
    """
    returned = (range_m > 0) & (label != NOT_SCORED)
    humans = int(np.count_nonzero(returned & (label == 1)))
    if humans == 0:
        return 1.0
    return (int(np.count_nonzero(returned)) - humans) / humans


#: A velocity mirrored left for right (the world reflected in the sensor's x-z plane, the range
#: image's columns reversed): its y negated. Training's mirrored windows and ``predict
#: --mirror`` both use it.
MIRROR_VELOCITY = (1.0, -1.0, 1.0)

#: A widened person's cells must lie this much nearer than what they cover, m.
WIDEN_STEP_M = 0.3


def widen_people(range_m: np.ndarray, label: np.ndarray, reach_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One frame's people made up to ``reach_m`` wider on either side, as clothes, bags and
    carried things make real people wider than the bodies pedscan draws.

    range_m f32 [H,W] (0 = no return) and label [H,W] (1 human) of a whole turn (columns wrap).
    A cell takes the range and label of the human cell ``d`` columns to its left or right when
    ``d`` columns span at most ``reach_m`` at that person's range, the cell is not human, and it
    holds no return or one more than :data:`WIDEN_STEP_M` farther (a person never grows over
    what stands in front of it) and every cell between them has grown too; the nearest such
    human cell wins, the left one on a tie.
    Returns the new range, the new label and, per cell, the column it was taken from (its own
    where unchanged), for the arrays that go with the cell (intensity, velocity).
    """
    h, w = range_m.shape
    cols = np.broadcast_to(np.arange(w), (h, w))
    src = cols.copy()
    r_out, l_out = range_m.copy(), label.copy()
    human = label == 1
    if reach_m <= 0 or not human.any():
        return r_out, l_out, src
    column_rad = 2.0 * np.pi / w
    nearest = float(range_m[human & (range_m > 0)].min(initial=np.inf))
    if not np.isfinite(nearest):
        return r_out, l_out, src
    reach_cols = np.zeros((h, w), dtype=np.float64)
    ok = human & (range_m > 0)
    reach_cols[ok] = reach_m / (range_m[ok] * column_rad)
    grown = human.copy()
    # Per side, the cells grown from it so far: growth stays contiguous (it stops at what it
    # may not cover).
    chain = {1: human.copy(), -1: human.copy()}
    for d in range(1, min(int(reach_m / (nearest * column_rad)), w // 2) + 1):
        for side in (1, -1):  # from the human cell d columns to the left, then to the right
            sr, sh, sreach = (np.roll(a, side * d, axis=1) for a in (range_m, human, reach_cols))
            take = (sh & (sreach >= d) & ~grown & np.roll(chain[side], side, axis=1)
                    & ((r_out <= 0) | (sr < r_out - WIDEN_STEP_M)))
            r_out[take], l_out[take], src[take] = sr[take], 1, ((cols - side * d) % w)[take]
            grown |= take
            chain[side] |= take
    return r_out, l_out, src


def person_cells(range_m: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, float]:
    """A person's cells (a mask of a whole turn) as rows, columns, the shift of those columns
    and its median range. A person across the turn's seam is seen from the seam's other side:
    its columns are shifted by half a turn (``shift``; 0 otherwise), so that they run on;
    ``(c - shift) % w`` gives a grid column back."""
    w = range_m.shape[1]
    rows, cc = np.nonzero(cells)
    shift = w // 2 if cc.max() - cc.min() > w // 2 else 0
    return rows, (cc + shift) % w, shift, float(np.median(range_m[cells]))


#: What :func:`flank_people` puts beside a person: a patch this wide (m, at the person's range),
#: standing this far behind the person's front (m), its cells within this depth of the patch's
#: median (m).
FLANK_WIDTH_M = (0.2, 1.0)
FLANK_BEHIND_M = (0.05, 0.5)
FLANK_DEPTH_M = 1.5


def flank_people(range_m: np.ndarray, label: np.ndarray, instance: np.ndarray, p: float,
                 rng: np.random.Generator, people: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One frame's people, each with probability ``p``, given structure right beside them, as
    real people stand in stalls, frames and doorways whose returns meet their edges at nearly
    their range.

    range_m f32 [H,W] (0 = no return), label [H,W] (1 human, 255 not scored), instance [H,W]
    (the person of each human cell; 0 elsewhere) of a whole turn. For a person chosen, on its
    left, its right or both sides (a third each), a patch of the frame's own returns from
    elsewhere (the person's rows, a drawn column, ``FLANK_WIDTH_M`` wide at the person's median
    range) is moved in range so that its median stands ``FLANK_BEHIND_M`` behind the person's
    median range, and put against the person's edge row by row: a cell takes the patch's cell
    if it is background (label 0), holds no return or one farther than the moved one, and the
    patch's cell is a background return within ``FLANK_DEPTH_M`` of the patch's median. Labels
    do not change (what is put there is background). The draws come from ``rng``, person by
    person in the order of ``people`` (the ids to draw for; default: the frame's people, in
    order), a person absent from the frame drawing as one present: a generator of one state
    and the ids of all of a window's frames give each person one patch in all of them.
    Returns the new range and, per cell, the column it was taken from (its own where
    unchanged), for the arrays that go with the cell (intensity, velocity).
    """
    h, w = range_m.shape
    cols = np.broadcast_to(np.arange(w), (h, w))
    src = cols.copy()
    r_out = range_m.copy()
    ids = np.unique(instance[(label == 1) & (instance > 0)]) if people is None else people
    column_rad = 2.0 * np.pi / w
    background = (label == 0) & (range_m > 0)
    for pid in ids:
        chosen, side, width_m, behind_m = rng.random() < p, int(rng.integers(3)), rng.uniform(*FLANK_WIDTH_M), rng.uniform(*FLANK_BEHIND_M)
        starts = rng.integers(w, size=8)
        cells = (instance == pid) & (label == 1) & (range_m > 0)
        if not chosen or not cells.any():
            continue
        rows, cc, shift, rp = person_cells(range_m, cells)
        k = max(1, int(round(width_m / (rp * column_rad))))
        r0, r1 = int(rows.min()), int(rows.max()) + 1
        patch = None
        for s0 in starts:
            pc = (int(s0) + np.arange(k)) % w
            pr = range_m[r0:r1][:, pc]
            ok = background[r0:r1][:, pc]
            if ok.mean() < 0.3:
                continue
            med = float(np.median(pr[ok]))
            ok &= np.abs(pr - med) < FLANK_DEPTH_M
            patch = (pc, np.where(ok, pr - med + rp + behind_m, 0.0))
            break
        if patch is None:
            continue
        pc, moved = patch
        for row in range(r0, r1):
            in_row = cc[rows == row]
            if in_row.size == 0:
                continue
            edges = []
            if side in (0, 2):  # left: the patch's last column against the person's first
                edges.append((int(in_row.min()) - k + np.arange(k) - shift) % w)
            if side in (1, 2):
                edges.append((int(in_row.max()) + 1 + np.arange(k) - shift) % w)
            for dst in edges:
                new = moved[row - r0]
                cur = r_out[row, dst]
                take = (new > 0) & (label[row, dst] == 0) & ((cur <= 0) | (cur > new))
                r_out[row, dst[take]] = new[take]
                src[row, dst[take]] = pc[take]
    return r_out, src


#: What :func:`backdrop_people` puts behind a person: a wall this far behind the person's median
#: range (m), reaching this far past each of its sides (m, at its range) and up to this share of
#: the person's rows above its head, turned so that its range changes by up to this much per
#: metre across, with this range noise (m, one sigma).
BACKDROP_BEHIND_M = (0.5, 2.0)
BACKDROP_SIDE_M = (0.3, 1.5)
BACKDROP_ABOVE = 1.0
BACKDROP_SLOPE = 0.3
BACKDROP_NOISE_M = 0.02


def backdrop_people(range_m: np.ndarray, label: np.ndarray, instance: np.ndarray, p: float,
                    rng: np.random.Generator, people: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One frame's people, each with probability ``p``, given a wall close behind them, as real
    people stand before stalls, shop fronts, parked cars and hedges: a real person's rows hold
    returns 0.5-2 m behind it on either side far more often than a generated person's.

    range_m f32 [H,W] (0 = no return), label [H,W] (1 human, 255 not scored), instance [H,W]
    (the person of each human cell) of a whole turn. For a person chosen, a wall stands
    ``BACKDROP_BEHIND_M`` behind its median range, from ``BACKDROP_SIDE_M`` left of its first
    column to as far right of its last (each side drawn), over its rows and up to
    ``BACKDROP_ABOVE`` of its height in rows above its head, its range turning by up to
    ``BACKDROP_SLOPE`` m per metre across and noisy by ``BACKDROP_NOISE_M``. A cell takes the
    wall where it is not the person's own, not "not scored", and holds no return or one farther
    than the wall (what stands in front stays; another person behind it is hidden: label 0).
    The draws come from ``rng``, person by person in the order of ``people`` (default: the
    frame's people), a person absent from the frame drawing as one present: a generator of one
    state and the ids of all of a window's frames give each person one wall in all of them.
    Returns the new range and label; the cells keep their own velocity and intensity (a wall
    stands still, as the background behind it).
    """
    h, w = range_m.shape
    r_out, l_out = range_m.copy(), label.copy()
    ids = np.unique(instance[(label == 1) & (instance > 0)]) if people is None else people
    column_rad = 2.0 * np.pi / w
    for pid in ids:
        chosen, behind_m = rng.random() < p, rng.uniform(*BACKDROP_BEHIND_M)
        left_m, right_m = rng.uniform(*BACKDROP_SIDE_M, size=2)
        above, slope = rng.uniform(0.0, BACKDROP_ABOVE), rng.uniform(-BACKDROP_SLOPE, BACKDROP_SLOPE)
        noise_seed = int(rng.integers(2**31))
        cells = (instance == pid) & (label == 1) & (range_m > 0)
        if not chosen or not cells.any():
            continue
        rows, cc, shift, rp = person_cells(range_m, cells)
        c0 = int(cc.min()) - int(round(left_m / (rp * column_rad)))
        c1 = int(cc.max()) + int(round(right_m / (rp * column_rad)))
        half = (w - 1 - (int(cc.max()) - int(cc.min()))) // 2
        c0, c1 = max(c0, int(cc.min()) - half), min(c1, int(cc.max()) + half)  # never round the turn
        r1 = int(rows.max()) + 1
        r0 = max(0, int(rows.min()) - int(round(above * (r1 - int(rows.min())))))
        offsets = np.arange(c0, c1 + 1)
        across_m = (offsets - 0.5 * (c0 + c1)) * rp * column_rad
        noise = np.random.default_rng(noise_seed).normal(0.0, BACKDROP_NOISE_M, size=(r1 - r0, offsets.size))
        wall = (rp + behind_m + slope * across_m)[None, :] + noise
        dst = (offsets - shift) % w
        cur, lab, own = r_out[r0:r1][:, dst], l_out[r0:r1][:, dst], (instance[r0:r1][:, dst] == pid) & (label[r0:r1][:, dst] == 1)
        take = ~own & (lab != NOT_SCORED) & ((cur <= 0) | (cur > wall)) & (wall > 0)
        r_out[r0:r1, dst] = np.where(take, wall, cur).astype(r_out.dtype)
        l_out[r0:r1, dst] = np.where(take, 0, lab).astype(l_out.dtype)
    return r_out, l_out


class WindowDataset:
    """Windows of ``length`` consecutive frames over one sequence file or a pedscan folder.

    Item ``i`` is a dict of numpy arrays (H rows, W columns):

    - ``range``: f32 [length,H,W], frames t-length+1 .. t (0 = no return)
    - ``label``: u8 [H,W], frame t (1 human); ``instance``: u16 [H,W] if asked for
    - ``velocity``: f32 [H,W,3], frame t, m/s in the sensor frame (if in ``targets``)
    - ``class_weight``: f32 scalar, background beams / human beams of frame t
    - ``sequence``, ``frame``: the sequence index and t

    Consecutive windows start ``stride`` frames apart; a sequence shorter than ``length``
    contributes none.
    """

    def __init__(
        self,
        source: str | os.PathLike[str] | list[Sequence],
        length: int,
        stride: int = 1,
        targets: tuple[str, ...] = ("label", "velocity"),
    ) -> None:
        if length < 1 or stride < 1:
            raise ValueError(f"length and stride must be at least 1 (got {length} and {stride})")
        self.sequences = source if isinstance(source, list) else open_sequences(source)
        self.length = length
        self.targets = tuple(dict.fromkeys(("label",) + tuple(targets)))
        for seq in self.sequences:
            for key in ("range",) + self.targets:
                if not seq.has(key):
                    raise PedscanError(f"{seq.path}: no dataset /{key}, which the windows need")
        self._index: list[tuple[int, int]] = [
            (s, t)
            for s, seq in enumerate(self.sequences)
            for t in range(length - 1, seq.frames, stride)
        ]

    def __len__(self) -> int:
        return len(self._index)

    def __getitem__(self, i: int) -> dict[str, Any]:
        s, t = self._index[i]
        seq = self.sequences[s]
        item: dict[str, Any] = {"range": seq.read("range", slice(t - self.length + 1, t + 1))}
        for key in self.targets:
            item[key] = seq.read(key, t)
        item["class_weight"] = np.float32(class_weight(item["label"], item["range"][-1]))
        item["sequence"] = seq.index
        item["frame"] = t
        return item


class TorchWindowDataset(WindowDataset):
    """:class:`WindowDataset` returning torch tensors, for ``torch.utils.data.DataLoader``.

    ``label`` and ``instance`` become int64 (what the losses take), the rest keep their
    types; ``sequence`` and ``frame`` stay ints. Needs PyTorch, imported here.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        try:
            import torch
        except ImportError as e:
            raise ImportError(
                "TorchWindowDataset needs PyTorch (pip install torch; a CPU-only build: "
                "pip install torch --index-url https://download.pytorch.org/whl/cpu); "
                "WindowDataset gives the same windows as numpy arrays"
            ) from e
        del torch
        super().__init__(*args, **kwargs)

    def __getitem__(self, i: int) -> dict[str, Any]:
        import torch

        item = super().__getitem__(i)
        out: dict[str, Any] = {}
        for key, value in item.items():
            if key in ("label", "instance"):
                out[key] = torch.from_numpy(value.astype(np.int64))
            elif isinstance(value, np.ndarray):
                out[key] = torch.from_numpy(value)
            elif isinstance(value, np.floating):
                out[key] = torch.tensor(float(value), dtype=torch.float32)
            else:
                out[key] = value
        return out
