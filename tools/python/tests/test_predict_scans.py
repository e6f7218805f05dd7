"""Prediction on real scans' layout, per point, as a user runs it: pedscan's own SemanticKITTI
export (each returned beam a point, with its label) projected back by ``pedscan project``
gets the predictions the network makes on the grid; the layouts, the files written, and bad
input refused with nothing written."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from conftest import SENSOR_TOML, generate_test16, net_for, save_model
from pedscan_data import predict as pr
from pedscan_data.evaluate import evaluate, evaluate_scans
from pedscan_data.reader import Sequence
from pedscan_data.scans import Knn, knn_labels, read_points


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two sequences of three frames on the test sensor, as HDF5 and as SemanticKITTI scans."""
    return generate_test16(
        tmp_path_factory.mktemp("exported"), "--sequences", "2", "--frames", "3", "--humans", "3..5", "--seed", "5",
        "--formats", "h5,semantickitti",
    )


def sensor_table(seq: Sequence) -> dict:
    """What a model file would carry to say its grid: the sequence's own beam table."""
    return {"name": seq.sensor, "elevation_deg": seq.elevation_deg.tolist(), "columns": seq.columns}


def grid_truth(exported: Path, net, cut: float) -> dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]]:
    """Per sequence folder name, per frame: the returned beams' margins (in the export's point
    order: row-major), the range image and the margin image, from the HDF5 sequence."""
    out = {}
    for h5 in sorted(exported.glob("seq_*.h5")):
        seq = Sequence(h5)
        margin, _, _ = pr.predict_sequence(net, seq, "cpu")
        frames = []
        for t in range(seq.frames):
            r = seq.read("range", t)
            frames.append((margin[t].ravel()[r.ravel() > 0], r, margin[t]))
        out[f"{seq.index:02d}"] = frames
    return out


def test_points_take_the_predictions_the_network_makes_on_the_grid(exported: Path, tmp_path: Path) -> None:
    """Cell by cell, every point's label is its beam's prediction on the pedscan sequence (bar
    margins within 1e-4 of the cut: the point's range is recomputed from x y z); with the kNN
    vote, RangeNet++'s clean-up of that grid; an N-frame network's frames are the scans in
    file order; the model file's sensor table gives the grid."""
    net = net_for(2, width=4, seed=1)
    seq0 = Sequence(exported / "seq_000000.h5")
    model = save_model(net, tmp_path / "net.pt", threshold=0.6)
    obj = torch.load(model, weights_only=True)
    obj["sensor"] = sensor_table(seq0)
    torch.save(obj, model)
    cut = math.log(0.6 / 0.4)
    truth = grid_truth(exported, net, cut)
    scans = exported / "semantickitti"
    cell, knn = tmp_path / "cell", tmp_path / "knn"
    rec = pr.predict_scans(model, scans, cell, knn=None, quiet=True)
    pr.predict_scans(model, scans, knn, quiet=True)
    assert (rec["per_point"], rec["rows"], rec["cols"], rec["sensor"]) == ("cell", 16, 512, "test16")
    assert [s["predictions"] for s in rec["sequences"]] == ["sequences/00/predictions", "sequences/01/predictions"]
    assert json.loads((cell / "predict.json").read_text()) == rec and rec["notes"] == []
    # --sensor wins over the model file's, and says so.
    other = pr.predict_scans(model, scans, tmp_path / "other", sensor="hdl32e", knn=None, quiet=True)
    assert other["notes"] == [f"--sensor hdl32e in place of the model file's sensor {obj['sensor']!r}"]
    assert (other["rows"], other["cols"]) == (32, 1024)
    checked = 0
    for ss, frames in truth.items():
        for t, (margin, r, margin_img) in enumerate(frames):
            got = np.fromfile(cell / "sequences" / ss / "predictions" / f"{t:06d}.label", dtype="<u4")
            assert got.size == margin.size
            clear = np.abs(margin - cut) > 1e-4
            np.testing.assert_array_equal(got[clear], np.where(margin[clear] > cut, 30, 0))
            checked += int(clear.sum())
            # kNN: the same vote on the sequence's own grid (each point in its beam's cell).
            pts = read_points(scans / "sequences" / ss / "velodyne" / f"{t:06d}.bin")
            cells = np.flatnonzero(r.ravel() > 0).astype(np.uint32)
            want = knn_labels(margin_img > cut, r, cells, np.linalg.norm(pts[:, :3], axis=1), Knn())
            got = np.fromfile(knn / "sequences" / ss / "predictions" / f"{t:06d}.label", dtype="<u4")
            assert np.count_nonzero(got != np.where(want, 30, 0)) <= np.count_nonzero(~clear)
    assert checked > 20000
    # --mirror: the points take the mirrored passes' mean, as the sequences get it.
    mirrored = pr.predict_scans(model, scans, tmp_path / "mirrored", knn=None, quiet=True, mirror=True)
    assert mirrored["mirrored"] is True and rec["mirrored"] is False
    seq1 = Sequence(exported / "seq_000001.h5")
    both, _, _ = pr.predict_sequence(net, seq1, "cpu", mirror=True)
    for t in range(seq1.frames):
        m = both[t].ravel()[seq1.read("range", t).ravel() > 0]
        got = np.fromfile(tmp_path / "mirrored" / "sequences" / "01" / "predictions" / f"{t:06d}.label", dtype="<u4")
        clear = np.abs(m - cut) > 1e-4
        np.testing.assert_array_equal(got[clear], np.where(m[clear] > cut, 30, 0))
        assert np.abs(m - truth["01"][t][0]).max() > 1e-4  # the mirrored pass changed the margins
    # The scores agree: per point on the export, per beam on the sequences' own predictions.
    pr.predict(model, exported, tmp_path / "h5", quiet=True)
    on_grid = evaluate(exported, tmp_path / "h5").as_dict()["overall"]
    on_points = evaluate_scans(scans, cell).as_dict()["overall"]
    assert on_points["person_points"] == on_grid["human_beams"]
    assert on_points["iou"] == pytest.approx(on_grid["iou"], abs=2e-3)


