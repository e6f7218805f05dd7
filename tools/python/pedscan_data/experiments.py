"""The paper's experiments (Kim et al. 2020, Tables 4 and 5) on pedscan sequences, as one
resumable command.

    python -m pedscan_data.experiments paper --work DIR [--scale small|full]
        [--pedscan BIN] [--recorded FILE] [--device auto|cpu|cuda] [--only STAGE,...]
        [--jobs J] [--max-minutes M] [--world hall|street|indoor[,...]] [--seeds S,...]
        [--steps N] [--average-tail F] [--precision fp32|bf16]

Stages, each skipped when done (so the table survives interruptions and several sittings;
run the same command again):

1. **data**: ``pedscan generate`` makes, under ``DIR/data/``, the training, validation and
   test sets of the paper's Table 2 scenario (HDL-32E, 1-30 people, 32 frames at 10 Hz,
   sensor model on) from distinct seeds (training 101, validation 102, test 103: no test
   sequence shares a seed with training or tuning), the three Table 5 ablations' training sets
   (``--motion static``, ``sliding``, ``in-place``: the training set's seed, so the same people
   and paths, only the motion differs) and, with ``--recorded FILE``, a test set of people
   composited into that recording (seed 104), with a training (105) and a validation (106)
   set of other people in the same recording. Generation resumes sequence by sequence.
2. **train**: Table 4's networks (N = 16 first, then 1, 2, 4, 8), the three ablations
   (N = 16), beyond the paper ``frames16-change`` (N = 16 with range-change channels,
   ``train --range-change``, on Table 4's data) and, with ``--recorded``, N = 16 and 1 trained on the recording's training set
   (the paper's own setting: people composited into the background they are tested on);
   each run resumes from its checkpoint.
3. **test**: every network predicts the test set(s); scored from frame 15 on, the first frame
   with a full 16-frame window, for *every* N, so all networks are scored on the same beams;
   a beam is human above the network's threshold calibrated on the validation set (and, in a
   second table, at the softmax's argmax).
4. **results**: ``DIR/results.md``, ``results.json`` and ``results.png``: IoU by distance bin
   per N beside the paper's, Table 5, velocity, the recorded background, the time taken.

Scales (``small`` is what two CPU cores train in hours; ``full`` is the paper's data):

=========  ========  ===========  =====  =========================  ======
scale      training  validation   test   steps per network (batch)  frames
=========  ========  ===========  =====  =========================  ======
small      200       12           36     4,000 (1)                  32
full       1,000     24           108    150,000 (1): the paper's   32
smoke      2         1            1      3 (1)                      17
=========  ========  ===========  =====  =========================  ======

``smoke`` checks the pipeline in a minute (the tests run it); its numbers mean nothing.
``--steps N`` trains every network N steps on the scale's data (longer training where the
machine allows); a work folder keeps the steps it was made with.

``--jobs J`` runs J ``pedscan generate --shard I/J`` processes per data set (the same bytes as
one process: a sequence depends only on the seed and its index); one process keeps about two
cores busy, so a many-core machine wants J near its cores / 2. ``--max-minutes M`` bounds this
sitting's training (counted from when training begins; data generation is not counted): each
run gets what is left of M (``train --max-minutes``), and when it is spent the command stops
training, tests what is complete and writes the results so far; the same command continues.
``--pedscan-flag`` passes a flag to every ``pedscan generate`` (``--pedscan-flag=--sensor=vlp16``).
``--sensor-height M`` puts the sensor M metres over the floor in every generated set of every
world (``generate --sensor-height``; the recorded sets keep the recording's own);
``--sensor-height recorded`` takes M from the ``--recorded`` recording (the median floor of its
test set, made first), so that the worlds' networks meet the recording's people on the rows
where they stand in it (a network trained at 0.8 m sees them nowhere near there from 2.3 m).

``--seeds S[,S...]`` trains only the 1- and 16-frame networks, once per training seed (``train
--seed S``; seed 0 is ``frames1`` and ``frames16``, another ``frames1-seedS`` and
``frames16-seedS``, on the same data and steps), and the results add the 16-frame network's lead
per distance bin: each seed's, the mean and the spread, and each world's lead against the
hall's (the paper's finding is a lead on far people; whether a world shows it more than the
hall takes the spread over seeds to tell). ``--average-tail F`` makes every run's weights the
mean of those after each of its last F of the steps (``train --average-from``), so that a
network is not decided by where its last step happened to land: the seeds' spread is then
the networks', not their last steps'.

Worlds (``--world``, default ``hall``; several, comma separated, run one after another):
``hall`` is the bundled environment, everything above, in ``DIR`` itself as before worlds
existed; ``street`` and ``indoor`` are pedscan's built-in worlds (``generate --background
NAME``, a new layout per sequence), each in ``DIR/worlds/NAME/`` (its ``data/``, ``runs/`` and
``scores/``) with Table 4 only: its training, validation and test sets are the hall's
commands (sensor, frames, people, seeds, ``--pedscan-flag``) plus ``--background NAME``, so
the rows compare, and its networks N = 16, 1, 2, 4, 8. Table 5's ablations, the range-change
network and ``--recorded``'s data and networks belong to the hall; with ``--recorded`` every
world's networks are also tested on the hall's recorded test set (``DIR/data/test-recorded``):
what each world's data teaches about the recording's real surroundings. ``results.json`` keeps the hall's runs and
scores at its top level and puts each other world's under ``worlds.NAME``; ``results.md``
labels every Table 4 row with its world and shows a block for each world with scores (from
any command on ``DIR``, not only this one's ``--world``).
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from .leads import BIN_NAMES, SEED_FRAMES, fmt, iou_row, render_leads, render_recorded_seeds, run_seed, seed_leads, seed_run
from .netio import atomic_write_text, save_figure
from .reader import PedscanError
from .train import PRECISIONS

#: The paper's Table 4 (generated data): IoU over all, 0-4, 4-8, 8+ m per N.
PAPER_TABLE4 = {
    1: (0.4358, 0.6301, 0.2346, 0.0725),
    2: (0.5869, 0.7774, 0.4054, 0.1323),
    4: (0.5461, 0.7278, 0.3740, 0.1222),
    8: (0.5523, 0.7250, 0.3831, 0.1272),
    16: (0.6443, 0.8141, 0.4695, 0.1622),
}
#: The paper's Table 5 (16 frames, 100 training sequences each, scored on its real data).
PAPER_TABLE5 = {"static": 0.2276, "sliding": 0.3318, "in-place": 0.3395, "full": 0.3814}
#: Seeds of the data sets: never shared between training, validation and test.
SEEDS = {"train": 101, "val": 102, "test": 103, "recorded": 104, "train-recorded": 105, "val-recorded": 106}
#: The first frame scored in every sequence: the first with a full 16-frame window.
SCORE_FROM = 15
RECORDED_FRAMES = 17
#: The networks trained on people composited into the recording (``--recorded``).
RECORDED_FRAMES_N = (16, 1)


#: What a training process imports before its first step (torch, and torch._dynamo, which
#: torch.optim imports at the first optimizer): about 5 s a run, paid once by the server that
#: forks the runs (:func:`run_train`).
TRAIN_PRELOAD = ["pedscan_data.train", "torch._dynamo"]


#: The processes this command waits on now (a training run, ``generate``'s shards): a SIGTERM
#: to the command reaches them too (:func:`_on_sigterm`), where it would otherwise leave them
#: running on their own.
_CHILDREN: set[int] = set()


def _on_sigterm(signum: int, frame: object) -> None:
    """SIGTERM stops the command as Ctrl-C does: each child it waits on gets the signal (a
    training run stops as on Ctrl-C, its last checkpoint kept, exit 130) and the command waits
    for it, then exits 130; the same command continues."""
    for pid in list(_CHILDREN):
        try:
            os.kill(pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
    raise KeyboardInterrupt


def _train_process(argv: list[str]) -> None:
    from .train import main

    sys.exit(main(argv))


def run_train(argv: list[str]) -> int:
    """``python -m pedscan_data.train ARGV``'s exit code. Each run is a process of its own as
    before (its memory, threads and seeds its own), forked from a server that has imported
    :data:`TRAIN_PRELOAD` once, so runs after the first start at once; where a platform
    cannot fork, a fresh interpreter."""
    import multiprocessing

    if "forkserver" not in multiprocessing.get_all_start_methods():
        return subprocess.run([sys.executable, "-m", "pedscan_data.train", *argv], check=False).returncode
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(TRAIN_PRELOAD)
    # By the module's name: run as `python -m`, this one is __main__, which the server lacks.
    target = importlib.import_module("pedscan_data.experiments")._train_process
    proc = ctx.Process(target=target, args=(argv,))
    proc.start()
    assert proc.pid is not None
    _CHILDREN.add(proc.pid)
    try:
        proc.join()
    except KeyboardInterrupt:
        # The run saw Ctrl-C too (one terminal), or SIGTERM from :func:`_on_sigterm`: it
        # stops, its last checkpoint kept, and ends with 130.
        proc.join()
        raise
    finally:
        _CHILDREN.discard(proc.pid)
    # As subprocess's: -N when a signal N ended it.
    return int(proc.exitcode if proc.exitcode is not None else 1)


@dataclass(frozen=True)
class Scale:
    train: int
    val: int
    test: int
    steps: int
    recorded: int
    val_every: int
    frames: int = 32


SCALES = {
    "small": Scale(train=200, val=12, test=36, steps=4000, recorded=36, val_every=500),
    "full": Scale(train=1000, val=24, test=108, steps=150_000, recorded=108, val_every=5000),
    "smoke": Scale(train=2, val=1, test=1, steps=3, recorded=1, val_every=3, frames=17),
}
TABLE4_FRAMES = (16, 1, 2, 4, 8)
ABLATIONS = ("static", "sliding", "in-place")
#: The worlds Table 4 runs in (``--world``): the bundled environment and pedscan's built-in
#: procedural ones (``generate --background NAME``); the report's order.
WORLDS = ("hall", "street", "indoor")


def find_pedscan(given: Path | None) -> Path:
    if given is not None:
        if not given.is_file():
            raise PedscanError(f"--pedscan {given}: no such file")
        return given
    root = Path(__file__).resolve().parents[3]
    for p in (root / "target/release/pedscan", shutil.which("pedscan")):
        if p and Path(p).is_file():
            return Path(p)
    raise PedscanError("no pedscan binary found: build it (cargo build --release) or give --pedscan BIN")


@dataclass
class Sitting:
    """This command's training time, shared by the worlds it trains one after another:
    ``--max-minutes`` counts from the first world's training, and only the sitting's first run
    always starts."""

    max_minutes: float | None
    deadline: float | None = None
    started: bool = False


class Experiment:
    """The experiment in one world (``world``): its data sets, runs and scores in ``work``."""

    def __init__(self, args: argparse.Namespace, world: str = "hall") -> None:
        if world not in WORLDS:
            raise PedscanError(f"world {world}: not one of {', '.join(WORLDS)}")
        self.world = world
        #: The folder of the whole command (``--work``): the state and the results.
        self.root: Path = args.work
        # The hall keeps the layout from before worlds existed, so old work folders continue.
        self.work: Path = self.root if world == "hall" else self.root / "worlds" / world
        self.scale_name: str = args.scale
        self.scale = SCALES[args.scale]
        if args.steps is not None:
            self.scale = replace(self.scale, steps=args.steps)
        self.pedscan = find_pedscan(args.pedscan)
        # A recording is the hall's experiment (its networks tested on it, N = 16 and 1 trained on it).
        self.recorded: Path | None = args.recorded if world == "hall" else None
        # Every world's networks are tested on the hall's recorded test set too: what each
        # world's data teaches about the recording's real surroundings.
        self.recorded_test: Path | None = self.root / "data" / "test-recorded" if args.recorded is not None else None
        self.device: str = args.device
        self.workers: int = args.workers
        self.python = sys.executable
        self.extra: list[str] = list(args.pedscan_flag or [])
        #: The sensor's height over the floor for every generated (not recorded) set, in metres;
        #: None: each world's own. ``--sensor-height recorded`` is resolved by :func:`recorded_height`.
        self.sensor_height: float | None = args.sensor_height if isinstance(args.sensor_height, float) else None
        #: The training seeds of the 1- and 16-frame networks (``--seeds``): seed 0 is the plain
        #: ``frames1``/``frames16`` runs, another seed S ``frames1-seedS``/``frames16-seedS``.
        self.seeds: list[int] = list(args.seeds or [0])
        self.jobs: int = args.jobs
        if self.jobs < 1:
            raise PedscanError(f"--jobs {self.jobs}: at least one process")
        if args.max_minutes is not None and not (args.max_minutes > 0 and args.max_minutes < float("inf")):
            raise PedscanError(f"--max-minutes {args.max_minutes}: not a positive number of minutes")
        self.max_minutes: float | None = args.max_minutes
        tail = args.average_tail
        if tail is not None and not 0.0 < tail <= 1.0:
            raise PedscanError(f"--average-tail {tail:g}: a share of the steps, above 0 and at most 1")
        #: ``train --average-from`` for every run: the weights averaged over the last share of
        #: the steps (None: the last step's, the paper's).
        self.average_from: int | None = None if tail is None else round(self.scale.steps * (1.0 - tail))
        if self.average_from is not None and self.average_from >= self.scale.steps:
            raise PedscanError(f"--average-tail {tail:g}: averages none of the {self.scale.steps:,} steps; give a larger share")
        #: ``train --precision`` for every run.
        self.precision: str = args.precision
        if self.recorded is not None and not self.recorded.exists():
            raise PedscanError(f"--recorded {self.recorded}: no such file or folder")
        # One state for all worlds: one scale per work folder, and the time of every stage.
        self.state_path = self.root / "state.json"

    # ---- bookkeeping -------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        if self.state_path.is_file():
            return json.loads(self.state_path.read_text())
        return {"scale": self.scale_name, "steps": self.scale.steps, "seconds": {}}

    def add_time(self, key: str, seconds: float) -> None:
        if self.world != "hall":
            key = f"{self.world} {key}"
        s = self.state()
        s["seconds"][key] = s["seconds"].get(key, 0.0) + seconds
        atomic_write_text(self.state_path, json.dumps(s, indent=2) + "\n")

    def check_scale(self) -> None:
        self.work.mkdir(parents=True, exist_ok=True)
        s = self.state()
        if s.get("scale") != self.scale_name:
            raise PedscanError(f"{self.root}: holds the {s.get('scale')} scale; give --scale {s.get('scale')} or another --work")
        # A folder made before --steps holds its scale's steps (from now on recorded).
        held = s.get("steps", SCALES[self.scale_name].steps)
        if held != self.scale.steps:
            raise PedscanError(f"{self.root}: holds networks of {held:,} steps; give --steps {held} or another --work")
        if self.state_path.is_file() and "steps" not in s:
            s["steps"] = held
            atomic_write_text(self.state_path, json.dumps(s, indent=2) + "\n")
        if not self.state_path.is_file():
            self.add_time("data", 0.0)

    def run(self, cmd: list[str], what: str) -> None:
        print(f"[{what}] {' '.join(cmd)}", file=sys.stderr, flush=True)
        if cmd[:3] == [self.python, "-m", "pedscan_data.train"]:
            code = run_train(cmd[3:])
        else:
            code = subprocess.run(cmd, check=False).returncode
        if code == 130:
            raise KeyboardInterrupt
        if code != 0:
            raise PedscanError(f"{what}: `{' '.join(cmd)}` exited {code}")

    def run_shards(self, cmd: list[str], what: str) -> None:
        """``cmd`` as ``--jobs`` processes, one ``--shard I/J`` each, at once; every one must end well."""
        print(f"[{what}] {self.jobs} x {' '.join(cmd)} --shard I/{self.jobs}", file=sys.stderr, flush=True)
        procs = [subprocess.Popen([*cmd, "--shard", f"{i}/{self.jobs}"]) for i in range(self.jobs)]
        _CHILDREN.update(p.pid for p in procs)
        try:
            codes = [p.wait() for p in procs]
        except KeyboardInterrupt:
            for p in procs:
                p.wait()
            raise
        finally:
            _CHILDREN.difference_update(p.pid for p in procs)
        if 130 in codes:
            raise KeyboardInterrupt
        bad = [(i, c) for i, c in enumerate(codes) if c != 0]
        if bad:
            raise PedscanError(f"{what}: `{' '.join(cmd)} --shard {bad[0][0]}/{self.jobs}` exited {bad[0][1]}")

    # ---- stage 1: data -----------------------------------------------------------------
    def datasets(self) -> dict[str, dict[str, Any]]:
        sc = self.scale
        # Another world: the hall's sets but for the background, so that their rows compare.
        world = [] if self.world == "hall" else ["--background", self.world]
        if self.sensor_height is not None:
            world += ["--sensor-height", f"{self.sensor_height:g}"]
        sets: dict[str, dict[str, Any]] = {
            "train": {"sequences": sc.train, "seed": SEEDS["train"], "flags": list(world)},
            "val": {"sequences": sc.val, "seed": SEEDS["val"], "flags": list(world)},
            "test": {"sequences": sc.test, "seed": SEEDS["test"], "flags": list(world)},
        }
        if self.world != "hall":
            return sets
        for m in ABLATIONS:
            sets[f"train-{m}"] = {"sequences": sc.train, "seed": SEEDS["train"], "flags": ["--motion", m, *world]}
        if self.recorded is not None:
            rec = ["--background", str(self.recorded.resolve()), "--frames", str(RECORDED_FRAMES)]
            sets["test-recorded"] = {"sequences": sc.recorded, "seed": SEEDS["recorded"], "flags": rec}
            sets["train-recorded"] = {"sequences": sc.train, "seed": SEEDS["train-recorded"], "flags": rec}
            sets["val-recorded"] = {"sequences": sc.val, "seed": SEEDS["val-recorded"], "flags": rec}
        return sets

    def needed_sets(self, only: set[str] | None) -> set[str]:
        """The data sets that the runs in ``only`` (all when None) train, validate and are
        tested on; none in a world that has none of those runs."""
        runs = self.runs()
        chosen = [r for name, r in runs.items() if only is None or name in only]
        if not chosen:
            return set()
        return {r["data"] for r in chosen} | {r["val"] for r in chosen} | set(self.test_sets())

    def generate_command(self, name: str) -> list[str]:
        """The ``pedscan generate`` command that makes the data set ``name`` (of :meth:`datasets`)."""
        d = self.datasets()[name]
        return [
            str(self.pedscan), "generate", "--out", str(self.work / "data" / name), "--sequences", str(d["sequences"]),
            "--seed", str(d["seed"]), "--outputs", "range,label,instance,velocity", "--resume",
            *(["--frames", str(self.scale.frames)] if "--frames" not in d["flags"] else []), *d["flags"], *self.extra,
        ]

    def data(self, only: set[str] | None = None) -> None:
        needed = self.needed_sets(only)
        for name in self.datasets():
            if name in needed:
                self.make_set(name)

    def make_set(self, name: str) -> None:
        """Generates the data set ``name`` unless it is complete (then checks it was made by
        the same command)."""
        out = self.work / "data" / name
        marker = out / ".complete"
        cmd = self.generate_command(name)
        if marker.is_file():
            if marker.read_text() != " ".join(cmd[1:]) + "\n":
                raise PedscanError(f"{out}: made by another command ({marker.read_text().strip()}); "
                                   "remove the folder to make it again, or give another --work")
            return
        t0 = time.perf_counter()
        what = f"data {name}" if self.world == "hall" else f"data {self.world}/{name}"
        if self.jobs == 1:
            self.run(cmd, what)
        else:
            self.run_shards(cmd, what)
        marker.write_text(" ".join(cmd[1:]) + "\n")
        self.add_time("data", time.perf_counter() - t0)

    # ---- stage 2: training -------------------------------------------------------------
    def runs(self) -> dict[str, dict[str, Any]]:
        r: dict[str, dict[str, Any]] = {f"frames{n}": {"frames": n, "data": "train", "val": "val"} for n in TABLE4_FRAMES}
        # The sequence's lead over seeds: N = 1 and 16 again from other training seeds, those
        # asked for and those a command before left in the folder.
        found = {seed for p in (self.work / "runs").glob("frames*-seed*")
                 if (seed := run_seed(p.name)) is not None} if (self.work / "runs").is_dir() else set()
        for seed in sorted(set(self.seeds) | found):
            if seed != 0:
                for n in SEED_FRAMES:
                    r[seed_run(n, seed)] = {"frames": n, "data": "train", "val": "val", "flags": ["--seed", str(seed)]}
        if self.world != "hall":
            return r  # Table 4 only: the rest is about the hall's data and the recording
        for m in ABLATIONS:
            r[f"motion-{m}"] = {"frames": 16, "data": f"train-{m}", "val": "val"}
        # Beyond the paper: the range-change channels (`train --range-change`) on Table 4's data.
        r["frames16-change"] = {"frames": 16, "data": "train", "val": "val", "flags": ["--range-change"]}
        if self.recorded is not None:
            # The paper's own setting: people composited into the recording they are tested on
            # (its frames are shared; the people, their paths and places come from other seeds).
            for n in RECORDED_FRAMES_N:
                r[f"recorded-frames{n}"] = {"frames": n, "data": "train-recorded", "val": "val-recorded"}
        return r

    def run_test_sets(self, name: str) -> list[str]:
        """The test sets a run is scored on: Table 5's ablations only on the generated one."""
        return ["test"] if name.startswith("motion-") else self.test_sets()

    def trained_step(self, run: Path) -> int:
        from .netio import load_file

        ck = run / "checkpoint.pt"
        return int(load_file(ck)["step"]) if ck.is_file() else 0

    def train_command(self, name: str) -> list[str]:
        """The ``pedscan_data.train`` command of the run ``name`` (of :meth:`runs`), resuming
        it if it has begun."""
        r, run = self.runs()[name], self.work / "runs" / name
        cmd = [
            self.python, "-m", "pedscan_data.train", str(self.work / "data" / r["data"]),
            "--frames", str(r["frames"]), "--out", str(run), "--steps", str(self.scale.steps),
            "--val", str(self.work / "data" / r["val"]), "--score-from", str(SCORE_FROM),
            "--val-every", str(self.scale.val_every), "--device", self.device, "--workers", str(self.workers),
            *r.get("flags", []),
        ]
        if self.average_from is not None:
            cmd += ["--average-from", str(self.average_from)]
        if self.precision != "fp32":
            cmd += ["--precision", self.precision]
        if (run / "run.json").is_file():
            cmd.append("--resume")
        return cmd

    def train(self, only: set[str] | None = None, sitting: Sitting | None = None) -> bool:
        """Trains every run not yet done; False when ``--max-minutes`` ran out first (counted
        from the sitting's first call here: the first run to train always starts)."""
        sitting = sitting or Sitting(self.max_minutes)
        if sitting.max_minutes is not None and sitting.deadline is None:
            sitting.deadline = time.monotonic() + 60.0 * sitting.max_minutes
        where = "" if self.world == "hall" else f"{self.world}/"
        for name in self.runs():
            if only and name not in only:
                continue
            run = self.work / "runs" / name
            if self.trained_step(run) >= self.scale.steps:
                continue
            budget: list[str] = []
            if sitting.deadline is not None:
                left = (sitting.deadline - time.monotonic()) / 60.0
                if sitting.started and left <= 0:
                    print(f"[train] the --max-minutes budget is spent before {where}{name}; run the same command "
                          "to continue", file=sys.stderr, flush=True)
                    return False
                budget = ["--max-minutes", f"{max(left, 1e-9):.6g}"]
            sitting.started = True
            t0 = time.perf_counter()
            cmd = self.train_command(name)
            try:
                self.run([*cmd, *budget], f"train {where}{name}")
            finally:
                self.add_time(f"train {name}", time.perf_counter() - t0)
            if self.trained_step(run) < self.scale.steps:
                print(f"[train] {where}{name} stopped at step {self.trained_step(run)} of {self.scale.steps} "
                      "(--max-minutes); run the same command to continue", file=sys.stderr, flush=True)
                return False
        return True

    # ---- stage 3: test -----------------------------------------------------------------
    def test_sets(self) -> list[str]:
        return ["test"] + (["test-recorded"] if self.recorded_test is not None else [])

    def test_data(self, ts: str) -> Path:
        """The folder of test set ``ts``: the world's own, or the hall's recorded test set."""
        if ts == "test-recorded" and self.recorded_test is not None:
            return self.recorded_test
        return self.work / "data" / ts

    def zero_epe(self, ts: str) -> float | None:
        """The end-point error of predicting zero velocity on the test set's human beams."""
        import numpy as np

        from .reader import open_sequences

        path = self.work / "scores" / f"zero--{ts}.json"
        if path.is_file():
            return json.loads(path.read_text())["epe_mps"]
        total, count = 0.0, 0
        for seq in open_sequences(self.test_data(ts)):
            for t in range(SCORE_FROM, seq.frames):
                human = (seq.read("label", t) == 1) & (seq.read("range", t) > 0)
                total += float(np.linalg.norm(seq.read("velocity", t)[human].astype(np.float64), axis=-1).sum())
                count += int(np.count_nonzero(human))
        epe = total / count if count else None
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"epe_mps": epe, "human_beams": count}) + "\n")
        return epe

    def test(self) -> None:
        """Scores every trained network on the test set(s): at the human threshold calibrated
        on the validation set (what the model file says; calibrated here if it is not yet),
        and at the softmax's argmax, in one pass of the network."""
        from .netio import load_file, load_net
        from .predict import human_margin, pick_device
        from .reader import open_sequences
        from .train import calibrate_model, validate

        dev = pick_device(self.device)
        for name, r in self.runs().items():
            run = self.work / "runs" / name
            if self.trained_step(run) < self.scale.steps:
                continue
            if "human_threshold" not in load_file(run / "model.pt"):
                calibrate_model(run / "model.pt", self.work / "data" / r["val"], dev, SCORE_FROM)
            for ts in self.run_test_sets(name):
                if self.world != "hall" and ts == "test-recorded" and not (self.test_data(ts) / ".complete").is_file():
                    # Another world's view of the hall's recorded test set, not made yet: its
                    # data stage makes it (run the hall with --recorded).
                    print(f"[test] {self.test_data(ts)} is not made yet: {self.world}/{name} is not scored on it",
                          file=sys.stderr, flush=True)
                    continue
                score = self.work / "scores" / f"{name}--{ts}.json"
                net, obj = load_net(run, dev)
                if score.is_file():
                    done = json.loads(score.read_text())
                    if (done.get("model_step"), done.get("human_threshold")) == (self.scale.steps, obj["human_threshold"]):
                        continue
                t0 = time.perf_counter()
                where = "" if self.world == "hall" else f"{self.world}/"
                print(f"[test {where}{name} on {ts}]", file=sys.stderr, flush=True)
                cal, arg = validate(net, open_sequences(self.test_data(ts)), dev, SCORE_FROM,
                                    (human_margin(obj), 0.0))
                rep = {**cal, "from_frame": SCORE_FROM, "human_threshold": obj["human_threshold"],
                       "argmax": {"overall": arg["overall"], "bins": arg["bins"]},
                       "model_step": self.scale.steps, "zero_epe_mps": self.zero_epe(ts)}
                score.parent.mkdir(parents=True, exist_ok=True)
                atomic_write_text(score, json.dumps(rep, indent=2) + "\n")
                self.add_time("test", time.perf_counter() - t0)

    # ---- stage 4: results --------------------------------------------------------------
    def world_results(self) -> dict[str, Any]:
        """This world's data sets, its runs begun (the step each reached) and its scores."""
        scores: dict[str, Any] = {}
        for p in sorted((self.work / "scores").glob("*--*.json")) if (self.work / "scores").is_dir() else []:
            if not p.stem.startswith("zero--"):
                scores[p.stem] = json.loads(p.read_text())
        runs_info = {}
        for name in self.runs():
            rj = self.work / "runs" / name / "run.json"
            if rj.is_file():
                info = json.loads(rj.read_text())
                runs_info[name] = {"step": self.trained_step(self.work / "runs" / name),
                                   "environment": info.get("environment"), "parameters": info.get("parameters"),
                                   "network": info.get("network"),
                                   "average_from": info.get("config", {}).get("average_from"),
                                   "precision": info.get("config", {}).get("precision", "fp32")}
        return {"datasets": {k: {**v, "flags": v["flags"]} for k, v in self.datasets().items()},
                "runs": runs_info, "scores": scores}

    def results(self, others: Sequence[Experiment] = ()) -> dict[str, Any]:
        """Writes ``DIR/results.*``. ``self`` is the hall, whose runs and scores stay at the top
        level of ``results.json`` (as before worlds existed); each world of ``others`` that
        has begun a run or has a score comes under ``worlds``, whichever command made it."""
        res = {
            "scale": self.scale_name, "steps": self.scale.steps, "score_from_frame": SCORE_FROM,
            **self.world_results(), "seconds": self.state()["seconds"],
            "paper": {"table4": {str(k): v for k, v in PAPER_TABLE4.items()}, "table5": PAPER_TABLE5},
            "worlds": {},
        }
        for ex in others:
            got = ex.world_results()
            if got["runs"] or got["scores"]:
                res["worlds"][ex.world] = {"folder": ex.work.relative_to(self.root).as_posix(), **got}
        res["leads"] = {w: lead for w, wsc in world_scores(res) if (lead := seed_leads(wsc)) is not None}
        atomic_write_text(self.root / "results.json", json.dumps(res, indent=2) + "\n")
        atomic_write_text(self.root / "results.md", render_markdown(res))
        plot_results(res, self.root / "results.png")
        # The hall's example frame, or the first other world's when the hall has no network yet.
        for ex in (self, *others):
            if ex.example_png(self.root / "results-example.png"):
                break
        return res

    def example_png(self, path: Path, sequence: int = 0) -> bool:
        """One test frame (the last of a sequence): range, truth, and the 1- and 16-frame
        networks' masks (green hit, red false alarm, blue miss); False, and nothing written,
        when neither network is trained."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import numpy as np

        from .netio import load_net
        from .predict import human_margin, predict_sequence
        from .reader import open_sequences

        nets = [n for n in (1, 16) if self.trained_step(self.work / "runs" / f"frames{n}") >= self.scale.steps]
        if not nets:
            return False
        seq = open_sequences(self.work / "data" / "test")[sequence]
        t = seq.frames - 1
        r = seq.read("range", t)
        truth = (seq.read("label", t) == 1) & (r > 0)
        rows = [("range (log)", None)]
        for n in nets:
            net, obj = load_net(self.work / "runs" / f"frames{n}", "cpu")
            margin, _, _ = predict_sequence(net, seq, "cpu", first=t)
            rows.append((f"N={n}", margin[t] > human_margin(obj)))
        fig, axes = plt.subplots(len(rows) + 1, 1, figsize=(16, 1.3 * (len(rows) + 1)))
        axes[0].imshow(np.log1p(r), cmap="gray", aspect="auto", interpolation="nearest")
        axes[0].set_title(f"{self.world}, {seq.path.name}, frame {t}: range (log)", fontsize=9, loc="left")
        rgb = np.zeros(r.shape + (3,))
        rgb[truth] = (1, 1, 1)
        axes[1].imshow(rgb, aspect="auto", interpolation="nearest")
        axes[1].set_title("ground truth (white: human)", fontsize=9, loc="left")
        for ax, (name, pred) in zip(axes[2:], rows[1:]):
            img = np.zeros(r.shape + (3,)) + 0.15 * (r > 0)[..., None]
            img[truth & pred] = (0.1, 0.8, 0.2)
            img[~truth & pred & (r > 0)] = (0.9, 0.1, 0.1)
            img[truth & ~pred] = (0.2, 0.4, 1.0)
            tp, fp, fn = int(np.sum(truth & pred)), int(np.sum(~truth & pred & (r > 0))), int(np.sum(truth & ~pred))
            ax.imshow(img, aspect="auto", interpolation="nearest")
            ax.set_title(f"{name}: green hit, red false alarm, blue miss (IoU {tp / max(tp + fp + fn, 1):.3f})",
                         fontsize=9, loc="left")
        for ax in axes:
            ax.set_xticks([])
            ax.set_yticks([])
        fig.tight_layout()
        save_figure(fig, path)
        return True


def world_scores(res: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    """(world, scores) of every world, the hall (``results.json``'s top level) first."""
    return [("hall", res["scores"])] + [(w, v["scores"]) for w, v in res.get("worlds", {}).items()]


def table4_worlds(res: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    """(world, scores) of each world with a Table 4 network scored, the hall first; the hall
    alone when none has, so the table still shows the paper's row."""
    every = world_scores(res)
    scored = [(w, sc) for w, sc in every if any(f"frames{n}--test" in sc for n in TABLE4_FRAMES)]
    return scored or every[:1]


def render_markdown(res: dict[str, Any]) -> str:
    sc = res["scores"]
    worlds = table4_worlds(res)
    lines = [
        f"# The paper's experiments on pedscan data ({res['scale']} scale)",
        "",
        f"Networks trained {res['steps']:,} steps each (batch 1); scored on the held-out test set "
        f"(seed {SEEDS['test']}) from frame {res['score_from_frame']} of every sequence, the same "
        "beams for every N. Paper: Kim et al. 2020, Table 4 (generated data) and Table 5.",
        "",
        "## Table 4: IoU of the human class by distance",
        "",
    ]
    heights = {f[i + 1] for d in res.get("datasets", {}).values() for f in [d["flags"]]
               for i in range(len(f) - 1) if f[i] == "--sensor-height"}
    if heights:
        lines[-2:-2] = [f"Every generated set's sensor stands {', '.join(sorted(heights))} m over the floor "
                        "(`--sensor-height`; the recorded sets: the recording's own).", ""]
    averaged = sorted({(run["average_from"], w) for w, wr in [("hall", res), *res.get("worlds", {}).items()]
                       for run in wr.get("runs", {}).values() if run.get("average_from") is not None})
    if averaged:
        lines[-2:-2] = [f"A network's weights are the mean of those after each step past step {k} "
                        f"(`--average-tail`, `train --average-from`): {w}'s." for k, w in averaged] + [""]
    bf16 = sorted({w for w, wr in [("hall", res), *res.get("worlds", {}).items()]
                   for run in wr.get("runs", {}).values() if run.get("precision", "fp32") != "fp32"})
    if bf16:
        lines[-2:-2] = [f"Networks trained with their forward pass in bfloat16 (`--precision bf16`): {', '.join(bf16)}'s.", ""]
    if any(w != "hall" for w, _ in worlds):
        lines += ["One block of rows per world: `hall` the bundled environment; `street` and `indoor` "
                  "pedscan's built-in worlds (`--background`, a new layout per sequence), with the hall's "
                  "sensor, frames, people and seeds.", ""]
    head = ["| world | range | " + " | ".join(f"N={n} (ours / paper)" for n in (1, 2, 4, 8, 16)) + " |",
            "|---|---|" + "---|" * 5]
    lines += head

    def table4(argmax: bool) -> None:
        for world, wsc in worlds:
            for k, name in enumerate(BIN_NAMES):
                row = []
                for n in (1, 2, 4, 8, 16):
                    ours = iou_row(wsc, f"frames{n}--test", argmax)[k]
                    row.append(f"{fmt(ours)} / {PAPER_TABLE4[n][k]:.4f}")
                lines.append(f"| {world} | {name} | " + " | ".join(row) + " |")

    table4(False)
    lines += ["", "A beam is human above each network's threshold, calibrated on the validation set "
              "(`human_threshold` in its model file). At the softmax's argmax instead (what the "
              "paper's class weight makes a recall-first mask):", "", *head]
    table4(True)
    lines += ["", "| world | N | human threshold | precision | recall | precision at argmax | recall at argmax |",
              "|---|---|---|---|---|---|---|"]
    for world, wsc in worlds:
        for n in (1, 2, 4, 8, 16):
            s = wsc.get(f"frames{n}--test")
            if s is not None:
                o, a = s["overall"], s["argmax"]["overall"]
                lines.append(f"| {world} | {n} | {s['human_threshold']:.3f} | {fmt(o['precision'])} | "
                             f"{fmt(o['recall'])} | {fmt(a['precision'])} | {fmt(a['recall'])} |")
    lines += ["", "Velocity end-point error on human beams (m/s), and predicting zero:", "",
              "| world | N | EPE | zero | ms per frame (streaming) |", "|---|---|---|---|---|"]
    for world, wsc in worlds:
        for n in (1, 2, 4, 8, 16):
            s = wsc.get(f"frames{n}--test")
            if s is not None:
                lines.append(f"| {world} | {n} | {fmt(s['overall'].get('epe_mps'), 3)} | "
                             f"{fmt(s.get('zero_epe_mps'), 3)} | {fmt(s.get('ms_per_frame'), 1)} |")
    if "frames16-change--test" in sc:
        lines += ["", "## Beyond the paper: range-change channels (N = 16)", "",
                  "`train --range-change`: the decoder also sees each beam's range change against the "
                  "earlier frames, and the velocity branch the whole scan's (the sensor's own motion). "
                  "Same data, steps and test set as Table 4:", "",
                  "| network | IoU | 0-4 m | 4-8 m | 8+ m | EPE m/s | zero m/s |", "|---|---|---|---|---|---|---|"]
        for run in ("frames1", "frames16", "frames16-change"):
            s = sc.get(f"{run}--test")
            if s is not None:
                lines.append(f"| {run} | " + " | ".join(fmt(v) for v in iou_row(sc, f"{run}--test"))
                             + f" | {fmt(s['overall'].get('epe_mps'), 3)} | {fmt(s.get('zero_epe_mps'), 3)} |")
    # The rest is the hall's (Table 5's ablations, range change and the recording are its own).
    lines += ["", "## Table 5: what the data's motion teaches (N = 16)", "",
              "| training data | IoU ours (generated test set) | paper (its real data) |", "|---|---|---|"]
    for m, label in (("static", "human model only (static)"), ("sliding", "+ trajectory (sliding)"),
                     ("in-place", "+ walking model (in place)"), ("full", "+ both (full)")):
        key = "frames16--test" if m == "full" else f"motion-{m}--test"
        lines.append(f"| {label} | {fmt(iou_row(sc, key)[0])} | {PAPER_TABLE5[m]:.4f} |")
    lines += render_leads(res.get("leads") or {})
    on_rec = [(w, wsc) for w, wsc in world_scores(res) if any(k.endswith("--test-recorded") for k in wsc)]
    if on_rec:
        lines += ["", "## A recorded background", "",
                  "Each world's networks on the hall's recorded test set (people composited into the "
                  f"recording, seed {SEEDS['recorded']}), against its own generated test set:", "",
                  "| world | N | IoU generated test | IoU recorded test | ratio |", "|---|---|---|---|---|"]
        for world, wsc in on_rec:
            for n in (1, 2, 4, 8, 16):
                g, r = iou_row(wsc, f"frames{n}--test")[0], iou_row(wsc, f"frames{n}--test-recorded")[0]
                if g is None and r is None:
                    continue
                lines.append(f"| {world} | {n} | {fmt(g)} | {fmt(r)} | {fmt(r / g if g and r is not None else None, 3)} |")
        lines += render_recorded_seeds(world_scores(res))
    if any(k.startswith("recorded-") for k in sc):
        lines += ["", "## Trained on the recording (the paper's setting)", "",
                  "People composited into the recording, from other seeds than its test set's "
                  f"(training {SEEDS['train-recorded']}, validation {SEEDS['val-recorded']}, "
                  f"test {SEEDS['recorded']}); the recording's frames are shared.", "",
                  "| network | test set | IoU | 0-4 m | 4-8 m | 8+ m | precision | recall | EPE m/s | zero m/s |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for n in RECORDED_FRAMES_N:
            for run in (f"recorded-frames{n}", f"frames{n}"):
                for ts in ("test-recorded", "test"):
                    s = sc.get(f"{run}--{ts}")
                    if s is None:
                        continue
                    o = s["overall"]
                    lines.append(f"| {run} | {ts} | " + " | ".join(fmt(v) for v in iou_row(sc, f"{run}--{ts}"))
                                 + f" | {fmt(o['precision'])} | {fmt(o['recall'])} | {fmt(o.get('epe_mps'), 3)}"
                                 f" | {fmt(s.get('zero_epe_mps'), 3)} |")
    lines += ["", "## Time (this machine)", "", "| stage | minutes |", "|---|---|"]
    for k, v in sorted(res["seconds"].items()):
        lines.append(f"| {k} | {v / 60:.1f} |")
    lines.append("")
    return "\n".join(lines)


def plot_results(res: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    worlds = table4_worlds(res)
    names = ("all", "0-4 m", "4-8 m", "8+ m")
    ns = (1, 2, 4, 8, 16)
    colors = ("#2a7", "#27a", "#a72")
    width = 0.8 / (1 + len(worlds))
    fig, axes = plt.subplots(1, 4, figsize=(15, 3.6), sharey=True)
    for k, ax in enumerate(axes):
        x = np.arange(len(ns))
        ax.bar(x - 0.4 + width / 2, [PAPER_TABLE4[n][k] for n in ns], width, label="paper", color="#bbb")
        for i, (world, wsc) in enumerate(worlds):
            ours = [iou_row(wsc, f"frames{n}--test")[k] for n in ns]
            ax.bar(x - 0.4 + width * (i + 1.5), [v if v is not None else 0 for v in ours], width,
                   label=f"pedscan {world}", color=colors[i % len(colors)])
        ax.set_xticks(x, [f"N={n}" for n in ns])
        ax.set_title(f"IoU, {names[k]}")
        ax.set_ylim(0, 1)
    axes[0].legend()
    fig.suptitle(f"Table 4 on pedscan data ({res['scale']} scale, {res['steps']:,} steps per network)")
    fig.tight_layout()
    save_figure(fig, path)


STAGES = ("data", "train", "test", "results")


def world_list(text: str) -> list[str]:
    """``--world``'s value: world names, comma separated, each once, in the order given."""
    names = [w.strip() for w in text.split(",") if w.strip()]
    bad = [w for w in names if w not in WORLDS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"unknown world {', '.join(bad) or repr(text)} (of {', '.join(WORLDS)})")
    return list(dict.fromkeys(names))


def step_count(text: str) -> int:
    """``--steps``: a positive number of training steps."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: a number of training steps") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: at least one training step")
    return n


def seed_list(text: str) -> list[int]:
    """``--seeds``: training seeds, comma separated, each once, in the order given."""
    try:
        seeds = [int(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: training seeds, comma separated (0,1,2)") from None
    if not seeds or any(s < 0 for s in seeds):
        raise argparse.ArgumentTypeError(f"{text!r}: training seeds, comma separated, none negative")
    return list(dict.fromkeys(seeds))


def sensor_height_arg(text: str) -> float | str:
    """``--sensor-height``: metres over the floor, or ``recorded``."""
    if text == "recorded":
        return text
    try:
        h = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: metres over the floor, or recorded") from None
    if not (0.0 < h < 100.0):
        raise argparse.ArgumentTypeError(f"{text}: not a sensor height (metres over the floor, 0-100)")
    return h


def recorded_height(hall: Experiment, make: bool) -> float:
    """The recording's sensor height over its floor: the median of ``floor_z_m`` (the floor in
    the sensor's frame) over the recorded test set's sequences, to the centimetre. The set is
    made first when ``make`` (the data stage runs) and it is not complete."""
    folder = hall.work / "data" / "test-recorded"
    if not (folder / ".complete").is_file():
        if not make:
            raise PedscanError(f"--sensor-height recorded: {folder} is not made yet; run the data stage")
        hall.make_set("test-recorded")
    floors = []
    for xml in sorted(folder.glob("*.xml")):
        m = re.search(r'\bfloor_z_m="([-+0-9.eE]+)"', xml.read_text(errors="replace"))
        if m:
            floors.append(float(m.group(1)))
    floors.sort()
    h = -floors[len(floors) // 2] if floors else float("nan")
    if not (0.0 < h < 100.0):
        raise PedscanError(f"--sensor-height recorded: {folder}: no floor below the sensor in the sequences' XML")
    return round(h, 2)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m pedscan_data.experiments", description=__doc__.split("\n\n")[0])
    p.add_argument("experiment", choices=("paper",))
    p.add_argument("--work", type=Path, required=True, help="folder for data, runs and results")
    p.add_argument("--scale", choices=tuple(SCALES), default="small")
    p.add_argument("--pedscan", type=Path, help="the pedscan binary (default: this repository's release build)")
    p.add_argument("--recorded", type=Path, help="a recording (pcap, KITTI or PCD folder) for a recorded-background test set")
    p.add_argument("--device", default="auto", help="auto | cpu | cuda")
    p.add_argument("--workers", type=int, default=1, help="data-loading processes per training run")
    p.add_argument("--only", default=",".join(STAGES), help=f"stages to run, of {','.join(STAGES)}")
    p.add_argument("--runs", help="only these runs (e.g. frames16,frames1): their data sets, the validation "
                   "and test sets, and their training")
    p.add_argument("--jobs", type=int, default=1, help="pedscan generate processes per data set (--shard I/J)")
    p.add_argument("--max-minutes", type=float, metavar="M", help="end this sitting's training after M minutes")
    p.add_argument("--sensor-height", type=sensor_height_arg, metavar="M|recorded",
                   help="the sensor's height over the floor in every generated set of every world (pedscan "
                   "generate --sensor-height); recorded: the --recorded recording's (default: each world's own)")
    p.add_argument("--seeds", type=seed_list, metavar="S[,S...]",
                   help="train the 1- and 16-frame networks once per training seed (train --seed S; 0 is "
                   "frames1/frames16, S the runs frames1-seedS/frames16-seedS) and report the 16-frame lead "
                   "per distance bin over the seeds; only these runs (of them, --runs picks frames1 or frames16)")
    p.add_argument("--steps", type=step_count, metavar="N",
                   help="train every network N steps instead of the scale's (the same data; a work folder keeps "
                   "the steps it was made with)")
    p.add_argument("--precision", choices=PRECISIONS, default="fp32",
                   help="every run's training step in fp32 (default, the paper's) or bf16 (train --precision)")
    p.add_argument("--average-tail", type=float, metavar="F",
                   help="every run's weights are the mean of those after each of its last F of the steps (train "
                   "--average-from; not in the paper; default: the last step's)")
    p.add_argument("--pedscan-flag", action="append", metavar="FLAG", help="a flag for every pedscan generate (repeatable)")
    p.add_argument("--world", type=world_list, default=["hall"], metavar="NAME[,NAME...]",
                   help=f"run Table 4 in these worlds, one after another (of {', '.join(WORLDS)}; default hall): "
                   "hall in --work itself, the others in --work/worlds/NAME")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    old_term = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        return _main(args)
    finally:
        signal.signal(signal.SIGTERM, old_term)


def _main(args: argparse.Namespace) -> int:
    stages = [s.strip() for s in args.only.split(",") if s.strip()]
    bad = [s for s in stages if s not in STAGES]
    try:
        if bad:
            raise PedscanError(f"--only: unknown stage {', '.join(bad)} (of {', '.join(STAGES)})")
        if args.recorded is not None and "hall" not in args.world:
            raise PedscanError("--recorded: a recording is the hall's experiment; add hall to --world")
        if args.sensor_height == "recorded" and args.recorded is None:
            raise PedscanError("--sensor-height recorded: give the recording (--recorded FILE)")
        backgrounds = [f for f in args.pedscan_flag or [] if f.split("=")[0] in ("--background", "--environment")]
        if backgrounds and args.world != ["hall"]:
            raise PedscanError(f"--pedscan-flag {backgrounds[0]}: --world {','.join(args.world)} gives the background")
        # Every world, for the results (which show whatever any command left in --work).
        every = {w: Experiment(args, w) for w in WORLDS}
        chosen = [every[w] for w in args.world]
        only = {r.strip() for r in args.runs.split(",") if r.strip()} if args.runs else None
        known = list(dict.fromkeys(name for ex in chosen for name in ex.runs()))
        unknown = sorted(only - set(known)) if only else []
        if unknown:
            raise PedscanError(f"--runs: unknown run {', '.join(unknown)} (of {', '.join(known)})")
        if args.seeds:
            # One pair a seed: the runs are frames1 and frames16 (or the one of them --runs names).
            base = only if only is not None else {f"frames{n}" for n in SEED_FRAMES}
            other = sorted(base - {f"frames{n}" for n in SEED_FRAMES})
            if other:
                raise PedscanError(f"--seeds: trains frames1 and frames16 once per seed; not {', '.join(other)}")
            only = {seed_run(n, s) for n in SEED_FRAMES if f"frames{n}" in base for s in args.seeds}
        for ex in chosen:
            ex.check_scale()
        if args.sensor_height == "recorded":
            # The recording's height, from its test set (made first): every world's generated
            # sets put their sensor there, so its people fall on the rows they do in the recording.
            h = recorded_height(every["hall"], "data" in stages)
            print(f"[data] the recording's sensor stands {h:.2f} m over its floor: every generated set's sensor too",
                  file=sys.stderr, flush=True)
            for ex in every.values():
                ex.sensor_height = h
        if "data" in stages:
            for ex in chosen:
                ex.data(only)
        trained = True
        if "train" in stages:
            sitting = Sitting(chosen[0].max_minutes)
            trained = all(ex.train(only, sitting) for ex in chosen)  # all() stops at the first spent budget
        if "test" in stages:
            for ex in chosen:
                ex.test()
        if "results" in stages:
            hall = every["hall"]
            hall.results([every[w] for w in WORLDS if w != "hall"])
            print(f"wrote {hall.root / 'results.md'}" + ("" if trained else " (training not complete: the same command continues)"))
    except KeyboardInterrupt:
        print("stopped; run the same command again to continue", file=sys.stderr)
        return 130
    except (PedscanError, FileNotFoundError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
