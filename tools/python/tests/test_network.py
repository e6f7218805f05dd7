"""The paper's network: shapes, the azimuth wrap, the loss, streaming, ONNX parity."""

from __future__ import annotations

import json

from pathlib import Path

import numpy as np
import pytest
import torch

from conftest import ROOT, net_for, watch_devices
from pedscan_data.model import NetConfig, SequenceNet, WrapConv, count_parameters, describe, input_channels
from pedscan_data.reader import Sequence
from pedscan_data.train import paper_loss


@pytest.mark.parametrize("frames,change", [(1, False), (2, False), (16, False), (2, True), (16, True)])
def test_shapes(frames: int, change: bool) -> None:
    net = net_for(frames, range_change=change)
    x = torch.rand(2, frames, 2, 16, 64)
    logits, velocity = net(x)
    assert logits.shape == (2, 2, 16, 64)
    assert velocity.shape == (2, 3, 16, 64)
    with pytest.raises(ValueError, match="frames"):
        net(torch.rand(1, frames + 1, 2, 16, 64))
    with pytest.raises(ValueError, match="multiple of 4 rows and of 8 columns"):
        net(torch.rand(1, frames, 2, 16, 60))


def test_wrap_conv_pads_circularly_along_columns_and_with_zeros_along_rows() -> None:
    conv = WrapConv(1, 1, relu=False)
    with torch.no_grad():
        conv.conv.weight.zero_()
        conv.conv.bias.zero_()
        conv.conv.weight[0, 0, 1, 0] = 1.0  # output(h, w) = input(h, w-1)
    x = torch.zeros(1, 1, 4, 8)
    x[0, 0, 2, 7] = 1.0
    y = conv(x)
    assert y[0, 0, 2, 0] == 1.0, "column 0 must see column W-1"
    assert float(y.detach().abs().sum()) == 1.0
    with torch.no_grad():
        conv.conv.weight.zero_()
        conv.conv.weight[0, 0, 0, 1] = 1.0  # output(h, w) = input(h-1, w)
    x = torch.zeros(1, 1, 4, 8)
    x[0, 0, 3, 5] = 1.0
    assert float(conv(x).detach().abs().sum()) == 0.0, "the last row must not wrap to the first"


@pytest.mark.parametrize("frames,change", [(1, False), (2, False), (16, False), (2, True), (16, True)])
def test_the_network_commutes_with_a_turn_of_the_sensor(frames: int, change: bool) -> None:
    """Rolling every input frame by 8 columns (a multiple of the strides) turns the scene by
    delta = 2 pi 8 / W: the mask rolls by 8 columns, and the velocities roll and turn by
    -delta about z (they are in the sensor frame). True only if every layer wraps; zero padding
    at the seam, or a velocity head blind to the column's azimuth, breaks it."""
    net = net_for(frames, range_change=change)
    w = 32
    x = torch.rand(1, frames, 2, 8, w)
    with torch.no_grad():
        logits, vel = net(x)
        logits_r, vel_r = net(torch.roll(x, 8, dims=-1))
    torch.testing.assert_close(torch.roll(logits, 8, dims=-1), logits_r, rtol=1e-5, atol=1e-5)
    d = -2 * np.pi * 8 / w
    v = torch.roll(vel, 8, dims=-1)
    turned = torch.stack([v[:, 0] * np.cos(d) - v[:, 1] * np.sin(d), v[:, 0] * np.sin(d) + v[:, 1] * np.cos(d), v[:, 2]], 1)
    torch.testing.assert_close(turned, vel_r, rtol=1e-4, atol=1e-5)
    assert float(vel.abs().max()) > 1e-3  # not vacuous


