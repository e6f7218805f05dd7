"""``experiments paper --world``: Table 4 in the bundled hall and in pedscan's built-in worlds,
each in its own folder of ``--work``, and one row block per world in the results."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from pedscan_data import experiments as exp
from pedscan_data.netio import load_file
from pedscan_data.reader import PedscanError

from conftest import SENSOR_TOML, generate


def experiments(tmp_path: Path, *flags: str) -> dict[str, exp.Experiment]:
    """Every world's experiment for ``paper --work tmp/work --scale smoke FLAGS``, on a stand-in
    pedscan binary (nothing is run: only the commands are built)."""
    fake = tmp_path / "pedscan"
    fake.write_text("")
    args = exp.parser().parse_args(["paper", "--work", str(tmp_path / "work"), "--scale", "smoke",
                                    "--pedscan", str(fake), *flags])
    return {w: exp.Experiment(args, w) for w in exp.WORLDS}


def test_experiments_hall_keeps_the_layout_and_commands_from_before_worlds(tmp_path: Path) -> None:
    """The hall's data, runs, state and generate commands are those of work folders made
    before ``--world`` existed (their ``.complete`` markers must still match)."""
    hall = experiments(tmp_path, "--pedscan-flag=--humans=1..2")["hall"]
    work = tmp_path / "work"
    assert hall.work == work and hall.state_path == work / "state.json"
    assert hall.generate_command("train") == [
        str(tmp_path / "pedscan"), "generate", "--out", str(work / "data" / "train"), "--sequences", "2",
        "--seed", "101", "--outputs", "range,label,instance,velocity", "--resume", "--frames", "17", "--humans=1..2",
    ]
    assert hall.generate_command("train-sliding")[-4:] == ["17", "--motion", "sliding", "--humans=1..2"]
    assert "--background" not in hall.generate_command("test")
    cmd = hall.train_command("frames16")
    assert cmd[1:5] == ["-m", "pedscan_data.train", str(work / "data" / "train"), "--frames"]
    assert cmd[cmd.index("--out") + 1] == str(work / "runs" / "frames16")
    assert cmd[cmd.index("--val") + 1] == str(work / "data" / "val")
    assert {"motion-static", "frames16-change"} <= set(hall.runs())


@pytest.mark.parametrize("world", ["street", "indoor"])
def test_experiments_another_world_is_the_halls_table4_with_its_background(tmp_path: Path, world: str) -> None:
    """A world's sets are the hall's commands plus ``--background NAME`` (same sensor, frames,
    people and seeds), in ``work/worlds/NAME``; its runs are Table 4's networks only."""
    every = experiments(tmp_path, "--world", f"hall,{world}", "--pedscan-flag=--sensor=vlp16")
    hall, other = every["hall"], every[world]
    root = tmp_path / "work" / "worlds" / world
    assert other.work == root and other.state_path == tmp_path / "work" / "state.json"
    assert set(other.datasets()) == {"train", "val", "test"}
    assert set(other.runs()) == {f"frames{n}" for n in (1, 2, 4, 8, 16)}
    assert other.test_sets() == ["test"]
    for name in ("train", "val", "test"):
        got, base = other.generate_command(name), hall.generate_command(name)
        i = got.index("--background")
        assert got[i + 1] == world
        assert got[got.index("--out") + 1] == str(root / "data" / name)
        # Nothing else differs from the hall's command: the rows compare.
        rest = got[:i] + got[i + 2:]
        rest[rest.index("--out") + 1] = base[base.index("--out") + 1]
        assert rest == base, name
        assert got[-1] == "--sensor=vlp16"  # the user's flags still come last
    cmd = other.train_command("frames4")
    assert cmd[3] == str(root / "data" / "train") and cmd[cmd.index("--out") + 1] == str(root / "runs" / "frames4")
    assert cmd[cmd.index("--val") + 1] == str(root / "data" / "val")
    # `--runs` of the hall's own runs leaves another world nothing to make.
    assert other.needed_sets({"motion-static"}) == set()
    assert other.needed_sets({"frames1"}) == {"train", "val", "test"}