def test_a_sequence_folder_is_written_beside_what_is_there(exported: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    seq = tmp_path / "07"
    shutil.copytree(exported / "semantickitti/sequences/01", seq)
    model = save_model(net_for(1, width=4, seed=2), tmp_path / "net.pt")
    sensor = tmp_path / "sensor.toml"
    sensor.write_text(SENSOR_TOML)
    out = tmp_path / "pred"
    out.mkdir()
    (out / "mine.txt").write_text("kept")
    for _ in range(2):  # a second run replaces the first's predictions
        code = pr.main([str(model), str(seq), "--out", str(out), "--sensor", str(sensor), "--device", "cpu", "--per-point", "cell"])
        assert code == 0
    stdout = capsys.readouterr().out
    assert f"wrote 3 scans' predictions to {out} in " in stdout
    assert sorted(p.name for p in out.iterdir()) == ["mine.txt", "predict.json", "predictions"]
    assert sorted(p.name for p in (out / "predictions").iterdir()) == ["000000.label", "000001.label", "000002.label"]
    assert not list(tmp_path.glob(".pred.*"))
    rec = json.loads((out / "predict.json").read_text())
    (s,) = rec["sequences"]
    assert (s["scans"], s["points"], s["kept"], s["replaced"], s["outside_band"]) == (3, s["kept"], s["points"], 0, 0)
    assert (rec["frames_seen"], rec["full_window_from"], rec["knn"]) == (1, 0, None)
    # The predictions sit where evaluate looks for them.
    assert evaluate_scans(seq, out).as_dict()["scans"] == 3


def test_scans_projected_a_few_at_a_time_stream_as_one_sequence(exported: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A two-frame network over three scans projected two at a time: the second chunk's first
    scan is decoded with the first chunk's last, as when all are projected at once."""
    import pedscan_data.scans as sc

    net = net_for(2, width=4, seed=4)
    # The threshold at the median margin: about half of the points are called people.
    margin, _, _ = pr.predict_sequence(net, Sequence(exported / "seq_000000.h5"), "cpu")
    model = save_model(net, tmp_path / "net.pt", threshold=float(1 / (1 + np.exp(-np.median(margin)))))
    sensor = tmp_path / "sensor.toml"
    sensor.write_text(SENSOR_TOML)
    seq = exported / "semantickitti/sequences/00"
    pr.predict_scans(model, seq, tmp_path / "whole", str(sensor), knn=None, quiet=True)
    monkeypatch.setattr(sc, "CHUNK_SCANS", 2)
    calls: list[int] = []
    real = sc.run_project
    monkeypatch.setattr(sc, "run_project", lambda b, scans, *a: (calls.append(len(scans)), real(b, scans, *a))[1])
    pr.predict_scans(model, seq, tmp_path / "chunked", str(sensor), knn=None, quiet=True)
    assert calls == [2, 1]
    for t in range(3):
        name = f"predictions/{t:06d}.label"
        assert (tmp_path / "whole" / name).read_bytes() == (tmp_path / "chunked" / name).read_bytes(), t
    # Which the test can tell: the last scan alone (its window its own frame twice) differs.
    alone = tmp_path / "alone"
    (alone / "velodyne").mkdir(parents=True)
    shutil.copy(seq / "velodyne/000002.bin", alone / "velodyne")
    pr.predict_scans(model, alone, tmp_path / "alone-pred", str(sensor), knn=None, quiet=True)
    last = "predictions/000002.label"
    assert (tmp_path / "alone-pred" / last).read_bytes() != (tmp_path / "whole" / last).read_bytes()


def test_bad_input_exits_2_naming_the_file_and_writes_nothing(exported: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    seq = tmp_path / "seq"
    shutil.copytree(exported / "semantickitti/sequences/00", seq)
    sensor = tmp_path / "sensor.toml"
    sensor.write_text(SENSOR_TOML)
    model = save_model(net_for(1, width=4, seed=2), tmp_path / "net.pt")
    out = tmp_path / "pred"

    def fails(*args: str) -> str:
        code = pr.main([str(model), str(seq), "--out", str(out), "--device", "cpu", *args])
        err = capsys.readouterr().err
        assert code == 2 and not out.exists() and not list(tmp_path.glob(".pred.*")), (code, err)
        return err

    # The model file does not say its grid.
    assert f"{model}: the model file does not say which sensor's grid it was trained on; give --sensor" in fails()
    # A scan that is not whole points, a scan missing from the numbering.
    bad = seq / "velodyne/000001.bin"
    bad.write_bytes(bad.read_bytes()[:-3])
    (seq / "velodyne/000002.bin").rename(seq / "velodyne/000003.bin")
    err = fails("--sensor", str(sensor))
    assert f"{bad}: " in err and "not a whole number of 16-byte points" in err
    assert f"{seq / 'velodyne/000002.bin'}: missing (the scans run from 000000 to 000003)" in err
    shutil.rmtree(seq)
    shutil.copytree(exported / "semantickitti/sequences/00", seq)
    # A grid the network cannot take, a sensor project refuses, --format, units of intensity.
    odd = tmp_path / "odd.toml"
    odd.write_text('name = "odd"\nelevation_deg = [-10.0, -5.0, 0.0, 5.0, 10.0, 15.0]\ncolumns = 64\n')
    assert "--sensor odd: a 6 x 64 grid; the network takes a multiple of 4 rows and of 8 columns" in fails("--sensor", str(odd))
    assert "--sensor nosuch" in fails("--sensor", "nosuch")
    assert "--format h5: for pedscan data; scans are written per point" in fails("--sensor", str(sensor), "--format", "h5")
    assert "kNN search window 4: not an odd number of cells" in fails("--sensor", str(sensor), "--knn", "5,4,1,1")
    model = save_model(net_for(1, width=4, seed=2, intensity=True), tmp_path / "net.pt")
    obj = torch.load(model, weights_only=True)
    obj["intensity_units"] = "percent"
    torch.save(obj, model)
    assert f"{model}: a network trained on intensity in percent, the scans' intensity is remission" in fails("--sensor", str(sensor))
    # A pedscan build without `project`.
    old = tmp_path / "old-pedscan"
    old.write_text("#!/bin/sh\necho \"error: unrecognized subcommand 'project'\" >&2\nexit 2\n")
    old.chmod(0o755)
    assert f"{old}: a build without `pedscan project`" in fails("--sensor", str(sensor), "--pedscan", str(old))


def test_an_intensity_network_on_scans_is_noted_when_its_units_are_not_recorded(exported: Path, tmp_path: Path) -> None:
    model = save_model(net_for(2, width=4, seed=3, intensity=True), tmp_path / "net.pt")
    obj = torch.load(model, weights_only=True)
    obj["sensor"] = sensor_table(Sequence(exported / "seq_000001.h5"))
    torch.save(obj, model)
    rec = pr.predict_scans(model, exported / "semantickitti/sequences/01", tmp_path / "p", knn=None, quiet=True)
    assert rec["notes"] == [f"{model}: the model file does not say its intensity's units; the scans' are remission"]
    # The intensity reaches the network: the labels are the HDF5 sequence's, which has /intensity.
    net = net_for(2, width=4, seed=3, intensity=True)
    margin, _, _ = pr.predict_sequence(net, Sequence(exported / "seq_000001.h5"), "cpu")
    seq = Sequence(exported / "seq_000001.h5")
    for t in range(3):
        m = margin[t].ravel()[seq.read("range", t).ravel() > 0]
        got = np.fromfile(tmp_path / "p/predictions" / f"{t:06d}.label", dtype="<u4")
        clear = np.abs(m) > 1e-4
        np.testing.assert_array_equal(got[clear], np.where(m[clear] > 0, 30, 0))
