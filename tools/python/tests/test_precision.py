"""--precision bf16 and --bench-step: the training step in bfloat16, and its cost beside fp32's."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import pytest
import torch

from pedscan_data import train as tr
from pedscan_data.netio import load_file


def run_train(*args: str) -> int:
    return tr.main([*map(str, args), "--quiet", "--workers", "0"])


def test_bf16_trains_the_forward_pass_in_bfloat16_and_resumes_to_the_same_bits(sample: Path, tmp_path: Path,
                                                                                 capsys) -> None:
    """--precision bf16: the step's forward pass under autocast moves the weights otherwise than
    float32 from the same start, though not far; the run records it; stopped and resumed it
    ends on the same bits; a float32 run is not resumed in bfloat16, nor an unknown precision
    taken."""
    common = ["--frames", "2", "--width", "4", "--steps", "4", "--checkpoint-every", "1", "--seed", "3"]
    assert run_train(sample, "--out", tmp_path / "f", *common) == 0
    assert run_train(sample, "--out", tmp_path / "b", *common, "--precision", "bf16") == 0
    f, b = (load_file(tmp_path / r / "model.pt") for r in ("f", "b"))
    assert f["training"]["config"]["precision"] == "fp32" and b["training"]["config"]["precision"] == "bf16"
    moved = [float((b["state_dict"][k] - f["state_dict"][k]).abs().max()) for k in f["state_dict"]]
    assert max(moved) > 0, "bfloat16 changed nothing"
    assert max(moved) < 0.05 * max(float(v.abs().max()) for v in f["state_dict"].values())
    assert run_train(sample, "--out", tmp_path / "r", *common, "--precision", "bf16", "--stop-at-step", "2") == 130
    assert run_train(sample, "--out", tmp_path / "r", *common, "--precision", "bf16", "--resume") == 0
    r = load_file(tmp_path / "r" / "model.pt")["state_dict"]
    assert all(torch.equal(r[k], v) for k, v in b["state_dict"].items())
    capsys.readouterr()
    assert run_train(sample, "--out", tmp_path / "f", *common, "--steps", "5", "--precision", "bf16", "--resume") == 2
    assert "a run of another configuration (differs in: precision)" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        run_train(sample, "--out", tmp_path / "x", *common, "--precision", "fp16")
    assert e.value.code == 2 and not (tmp_path / "x").exists()


def test_bench_step_times_each_precision_on_the_datas_grid(sample: Path, capsys) -> None:
    """--bench-step: one line of JSON, the step's seconds in fp32 and bf16 on the data's grid
    (cropped where asked) and their ratio to fp32's; nothing trained, no run folder."""
    assert tr.main([str(sample), "--frames", "2", "--width", "4", "--crop-columns", "16", "--bench-step", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    with h5py.File(sorted(sample.glob("*.h5"))[0]) as f:
        rows = f["range"].shape[1]
    assert out["frames"] == 2 and out["grid"] == [rows, 16]
    assert set(out["s_per_step"]) == {"fp32", "bf16"} and all(t > 0 for t in out["s_per_step"].values())
    assert out["ratio_to_fp32"]["fp32"] == 1.0
    assert tr.main([str(sample), "--frames", "2", "--width", "4", "--bench-step", "0"]) == 2
    assert "--bench-step 0: at least one step a round" in capsys.readouterr().err