def test_experiments_put_every_generated_sensor_at_the_given_height(tmp_path: Path) -> None:
    """``--sensor-height M``: every generated set of every world, the ablations' too, is made
    with ``generate --sensor-height M``; the recorded sets keep the recording's own; without
    the flag no command carries it (the hall's commands above stay those of old folders)."""
    rec = tmp_path / "rec.pcap"
    rec.write_text("")
    every = experiments(tmp_path, "--world", "hall,street", "--recorded", str(rec), "--sensor-height", "2.33")
    for world, ex in every.items():
        for name in ex.datasets():
            cmd = ex.generate_command(name)
            if name.endswith("-recorded"):
                assert "--sensor-height" not in cmd, (world, name)
            else:
                assert cmd[cmd.index("--sensor-height") + 1] == "2.33", (world, name)
    plain = experiments(tmp_path, "--world", "hall,street")
    assert not any("--sensor-height" in ex.generate_command(n) for ex in plain.values() for n in ex.datasets())


def test_the_recordings_height_is_the_median_floor_of_its_test_set(tmp_path: Path, capsys) -> None:
    """``--sensor-height recorded`` reads the floor each recorded test sequence's XML gives
    (in the sensor's frame); without the set and without the data stage, or without a
    recording, it refuses, exit 2."""
    rec = tmp_path / "rec.pcap"
    rec.write_text("")
    hall = experiments(tmp_path, "--recorded", str(rec))["hall"]
    with pytest.raises(exp.PedscanError, match="not made yet"):
        exp.recorded_height(hall, make=False)
    folder = tmp_path / "work" / "data" / "test-recorded"
    folder.mkdir(parents=True)
    (folder / ".complete").write_text("made\n")
    for i, z in enumerate((-2.3318, -2.2, -2.41)):
        (folder / f"seq_{i:06d}.xml").write_text(f'<sequence><provenance background="recording" floor_z_m="{z}"/></sequence>')
    assert exp.recorded_height(hall, make=False) == 2.33
    for i, z in enumerate((0.5, 1.5, 2.0), start=3):
        (folder / f"seq_{i:06d}.xml").write_text(f'<sequence><provenance floor_z_m="{z}"/></sequence>')
    with pytest.raises(exp.PedscanError, match="no floor below the sensor"):
        exp.recorded_height(hall, make=False)  # the median floor lies above the sensor
    base = ["paper", "--work", str(tmp_path / "w2"), "--scale", "smoke", "--pedscan", str(rec)]
    assert exp.main([*base, "--sensor-height", "recorded"]) == 2
    assert "give the recording (--recorded FILE)" in capsys.readouterr().err
    for bad in ("tall", "0", "nan", "-1"):
        with pytest.raises(SystemExit):
            exp.parser().parse_args([*base, "--sensor-height", bad])


def test_experiments_refuse_an_unknown_world_naming_the_known_ones(tmp_path: Path, capsys) -> None:
    fake = tmp_path / "pedscan"
    fake.write_text("")
    base = ["paper", "--work", str(tmp_path / "work"), "--scale", "smoke", "--pedscan", str(fake), "--only", "data"]
    for bad, named in (("hall,mars", "mars"), ("Street", "Street"), (",", "','")):
        with pytest.raises(SystemExit) as e:
            exp.main([*base, "--world", bad])
        assert e.value.code == 2
        err = capsys.readouterr().err
        assert f"argument --world: unknown world {named} (of hall, street, indoor)" in err, err
    assert exp.world_list("street, hall,street") == ["street", "hall"]
    # The recording and a background of one's own are the hall's; refused before anything is made.
    assert exp.main([*base, "--world", "street", "--recorded", str(fake)]) == 2
    assert "add hall to --world" in capsys.readouterr().err
    assert exp.main([*base, "--world", "hall,street", "--pedscan-flag=--background=x.glb"]) == 2
    assert "--world hall,street gives the background" in capsys.readouterr().err
    assert not (tmp_path / "work").exists()


def test_experiments_training_budget_is_shared_by_the_worlds(tmp_path: Path, monkeypatch) -> None:
    """``--max-minutes`` spent in one world stops the next before it starts a run; a fresh
    sitting always starts its first run."""
    every = experiments(tmp_path, "--world", "hall,street", "--max-minutes", "1")
    ran: list[str] = []
    monkeypatch.setattr(exp.Experiment, "run", lambda self, cmd, what: ran.append(what))
    monkeypatch.setattr(exp.Experiment, "add_time", lambda self, key, seconds: None)
    spent = exp.Sitting(1.0, deadline=time.monotonic() - 1.0, started=True)
    assert not every["street"].train(None, spent) and ran == []
    fresh = exp.Sitting(1e-9)
    time.sleep(0.01)
    assert not every["street"].train(None, fresh)  # stopped short of its steps (nothing trained)
    assert ran == ["train street/frames16"] and fresh.started


