"""The sequence's lead over training seeds: the paper's finding (16 frames beat one on far
people) measured as ``experiments paper --seeds`` trains it, the 16-frame network's IoU minus
the single frame's per distance bin, per seed, with its mean and spread, and each world's lead
against the hall's; and the same networks on the hall's recorded test set over their seeds, each
world against the hall's."""

from __future__ import annotations

import re
from typing import Any

#: The networks ``--seeds`` trains once per seed: the sequence's lead is N = 16 over N = 1.
SEED_FRAMES = (16, 1)
#: The distance bins of a score's IoU row (:func:`iou_row`): overall, then the paper's three.
BIN_NAMES = ("0-inf m", "0-4 m", "4-8 m", "8+ m")


def iou_row(scores: dict[str, Any], key: str, argmax: bool = False) -> list[float | None]:
    """The IoU of score ``key`` over all and per bin (:data:`BIN_NAMES`); Nones when unscored."""
    s = scores.get(key)
    if s is None:
        return [None] * len(BIN_NAMES)
    if argmax:
        s = s["argmax"]
    return [s["overall"]["iou"]] + [b["iou"] for b in s["bins"]]


def fmt(x: float | None, d: int = 4) -> str:
    """``x`` to ``d`` places, or a dash when missing."""
    return "—" if x is None else f"{x:.{d}f}"


def seed_run(frames: int, seed: int) -> str:
    """The run of the ``frames``-frame network trained with ``train --seed seed``."""
    return f"frames{frames}" if seed == 0 else f"frames{frames}-seed{seed}"


def run_seed(name: str) -> int | None:
    """The training seed of a ``--seeds`` run named by :func:`seed_run` (0 for the plain
    ``frames1``/``frames16``); None for any other name."""
    fs = run_frames_seed(name)
    return None if fs is None else fs[1]


def seed_leads(scores: dict[str, Any]) -> dict[str, Any] | None:
    """The 16-frame network's IoU minus the single frame's on the generated test set, per
    distance bin, for every training seed with both scored: each seed's, their mean and their
    spread (largest minus smallest; None with one seed). None when no seed has both."""
    seeds = sorted({seed for k in scores if k.endswith("--test") and (seed := run_seed(k[:-len("--test")])) is not None})
    per: dict[int, list[float | None]] = {}
    for seed in seeds:
        one, many = f"{seed_run(1, seed)}--test", f"{seed_run(16, seed)}--test"
        if one in scores and many in scores:
            per[seed] = [b - a if a is not None and b is not None else None
                         for a, b in zip(iou_row(scores, one), iou_row(scores, many))]
    if not per:
        return None
    bins = {}
    for k, name in enumerate(BIN_NAMES):
        vals = {s: v[k] for s, v in per.items() if v[k] is not None}
        got = list(vals.values())
        bins[name] = {"per_seed": {str(s): v for s, v in vals.items()},
                      "mean": sum(got) / len(got) if got else None,
                      "spread": max(got) - min(got) if len(got) > 1 else None}
    return {"seeds": sorted(per), "bins": bins}


def render_leads(leads: dict[str, Any]) -> list[str]:
    """The sequence's lead over training seeds (``results.json``'s ``leads``), each world's, and
    each world's against the hall's: shown when some world has two seeds or two worlds have one."""
    if not leads or (len(leads) < 2 and all(len(v["seeds"]) < 2 for v in leads.values())):
        return []

    def cell(b: dict[str, Any]) -> str:
        vals = list(b["per_seed"].values())
        if b["mean"] is None:
            return "—"
        if b["spread"] is None:
            return f"{b['mean']:+.4f}"
        return f"{b['mean']:+.4f} ({min(vals):+.4f} to {max(vals):+.4f})"

    lines = ["", "## The sequence's lead over training seeds (N = 16 minus N = 1)", "",
             "IoU of the 16-frame network minus the single frame's on the generated test set, each pair "
             "trained with the same seed (`--seeds`: `train --seed S`, the same data and steps); the mean "
             "over the seeds and, with two or more, the smallest and largest:", "",
             "| world | seeds | " + " | ".join(BIN_NAMES) + " |", "|---|---|" + "---|" * len(BIN_NAMES)]
    for world, lead in leads.items():
        lines.append(f"| {world} | {', '.join(map(str, lead['seeds']))} | "
                     + " | ".join(cell(lead["bins"][b]) for b in BIN_NAMES) + " |")
    hall = leads.get("hall")
    others = [(w, v) for w, v in leads.items() if w != "hall"]
    if hall is not None and others:
        lines += ["", "Each world's mean lead minus the hall's, against the spread (the larger of the two "
                  "worlds' largest-minus-smallest): the world's lead is larger than the hall's when the "
                  "difference exceeds it.", "",
                  "| world | " + " | ".join(BIN_NAMES) + " |", "|---|" + "---|" * len(BIN_NAMES)]
        for world, lead in others:
            row = []
            for b in BIN_NAMES:
                mine, theirs = lead["bins"][b], hall["bins"][b]
                if mine["mean"] is None or theirs["mean"] is None:
                    row.append("—")
                    continue
                diff = mine["mean"] - theirs["mean"]
                if mine["spread"] is None or theirs["spread"] is None:
                    row.append(f"{diff:+.4f} (no spread: one seed)")
                    continue
                spread = max(mine["spread"], theirs["spread"])
                verdict = "larger" if diff > spread else "not larger"
                row.append(f"{diff:+.4f} against {spread:.4f}: {verdict}")
            lines.append(f"| {world} | " + " | ".join(row) + " |")
    return lines


