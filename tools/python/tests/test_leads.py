"""``experiments paper --seeds``: the 1- and 16-frame networks trained once per seed on the
same data, and the 16-frame lead per distance bin over the seeds, each world's against the hall's."""

from __future__ import annotations

from pathlib import Path

import pytest

from pedscan_data import experiments as exp
from pedscan_data.leads import render_leads, run_seed, seed_leads, seed_run

from test_experiments import experiments, table4_rows


def scored(overall: float, bins: tuple[float, float, float]) -> dict:
    """A score file's content: the IoU over all and at 0-4, 4-8 and 8+ m, and what else the report reads."""
    o = {"iou": overall, "precision": 0.5, "recall": 0.5, "epe_mps": 1.0}
    b = [{"iou": v} for v in bins]
    return {"overall": o, "bins": b, "argmax": {"overall": o, "bins": b}, "human_threshold": 0.9, "zero_epe_mps": 1.3}


def pairs(*leads: tuple[float, float, float, float]) -> dict:
    """Scores of a 1- and a 16-frame network for seeds 0, 1, ...: the single frame 0.5 in every
    bin, the sequence 0.5 plus the seed's lead (all, 0-4, 4-8, 8+ m)."""
    out = {}
    for seed, lead in enumerate(leads):
        suffix = "" if seed == 0 else f"-seed{seed}"
        out[f"frames1{suffix}--test"] = scored(0.5, (0.5, 0.5, 0.5))
        out[f"frames16{suffix}--test"] = scored(0.5 + lead[0], (0.5 + lead[1], 0.5 + lead[2], 0.5 + lead[3]))
    return out


def test_seeds_train_the_pair_once_per_seed_on_the_same_data(tmp_path: Path) -> None:
    every = experiments(tmp_path, "--seeds", "0,2", "--world", "hall,street")
    for world in ("hall", "street"):
        ex = every[world]
        runs = ex.runs()
        assert {"frames1-seed2", "frames16-seed2"} <= set(runs)
        assert not any(name.startswith(("frames4-seed", "frames16-seed0")) for name in runs)
        seeded, plain = ex.train_command("frames16-seed2"), ex.train_command("frames16")
        assert seeded[seeded.index("--seed") + 1] == "2" and "--seed" not in plain
        assert seeded[seeded.index("--out") + 1] == str(ex.work / "runs" / "frames16-seed2")
        # The same data, validation set, frames and steps: only the seed differs.
        for flag in ("--frames", "--steps", "--val"):
            assert seeded[seeded.index(flag) + 1] == plain[plain.index(flag) + 1]
        assert seeded[3] == plain[3] == str(ex.work / "data" / "train")
        single = ex.train_command("frames1-seed2")
        assert single[single.index("--frames") + 1] == "1" and single[single.index("--seed") + 1] == "2"


def test_seeds_choose_the_runs_and_refuse_what_they_cannot_train(tmp_path: Path, monkeypatch, capsys) -> None:
    chosen: list[tuple[str, list[str]]] = []
    monkeypatch.setattr(exp.Experiment, "train", lambda self, only, sitting: chosen.append((self.world, sorted(only))) or True)
    fake = tmp_path / "pedscan"
    fake.write_text("")
    base = ["paper", "--work", str(tmp_path / "work"), "--scale", "smoke", "--pedscan", str(fake), "--only", "train"]
    assert exp.main([*base, "--world", "street", "--seeds", "0,3"]) == 0
    assert chosen == [("street", ["frames1", "frames1-seed3", "frames16", "frames16-seed3"])]
    chosen.clear()
    assert exp.main([*base, "--seeds", "3,4", "--runs", "frames16"]) == 0
    assert chosen == [("hall", ["frames16-seed3", "frames16-seed4"])]
    chosen.clear()
    assert exp.main([*base, "--seeds", "1", "--runs", "frames16,frames4"]) == 2
    assert "--seeds: trains frames1 and frames16 once per seed; not frames4" in capsys.readouterr().err
    for bad in ("-1", "a,b", ","):
        with pytest.raises(SystemExit) as e:
            exp.main([*base, "--seeds", bad])
        assert e.value.code == 2
        assert "argument --seeds" in capsys.readouterr().err
    assert chosen == []
    assert exp.seed_list("2, 0,2") == [2, 0]


def test_the_runs_of_seeds_an_earlier_command_trained_stay_in_the_experiment(tmp_path: Path) -> None:
    """A later command without ``--seeds`` still tests and reports them; other folders are not runs."""
    for name in ("frames16-seed7", "frames4-seed8", "frames16-seedx"):
        (tmp_path / "work" / "runs" / name).mkdir(parents=True)
    runs = experiments(tmp_path)["hall"].runs()
    assert {"frames1-seed7", "frames16-seed7"} <= set(runs)
    assert not [n for n in runs if "seed8" in n or "seedx" in n]
    # The seed of a run's name is the inverse of its name for the seed; other runs have none.
    assert [run_seed(seed_run(n, s)) for n in (1, 16) for s in (0, 7, 12)] == [0, 7, 12] * 2
    assert [run_seed(n) for n in ("frames4-seed8", "frames16-seedx", "frames16-change", "motion-static")] == [None] * 4