def score(iou: float) -> dict:
    """A score file's content with every figure the report reads, all from ``iou``."""
    o = {"iou": iou, "precision": iou, "recall": iou, "epe_mps": 1.0}
    bins = [{"iou": iou + 0.01 * (k + 1)} for k in range(3)]
    return {"overall": o, "bins": bins, "argmax": {"overall": o, "bins": bins}, "human_threshold": 0.9,
            "zero_epe_mps": 1.3}


def table4_rows(md: str) -> list[str]:
    """The first Table 4's body rows."""
    part = md.split("## Table 4")[1].split("A beam is human")[0]
    return [ln for ln in part.splitlines() if ln.startswith("| ") and not ln.startswith("| world")]


def test_experiments_report_a_table4_row_block_per_world_with_scores(tmp_path: Path) -> None:
    """Scores in the hall's and the street's folders (as any commands left them): results.json
    keeps the hall's at its top level and the street's under worlds; results.md has four rows
    for each, labeled; the indoor world, with nothing, has none."""
    every = experiments(tmp_path)
    work = tmp_path / "work"
    for folder, iou in ((work, 0.5), (work / "worlds" / "street", 0.25)):
        (folder / "scores").mkdir(parents=True)
        for n in (1, 16):
            (folder / "scores" / f"frames{n}--test.json").write_text(json.dumps(score(iou + n / 1000)))
    every["hall"].check_scale()
    res = every["hall"].results([every["street"], every["indoor"]])
    assert set(res["scores"]) == {"frames1--test", "frames16--test"}
    assert list(res["worlds"]) == ["street"] and res["worlds"]["street"]["folder"] == "worlds/street"
    assert res["worlds"]["street"]["scores"]["frames16--test"]["overall"]["iou"] == 0.266
    assert res["worlds"]["street"]["datasets"]["test"]["flags"] == ["--background", "street"]
    assert json.loads((work / "results.json").read_text()) == json.loads(json.dumps(res))
    md = (work / "results.md").read_text()
    rows = table4_rows(md)
    assert [r.split(" | ")[:2] for r in rows] == [
        ["| hall", "0-inf m"], ["| hall", "0-4 m"], ["| hall", "4-8 m"], ["| hall", "8+ m"],
        ["| street", "0-inf m"], ["| street", "0-4 m"], ["| street", "4-8 m"], ["| street", "8+ m"]]
    assert rows[0] == ("| hall | 0-inf m | 0.5010 / 0.4358 | — / 0.5869 | — / 0.5461 | — / 0.5523 | "
                       "0.5160 / 0.6443 |")
    assert rows[7].startswith("| street | 8+ m | 0.2810 / 0.0725 |")
    assert "| street | 16 | 0.900 | 0.2660 |" in md and "| hall | 1 | 1.000 | 1.300 |" in md
    assert "indoor |" not in md
    assert (work / "results.png").stat().st_size > 1000


@pytest.mark.parametrize("flags, train_flag, value, config, says", [
    (("--average-tail", "0.5"), "--average-from", "2", {"average_from": 2},
     "A network's weights are the mean of those after each step past step 2 (`--average-tail`, "
     "`train --average-from`): hall's."),
    (("--precision", "bf16"), "--precision", "bf16", {"precision": "bf16"},
     "Networks trained with their forward pass in bfloat16 (`--precision bf16`): hall's."),
])
def test_experiments_pass_a_training_option_to_every_run_and_say_so(
        tmp_path: Path, flags: tuple[str, str], train_flag: str, value: str, config: dict, says: str) -> None:
    """``--average-tail F`` (every run trains with ``--average-from`` at the last F of the
    scale's steps: smoke's 3 steps, so 0.5 averages those past step 2) and ``--precision
    bf16``: the flag reaches every run's training command, and the results say whose
    networks it made; without it, neither."""
    plain = experiments(tmp_path)
    assert train_flag not in plain["hall"].train_command("frames16")
    every = experiments(tmp_path, *flags)
    for world, run in (("hall", "frames16"), ("street", "frames1")):
        cmd = every[world].train_command(run)
        assert cmd[cmd.index(train_flag) + 1] == value, cmd
    work = tmp_path / "work"
    (work / "runs" / "frames16").mkdir(parents=True)
    (work / "runs" / "frames16" / "run.json").write_text(json.dumps({"config": config}))
    (work / "scores").mkdir()
    (work / "scores" / "frames16--test.json").write_text(json.dumps(score(0.5)))
    every["hall"].check_scale()
    res = every["hall"].results([every["street"], every["indoor"]])
    key = next(iter(config))
    assert res["runs"]["frames16"][key] == config[key]
    assert says in (work / "results.md").read_text()
    (work / "runs" / "frames16" / "run.json").write_text(json.dumps({"config": {}}))
    every["hall"].results([every["street"], every["indoor"]])
    assert says not in (work / "results.md").read_text()


