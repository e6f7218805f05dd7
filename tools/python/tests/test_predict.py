"""Prediction as a user runs it: the files and attributes it writes, the inputs it reads, the
grids it refuses, its command line and the ONNX file it exports."""

from __future__ import annotations

import math
import platform
import shutil
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from conftest import generate, net_for, save_model, watch_devices
from pedscan_data import predict as pr
from pedscan_data.model import NetConfig, SequenceNet, input_channels
from pedscan_data.netio import MODEL_FORMAT, environment
from pedscan_data.reader import Sequence


def test_an_intensity_network_is_fed_the_sequences_intensity(sample: Path) -> None:
    net = net_for(2, width=4, seed=1, intensity=True)
    seq = Sequence(sample / "seq_000000.h5")
    assert seq.has("intensity")
    margin, velocity, _ = pr.predict_sequence(net, seq, "cpu", chunk=3)
    x = torch.from_numpy(input_channels(seq.read("range"), seq.read("intensity")))
    assert x.shape[1] == 3
    with torch.no_grad():
        for t in range(seq.frames):
            logits, vel = net(x[[max(t - 1, 0), t]].unsqueeze(0))
            np.testing.assert_allclose(margin[t], (logits[0, 1] - logits[0, 0]).numpy(), rtol=1e-4, atol=1e-4)
            np.testing.assert_allclose(velocity[t], vel[0].permute(1, 2, 0).numpy(), rtol=1e-4, atol=1e-5)