def test_range_change_channels_where_both_frames_returned() -> None:
    from pedscan_data.model import CHANGE_CLIP_M, range_change_channels

    r = np.zeros((3, 1, 8), dtype=np.float32)  # 3 frames, one row of 8 beams
    r[:, 0, 0] = [10.0, 10.5, 11.0]  # receding at 0.5 m a frame
    r[:, 0, 1] = [0.0, 4.0, 4.2]  # no return in frame 0
    r[:, 0, 2] = [5.0, 5.0, 0.0]  # no return in the last frame
    r[:, 0, 3] = [2.0, 30.0, 30.0]  # met another surface: clipped
    m = range_change_channels(torch.from_numpy(input_channels(r)).unsqueeze(0))[0, :, 0]
    assert m.shape == (4, 8)  # 2 (N-1) channels: two range changes, then two validities
    np.testing.assert_allclose(m[0, :4].numpy(), [1.0, 0.0, 0.0, CHANGE_CLIP_M], atol=1e-5)
    np.testing.assert_allclose(m[1, :4].numpy(), [0.5, 0.2, 0.0, 0.0], atol=1e-5)
    np.testing.assert_array_equal(m[2, :4].numpy(), [1, 0, 0, 1])
    np.testing.assert_array_equal(m[3, :4].numpy(), [1, 1, 0, 1])
    assert float(m[:, 4:].abs().sum()) == 0.0  # no returns anywhere else
    with pytest.raises(ValueError, match="at least 2 frames"):
        NetConfig(frames=1, range_change=True)
    # The option adds one layer and leaves every other name as it was (older model files load).
    a, b = net_for(4, range_change=True), net_for(4)
    assert set(a.state_dict()) - set(b.state_dict()) == {
        "decoder.change.conv.weight", "decoder.change.conv.bias", "decoder.ego.q.weight", "decoder.ego.q.bias"}
    assert set(b.state_dict()) <= set(a.state_dict())


def test_the_velocity_branch_sees_the_whole_scans_motion_only_with_range_change_channels() -> None:
    """The sensor's own velocity is in every beam's target and shows in range changes all
    round the scan: with range-change channels, range changes half a scan away move the velocity of
    column 0; without them, column 0 sees only its convolutions' window (and its mask never
    hears of it either way: the global view feeds the velocity branch alone)."""
    w = 512
    r = np.full((4, 8, w), 10.0, dtype=np.float32)
    x = torch.from_numpy(input_channels(r)).unsqueeze(0)
    r[:3, :, 200:300] -= 0.3  # the far side approached over the window
    y = torch.from_numpy(input_channels(r)).unsqueeze(0)
    for change in (False, True):
        net = net_for(4, range_change=change)
        with torch.no_grad():
            (lx, vx), (ly, vy) = net(x), net(y)
        dv = float((vy - vx)[..., :8].abs().max())
        assert (dv > 1e-4) == change, (change, dv)
        assert float((ly - lx)[..., :8].abs().max()) == 0.0


def test_velocity_head_turns_the_beam_frame_by_the_column_azimuth() -> None:
    from pedscan_data.model import beam_to_sensor, column_azimuth

    az = column_azimuth(8)
    # pedscan's grid: column 0 looks just left of straight back (+180 deg), W/2 just right of ahead.
    assert float(az[0]) == pytest.approx(np.pi * (1 - 1 / 8))
    assert float(az[4]) == pytest.approx(-np.pi / 8)
    local = torch.zeros(1, 3, 1, 8)
    local[0, 0] = 1.0  # 1 m/s away from the sensor along each column
    v = beam_to_sensor(local)[0, :, 0]
    np.testing.assert_allclose(v[0].numpy(), np.cos(az.numpy()), atol=1e-6)
    np.testing.assert_allclose(v[1].numpy(), np.sin(az.numpy()), atol=1e-6)


def test_input_channels_mark_holes_with_a_validity_channel() -> None:
    r = np.array([[0.0, 5.0], [np.nan, 25.0]], dtype=np.float32)
    x = input_channels(r)
    assert x.shape == (2, 2, 2)
    np.testing.assert_allclose(x[0], [[0.0, 0.5], [0.0, 2.5]])
    np.testing.assert_array_equal(x[1], [[0, 1], [0, 1]])
    xi = input_channels(r, np.array([[9.0, 0.3], [7.0, 0.8]], dtype=np.float32))
    np.testing.assert_allclose(xi[2], [[0.0, 0.3], [0.0, 0.8]])


