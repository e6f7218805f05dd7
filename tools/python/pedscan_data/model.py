"""The paper's sequence network (Kim et al., IEEE Access 2020, Section IV and Fig. 5), in PyTorch.

Per frame, a **shared-weight encoder** turns the range image (H x W, the sensor's grid) into
features at a quarter of the columns and half of the rows; the N frames' features are
**concatenated along channels**; a **decoder** gives a 2-class softmax for the *last* frame's
human mask; a **velocity branch** takes the concatenated features and the segmentation
output through more convolutions to a linear per-beam velocity (m/s, sensor frame, the
stored ``/velocity``).

Inputs per beam (:func:`input_channels`): ``range / 10 m`` on returned beams and 0 elsewhere,
and a **validity channel** (1 returned, 0 no return), so a hole is never confused with a
near surface; with ``intensity`` also the return's intensity (0 on holes). With
``elevation_deg`` (not in the paper) the encoder also gets each return's **height** relative to
the sensor, range x sin(its row's elevation) / 2 m, computed inside the network from the range
channel (the inputs stay the same; the ONNX file holds the elevations): a range image alone
says how far a surface is, not whether it stands on the road or hangs at a person's head.

Every 3x3 convolution pads **circularly along the columns** (azimuth wraps: column 0 and
W-1 are neighbours) and with zeros along the rows (the top and bottom beams are not).

What the paper's figure does not fix (channel widths, strides, the skips) is chosen here to
train on two CPU cores in hours (see :func:`describe`); the last frame's full- and
half-resolution encoder features skip to the decoder, so the mask keeps every column.

With ``range_change`` (not in the paper; off by default) the decoder also sees, at full resolution,
each beam's **range change**: the last frame's range minus each earlier frame's, where both
returned (:func:`range_change_channels`). The encoder's features are at a quarter of the columns
and the range scaled to 0-7, so a person's 0.14 m per frame towards the sensor is a change
of 0.014 in one input among thousands; given as a difference, a linear layer reads the
radial speed from it. And the velocity branch gets a **global view** (:class:`EgoMotion`):
the stored velocity is relative to the sensor (the paper's eq. 1, ``R^T (V_h - V_s)``), so
every beam's target holds the sensor's own velocity, one vector per frame that no
convolution's window sees whole; the range changes of the whole scan, pooled with each
column's direction and projected back onto each beam's, give it.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

#: Range scale of the input channel, metres (ranges of 0-70 m become 0-7).
RANGE_SCALE_M = 10.0

#: Range changes beyond this many metres (a beam that met another surface) are clipped.
CHANGE_CLIP_M = 3.0

#: Height scale of the height channel, metres.
HEIGHT_SCALE_M = 2.0


@dataclass(frozen=True)
class NetConfig:
    """What fixes the network's shape; stored in every run and model file."""

    frames: int = 16
    """N, the frames the network sees (the last one is labelled)"""
    intensity: bool = False
    """a third input channel: the return's intensity"""
    width: int = 16
    """channels of the encoder's first layer; the others are multiples of it"""
    range_change: bool = False
    """the decoder also sees each beam's range change against the earlier frames (N >= 2)"""
    elevation_deg: tuple[float, ...] = ()
    """the grid rows' elevations, top row first: the encoder also sees each return's height
    (range x sin(elevation)); empty: no height channel"""

    def __post_init__(self) -> None:
        if self.range_change and self.frames < 2:
            raise ValueError("range-change channels need at least 2 frames")
        # A model file's JSON gives a list.
        object.__setattr__(self, "elevation_deg", tuple(float(e) for e in self.elevation_deg))
        if not all(math.isfinite(e) and -90.0 <= e <= 90.0 for e in self.elevation_deg):
            raise ValueError("row elevations must be finite degrees within +-90")

    @property
    def in_channels(self) -> int:
        return 3 if self.intensity else 2

    @property
    def change_channels(self) -> int:
        return 2 * (self.frames - 1) if self.range_change else 0

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def input_channels(range_m: np.ndarray, intensity: np.ndarray | None = None) -> np.ndarray:
    """The network's input for frames ``range_m`` ([..., H, W], 0 = no return): f32 [..., C, H, W].

    Channels: range / 10 m on returned beams (0 on holes), validity (1 returned, 0 not), and
    intensity (0 on holes) when given. A NaN or negative range is a hole.
    """
    r = np.asarray(range_m, dtype=np.float32)
    valid = np.isfinite(r) & (r > 0)
    chans = [np.where(valid, r / RANGE_SCALE_M, 0.0), valid]
    if intensity is not None:
        i = np.asarray(intensity, dtype=np.float32)
        chans.append(np.where(valid & np.isfinite(i), i, 0.0))
    return np.stack(chans, axis=-3).astype(np.float32)


