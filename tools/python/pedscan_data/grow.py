"""Region growing from confident beams: a network's human margins read as a hysteresis.

A plain threshold calls a beam human where its own margin (logit of human minus logit of
background) exceeds a cut. Growing calls it human where the highest margin of its *component*
does: the beams whose margins exceed a lower cut ``low``, joined where they are 4-neighbours on
the sensor grid (columns wrap round: the grid is a full turn) and their ranges step by less
than ``step_m``. A person's confident core then carries the beams at their edges that the
network is less sure of, and a weak beam with no confident beam beside it stays background.

With ``low`` at or above the cut, growing is the plain threshold. A model file opts in with
``grow`` (``{"margin": low, "step_m": step}``), chosen on validation data by
:func:`calibrate_grow` (``python -m pedscan_data.calibrate MODEL --val DATA --grow``);
``predict`` then applies it (:func:`human_mask`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: The lower cuts tried, as margins below the plain threshold's cut, and the range steps (m).
LOW_BELOW = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0)
STEPS_M = (0.05, 0.1, 0.2, 0.5, 1.0)


def component_roots(joined: np.ndarray, range_m: np.ndarray, step_m: float) -> np.ndarray:
    """Per beam of an [H, W] grid, the smallest flat index of its component (an int64 [H, W]):
    beams of ``joined`` that are 4-neighbours (columns wrap) with ranges less than ``step_m``
    apart share a component; every other beam is its own."""
    h, w = joined.shape
    flat = np.arange(h * w, dtype=np.int64).reshape(h, w)
    right = joined & np.roll(joined, -1, axis=1) & (np.abs(range_m - np.roll(range_m, -1, axis=1)) < step_m)
    down = joined[:-1] & joined[1:] & (np.abs(range_m[:-1] - range_m[1:]) < step_m)
    u = np.concatenate([flat[right], flat[:-1][down]])
    v = np.concatenate([np.roll(flat, -1, axis=1)[right], flat[1:][down]])
    parent = flat.ravel().copy()
    while u.size:
        pu, pv = parent[u], parent[v]
        apart = pu != pv
        if not apart.any():
            break
        # Hook each edge's larger root under its smaller one (parent[i] <= i throughout: no
        # cycles), then follow the pointers to the roots.
        np.minimum.at(parent, np.maximum(pu, pv)[apart], np.minimum(pu, pv)[apart])
        while True:
            up = parent[parent]
            if np.array_equal(up, parent):
                break
            parent = up
        u, v = u[apart], v[apart]
    return parent.reshape(h, w)


def grown_margin(margin: np.ndarray, range_m: np.ndarray, low: float, step_m: float) -> np.ndarray:
    """Each beam's margin replaced by the highest of its component (:func:`component_roots`
    over the returned beams whose margins exceed ``low``); the others keep their own. A beam
    is human where this exceeds the threshold's cut."""
    joined = (margin > low) & (range_m > 0)
    out = margin.astype(np.float32, copy=True)
    if not joined.any():
        return out
    roots = component_roots(joined, range_m, step_m)[joined]
    top = np.full(margin.size, -np.inf, dtype=np.float32)
    np.maximum.at(top, roots, margin[joined].astype(np.float32))
    out[joined] = top[roots]
    return out


def model_grow(obj: dict[str, Any], model: Any) -> dict[str, float] | None:
    """A model file's ``grow``, checked: None, or a finite ``margin`` and a positive finite
    ``step_m``; PedscanError naming ``model`` otherwise."""
    from .reader import PedscanError

    g = obj.get("grow")
    if g is None:
        return None
    try:
        margin, step = float(g["margin"]), float(g["step_m"])
    except (TypeError, KeyError, ValueError) as e:
        raise PedscanError(f"{model}: its grow {g!r} is not a margin and a step_m ({e})") from e
    if not (np.isfinite(margin) and np.isfinite(step) and step > 0):
        raise PedscanError(f"{model}: its grow needs a finite margin and a positive step_m, not {g!r}")
    return {"margin": margin, "step_m": step}


def as_predicted(margin: np.ndarray, range_m: np.ndarray, grow: dict[str, Any] | None) -> np.ndarray:
    """One frame's margins as the threshold reads them: grown with ``grow`` (a model file's),
    else as they are."""
    if not grow:
        return margin
    return grown_margin(margin, range_m, float(grow["margin"]), float(grow["step_m"]))


def human_mask(margin: np.ndarray, range_m: np.ndarray, cut: float, grow: dict[str, Any] | None) -> np.ndarray:
    """Human beams of one frame: its margins as predicted (:func:`as_predicted`) above ``cut``."""
    return as_predicted(margin, range_m, grow) > cut


def calibrate_grow(
    frames: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]], plain_cut: float,
) -> dict[str, Any]:
    """Chooses growing on validation frames, each (margin [H,W], range_m [H,W], human [H,W]
    bool, scored [H,W] bool): for every lower cut ``plain_cut`` - d (d in :data:`LOW_BELOW`)
    and step in :data:`STEPS_M`, the cut that maximizes the IoU over the scored beams of the
    grown margins, found exactly (:func:`~pedscan_data.train.best_cut`). Returns the best
    (``margin``, ``step_m``, ``cut``, ``iou``) and every pair's IoU (``tried``)."""
    from .train import best_cut

    y = np.concatenate([h[s] for _, _, h, s in frames])
    best: dict[str, Any] | None = None
    tried = []
    for d in LOW_BELOW:
        low = plain_cut - d
        for step in STEPS_M:
            g = np.concatenate([grown_margin(m, r, low, step)[s] for m, r, _, s in frames]).astype(np.float64)
            cut, iou = best_cut(g, y)
            tried.append({"margin": low, "step_m": step, "cut": cut, "iou": iou})
            if best is None or iou > best["iou"]:
                best = tried[-1]
    assert best is not None
    return {**best, "tried": tried}