def test_paper_loss_counts_returned_beams_only_and_matches_a_hand_count() -> None:
    torch.manual_seed(1)
    h, w = 4, 8
    logits = torch.randn(1, 2, h, w)
    velocity = torch.randn(1, 3, h, w)
    v_true = torch.randn(1, 3, h, w)
    label = torch.zeros(1, h, w, dtype=torch.int64)
    label[0, 1, 2:5] = 1
    valid = torch.ones(1, h, w, dtype=torch.bool)
    valid[0, 3, :] = False
    valid[0, 1, 4] = False  # one human beam without a return
    loss, terms = paper_loss(logits, velocity, label, v_true, valid)

    # By hand, beam by beam.
    lp = torch.log_softmax(logits, dim=1)[0]
    n_valid = int(valid.sum())
    n_human = int(((label == 1) & valid).sum())
    cw = (n_valid - n_human) / n_human
    ce = se_bg = se_h = 0.0
    for i in range(h):
        for j in range(w):
            if not valid[0, i, j]:
                continue
            k = int(label[0, i, j])
            ce += (cw if k == 1 else 1.0) * -float(lp[k, i, j])
            se = float((velocity[0, :, i, j] - v_true[0, :, i, j]).square().mean())
            if k == 1:
                se_h += se
            else:
                se_bg += se
    expected = 10_000 * ce / n_valid + se_bg / n_valid + 1001 * se_h / n_valid
    assert float(loss) == pytest.approx(expected, rel=1e-5)
    assert set(terms) == {"ce", "mse_bg", "mse_human"}
    assert terms["ce"] == pytest.approx(ce / n_valid, rel=1e-5)
    assert terms["mse_bg"] == pytest.approx(se_bg / n_valid, rel=1e-5)
    assert terms["mse_human"] == pytest.approx(se_h / n_valid, rel=1e-5)

    # Anything on the no-return beams changes nothing.
    logits2, velocity2, label2 = logits.clone(), velocity.clone(), label.clone()
    logits2[0][:, ~valid[0]] = 50.0
    velocity2[0][:, ~valid[0]] = -30.0
    label2[0][~valid[0]] = 1
    loss2, _ = paper_loss(logits2, velocity2, label2, v_true, valid)
    assert float(loss2) == pytest.approx(float(loss), rel=1e-6)


def test_paper_loss_weights_human_beams_by_the_frames_class_ratio() -> None:
    h, w = 2, 4
    logits = torch.zeros(1, 2, h, w)  # cross-entropy log 2 everywhere
    label = torch.zeros(1, h, w, dtype=torch.int64)
    label[0, 0, 0] = 1
    valid = torch.ones(1, h, w, dtype=torch.bool)
    v = torch.zeros(1, 3, h, w)
    loss, terms = paper_loss(logits, v, label, v, valid)
    # 7 background beams of weight 1 and 1 human beam of weight 7: 14 log 2 over 8 beams.
    assert terms["ce"] == pytest.approx(14 * np.log(2) / 8, rel=1e-6)
    no_human = torch.zeros_like(label)
    _, t2 = paper_loss(logits, v, no_human, v, valid)
    assert t2["ce"] == pytest.approx(np.log(2), rel=1e-6)
    # The weight to a power: sqrt(7) with 0.5, every beam alike with 0.
    for power, human_weight in [(0.5, np.sqrt(7)), (0.0, 1.0)]:
        _, t3 = paper_loss(logits, v, label, v, valid, class_weight_power=power)
        assert t3["ce"] == pytest.approx((7 + human_weight) * np.log(2) / 8, rel=1e-6)


@pytest.mark.parametrize("n,change", [(2, False), (3, True)])
def test_streaming_prediction_equals_whole_windows(sample: Path, n: int, change: bool) -> None:
    from pedscan_data.predict import predict_sequence, sequence_inputs

    net = net_for(n, range_change=change)
    seq = Sequence(sample / "seq_000000.h5")
    margin, velocity, _ = predict_sequence(net, seq, "cpu", chunk=3)
    x = torch.from_numpy(sequence_inputs(seq, False))
    with torch.no_grad():
        for t in range(seq.frames):
            idx = [max(k, 0) for k in range(t - n + 1, t + 1)]  # frame 0 in place of missing ones
            logits, vel = net(x[idx].unsqueeze(0))
            np.testing.assert_allclose(margin[t], (logits[0, 1] - logits[0, 0]).numpy(), rtol=1e-4, atol=1e-4)
            np.testing.assert_allclose(velocity[t], vel[0].permute(1, 2, 0).numpy(), rtol=1e-4, atol=1e-5)


def test_parameters_are_counted_and_fit_a_small_file() -> None:
    net = SequenceNet(NetConfig(frames=16))
    assert 50_000 < count_parameters(net) < 500_000  # about 0.5 MB of f32


def test_the_cost_is_counted_on_the_networks_own_device() -> None:
    """describe() runs the network once; on a network moved off the CPU (a GPU run) its probe
    input must follow it (the meta device stands in for CUDA; every convolution checks that its
    input lies where its weights do, as CUDA's would)."""
    net = SequenceNet(NetConfig(frames=2, width=4)).to("meta")
    seen = watch_devices(net)
    assert "multiply-adds per frame" in describe(net, 8, 64)
    assert len(seen) > 5