def test_experiments_train_the_steps_asked_and_a_work_folder_keeps_them(tmp_path: Path, capsys) -> None:
    """``--steps N``: every run of every world trains N steps (its weights averaged over the
    last share of those N), the results say N; the work folder then refuses other steps, and
    a folder made before ``--steps`` existed holds its scale's."""
    every = experiments(tmp_path, "--steps", "8", "--average-tail", "0.5")
    for world, run in (("hall", "frames16"), ("street", "frames1")):
        cmd = every[world].train_command(run)
        assert cmd[cmd.index("--steps") + 1] == "8" and cmd[cmd.index("--average-from") + 1] == "4", cmd
    every["hall"].check_scale()
    assert json.loads((tmp_path / "work" / "state.json").read_text())["steps"] == 8
    assert every["hall"].results([])["steps"] == 8
    assert "Networks trained 8 steps each" in (tmp_path / "work" / "results.md").read_text()
    with pytest.raises(PedscanError, match="holds networks of 8 steps; give --steps 8 or another --work"):
        experiments(tmp_path)["hall"].check_scale()
    with pytest.raises(PedscanError, match="holds networks of 8 steps"):
        experiments(tmp_path, "--steps", "9")["street"].check_scale()
    experiments(tmp_path, "--steps", "8")["street"].check_scale()
    # A folder of before: its scale's steps (smoke: 3).
    state = tmp_path / "work" / "state.json"
    state.write_text(json.dumps({"scale": "smoke", "seconds": {"data": 1.0}}))
    experiments(tmp_path)["hall"].check_scale()
    assert json.loads(state.read_text()) == {"scale": "smoke", "seconds": {"data": 1.0}, "steps": 3}
    experiments(tmp_path, "--steps", "3")["hall"].check_scale()
    with pytest.raises(PedscanError, match="holds networks of 3 steps"):
        experiments(tmp_path, "--steps", "8")["hall"].check_scale()
    for bad in ("0", "-2", "x"):
        with pytest.raises(SystemExit):
            experiments(tmp_path, "--steps", bad)
        assert f"--steps: '{bad}'" in capsys.readouterr().err
    # A tail too short to hold a step.
    with pytest.raises(PedscanError, match="--average-tail 0.1: averages none of the 3 steps"):
        experiments(tmp_path, "--steps", "3", "--average-tail", "0.1")


@pytest.mark.parametrize("bad", ["0", "1.5", "nan"])
def test_experiments_refuse_an_average_tail_outside_0_1(tmp_path: Path, bad: str) -> None:
    with pytest.raises(PedscanError, match=f"--average-tail {bad}: a share of the steps"):
        experiments(tmp_path, "--average-tail", bad)


def test_experiments_report_only_the_worlds_that_have_scores() -> None:
    """The street alone when the hall has no score; the hall alone (the paper's row beside
    empty cells) when nothing is scored or the results predate worlds."""
    base = {"scale": "smoke", "steps": 3, "score_from_frame": 15, "seconds": {}}
    street = {"worlds": {"street": {"scores": {"frames2--test": score(0.3)}}, "indoor": {"scores": {}}}}
    rows = table4_rows(exp.render_markdown({**base, "scores": {}, **street}))
    assert [r.split(" | ")[0] for r in rows] == ["| street"] * 4
    assert rows[0] == "| street | 0-inf m | — / 0.4358 | 0.3000 / 0.5869 | — / 0.5461 | — / 0.5523 | — / 0.6443 |"
    for res in ({**base, "scores": {}}, {**base, "scores": {}, "worlds": {"indoor": {"scores": {}}}}):
        rows = table4_rows(exp.render_markdown(res))
        assert [r.split(" | ")[0] for r in rows] == ["| hall"] * 4