def test_the_lead_over_seeds_its_spread_and_each_world_against_the_hall() -> None:
    hall = seed_leads(pairs((0.02, 0.0, 0.02, 0.01), (0.01, 0.0, 0.02, 0.02), (0.03, 0.0, 0.02, 0.00)))
    street = seed_leads(pairs((0.05, -0.05, 0.03, 0.10), (0.04, -0.06, 0.05, 0.12), (0.06, -0.04, 0.01, 0.08)))
    assert hall is not None and street is not None and hall["seeds"] == [0, 1, 2]
    b = street["bins"]["8+ m"]
    assert b["per_seed"] == pytest.approx({"0": 0.10, "1": 0.12, "2": 0.08})
    assert b["mean"] == pytest.approx(0.10) and b["spread"] == pytest.approx(0.04)
    md = "\n".join(render_leads({"hall": hall, "street": street}))
    assert "| street | 0, 1, 2 | +0.0500 (+0.0400 to +0.0600) | -0.0500 (-0.0600 to -0.0400) |" in md
    # 8+ m: 0.10 against 0.01, the spread the street's 0.04: larger. 4-8 m: 0.03 against 0.02,
    # spread 0.04: not larger. 0-4 m: below the hall's.
    row = [ln for ln in md.splitlines() if ln.startswith("| street | ") and "against" in ln][0]
    cells = row.split(" | ")[1:]
    assert cells[3] == "+0.0900 against 0.0400: larger |"
    assert cells[2] == "+0.0100 against 0.0400: not larger"
    assert cells[1] == "-0.0500 against 0.0200: not larger"


def test_one_seed_has_no_spread_and_a_lone_pair_no_section() -> None:
    one = seed_leads(pairs((0.02, 0.01, 0.03, 0.04)))
    assert one is not None and one["bins"]["4-8 m"]["spread"] is None
    assert render_leads({"hall": one}) == []
    md = "\n".join(render_leads({"hall": one, "street": one}))
    assert "| hall | 0 | +0.0200 | +0.0100 | +0.0300 | +0.0400 |" in md
    assert "+0.0000 (no spread: one seed)" in md
    # A seed with only one of the pair scored is not a seed of the lead.
    half = pairs((0.02, 0.01, 0.03, 0.04))
    half["frames16-seed5--test"] = scored(0.9, (0.9, 0.9, 0.9))
    assert seed_leads(half)["seeds"] == [0]
    assert seed_leads({"frames16--test": scored(0.9, (0.9, 0.9, 0.9))}) is None


def test_the_report_carries_the_leads_and_table4_keeps_seed_0(tmp_path: Path) -> None:
    import json

    every = experiments(tmp_path)
    work = tmp_path / "work"
    for folder, leads in ((work, ((0.02, 0.0, 0.02, 0.01), (0.01, 0.0, 0.02, 0.02))),
                          (work / "worlds" / "street", ((0.05, 0.0, 0.03, 0.10), (0.04, 0.0, 0.05, 0.12)))):
        (folder / "scores").mkdir(parents=True)
        for key, s in pairs(*leads).items():
            (folder / "scores" / f"{key}.json").write_text(json.dumps(s))
    every["hall"].check_scale()
    res = every["hall"].results([every["street"], every["indoor"]])
    assert set(res["leads"]) == {"hall", "street"}
    assert res["leads"]["street"]["bins"]["8+ m"]["mean"] == pytest.approx(0.11)
    md = (work / "results.md").read_text()
    assert "## The sequence's lead over training seeds" in md
    # Over all: the street's mean lead 0.045 against the hall's 0.015, both spreads 0.01.
    assert "| street | +0.0300 against 0.0100: larger |" in md
    # Table 4 shows seed 0 (the plain runs): the street's 16 frames at 8+ m are 0.5 + 0.10.
    rows = table4_rows(md)
    assert rows[7].split(" | ")[6] == "0.6000 / 0.1622 |"


def test_the_worlds_on_the_recording_over_seeds_seed_by_seed_and_against_the_spread() -> None:
    from pedscan_data.leads import recorded_seeds, render_recorded_seeds

    def on_recording(ious: dict[str, float]) -> dict:
        return {f"{run}--test-recorded": scored(v, (v, v, v)) for run, v in ious.items()}

    hall = on_recording({"frames1": 0.40, "frames1-seed1": 0.35, "frames1-seed2": 0.33,
                         "frames16": 0.27, "frames16-seed1": 0.21})
    street = on_recording({"frames1-seed1": 0.39, "frames1-seed2": 0.41, "frames16-seed1": 0.30,
                           "frames16-seed2": 0.60, "motion-static": 0.9})
    assert recorded_seeds([("hall", hall), ("street", street)])["street"] == {1: {1: 0.39, 2: 0.41}, 16: {1: 0.30, 2: 0.60}}
    md = "\n".join(render_recorded_seeds([("hall", hall), ("street", street)]))
    assert "| hall | 1 | 0, 1, 2 | 0.3600 (0.3300 to 0.4000) | | |" in md
    # One frame: higher at both seeds both trained, but its mean lead (0.04) is within the
    # hall's spread (0.07). Sixteen: the street's own spread (0.30) is what the lead must beat.
    assert "| street | 1 | 1, 2 | 0.4000 (0.3900 to 0.4100) | higher at 2 of 2 (+0.0400, +0.0800) | +0.0400 against 0.0700: not higher |" in md
    assert "| street | 16 | 1, 2 | 0.4500 (0.3000 to 0.6000) | higher at 1 of 1 (+0.0900) | +0.2100 against 0.3000: not higher |" in md
    # A lead beyond both spreads is higher; the hall alone, or one seed a side, shows nothing.
    wide = on_recording({"frames1-seed1": 0.50, "frames1-seed2": 0.52})
    assert "| +0.1500 against 0.0700: higher |" in "\n".join(render_recorded_seeds([("hall", hall), ("street", wide)]))
    assert render_recorded_seeds([("hall", hall)]) == []
    assert render_recorded_seeds([("hall", on_recording({"frames1": 0.4})), ("street", street)]) == []