@pytest.mark.parametrize("change", [False, True])
def test_onnx_export_matches_pytorch(tmp_path: Path, change: bool) -> None:
    import onnxruntime as ort

    from pedscan_data.predict import export_onnx

    net = net_for(2, intensity=True, range_change=change)
    diff = export_onnx(net, tmp_path / "net.onnx", 16, 64)
    assert diff <= 1e-4
    # Independently of the export's own check: a second input through both.
    x = torch.rand(3, 2, 3, 16, 64)
    with torch.no_grad():
        ref = [o.numpy() for o in net(x)]
    out = ort.InferenceSession(str(tmp_path / "net.onnx"), providers=["CPUExecutionProvider"]).run(
        None, {"input": x.numpy()}
    )
    for a, b in zip(ref, out):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-4)
    assert not list(tmp_path.glob("*.tmp"))


def test_the_height_channel_is_range_times_the_rows_sine_and_travels_with_the_model(tmp_path: Path) -> None:
    """A network with ``elevation_deg`` sees each return's height: its first layer is fed the
    range channel times sin(elevation) / 2 m as one more channel, which the model file and the
    ONNX file both carry; a grid of other rows is refused."""
    import onnxruntime as ort

    from conftest import save_model
    from pedscan_data.model import HEIGHT_SCALE_M, RANGE_SCALE_M
    from pedscan_data.netio import load_net
    from pedscan_data.predict import export_onnx

    el = tuple(np.linspace(2.0, -24.9, 16))
    net = net_for(1, elevation_deg=el)
    assert net.encoder.e1.conv.in_channels == 3 and not any("height" in k for k in net.state_dict())
    fed = []
    net.encoder.e1.register_forward_hook(lambda m, inp, out: fed.append(inp[0]))
    r = torch.rand(1, 16, 64) * 30.0
    x = torch.from_numpy(input_channels(r.numpy()))[:, None]
    with torch.no_grad():
        net(x)
    expected = x[0, 0, 0] * RANGE_SCALE_M * torch.sin(torch.deg2rad(torch.tensor(el)))[:, None] / HEIGHT_SCALE_M
    torch.testing.assert_close(fed[0][0, 2], expected.float(), rtol=1e-5, atol=1e-6)
    # The same weights on other elevations answer otherwise: the channel is used.
    other = SequenceNet(NetConfig(frames=1, width=8, elevation_deg=tuple(e + 5.0 for e in el))).eval()
    other.load_state_dict(net.state_dict())
    with torch.no_grad():
        assert not torch.allclose(net(x)[0], other(x)[0])
    # Through the model file and ONNX.
    back, _ = load_net(save_model(net, tmp_path / "h.pt"), torch.device("cpu"))
    assert back.cfg == net.cfg
    with torch.no_grad():
        torch.testing.assert_close(back(x)[0], net(x)[0])
    assert export_onnx(net, tmp_path / "h.onnx", 16, 64) <= 1e-4
    out = ort.InferenceSession(str(tmp_path / "h.onnx"), providers=["CPUExecutionProvider"]).run(None, {"input": x.numpy()})
    np.testing.assert_allclose(out[0], net(x)[0].detach().numpy(), rtol=1e-4, atol=1e-4)
    with pytest.raises(ValueError, match="height channel is for 16 rows"):
        net(torch.zeros(1, 1, 2, 20, 64))
    with pytest.raises(ValueError, match="elevations"):
        NetConfig(frames=1, elevation_deg=(float("nan"),))


def test_the_calibrated_cut_is_the_best_of_every_cut() -> None:
    from pedscan_data.train import best_cut

    rng = np.random.default_rng(5)
    human = rng.random(4000) < 0.05
    margin = np.round(rng.normal(0, 1, 4000) + 2.5 * human, 1)  # ties on purpose
    cut, iou = best_cut(margin, human)
    candidates = np.unique(margin)
    brute = max(np.sum(human & (margin > c)) / np.sum(human | (margin > c)) for c in np.r_[candidates, candidates[0] - 1])
    assert iou == pytest.approx(brute)
    called = margin > cut
    assert iou == pytest.approx(np.sum(human & called) / np.sum(human | called))
    assert iou > np.sum(human & (margin > 0)) / np.sum(human | (margin > 0))  # better than the argmax here