def test_the_paper_experiments_run_in_a_world_beside_the_hall(tmp_path: Path) -> None:
    """The real pipeline, smoke scale, N = 1 only: the street's sets are made with
    ``--background street`` in its own folder and its network trained and scored there; after
    a run in the hall of the same folder the report shows both worlds."""
    from conftest import find_pedscan

    (tmp_path / "sensor.toml").write_text(SENSOR_TOML)
    # People start close to the sensor: a street's parked cars and trees hide a far one, and
    # the one validation sequence must show a human beam to calibrate on.
    (tmp_path / "near.toml").write_text("[humans]\nspawn_radius_m = 9.0\n")
    work = tmp_path / "work"
    common = ["paper", "--work", str(work), "--scale", "smoke", "--pedscan", str(find_pedscan()),
              "--device", "cpu", "--workers", "0", "--runs", "frames1",
              f"--pedscan-flag=--sensor={tmp_path / 'sensor.toml'}", "--pedscan-flag=--humans=2..2",
              f"--pedscan-flag=--config={tmp_path / 'near.toml'}"]
    assert exp.main([*common, "--world", "street"]) == 0
    street = work / "worlds" / "street"
    for name in ("train", "val", "test"):
        marker = (street / "data" / name / ".complete").read_text()
        assert "--background street" in marker and f"--out {street / 'data' / name} " in marker, marker
        assert list((street / "data" / name).glob("seq_*.h5"))
    assert not (work / "data").exists() and not (work / "runs").exists()
    assert json.loads((street / "scores" / "frames1--test.json").read_text())["model_step"] == 3
    res = json.loads((work / "results.json").read_text())
    assert res["scores"] == {} and set(res["worlds"]) == {"street"}
    assert "street data" in res["seconds"] and "street train frames1" in res["seconds"]
    assert {r.split(" | ")[0] for r in table4_rows((work / "results.md").read_text())} == {"| street"}
    assert exp.main(common) == 0  # the hall, default world, in the same folder
    assert "--background" not in (work / "data" / "test" / ".complete").read_text()
    rows = table4_rows((work / "results.md").read_text())
    assert [r.split(" | ")[0] for r in rows] == ["| hall"] * 4 + ["| street"] * 4
    assert all(r.split(" | ")[2] != "— / 0.4358" for r in rows if r.split(" | ")[1] == "0-inf m")
    # With a recording, the street's network is scored on the hall's recorded test set too (made
    # once, in the hall's folder), and the report has a row for each world's network there.
    rec = generate(tmp_path / "rec", "--sequences", "1", "--frames", "18", "--humans", "0..0",
                   "--sensor", str(tmp_path / "sensor.toml"), "--formats", "semantickitti")
    velodyne = rec / "semantickitti" / "sequences" / "00" / "velodyne"
    assert exp.main([*common, "--world", "street,hall", "--recorded", str(velodyne)]) == 0
    assert not (street / "data" / "test-recorded").exists()
    hall_score = json.loads((work / "scores" / "frames1--test-recorded.json").read_text())
    street_score = json.loads((street / "scores" / "frames1--test-recorded.json").read_text())
    assert street_score["overall"]["human_beams"] == hall_score["overall"]["human_beams"] > 0

    for folder, score in ((street, street_score), (work, hall_score)):
        assert score["human_threshold"] == load_file(folder / "runs" / "frames1" / "model.pt")["human_threshold"]
    md = (work / "results.md").read_text()
    recorded = md[md.index("## A recorded background"):].split("\n\n")[2].splitlines()[2:]
    assert [r.split(" | ")[:2] for r in recorded] == [["| hall", "1"], ["| street", "1"]], recorded