def range_change_channels(x: torch.Tensor) -> torch.Tensor:
    """[B, N, C, H, W] network inputs -> [B, 2 (N-1), H, W]: for each earlier frame i, the last
    frame's range minus frame i's in metres, clipped to +-CHANGE_CLIP_M, where both returned
    (0 elsewhere), then whether both returned (1 or 0)."""
    r = x[:, :, 0] * RANGE_SCALE_M
    v = x[:, :, 1]
    both = v[:, :-1] * v[:, -1:]
    diff = torch.clamp(r[:, -1:] - r[:, :-1], -CHANGE_CLIP_M, CHANGE_CLIP_M) * both
    return torch.cat([diff, both], dim=1)


class WrapConv(nn.Module):
    """A 3x3 convolution (+ ReLU unless ``relu=False``): circular along W, zeros along H."""

    def __init__(self, cin: int, cout: int, stride: tuple[int, int] = (1, 1), relu: bool = True) -> None:
        super().__init__()
        self.conv = nn.Conv2d(cin, cout, 3, stride=stride, padding=0)
        self.relu = relu

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # Slices and a concatenation: exported to ONNX as Slice + Concat, any opset.
        x = torch.cat([x[..., -1:], x, x[..., :1]], dim=-1)
        x = F.pad(x, (0, 0, 1, 1))
        x = self.conv(x)
        return F.relu(x) if self.relu else x