def onnx_matches(net: SequenceNet, obj: dict, onnx: Path, rows: int, columns: int, far_m: float) -> None:
    """The shipped ONNX twin of a model file: its threshold, and its outputs within 1e-4 of
    PyTorch's on a random window of the grid (a tenth of the beams holes)."""
    import onnxruntime as ort

    sess = ort.InferenceSession(str(onnx), providers=["CPUExecutionProvider"])
    meta = sess.get_modelmeta().custom_metadata_map
    assert float(meta["human_threshold"]) == obj["human_threshold"]
    assert meta.get("mirror", "false") == str(bool(obj.get("mirror", False))).lower()  # what the threshold is for
    grow = obj.get("grow")  # and the region growing it is for
    assert (float(meta["grow_margin"]), float(meta["grow_step_m"])) == (grow["margin"], grow["step_m"]) if grow else "grow_margin" not in meta
    rng = np.random.default_rng(0)
    r = rng.uniform(0.5, far_m, (net.cfg.frames, rows, columns)).astype(np.float32)
    r[rng.random(r.shape) < 0.1] = 0
    x = torch.from_numpy(input_channels(r)).unsqueeze(0)
    with torch.no_grad():
        ref = [o.numpy() for o in net(x)]
    for a, b in zip(ref, sess.run(None, {"input": x.numpy()})):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("name", ["frames1", "frames16"])
def test_the_shipped_networks_load_predict_and_match_their_onnx(name: str, sample: Path, tmp_path: Path) -> None:
    from pedscan_data.netio import load_net
    from pedscan_data.predict import main as predict_main

    models = ROOT / "data" / "models"
    net, obj = load_net(models / f"{name}.pt")
    assert net.cfg.frames == int(name[len("frames"):]) and 0.5 < obj["human_threshold"] < 1
    onnx_matches(net, obj, models / f"{name}.onnx", 32, 1024, 40.0)
    # Out of the box on a pedscan output of another sensor (16 x 512).
    assert predict_main([str(models / f"{name}.pt"), str(sample), "--out", str(tmp_path / "p")]) == 0
    assert sorted(p.name for p in (tmp_path / "p").iterdir()) == sorted(p.name for p in sample.glob("seq_*.h5"))


@pytest.mark.parametrize("change", [False, True])
def test_multiply_adds_and_the_description_match_torchs_own_count(change: bool) -> None:
    """PyTorch's FLOP counter (2 per multiply-add) over one frame's encoding and over a whole
    window's forward pass (N encodings and the decoder) against the layers' own count."""
    from torch.utils.flop_counter import FlopCounterMode

    from pedscan_data.model import multiply_adds

    net = net_for(2, range_change=change)
    m = multiply_adds(net, 8, 64)

    def flops(run) -> int:
        with torch.no_grad(), FlopCounterMode(display=False) as fc:
            run()
        return sum(fc.get_flop_counts()["Global"].values())

    x = torch.rand(1, 2, net.cfg.in_channels, 8, 64)
    assert 2 * m["encoder_per_frame"] == flops(lambda: net.encode(x[:, 0]))
    assert 2 * (2 * m["encoder_per_frame"] + m["decoder_per_window"]) == flops(lambda: net(x))
    # The description, at the grid given and at the HDL-32E's by default.
    enc, dec = m["encoder_per_frame"], m["decoder_per_window"]
    assert describe(net, 8, 64) == (
        f"N=2 width=8 inputs=2{' range-change' if change else ''}: {count_parameters(net):,} parameters; at 8x64: "
        f"encoder {enc / 1e6:.1f} M multiply-adds per frame, decoder {dec / 1e6:.1f} M per window; streaming "
        f"{(enc + dec) / 1e6:.1f} M per frame, training {(2 * enc + dec) / 1e6:.1f} M per window (forward)"
    )
    full = multiply_adds(net, 32, 1024)
    assert describe(net).split(": ", 1)[1].startswith(f"{count_parameters(net):,} parameters; at 32x1024: encoder "
                                                       f"{full['encoder_per_frame'] / 1e6:.1f} M")


