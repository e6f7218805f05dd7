"""`python -m pedscan_data.average`: the mean of networks' weights, calibrated as train does."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest
import torch

from conftest import net_for, save_model
from pedscan_data import average as av
from pedscan_data import train as tr
from pedscan_data.netio import load_file, load_net
from pedscan_data.reader import Sequence


def two_models(tmp_path: Path, **extra: object) -> list[Path]:
    """Two one-frame networks of different random weights, as train and a shipped file write them."""
    paths = []
    for i in range(2):
        p = save_model(net_for(1, width=4, seed=i), tmp_path / f"m{i}.pt", threshold=0.3 + 0.2 * i,
                       training={"step": 100 * (i + 1), "sensor": "test16"})
        obj = load_file(p)
        obj.update({"licence": "CC0" if i == 0 else "CC BY-NC-SA 3.0", **extra})
        torch.save(obj, p)
        paths.append(p)
    return paths


def test_the_average_is_the_mean_of_the_weights_with_its_own_calibrated_threshold(sample: Path, tmp_path: Path,
                                                                                  capsys) -> None:
    a, b = two_models(tmp_path, mirror=True)
    out = tmp_path / "avg.pt"
    assert av.main([str(a), str(b), "--out", str(out), "--val", str(sample), "--device", "cpu"]) == 0
    assert "the mean of 2 networks" in capsys.readouterr().out
    obj, sa, sb = load_file(out), load_file(a)["state_dict"], load_file(b)["state_dict"]
    assert set(obj["state_dict"]) == set(sa)
    for k, v in obj["state_dict"].items():
        assert v.dtype == sa[k].dtype and torch.equal(v, ((sa[k].double() + sb[k].double()) / 2).to(v.dtype)), k
    assert all(not torch.equal(obj["state_dict"][k], sa[k]) and not torch.equal(obj["state_dict"][k], sb[k])
               for k in sa if sa[k].ndim > 1)
    # Its threshold is its own: calibrated on the validation sequences, mirrored as the files predict.
    net, _ = load_net(out)
    seqs = [Sequence(p) for p in sorted(sample.glob("seq_*.h5"))]
    c = tr.calibrate(net, seqs, "cpu", 0, mirror=True)
    assert obj["mirror"] is True and obj["human_threshold"] == pytest.approx(c["human_threshold"])
    assert obj["human_threshold"] not in (0.3, 0.5) and obj["training"]["calibration"]["mirrored"] is True
    rec = obj["training"]
    assert rec["averaged"] == [{"file": p.name, "sha256": hashlib.sha256(p.read_bytes()).hexdigest(), "step": s}
                               for p, s in ((a, 100), (b, 200))]
    assert rec["sensor"] == "test16" and rec["environment"]["device"] == "cpu"
    assert obj["licence"] == "CC0 | CC BY-NC-SA 3.0" and obj["net"] == load_file(a)["net"]
    assert not list(tmp_path.glob("*.calibrating"))
    # --no-mirror overrides the files: calibrated on one pass.
    assert av.main([str(a), str(b), "--out", str(out), "--val", str(sample), "--device", "cpu", "--no-mirror"]) == 0
    one = load_file(out)
    assert one["mirror"] is False and one["human_threshold"] == pytest.approx(tr.calibrate(net, seqs, "cpu", 0)["human_threshold"])


def test_average_refuses_what_it_cannot_average_with_exit_2_and_writes_nothing(sample: Path, tmp_path: Path,
                                                                               capsys) -> None:
    a, b = two_models(tmp_path)
    wide = save_model(net_for(1, width=8), tmp_path / "wide.pt", training={"sensor": "test16"})
    grid = save_model(net_for(1, width=4, seed=3), tmp_path / "grid.pt", training={"sensor": "hdl64e"})
    nan = load_file(b)
    k = next(k for k, v in nan["state_dict"].items() if v.ndim > 1)
    nan["state_dict"][k][0].view(-1)[0] = float("nan")
    torch.save(nan, tmp_path / "nan.pt")
    flipped = load_file(b)
    flipped["mirror"] = True
    torch.save(flipped, tmp_path / "flipped.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a model")
    out = tmp_path / "avg.pt"
    cases = [
        ([a], "two model files or more"),
        ([a, a], "given twice"),
        ([a, wide], "wide.pt: another network"),
        ([a, grid], "grid.pt: trained on another grid"),
        ([a, tmp_path / "nan.pt"], "nan.pt: weights that are not finite"),
        ([a, tmp_path / "flipped.pt"], "--mirror or --no-mirror"),
        ([a, tmp_path / "junk.pt"], "junk.pt"),
        ([a, tmp_path / "missing.pt"], "missing.pt: no such file"),
    ]
    for models, message in cases:
        assert av.main([*map(str, models), "--out", str(out), "--val", str(sample), "--device", "cpu"]) == 2, message
        assert message in capsys.readouterr().err
        assert not out.exists() and not list(tmp_path.glob("*.calibrating")), message
    # Validation data that is not there, or holds no person to calibrate on: nothing written either.
    assert av.main([str(a), str(b), "--out", str(out), "--val", str(tmp_path / "none"), "--device", "cpu"]) == 2
    assert "--val" in capsys.readouterr().err and not out.exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    assert av.main([str(a), str(b), "--out", str(out), "--val", str(empty), "--device", "cpu"]) == 2
    assert str(empty) in capsys.readouterr().err
    assert not out.exists() and not list(tmp_path.glob("*.calibrating"))
    # The file as it was is kept when a later average fails.
    assert av.main([str(a), str(b), "--out", str(out), "--val", str(sample), "--device", "cpu"]) == 0
    before = out.read_bytes()
    assert av.main([str(a), str(tmp_path / "nan.pt"), "--out", str(out), "--val", str(sample), "--device", "cpu"]) == 2
    assert out.read_bytes() == before
    assert np.isfinite(load_file(out)["human_threshold"])


def test_calibrate_pools_validation_folders_and_writes_only_what_it_was_asked(sample: Path, tmp_path: Path,
                                                                            capsys) -> None:
    """`python -m pedscan_data.calibrate`: the threshold of a model file over several validation
    folders pooled (as train calibrates, mirrored where the file predicts so), into --out or
    the file itself; bad input is refused with exit 2 and nothing written."""
    import shutil

    from pedscan_data import calibrate as cal

    (a, _) = two_models(tmp_path, mirror=True)
    other = tmp_path / "other"
    other.mkdir()
    shutil.copyfile(sample / "seq_000001.h5", other / "seq_000000.h5")
    before = a.read_bytes()
    out = tmp_path / "cal.pt"
    assert cal.main([str(a), "--val", str(sample), str(other), "--out", str(out), "--device", "cpu"]) == 0
    assert "2 folders, mirrored" in capsys.readouterr().out
    assert a.read_bytes() == before
    net, _ = load_net(a)
    seqs = [Sequence(p) for p in (sample / "seq_000000.h5", sample / "seq_000001.h5", other / "seq_000000.h5")]
    c = tr.calibrate(net, seqs, "cpu", 0, mirror=True)
    obj = load_file(out)
    assert obj["human_threshold"] == pytest.approx(c["human_threshold"]) and c["beams"] == obj["training"]["calibration"]["beams"]
    assert obj["training"]["calibration"]["val"] == [f"{sample.name}/seq_000000.h5", f"{sample.name}/seq_000001.h5", "other/seq_000000.h5"]
    # Pooled, the second sequence counts twice: not the threshold of the first folder alone.
    alone = tr.calibrate(net, seqs[:2], "cpu", 0, mirror=True)
    assert alone["beams"] < c["beams"]
    # In place, without --out.
    assert cal.main([str(a), "--val", str(sample), "--device", "cpu"]) == 0
    assert load_file(a)["human_threshold"] == pytest.approx(alone["human_threshold"])
    assert load_file(a)["training"]["calibration"]["val"] == ["seq_000000.h5", "seq_000001.h5"]
    # Bad input: nothing written.
    for args, message in (([str(tmp_path / "none.pt"), "--val", str(sample)], "none.pt"),
                          ([str(a), "--val", str(sample), str(tmp_path / "nowhere")], "nowhere"),
                          ([str(a), "--val", str(sample), "--score-from", "-1"], "--score-from")):
        after = a.read_bytes()
        assert cal.main([*args, "--out", str(tmp_path / "bad.pt"), "--device", "cpu"]) == 2, message
        assert message in capsys.readouterr().err
        assert not (tmp_path / "bad.pt").exists() and a.read_bytes() == after
        assert not list(tmp_path.glob("*.calibrating"))