def test_a_mirrored_prediction_is_the_mean_of_both_passes_and_mirrors_with_its_input(sample: Path, tmp_path: Path) -> None:
    """--mirror: per frame, the mean of the network's outputs on the frame and on the frame's
    columns reversed (reversed back, its velocities' y negated back), over a 2-frame window; so
    the frame mirrored gives the outputs mirrored, exactly, which one pass does not; the files
    say so."""
    net = net_for(2, width=4, seed=1)
    seq = Sequence(sample / "seq_000000.h5")
    x = input_channels(seq.read("range"))
    turn = np.array([1.0, -1.0, 1.0], dtype=np.float32)
    one, one_v, _ = zip(*[(m, v, ms) for _, m, v, ms in pr.stream(net, x, "cpu")])
    flipped, flipped_v, _ = zip(*[(m, v, ms) for _, m, v, ms in pr.stream(net, np.ascontiguousarray(x[..., ::-1]), "cpu")])
    both, both_v, _ = zip(*[(m, v, ms) for _, m, v, ms in pr.stream(net, x, "cpu", mirror=True)])
    back, back_v, _ = zip(*[(m, v, ms) for _, m, v, ms in pr.stream(net, np.ascontiguousarray(x[..., ::-1]), "cpu", mirror=True)])
    for t in range(seq.frames):
        np.testing.assert_allclose(both[t], (one[t] + flipped[t][:, ::-1]) / 2, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(both_v[t], (one_v[t] + flipped_v[t][:, ::-1] * turn) / 2, rtol=1e-5, atol=1e-6)
        np.testing.assert_array_equal(back[t][:, ::-1], both[t])
        np.testing.assert_array_equal(back_v[t][:, ::-1] * turn, both_v[t])
    assert not np.allclose(flipped[-1][:, ::-1], one[-1], atol=1e-3)  # one pass is not mirror-symmetric
    # The model file's "mirror" is the default; --mirror / --no-mirror win over it.
    model = save_model(net, tmp_path / "net.pt")
    obj = torch.load(model, weights_only=True)
    obj["mirror"] = True
    torch.save(obj, tmp_path / "asks.pt")
    for name, args, want in (("flag", [str(model), "--mirror"], 1), ("file", [str(tmp_path / "asks.pt")], 1),
                             ("off", [str(tmp_path / "asks.pt"), "--no-mirror"], 0), ("plain", [str(model)], 0)):
        assert pr.main([*args[:1], str(sample), "--out", str(tmp_path / name), "--device", "cpu", *args[1:]]) == 0
        with h5py.File(tmp_path / name / "seq_000000.h5", "r") as f:
            assert f.attrs["mirrored"] == want, name
            np.testing.assert_array_equal(f["label"][()], (np.stack(both if want else one) > 0).astype(np.uint8))


def test_predictions_are_written_as_documented_and_may_be_written_again(sample: Path, tmp_path: Path) -> None:
    net = net_for(2, width=4, seed=1)
    model = save_model(net, tmp_path / "net.pt", threshold=0.7)
    out = tmp_path / "pred"
    out.mkdir()  # an existing folder is used, and a second run writes over the first
    for _ in range(2):
        res = pr.predict(model, sample, out, quiet=True)  # the default device: auto
        assert res["sequences"] == 2 and res["ms_per_frame_median"] > 0
    cut = math.log(0.7 / 0.3)
    for src in sorted(sample.glob("seq_*.h5")):
        seq = Sequence(src)
        margin, velocity, _ = pr.predict_sequence(net, seq, "cpu")
        with h5py.File(out / src.name, "r") as f:
            assert dict(f.attrs) == {"frames_seen": 2, "full_window_from": 1, "human_threshold": 0.7, "model": "net.pt",
                                     "mirrored": 0, "source_range_sha256": seq.range_digest()}
            t, h, w = seq.frames, seq.rows, seq.columns
            for name, shape, dtype in (("label", (t, h, w), np.uint8), ("velocity", (t, h, w, 3), np.float32)):
                d = f[name]
                assert (d.shape, d.dtype, d.chunks) == (shape, dtype, (1,) + shape[1:]), name
                assert (d.compression, d.compression_opts, d.shuffle) == ("gzip", 1, True), name
            np.testing.assert_array_equal(f["label"][()], (margin > cut).astype(np.uint8))
            np.testing.assert_allclose(f["velocity"][()], velocity, rtol=1e-5, atol=1e-6)
    assert not list(out.glob("*.tmp"))
    # SemanticKITTI, twice into the same folder: one label and one velocity per returned beam.
    kitti = tmp_path / "kitti"
    for _ in range(2):
        pr.predict(model, sample, kitti, fmt="semantickitti", quiet=True)
    for src in sorted(sample.glob("seq_*.h5")):
        seq = Sequence(src)
        margin, velocity, _ = pr.predict_sequence(net, seq, "cpu")
        base = kitti / "sequences" / f"{seq.index:02d}"
        for t in range(seq.frames):
            returned = seq.read("range", t).ravel() > 0
            labels = np.fromfile(base / "labels" / f"{t:06d}.label", dtype="<u4")
            np.testing.assert_array_equal(labels, np.where(margin[t].ravel()[returned] > cut, 30, 0))
            v = np.fromfile(base / "velocity" / f"{t:06d}.bin", dtype="<f4").reshape(-1, 3)
            np.testing.assert_allclose(v, velocity[t].reshape(-1, 3)[returned], rtol=1e-5, atol=1e-6)


def test_a_one_frame_sequence_is_timed_and_odd_grids_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = save_model(net_for(1, width=4, seed=1), tmp_path / "net.pt")
    one = generate(tmp_path / "one", "--sequences", "1", "--frames", "1", "--humans", "1..1", "--outputs", "range,label")
    res = pr.predict(model, one, tmp_path / "deep" / "p1", quiet=True)  # parent folders are made
    assert res["sequences"] == 1 and res["ms_per_frame_median"] > 0
    assert (tmp_path / "deep" / "p1" / "seq_000000.h5").is_file()
    # A network that takes intensity is refused data without it, naming the file.
    wants = save_model(net_for(1, width=4, seed=1, intensity=True), tmp_path / "intensity.pt")
    bare = tmp_path / "bare"
    shutil.copytree(one, bare)
    with h5py.File(bare / "seq_000000.h5", "a") as f:
        del f["intensity"]
    assert pr.main([str(wants), str(bare), "--out", str(tmp_path / "pi"), "--device", "cpu"]) == 2
    err = capsys.readouterr().err
    assert "seq_000000.h5: no dataset /intensity, which this network takes as input" in err, err
    assert not (tmp_path / "pi").exists()
    # Rows a multiple of 4 and columns of 8 (the network halves the rows twice and the columns
    # three times): either alone off is refused, naming the file and the grid.
    for rows, columns in ((6, 64), (8, 60)):
        sensor = tmp_path / f"s{rows}x{columns}.toml"
        el = ", ".join(str(-10.0 + 3.0 * k) for k in range(rows))
        sensor.write_text(f'name = "odd"\nelevation_deg = [{el}]\ncolumns = {columns}\n')
        data = generate(tmp_path / f"d{rows}x{columns}", "--sequences", "1", "--frames", "1", "--humans", "1..1",
                        "--outputs", "range,label", "--sensor", str(sensor))
        out = tmp_path / f"p{rows}x{columns}"
        assert pr.main([str(model), str(data), "--out", str(out), "--device", "cpu"]) == 2
        err = capsys.readouterr().err
        assert f"seq_000000.h5: a {rows} x {columns} grid; the network takes a multiple of 4 rows and of 8 columns" in err
        assert not out.exists()


def help_text(main, capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    return " ".join(capsys.readouterr().out.split())


def test_the_command_lines_say_what_they_take(capsys: pytest.CaptureFixture[str]) -> None:
    """The help a user reads, argument by argument (whitespace aside)."""
    from pedscan_data.evaluate import main as evaluate_main

    text = help_text(pr.main, capsys)
    for want in (
        "usage: python -m pedscan_data.predict",
        "Runs a trained network over pedscan sequences or real scans and writes its predictions.",
        "model run folder or model file (.pt)",
        "[data]",
        "data pedscan output folder or sequence file; or SemanticKITTI scans: a sequence folder (velodyne/) "
        "or a dataset root (sequences/SS/velodyne/)",
        "--out OUT folder for the predictions",
        "--format {h5,semantickitti} for pedscan data (default h5)",
        "--sensor NAME|FILE.toml scans: the grid to project on (default: the model file's)",
        "--pedscan BIN scans: the pedscan binary (default: $PEDSCAN, this checkout's build, PATH)",
        "--per-point {knn,cell} scans: a point's label from RangeNet++'s kNN vote or its cell's (default knn)",
        "--knn K,SEARCH,SIGMA,CUTOFF_M scans: the kNN vote's neighbours, window, Gaussian sigma (cells) and "
        "range cutoff (default 5,5,1,1)",
        "--device DEVICE auto | cpu | cuda (default auto)",
        "--export-onnx FILE write the network as ONNX",
        "--onnx-grid HxW grid of the ONNX check (default 32x1024)",
    ):
        assert want in text, (want, text)
    text = help_text(evaluate_main, capsys)
    for want in (
        "usage: python -m pedscan_data.evaluate",
        "Human IoU, precision, recall (and velocity EPE) of predictions against pedscan ground truth or "
        "SemanticKITTI's labeled scans.",
        "ground_truth pedscan output folder or sequence file; or labeled scans: a SemanticKITTI sequence folder "
        "(velodyne/, labels/) or dataset root (sequences/SS/labels/)",
        "predictions SemanticKITTI folder or HDF5 file(s); for scans, predict's folder (predictions/ or "
        "sequences/SS/predictions/)",
        "--json FILE also write the scores as JSON",
        "--from-frame K score frames K onwards of each sequence (an N-frame network's full windows: K = N-1)",
    ):
        assert want in text, (want, text)


class TracedOff(SequenceNet):
    """A network whose traced graph (what ONNX gets) adds `offset` to the logits that eager
    PyTorch does not: the export's check must see the difference."""

    offset = 0.0

    def forward(self, x):  # type: ignore[override]
        logits, velocity = super().forward(x)
        if torch.jit.is_tracing():
            logits = logits + self.offset
        return logits, velocity


def test_the_onnx_file_is_documented_and_refused_when_it_differs(tmp_path: Path) -> None:
    import onnxruntime as ort

    net = net_for(2, width=4, seed=1, intensity=True)
    path = tmp_path / "net.onnx"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # ONNX Runtime only warns of an unknown execution provider
        diff = pr.export_onnx(net, path, 8, 32, human_threshold=0.625)
    torch.manual_seed(123)  # the check's window comes from its own generator, not the global one
    assert pr.export_onnx(net, tmp_path / "again.onnx", 8, 32, human_threshold=0.625) == diff
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    assert [i.name for i in sess.get_inputs()] == ["input"]
    assert [o.name for o in sess.get_outputs()] == ["logits", "velocity"]
    assert sess.get_inputs()[0].shape == ["batch", 2, 3, 8, 32]
    assert [o.shape[0] for o in sess.get_outputs()] == ["batch", "batch"]
    assert sess.get_modelmeta().custom_metadata_map == {
        "human_threshold": "0.625", "frames": "2", "inputs": "range/10m, valid, intensity", "range_change": "false",
        "mirror": "false",
    }
    pr.export_onnx(net, tmp_path / "mirrored.onnx", 8, 32, human_threshold=0.625, mirror=True)
    meta = ort.InferenceSession(str(tmp_path / "mirrored.onnx"), providers=["CPUExecutionProvider"]).get_modelmeta()
    assert meta.custom_metadata_map["mirror"] == "true"
    # A traced graph 1e-3 off is refused at the default 1e-4 and leaves no file. The check is
    # seeded, so a probe gives the exact difference: a tolerance of exactly that keeps the file.
    off = TracedOff(NetConfig(frames=2, width=4))
    off.load_state_dict(net_for(2, width=4, seed=1).state_dict())
    off.eval().offset = 1e-3
    bad = tmp_path / "off.onnx"
    with pytest.raises(pr.PedscanError, match="ONNX Runtime differs from PyTorch by 0.001 "):
        pr.export_onnx(off, bad, 8, 32)
    assert not bad.exists() and not list(tmp_path.glob("*.tmp"))
    got = pr.export_onnx(off, bad, 8, 32, atol=pr.export_onnx(off, tmp_path / "probe.onnx", 8, 32, atol=1.0))
    assert got == pytest.approx(1e-3, rel=1e-3) and bad.exists()
    # Without a calibrated threshold the file says 0.5 (the softmax's even odds).
    probe = ort.InferenceSession(str(tmp_path / "probe.onnx"), providers=["CPUExecutionProvider"])
    assert probe.get_modelmeta().custom_metadata_map["human_threshold"] == "0.5"


def test_the_command_line_exports_onnx_alone_or_before_predicting(
    sample: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import onnxruntime as ort

    model = save_model(net_for(2, width=4, seed=1), tmp_path / "net.pt", threshold=0.7)
    onnx_file = tmp_path / "alone.onnx"
    assert pr.main([str(model), "--export-onnx", str(onnx_file), "--onnx-grid", "8X32"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"wrote {onnx_file} (ONNX Runtime against PyTorch: max difference "), out
    sess = ort.InferenceSession(str(onnx_file), providers=["CPUExecutionProvider"])
    assert sess.get_inputs()[0].shape == ["batch", 2, 2, 8, 32]
    assert sess.get_modelmeta().custom_metadata_map["human_threshold"] == "0.7"
    # Then predicting, on the device asked for.
    asked: list[str] = []
    real = pr.pick_device
    monkeypatch.setattr(pr, "pick_device", lambda name: (asked.append(name), real(name))[1])
    both = tmp_path / "both.onnx"
    code = pr.main([str(model), str(sample), "--out", str(tmp_path / "p"), "--export-onnx", str(both),
                    "--onnx-grid", "8x32", "--device", "cpu"])
    out = capsys.readouterr().out
    assert code == 0 and both.is_file() and asked == ["cpu"], (code, asked)
    assert f"wrote {both} (" in out and f"wrote 2 sequences to {tmp_path / 'p'}; " in out, out
    # Neither data nor an export: the usage error.
    with pytest.raises(SystemExit) as e:
        pr.main([str(model)])
    assert e.value.code == 2 and "DATA and --out are needed to predict" in capsys.readouterr().err


def test_the_timing_leaves_out_each_sequences_warm_up_and_progress_goes_to_stderr(
    sample: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    real = pr.predict_sequence

    def timed(net, seq, dev, first=0, mirror=False):
        margin, velocity, ms = real(net, seq, dev, first=first, mirror=mirror)
        return margin, velocity, [100.0, 1.0, 2.0, 3.0][: len(ms)]

    monkeypatch.setattr(pr, "predict_sequence", timed)
    model = save_model(net_for(2, width=4, seed=1), tmp_path / "net.pt")
    capsys.readouterr()
    res = pr.predict(model, sample, tmp_path / "p", device="cpu")
    assert res == {"sequences": 2, "ms_per_frame_median": 2.0}
    out, err = capsys.readouterr()
    assert out == "" and err == "\r1/2 sequences, 2.0 ms per frame\r2/2 sequences, 2.0 ms per frame\n", repr(err)


def test_prediction_feeds_the_network_on_its_own_device_and_times_in_milliseconds(sample: Path) -> None:
    import time

    # On the meta device (no data, no GPU needed) every convolution's input must be there too;
    # the first copy back to the CPU then fails, as it must for a tensor without data.
    net = net_for(2, width=4, seed=1).to("meta")
    seen = watch_devices(net)
    seq = Sequence(sample / "seq_000000.h5")
    with pytest.raises(NotImplementedError, match="meta"):
        pr.predict_sequence(net, seq, torch.device("meta"))
    assert len(seen) > 5
    # The per-frame times are milliseconds of the same clock: together no more than the call
    # took, and most of it (the rest is reading the inputs).
    start = time.perf_counter()
    _, _, ms = pr.predict_sequence(net_for(2, width=4, seed=1), seq, "cpu")
    wall_ms = (time.perf_counter() - start) * 1e3
    assert len(ms) == seq.frames and 0.05 * wall_ms < sum(ms) <= wall_ms, (ms, wall_ms)


class Reduced:
    """Pickles as a call of `touch` on `path`: loading it with pickled code allowed runs it."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self):
        return (Path.touch, (self.path,))


def test_model_files_are_read_without_running_pickled_code(tmp_path: Path) -> None:
    from pedscan_data.netio import RunError, load_file

    marker = tmp_path / "ran"
    model = tmp_path / "evil.pt"
    torch.save({"format": MODEL_FORMAT, "net": {}, "payload": Reduced(marker)}, model)
    with pytest.raises(RunError, match=f"{model}: not a readable pedscan model or checkpoint"):
        load_file(model)
    assert not marker.exists()


def test_a_run_records_the_python_it_ran_on() -> None:
    env = environment("cpu")
    assert env["python"] == platform.python_version()
    assert env["device"] == "cpu" and env["torch"] == torch.__version__



def test_a_model_loads_onto_the_device_asked_for_and_figures_are_saved_at_80_dpi(tmp_path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.image
    import matplotlib.pyplot as plt

    from pedscan_data.netio import load_net, save_figure

    net, _ = load_net(save_model(net_for(2, width=4, seed=1), tmp_path / "net.pt"), "meta")
    assert {p.device.type for p in net.parameters()} == {"meta"} and not net.training
    save_figure(plt.figure(figsize=(2.0, 1.5)), tmp_path / "f.png")
    assert matplotlib.image.imread(tmp_path / "f.png").shape[:2] == (120, 160)
    assert [p.name for p in tmp_path.iterdir() if p.suffix == ".png"] == ["f.png"]