def run_frames_seed(name: str) -> tuple[int, int] | None:
    """(frames, training seed) of a ``--seeds`` run named by :func:`seed_run`; None for any
    other name."""
    frames = "|".join(map(str, SEED_FRAMES))
    m = re.fullmatch(rf"frames({frames})(?:-seed(\d+))?", name)
    return None if m is None else (int(m.group(1)), int(m.group(2) or 0))


def recorded_seeds(worlds: list[tuple[str, dict[str, Any]]]) -> dict[str, dict[int, dict[int, float]]]:
    """Per world and N (1 and 16), each training seed's IoU on the hall's recorded test set
    (score ``frames{N}[-seed{S}]--test-recorded``); worlds and N without one are left out."""
    out: dict[str, dict[int, dict[int, float]]] = {}
    for world, scores in worlds:
        for key, s in scores.items():
            if not key.endswith("--test-recorded"):
                continue
            fs = run_frames_seed(key[:-len("--test-recorded")])
            if fs is not None:
                out.setdefault(world, {}).setdefault(fs[0], {})[fs[1]] = s["overall"]["iou"]
    return out


def render_recorded_seeds(worlds: list[tuple[str, dict[str, Any]]]) -> list[str]:
    """Each world's networks on the hall's recorded test set over their training seeds, and
    each world against the hall's: seed by seed where both trained one, and the means against
    the spread (as the leads: higher when the difference exceeds the larger of the two worlds'
    largest-minus-smallest). Shown when the hall and another world each have two seeds of one N."""
    rec = recorded_seeds(worlds)
    hall = rec.get("hall", {})
    pairs = [(w, n) for w, per_n in rec.items() if w != "hall" for n in sorted(per_n)
             if len(per_n[n]) > 1 and len(hall.get(n, {})) > 1]
    if not pairs:
        return []

    def spread(v: dict[int, float]) -> float:
        return max(v.values()) - min(v.values())

    def mean(v: dict[int, float]) -> float:
        return sum(v.values()) / len(v)

    lines = ["", "### Over training seeds", "",
             "The 1- and 16-frame networks of `--seeds` on the hall's recorded test set: each world's "
             "mean over its seeds (lowest to highest), and each world against the hall's, seed by seed "
             "where both trained one and by the means against the spread (the larger of the two worlds' "
             "highest-minus-lowest): higher when the difference exceeds it.", "",
             "| world | N | seeds | IoU recorded test | against the hall, seed by seed | means, against the spread |",
             "|---|---|---|---|---|---|"]
    for world, per_n in [("hall", hall)] + [(w, rec[w]) for w in dict.fromkeys(w for w, _ in pairs)]:
        for n in sorted(per_n):
            v = per_n[n]
            seeds = ", ".join(map(str, sorted(v)))
            got = f"{mean(v):.4f} ({min(v.values()):.4f} to {max(v.values()):.4f})" if len(v) > 1 else f"{mean(v):.4f}"
            if world == "hall" or (world, n) not in pairs:
                lines.append(f"| {world} | {n} | {seeds} | {got} | | |")
                continue
            h = hall[n]
            both = sorted(set(v) & set(h))
            above = sum(v[s] > h[s] for s in both)
            by_seed = f"higher at {above} of {len(both)} ({', '.join(f'{v[s] - h[s]:+.4f}' for s in both)})" if both else "no seed in common"
            diff, sp = mean(v) - mean(h), max(spread(v), spread(h))
            verdict = "higher" if diff > sp else "not higher"
            lines.append(f"| {world} | {n} | {seeds} | {got} | {by_seed} | {diff:+.4f} against {sp:.4f}: {verdict} |")
    return lines