@pytest.mark.parametrize("frames,change", [(1, False), (3, False), (3, True)])
def test_each_window_of_a_batch_is_its_own(frames: int, change: bool) -> None:
    """A batch of three windows gives each the outputs it gets alone (nothing is pooled
    across windows: the ego-motion's whole-scan summary included)."""
    net = net_for(frames, range_change=change)
    torch.manual_seed(4)
    x = torch.from_numpy(input_channels(np.where(torch.rand(3, frames, 8, 64).numpy() < 0.1, 0.0, 40 * torch.rand(3, frames, 8, 64).numpy())))
    with torch.no_grad():
        together = net(x)
        for k in range(3):
            for a, b in zip(net(x[k : k + 1]), together):
                np.testing.assert_allclose(a[0].numpy(), b[k].numpy(), rtol=1e-5, atol=1e-5)


def test_the_ego_motion_pools_over_beams_that_returned_in_the_last_frame_and_an_earlier_one() -> None:
    net = net_for(3, range_change=True)
    seen = []
    net.decoder.ego.register_forward_pre_hook(lambda m, inp: seen.append(inp[1]))
    torch.manual_seed(5)
    r = 40 * torch.rand(2, 3, 8, 64)
    r[torch.rand(r.shape) < 0.3] = 0  # holes, different in every frame
    x = torch.from_numpy(input_channels(r.numpy()))
    with torch.no_grad():
        net(x)
    (mask,) = seen
    returned = r > 0
    want = returned[:, 2] & (returned[:, 0] | returned[:, 1])
    assert mask.shape == (2, 1, 8, 64)
    np.testing.assert_array_equal(mask[:, 0].numpy(), want.numpy().astype(np.float32))
    assert 0.3 < want.float().mean() < 0.9


def test_the_shipped_street_network_records_its_grid_data_and_licence_and_matches_its_onnx(tmp_path: Path) -> None:
    """data/models/hdl64e.pt: trained for the HDL-64E on pedscan data alone, it says so (its
    grid, its backgrounds and the licence they carry); its ONNX twin gives the same outputs on that grid;
    predict takes real-layout scans with it out of the box (no --sensor)."""
    from pedscan_data.netio import load_net
    from pedscan_data.predict import main as predict_main

    models = ROOT / "data" / "models"
    net, obj = load_net(models / "hdl64e.pt")
    sensor = obj["training"]["sensor"]
    assert sensor["name"] == "hdl64e" and len(sensor["elevation_deg"]) == 64 and sensor["columns"] == 2048
    assert 0 < obj["human_threshold"] < 1
    # pedscan data alone: the built-in street world, and pedscan people composited into
    # unlabeled KITTI scans, whose licence (CC BY-NC-SA) the network carries.
    backgrounds = obj["provenance"]["backgrounds"]
    assert backgrounds and all("street world" in b or "composited into the unlabeled KITTI" in b for b in backgrounds)
    recorded = any("KITTI" in b for b in backgrounds)
    assert obj["licence"].startswith("CC BY-NC-SA" if recorded else "CC0"), obj["licence"]
    assert obj["provenance"]["labeled_real_scans_used"].startswith("none")
    onnx_matches(net, obj, models / "hdl64e.onnx", 64, 2048, 60.0)
    # A scan folder in SemanticKITTI's layout: one label per point back.
    (tmp_path / "seq" / "velodyne").mkdir(parents=True)
    az = np.linspace(0, 2 * np.pi, 5000, endpoint=False)
    pts = np.stack([10 * np.cos(az), 10 * np.sin(az), np.full_like(az, -1.0), np.full_like(az, 0.3)], axis=1)
    pts.astype("<f4").tofile(tmp_path / "seq" / "velodyne" / "000000.bin")
    assert predict_main([str(models / "hdl64e.pt"), str(tmp_path / "seq"), "--out", str(tmp_path / "p")]) == 0
    labels = np.fromfile(tmp_path / "p" / "predictions" / "000000.label", "<u4")
    assert len(labels) == 5000 and set(np.unique(labels)) <= {0, 30}
    # Its threshold was chosen for mirrored prediction, which predict then makes by default.
    assert obj["mirror"] is True and "mirrored" in obj["provenance"]["prediction"]
    assert json.loads((tmp_path / "p" / "predict.json").read_text())["mirrored"] is True
    # It was chosen with region growing from confident beams, which predict then applies.
    assert obj["grow"]["step_m"] > 0 and obj["grow"]["margin"] < np.log(obj["human_threshold"] / (1 - obj["human_threshold"]))
    assert json.loads((tmp_path / "p" / "predict.json").read_text())["grow"] == obj["grow"]
    assert "grown" in obj["provenance"]["prediction"]