def test_the_worlds_sets_are_made_at_the_recordings_height(tmp_path: Path, capsys) -> None:
    """The real data stage with ``--sensor-height recorded``: a recording made with its sensor
    1.5 m up gives every world's generated sets a sensor 1.5 m over their floor."""
    import h5py
    import numpy as np

    from conftest import find_pedscan

    (tmp_path / "sensor.toml").write_text(SENSOR_TOML)
    rec = generate(tmp_path / "rec", "--sequences", "1", "--frames", "18", "--humans", "0..0", "--sensor-height", "1.5",
                   "--sensor", str(tmp_path / "sensor.toml"), "--formats", "semantickitti")
    velodyne = rec / "semantickitti" / "sequences" / "00" / "velodyne"
    work = tmp_path / "work"
    assert exp.main(["paper", "--work", str(work), "--scale", "smoke", "--pedscan", str(find_pedscan()),
                     "--only", "data", "--runs", "frames1", "--world", "street,hall", "--recorded", str(velodyne),
                     "--sensor-height", "recorded", f"--pedscan-flag=--sensor={tmp_path / 'sensor.toml'}",
                     "--pedscan-flag=--humans=1..1"]) == 0
    said = capsys.readouterr().err
    h = float(said.split("sensor stands ")[1].split(" m")[0])
    assert abs(h - 1.5) <= 0.02, said
    assert "--sensor-height" not in (work / "data" / "test-recorded" / ".complete").read_text()
    for folder in (work / "data", work / "worlds" / "street" / "data"):
        for name in ("train", "val", "test"):
            assert f"--sensor-height {h:g} " in (folder / name / ".complete").read_text() + " ", (folder, name)
    with h5py.File(work / "data" / "train" / "seq_000000.h5", "r") as f:
        z = np.asarray(f["/sensor/world_from_sensor"])[:, 2, 3]
    np.testing.assert_allclose(z, h, atol=1e-6)  # the hall's floor is z = 0


def test_sigterm_reaches_the_training_run_and_leaves_nothing_running(sample: Path, tmp_path: Path) -> None:
    """A batch system's SIGTERM to ``experiments`` stops it as Ctrl-C does: the training run it
    waits on (a process of the fork server, not of the command) gets the signal too, stops
    with its last checkpoint kept, and the command waits for it before it exits 130."""
    import os
    import subprocess
    import sys

    run = tmp_path / "run"
    argv = [str(sample), "--out", str(run), "--frames", "2", "--width", "4", "--steps", "1000000",
            "--checkpoint-every", "2", "--workers", "0", "--quiet"]
    script = f"""
import os, signal, sys, threading, time
from pathlib import Path
from pedscan_data import experiments as exp
from pedscan_data.netio import load_file
signal.signal(signal.SIGTERM, exp._on_sigterm)  # as main() does
def poke():
    while not Path({str(run / "checkpoint.pt")!r}).exists():
        time.sleep(0.05)
    print("training", *exp._CHILDREN, flush=True)
    os.kill(os.getpid(), signal.SIGTERM)
threading.Thread(target=poke, daemon=True).start()
try:
    exp.run_train({argv!r})
except KeyboardInterrupt:
    print("left", *exp._CHILDREN, flush=True)
    sys.exit(130)
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 130, done.stderr
    lines = done.stdout.splitlines()
    pids = [int(p) for p in lines[0].split()[1:]]
    assert lines[0].startswith("training ") and len(pids) == 1, done.stdout
    assert lines[1] == "left", done.stdout  # waited for, and forgotten
    assert "stopped at step" in done.stderr and "stays (--resume continues)" in done.stderr, done.stderr
    assert 2 <= load_file(run / "checkpoint.pt")["step"] < 1000000
    with pytest.raises(ProcessLookupError):
        os.kill(pids[0], 0)


def test_a_training_run_is_a_process_of_its_own_and_its_failure_names_the_command(tmp_path: Path) -> None:
    """Runs are forked from a server that imported torch once, each its own process: its exit
    code comes back (2 for bad input, as ``python -m pedscan_data.train`` gives) and a failed
    run stops the experiment naming the command."""
    missing = tmp_path / "no-data"
    assert exp.run_train([str(missing), "--out", str(tmp_path / "run"), "--steps", "1"]) == 2
    assert exp.run_train(["--no-such-flag"]) == 2
    assert not (tmp_path / "run").exists()
    hall = experiments(tmp_path)["hall"]
    with pytest.raises(exp.PedscanError, match=r"train frames1: `.* -m pedscan_data.train .*no-data.*` exited 2"):
        hall.run([hall.python, "-m", "pedscan_data.train", str(missing), "--out", str(tmp_path / "run")], "train frames1")