class Encoder(nn.Module):
    """Shared per frame: [B, C, H, W] -> full-res skip, half-column skip, features at H/2 x W/4."""

    def __init__(self, cfg: NetConfig) -> None:
        super().__init__()
        w = cfg.width
        self.e1 = WrapConv(cfg.in_channels + (1 if cfg.elevation_deg else 0), w)  # H x W
        self.e2 = WrapConv(w, w * 3 // 2, stride=(1, 2))  # H x W/2
        self.e3 = WrapConv(w * 3 // 2, 2 * w, stride=(2, 2))  # H/2 x W/4
        self.e4 = WrapConv(2 * w, 2 * w)
        self.channels = (w, w * 3 // 2, 2 * w)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        s1 = self.e1(x)
        s2 = self.e2(s1)
        f = self.e4(self.e3(s2))
        return s1, s2, f


def _up(x: torch.Tensor, factor: tuple[int, int]) -> torch.Tensor:
    return F.interpolate(x, scale_factor=factor, mode="nearest")


def column_azimuth(columns: int, device: Any = None) -> torch.Tensor:
    """Azimuth of each column's centre, radians: pi (1 - 2 (col + 0.5) / W) (pedscan's grid)."""
    col = torch.arange(columns, dtype=torch.float32, device=device)
    return math.pi * (1.0 - 2.0 * (col + 0.5) / columns)


def beam_to_sensor(local: torch.Tensor) -> torch.Tensor:
    """[B, 3, H, W] velocities in each column's horizontal frame (radial, tangential, up) ->
    the sensor frame (x, y, z): a fixed rotation by the column's azimuth, no weights."""
    az = column_azimuth(local.shape[-1], local.device)
    c, s = torch.cos(az), torch.sin(az)
    vr, vt, vz = local[:, 0], local[:, 1], local[:, 2]
    return torch.stack([vr * c - vt * s, vr * s + vt * c, vz], dim=1)


class EgoMotion(nn.Module):
    """The whole scan's range changes -> per-beam features of the sensor's own motion.

    Per beam, ``q = relu(1x1 conv(range-change channels))``; pooled over the returned beams, each
    of its channels gives a scalar ``mean(q)`` and a horizontal vector ``mean(q (cos a, sin a))``
    (a the column's azimuth: a static wall's range change is minus the sensor's displacement
    along the beam, so these moments are linear in the sensor's velocity); each vector is
    projected back onto every beam's horizontal frame (radial, tangential). Returns q and
    [B, 3 w, H, W]: the scalars, the radial and the tangential projections. A turn of the
    sensor (a roll of the columns) rolls the outputs and changes nothing else.
    """

    def __init__(self, cin: int, w: int) -> None:
        super().__init__()
        self.q = nn.Conv2d(cin, w, 1)

    def forward(self, change: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        q = F.relu(self.q(change))
        b, c, h, w = q.shape
        az = column_azimuth(w, q.device)
        cos, sin = torch.cos(az), torch.sin(az)
        n = torch.clamp(mask.sum(dim=(2, 3)), min=1.0)  # [B, 1]
        qm = q * mask
        mean = qm.sum(dim=(2, 3)) / n  # [B, C]
        vx = (qm * cos).sum(dim=(2, 3)) / n
        vy = (qm * sin).sum(dim=(2, 3)) / n
        radial = vx[:, :, None, None] * cos + vy[:, :, None, None] * sin  # [B, C, 1, W]
        tangential = vy[:, :, None, None] * cos - vx[:, :, None, None] * sin
        glob = torch.cat([mean[:, :, None, None].expand(b, c, 1, w), radial, tangential], dim=1)
        return q, glob.expand(b, 3 * c, h, w)


class Decoder(nn.Module):
    """The concatenated features of N frames and the last frame's skips -> logits and velocity.

    Segmentation (the paper's black ink): a 1x1 fusion of the N frames' features at
    H/2 x W/4, a context level at H/4 x W/8 added back, a 3x3 convolution, then up to
    H x W/2 and H x W, each time beside the last frame's encoder features of that resolution,
    and a 1x1 "Conv-2" with no activation (softmax).

    Velocity (the red ink): its own 1x1 fusion of the concatenated features beside the
    segmentation's features at H/2 x W/4, a 3x3 convolution, up to H x W, concatenated with
    the segmentation's last features and its softmax, then 1x1 convolutions to a linear
    3-vector per beam in the beam's horizontal frame (radial, tangential, up), turned into the
    sensor frame by the column's azimuth (:func:`beam_to_sensor`). A convolution does not know
    which azimuth its column has; in the beam's frame what it sees (range changing between
    frames, a shift across columns) is the same at every azimuth.
    """

    def __init__(self, cfg: NetConfig, enc_channels: tuple[int, int, int]) -> None:
        super().__init__()
        c1, c2, cf = enc_channels
        w = cfg.width
        fused = 3 * w
        self.fuse = nn.Conv2d(cfg.frames * cf, fused, 1)
        self.down = WrapConv(fused, fused, stride=(2, 2))
        self.context = WrapConv(fused, fused)
        self.d1 = WrapConv(fused, fused)
        self.d2 = WrapConv(fused + c2, w)
        m = w if cfg.range_change else 0
        self.change = WrapConv(cfg.change_channels, w) if cfg.range_change else None
        self.ego = EgoMotion(cfg.change_channels, w) if cfg.range_change else None
        self.d3 = WrapConv(w + c1 + m, w)
        self.seg = nn.Conv2d(w, 2, 1)
        self.vfuse = nn.Conv2d(cfg.frames * cf, fused, 1)
        self.v1 = WrapConv(2 * fused, 2 * w)
        self.v2 = nn.Conv2d(2 * w + w + 2 + 5 * m, w, 1)
        self.vel = nn.Conv2d(w, 3, 1)

    def forward(
        self, s1: torch.Tensor, s2: torch.Tensor, cat: torch.Tensor, change: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        if (change is None) != (self.change is None):
            raise ValueError("range-change channels are given to a network without them, or missing")
        mf: list[torch.Tensor] = []
        vf: list[torch.Tensor] = []
        if change is not None and self.change is not None and self.ego is not None:
            mf = [self.change(change)]
            # Beams that returned in the last frame and one earlier frame at least.
            q, glob = self.ego(change, change[:, change.shape[1] // 2 :].amax(dim=1, keepdim=True))
            vf = [*mf, q, glob]
        f = F.relu(self.fuse(cat))
        g1 = self.d1(f + _up(self.context(self.down(f)), (2, 2)))
        g = self.d2(torch.cat([_up(g1, (2, 2)), s2], dim=1))
        g = self.d3(torch.cat([_up(g, (1, 2)), s1, *mf], dim=1))
        logits = self.seg(g)
        v = self.v1(torch.cat([F.relu(self.vfuse(cat)), g1], dim=1))
        v = torch.cat([_up(v, (2, 4)), g, torch.softmax(logits, dim=1), *vf], dim=1)
        velocity = beam_to_sensor(self.vel(F.relu(self.v2(v))))
        return logits, velocity


class SequenceNet(nn.Module):
    """The whole network: ``forward(x)`` with x f32 [B, N, C, H, W] (see :func:`input_channels`)
    gives the last frame's logits [B, 2, H, W] (softmax: background, human) and velocity
    [B, 3, H, W] (m/s, sensor frame). H must be a multiple of 4 and W of 8.

    For streaming, :meth:`encode` runs the shared encoder on single frames and
    :meth:`decode` takes N frames' features, so a frame is encoded once and reused by the
    next N-1 frames (``pedscan_data.predict``).
    """

    def __init__(self, cfg: NetConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.encoder = Encoder(cfg)
        self.decoder = Decoder(cfg, self.encoder.channels)
        # Not in the state dict: the model file's configuration gives it.
        sin_el = np.sin(np.deg2rad(np.asarray(cfg.elevation_deg, dtype=np.float64)))
        self.register_buffer("height_per_range", torch.tensor(sin_el * RANGE_SCALE_M / HEIGHT_SCALE_M, dtype=torch.float32),
                             persistent=False)

    def encode(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """[B, C, H, W] -> (s1, s2, features) of each frame."""
        h, w = x.shape[-2:]
        if h % 4 or w % 8:
            raise ValueError(f"the grid must have a multiple of 4 rows and of 8 columns (got {h} x {w})")
        if self.cfg.elevation_deg:
            if h != len(self.cfg.elevation_deg):
                raise ValueError(f"the network's height channel is for {len(self.cfg.elevation_deg)} rows (got {h})")
            # Range channel (0 on holes) x sin(elevation): the height channel.
            x = torch.cat([x, x[:, :1] * self.height_per_range.view(1, 1, h, 1)], dim=1)
        return self.encoder(x)

    def decode(
        self, s1: torch.Tensor, s2: torch.Tensor, features: torch.Tensor, inputs: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The last frame's skips s1, s2 and features [B, N, Cf, h, w] of N frames, oldest first;
        with ``range_change``, also the N frames' inputs [B, N, C, H, W] (for
        :func:`range_change_channels`)."""
        b, n, c, h, w = features.shape
        if self.cfg.range_change and inputs is None:
            raise ValueError("a network with range-change channels decodes from the N frames' inputs too")
        change = range_change_channels(inputs) if self.cfg.range_change else None
        return self.decoder(s1, s2, features.reshape(b, n * c, h, w), change)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        b, n, c, h, w = x.shape
        if n != self.cfg.frames or c != self.cfg.in_channels:
            raise ValueError(
                f"input has {n} frames of {c} channels, the network takes {self.cfg.frames} of {self.cfg.in_channels}"
            )
        s1, s2, f = self.encode(x.reshape(b * n, c, h, w))
        last = torch.arange(b, device=x.device) * n + (n - 1)
        return self.decode(s1[last], s2[last], f.reshape(b, n, *f.shape[1:]), x)


def count_parameters(net: nn.Module) -> int:
    return sum(p.numel() for p in net.parameters())


def multiply_adds(net: SequenceNet, rows: int, columns: int) -> dict[str, int]:
    """Multiply-adds of the encoder (one frame) and the decoder (one window), from the layers."""
    counts = {"encoder": 0, "decoder": 0}
    hooks = []

    def hook(name: str):
        def f(mod: nn.Conv2d, inp: tuple[torch.Tensor], out: torch.Tensor) -> None:
            k = mod.kernel_size[0] * mod.kernel_size[1] * (mod.in_channels // mod.groups)
            counts[name] += int(out.numel() * k)

        return f

    for name, part in (("encoder", net.encoder), ("decoder", net.decoder)):
        for m in part.modules():
            if isinstance(m, nn.Conv2d):
                hooks.append(m.register_forward_hook(hook(name)))
    try:
        with torch.no_grad():
            x = torch.zeros(1, net.cfg.in_channels, rows, columns, device=next(net.parameters()).device)
            s1, s2, f = net.encode(x)
            enc = counts["encoder"]
            net.decode(s1, s2, f.unsqueeze(1).expand(1, net.cfg.frames, *f.shape[1:]),
                       x.unsqueeze(1).expand(1, net.cfg.frames, *x.shape[1:]))
    finally:
        for h in hooks:
            h.remove()
    return {"encoder_per_frame": enc, "decoder_per_window": counts["decoder"]}


def describe(net: SequenceNet, rows: int = 32, columns: int = 1024) -> str:
    """Parameters and multiply-adds per frame at a grid size (the README's table)."""
    m = multiply_adds(net, rows, columns)
    streaming = m["encoder_per_frame"] + m["decoder_per_window"]
    return (
        f"N={net.cfg.frames} width={net.cfg.width} inputs={net.cfg.in_channels}"
        f"{' range-change' if net.cfg.range_change else ''}: "
        f"{count_parameters(net):,} parameters; at {rows}x{columns}: encoder "
        f"{m['encoder_per_frame'] / 1e6:.1f} M multiply-adds per frame, decoder "
        f"{m['decoder_per_window'] / 1e6:.1f} M per window; streaming "
        f"{streaming / 1e6:.1f} M per frame, training {(net.cfg.frames * m['encoder_per_frame'] + m['decoder_per_window']) / 1e6:.1f} M per window (forward)"
    )
