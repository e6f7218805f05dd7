#!/usr/bin/env python3
"""Writes the seed inputs of every fuzz target into fuzz/corpus/TARGET/seed-*.

Each seed is a small valid input of its reader, built the way pedscan's own tests build them
(src/input/**/tests, tests/it/real_inputs.rs), plus the bundled environment data/scene/hall.glb.
No inputs besides that file, no dependencies; the same bytes on every run.

    python3 fuzz/make_seeds.py
"""

import base64
import json
import math
import os
import shutil
import struct

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CORPUS = os.path.join(ROOT, "fuzz", "corpus")


def put(target, name, data):
    d = os.path.join(CORPUS, target)
    os.makedirs(d, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    with open(os.path.join(d, "seed-" + name), "wb") as f:
        f.write(data)


# --- Velodyne pcap -------------------------------------------------------------------------

HDL, VLP = 0x21, 0x22
STRONGEST, DUAL = 0x37, 0x39


def pcap_file(records, link=1, big=False, nanos=False):
    e = ">" if big else "<"
    out = struct.pack(e + "IHHiIII", 0xA1B23C4D if nanos else 0xA1B2C3D4, 2, 4, 0, 0, 65535, link)
    for k, frame in enumerate(records):
        sec, usec = divmod(k * 600, 1_000_000)
        out += struct.pack(e + "IIII", sec, usec * 1000 if nanos else usec, len(frame), len(frame))
        out += frame
    return out


def ipv4_udp(payload):
    udp = struct.pack(">HHHH", 2368, 2368, len(payload) + 8, 0) + payload
    ip = bytes([0x45, 0]) + struct.pack(">H", 20 + len(udp)) + bytes([0, 0, 0, 0, 64, 17, 0, 0])
    return ip + bytes([192, 168, 1, 201, 255, 255, 255, 255]) + udp


def ethernet(body, vlan=False):
    head = b"\xff" * 6 + bytes([0x60, 0x76, 0x88, 0x20, 0x12, 0x6E])
    if vlan:
        head += struct.pack(">HH", 0x8100, 7)
    return head + struct.pack(">H", 0x0800) + body


def sll(body):
    return struct.pack(">HHH", 0, 1, 6) + b"\x00" * 8 + struct.pack(">H", 0x0800) + body


def data_packet(product, mode, azimuths, dist):
    p = b""
    for b, az in enumerate(azimuths):
        p += b"\xff\xee" + struct.pack("<H", az)
        for ch in range(32):
            p += struct.pack("<HB", dist(b, ch), 100)
    return p + bytes([0x10, 0x20, 0x30, 0x00, mode, product])


def spin(product, mode, a0, step, packets):
    """Data packets of a sensor turning `step` (0.01 deg) per firing from azimuth `a0`; every
    return of the first four lasers at 5 m, the rest without return (small, sparse frames)."""
    per = 2 if mode == DUAL else 1
    out = []
    for k in range(packets):
        firing = lambda b: k * 12 // per + b // per
        az = [(a0 + step * firing(b)) % 36000 for b in range(12)]
        out.append(data_packet(product, mode, az, lambda b, ch: 2500 if ch < 4 else 0))
    return out


def pcap_seeds():
    # HDL-32E at 2 degrees per firing: 15 packets per turn; 33 packets cut two turns.
    put("pcap", "hdl32e-two-turns.pcap", pcap_file([ethernet(ipv4_udp(p)) for p in spin(HDL, STRONGEST, 17000, 200, 33)]))
    # VLP-16 dual return, big-endian nanosecond file, VLAN-tagged frames.
    put("pcap", "vlp16-dual-vlan.pcap",
        pcap_file([ethernet(ipv4_udp(p), vlan=True) for p in spin(VLP, DUAL, 17500, 200, 36)], big=True, nanos=True))
    # Linux cooked capture with a position packet (512 bytes) among a few data packets.
    recs = [sll(ipv4_udp(p)) for p in spin(HDL, STRONGEST, 0, 200, 3)]
    recs.insert(1, sll(ipv4_udp(b"\x00" * 512)))
    put("pcap", "sll-partial.pcap", pcap_file(recs, link=113))
    # Raw IPv4 link type.
    put("pcap", "raw-ipv4.pcap", pcap_file([ipv4_udp(p) for p in spin(VLP, STRONGEST, 35000, 200, 2)], link=101))


# --- PCD -----------------------------------------------------------------------------------

ID = "0 0 0 1 0 0 0"


def pcd_header(fields, size, ty, count, w, h, vp, data):
    return (f"# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\n"
            f"TYPE {ty}\nCOUNT {count}\nWIDTH {w}\nHEIGHT {h}\nVIEWPOINT {vp}\nPOINTS {w * h}\nDATA {data}\n")


def sample_points(n):
    return [(i * 0.5 + 1.0, -i * 0.25, math.sin(i * 0.1)) for i in range(n)]


def lzf_literals(data):
    out = b""
    for i in range(0, len(data), 32):
        chunk = data[i:i + 32]
        out += bytes([len(chunk) - 1]) + chunk
    return out


def pcd_seeds():
    pts = sample_points(12)
    s = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", len(pts) + 2, 1, ID, "ascii")
    s += "".join(f"{x} {y} {z}\n" for x, y, z in pts) + "nan nan nan\n0 0 0\n"
    put("pcd", "ascii.pcd", s)
    # binary with a ring field, an intensity and a padding field of COUNT 3.
    b = pcd_header("x y z intensity ring _", "4 4 4 4 2 1", "F F F F U U", "1 1 1 1 1 3", len(pts), 1, ID, "binary").encode()
    for i, (x, y, z) in enumerate(pts):
        b += struct.pack("<ffffH", x, y, z, 0.5, i % 32) + b"\x00\x00\x00"
    put("pcd", "binary-ring.pcd", b)
    # binary f64, organised 4 x 3, with a viewpoint.
    h = math.sqrt(0.5)
    b = pcd_header("x y z", "8 8 8", "F F F", "1 1 1", 4, 3, f"1 2 3 {h} 0 0 {h}", "binary").encode()
    for x, y, z in pts:
        b += struct.pack("<ddd", x, y, z)
    put("pcd", "binary-f64-viewpoint.pcd", b)
    # binary_compressed: the x and y columns and the first z as LZF literal runs, then the
    # other z values (all 2.0) as one overlapping back-reference 4 bytes back: control byte
    # 7 << 5 (long match), length byte (n - 2 - 7), distance byte (4 - 1).
    cols = b"".join(struct.pack("<f", p[c]) for c in range(2) for p in pts) + struct.pack("<f", 2.0)
    lzf = lzf_literals(cols) + bytes([7 << 5, (len(pts) - 1) * 4 - 2 - 7, 3])
    head = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", len(pts), 1, ID, "binary_compressed").encode()
    put("pcd", "binary-compressed.pcd", head + struct.pack("<II", len(lzf), len(pts) * 12) + lzf)


# --- KITTI .bin, times.txt, poses ----------------------------------------------------------

def pose_at(t):
    """The recording's arc in tests/it/real_inputs.rs: 1 m/s turning at 0.2 rad/s, 1.7 m up."""
    hd = 0.2 * t
    x, y = 5.0 * math.sin(hd), 5.0 * (1.0 - math.cos(hd))
    c, s = math.cos(hd), math.sin(hd)
    return [[c, -s, 0.0, x - 3.0], [s, c, 0.0, y - 2.0], [0.0, 0.0, 1.0, 1.7]]


def kitti_seeds():
    recs = []
    for i in range(48):
        az, el = i * 2 * math.pi / 48, math.radians(-10 + (i % 8) * 2.5)
        r = 5.0 + (i % 5)
        recs.append((r * math.cos(el) * math.cos(az), r * math.cos(el) * math.sin(az), r * math.sin(el), 0.5))
    recs.append((0.0, 0.0, 0.0, 0.0))
    recs.append((float("nan"), 1.0, 1.0, 0.0))
    put("kitti_bin", "frame.bin", b"".join(struct.pack("<ffff", *r) for r in recs))
    put("kitti_times", "times.txt", "".join(f"{k / 10:.6e}\n" for k in range(8)))
    put("kitti_times", "comments.txt", "# KITTI times\n0.0\n\n0.1036\n0.2073\n")
    put("poses_kitti", "poses.txt",
        "".join(" ".join(f"{v:.12e}" for row in pose_at(k / 10) for v in row) + "\n" for k in range(6)))
    put("poses_kitti", "identity.txt", "# KITTI\n1 0 0 0 0 1 0 0 0 0 1 0\n\n1 0 0 1 0 1 0 0 0 0 1 0\n")
    lines = []
    for k in range(6):
        t = k / 10
        hd = 0.2 * t
        m = pose_at(t)
        lines.append(f"{t:.6f} {m[0][3]:.6f} {m[1][3]:.6f} {m[2][3]:.6f} 0 0 {math.sin(hd / 2):.9f} {math.cos(hd / 2):.9f}\n")
    put("poses_tum", "trajectory.txt", "# timestamp tx ty tz qx qy qz qw\n" + "".join(lines))


# --- pedestrian tracks ---------------------------------------------------------------------

def track_seeds():
    put("tracks_eth", "obsmat.txt", "".join(
        f"   {f:.7e}   {i:.7e}   {x:.7e}   0.0000000e+00   {y:.7e}   {vx:.7e}   0.0000000e+00   {vy:.7e}\n"
        for f, i, x, y, vx, vy in [
            (780, 1, 8.4568443, 3.5880664, 1.6717144, 0.17629183), (780, 2, 1.0, 2.0, 0.0, 0.0),
            (790, 1, 9.1255301, 3.6585832, 1.6628772, 0.32672255), (800, 1, 9.787146, 3.8494445, 1.6833339, 0.37108399),
            (770, 1, 7.8, 3.5, 1.6, 0.2), (790, 2, 1.2, 2.1, 0.5, 0.25)]))
    put("tracks_eth4", "biwi.txt", "0\t1.0\t1.41\t-5.68\n0\t2.0\t0.51\t-6.94\n\n10 1.0  1.5 -5.0\n20.0\t1.0\t1.6\t-4.5\n10\t2.0\t0.6\t-6.9\n")
    put("tracks_atc", "atc.csv",
        "1351065600.025,9315700,-10000,2000,1650,1200,0.5,1.0\n"
        "1351065600.055,9315700,-9964,2019,1650,1200,0.5,1.1\n"
        "1351065600.085,9315700,-9928,2038,1650,1200,0.5,1.2\n"
        "1351065600.025,9315800,100,200,1600,0,0,\n"
        "1351065600.055,9315800,100,200,1600,0,0,\n")
    put("tracks_csv", "plain.csv", "# pedscan tracks\nt_s,id,x_m,y_m\n0.0,7,1,2\n0.5, 7, 2, 2\n1.0,7,2.5,3\n0.0,8,-1,0\n")
    put("tracks_csv", "heading.csv", "t_s,id,x_m,y_m,heading_rad\n0.0,1,0,0,3.0\n1.0,1,1,0,-3.0\n2.0,1,1,1,1.5\n")


# --- config and sensor TOML ----------------------------------------------------------------

def toml_seeds():
    put("config_toml", "config.toml", """seed = 4
sequences = 2
frames = 8
png = true
sensor = "vlp16"

[humans]
count = [2, 5]
models = ["humans/a.glb"]
motion = "full"
speed_mps = [0.8, 1.6]
walk = "goals"

[scene]
background = "scene/hall.glb"
floor_z_m = 0.0
sensor_height_m = 1.7
sensor_speed_mps = [0.3, 1.0]

[render]
backend = "raycast"
projection = "cube"
oversample = 2.0

[output]
compression = "deflate"
xyz = true
""")
    put("config_toml", "tracks.toml", """sensor = "my_sensor.toml"

[humans]
count = [0, 0]
tracks = "obsmat.txt"
tracks_format = "eth"
tracks_frame_period_s = 0.0666667
tracks_transform = { rotation_deg = 90.0, translation_m = [1.0, -2.0], scale = 1.0 }

[scene]
background = "velodyne"
poses = "poses.txt"
""")
    put("sensor_toml", "custom.toml", """name = "custom16"
elevation_deg = [15.0, 13.0, 11.0, 9.0, 7.0, 5.0, 3.0, 1.0, -1.0, -3.0, -5.0, -7.0, -9.0, -11.0, -13.0, -15.0]
columns = 1024
rate_hz = 10.0
min_range_m = 0.5
max_range_m = 100.0
""")
    put("sensor_toml", "one-row.toml", "elevation_deg = [-2.5]\ncolumns = 360\n")


# --- glTF: a tiny skinned, animated person and a small environment --------------------------

class Gltf:
    """Collects binary views and accessors of one buffer."""

    def __init__(self):
        self.bin = b""
        self.views = []
        self.accessors = []

    def add(self, data, comp, typ, count, minmax=None, target=None):
        while len(self.bin) % 4:
            self.bin += b"\x00"
        view = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)}
        if target:
            view["target"] = target
        self.bin += data
        self.views.append(view)
        acc = {"bufferView": len(self.views) - 1, "componentType": comp, "count": count, "type": typ}
        if minmax:
            acc["min"], acc["max"] = minmax
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def finish(self, doc):
        while len(self.bin) % 4:
            self.bin += b"\x00"
        doc["asset"] = {"version": "2.0", "generator": "pedscan fuzz seeds"}
        doc["bufferViews"], doc["accessors"] = self.views, self.accessors
        doc["buffers"] = [{"byteLength": len(self.bin)}]
        return doc

    def glb(self, doc):
        doc = self.finish(doc)
        js = json.dumps(doc, separators=(",", ":")).encode()
        js += b" " * (-len(js) % 4)
        body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(self.bin), 0x004E4942) + self.bin
        return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body

    def embedded(self, doc):
        doc = self.finish(doc)
        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(self.bin).decode()
        return json.dumps(doc, indent=1)


F32, U16, U8 = 5126, 5123, 5121


def box(lo, hi):
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = [(x, y, z) for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return v, tris


def mesh_accessors(g, verts, tris, skinned):
    pos = g.add(b"".join(struct.pack("<fff", *p) for p in verts), F32, "VEC3", len(verts),
                ([min(p[i] for p in verts) for i in range(3)], [max(p[i] for p in verts) for i in range(3)]), 34962)
    idx = g.add(b"".join(struct.pack("<HHH", *t) for t in tris), U16, "SCALAR", 3 * len(tris), target=34963)
    attrs = {"POSITION": pos}
    if skinned:
        # Lower half on joint 0 (hips), upper half on joint 1 (spine), blended in the middle.
        j = b"".join(struct.pack("<BBBB", 0, 1, 0, 0) for _ in verts)
        w = b"".join(struct.pack("<ffff", *((1.0, 0.0) if p[1] < 0.5 else (0.5, 0.5) if p[1] < 1.0 else (0.0, 1.0)), 0.0, 0.0)
                     for p in verts)
        attrs["JOINTS_0"] = g.add(j, U8, "VEC4", len(verts))
        attrs["WEIGHTS_0"] = g.add(w, F32, "VEC4", len(verts))
    return {"primitives": [{"attributes": attrs, "indices": idx, "mode": 4}]}


def human(embedded=False):
    """A 1.7 m person of two boxes on a two-joint skin with a one-second `walk` (rotation,
    translation and cubic-spline scale channels) and two levels of detail listed in extras."""
    g = Gltf()
    v0, t0 = box((-0.2, 0.0, -0.1), (0.2, 1.7, 0.1))
    v1, t1 = box((-0.2, 0.0, -0.1), (0.2, 1.7, 0.1))
    v0 += [(-0.05, 0.9, 0.1), (0.05, 0.9, 0.1), (0.0, 1.0, 0.15)]
    t0 += [(8, 9, 10)]
    meshes = [mesh_accessors(g, v0, t0, True), mesh_accessors(g, v1, t1, True)]
    ibm = g.add(b"".join(struct.pack("<16f", 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, -y, 0, 1) for y in (0.9, 1.2)),
                F32, "MAT4", 2)
    times = g.add(struct.pack("<3f", 0.0, 0.5, 1.0), F32, "SCALAR", 3, ([0.0], [1.0]))
    s, c = math.sin(0.1), math.cos(0.1)
    rot = g.add(struct.pack("<12f", 0, 0, 0, 1, s, 0, 0, c, 0, 0, 0, 1), F32, "VEC4", 3)
    tr = g.add(struct.pack("<9f", 0, 0.9, 0, 0, 0.92, 0, 0, 0.9, 0), F32, "VEC3", 3)
    sc = g.add(struct.pack("<27f", *([0, 0, 0, 1, 1, 1, 0, 0, 0] * 3)), F32, "VEC3", 9)
    doc = {
        "scene": 0,
        "scenes": [{"nodes": [0], "extras": {"pedscan": {
            "height_m": 1.7, "weight_kg": 60.0, "stride_length_m": 1.4, "cycle_s": 1.0,
            "lods": [{"mesh": 0, "error_m": 0.0}, {"mesh": 1, "error_m": 0.05}]}}}],
        "nodes": [
            {"name": "person", "children": [1, 3, 4]},
            {"name": "hips", "translation": [0, 0.9, 0], "children": [2]},
            {"name": "spine", "translation": [0, 0.3, 0], "rotation": [0, 0, 0, 1]},
            {"name": "lod0", "mesh": 0, "skin": 0},
            {"name": "lod1", "mesh": 1, "skin": 0},
        ],
        "skins": [{"joints": [1, 2], "inverseBindMatrices": ibm, "skeleton": 1}],
        "meshes": meshes,
        "animations": [{"name": "walk", "samplers": [
            {"input": times, "output": rot, "interpolation": "LINEAR"},
            {"input": times, "output": tr, "interpolation": "STEP"},
            {"input": times, "output": sc, "interpolation": "CUBICSPLINE"}],
            "channels": [
                {"sampler": 0, "target": {"node": 2, "path": "rotation"}},
                {"sampler": 1, "target": {"node": 1, "path": "translation"}},
                {"sampler": 2, "target": {"node": 2, "path": "scale"}}]}],
    }
    return g.embedded(doc) if embedded else g.glb(doc)


def rigid_human():
    """A person without skin or animation (the `static` and `sliding` motion modes)."""
    g = Gltf()
    v, t = box((-0.25, 0.0, -0.15), (0.25, 1.6, 0.15))
    doc = {"scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, "scale": [1.0, 1.1, 1.0], "translation": [0, 0.1, 0]}],
           "meshes": [mesh_accessors(g, v, t, False)]}
    return g.glb(doc)


def environment(embedded=False):
    """A floor and a table (a box) under a translated, rotated and scaled node tree."""
    g = Gltf()
    floor = [(-5.0, 0.0, -5.0), (5.0, 0.0, -5.0), (5.0, 0.0, 5.0), (-5.0, 0.0, 5.0)]
    fm = mesh_accessors(g, floor, [(0, 2, 1), (0, 3, 2)], False)
    v, t = box((-0.5, 0.0, -0.5), (0.5, 0.75, 0.5))
    bm = mesh_accessors(g, v, t, False)
    q = math.sqrt(0.5)
    doc = {"scene": 0, "scenes": [{"nodes": [0], "extras": {"pedscan": {"note": "fuzz seed"}}}],
           "nodes": [{"children": [1, 2]}, {"mesh": 0},
                     {"mesh": 1, "translation": [2.0, 0.0, 1.0], "rotation": [0, q, 0, q], "scale": [1.0, 1.0, 2.0]}],
           "meshes": [fm, bm]}
    return g.embedded(doc) if embedded else g.glb(doc)


def gltf_seeds():
    put("human_gltf", "skinned.glb", human())
    put("human_gltf", "skinned-embedded.gltf", human(embedded=True))
    put("human_gltf", "rigid.glb", rigid_human())
    put("environment_gltf", "room.glb", environment())
    put("environment_gltf", "room-embedded.gltf", environment(embedded=True))
    shutil.copyfile(os.path.join(ROOT, "data", "scene", "hall.glb"), os.path.join(CORPUS, "environment_gltf", "seed-hall.glb"))


# --- ROS 2 bags (MCAP, CDR) -----------------------------------------------------------------
# The `rosbag` target's first byte picks what the rest is: 0 an MCAP file (poses from /tf), 4 one
# with poses from /odom, 1 a PointCloud2 payload, 2 a TFMessage payload, 3 an Odometry payload
# (CDR, encapsulation header first).


class Cdr:
    def __init__(self, le=True):
        self.b = bytearray([0, 1 if le else 0, 0, 0])
        self.e = "<" if le else ">"

    def align(self, n):
        while (len(self.b) - 4) % n:
            self.b.append(0)

    def put(self, fmt, *v):
        self.align(struct.calcsize(fmt.lstrip("0123456789")))
        self.b += struct.pack(self.e + fmt, *v)
        return self

    def string(self, s):
        self.put("I", len(s) + 1)
        self.b += s.encode() + b"\0"
        return self

    def header(self, ns, frame):
        return self.put("i", ns // 10**9).put("I", ns % 10**9).string(frame)


BAG_T0 = 1_700_000_000 * 10**9


def cloud_cdr(ns, le=True):
    """8 returns of an HDL-32E-like cloud: x y z intensity (f32), ring (u16), time (f32)."""
    fields = [("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 7), ("ring", 16, 4), ("time", 20, 7)]
    data = bytearray()
    for k in range(8):
        a = 2 * math.pi * k / 8
        data += struct.pack(("<" if le else ">") + "4fH2xf", 5 * math.cos(a), 5 * math.sin(a), -1.0 + 0.1 * (k % 2), 10.0 * k, k % 2, 0.0125 * k)
    c = Cdr(le).header(ns, "lidar").put("I", 2).put("I", 4).put("I", len(fields))
    for name, off, ty in fields:
        c.string(name).put("I", off).put("B", ty).put("I", 1)
    c.put("B", 0 if le else 1).put("I", 24).put("I", 96).put("I", len(data))
    c.b += data
    return bytes(c.put("B", 1).b)


def tf_cdr(items):
    c = Cdr().put("I", len(items))
    for ns, parent, child, xyz, q in items:
        c.header(ns, parent).string(child).put("3d", *xyz).put("4d", *q)
    return bytes(c.b)


def odometry_cdr(ns):
    c = Cdr().header(ns, "odom").string("base").put("3d", 1.0, 2.0, 0.0).put("4d", 0.0, 0.0, 0.0, 1.0)
    return bytes(c.put("36d", *[0.0] * 36).put("6d", *[0.0] * 6).put("36d", *[0.0] * 36).b)


def mcap_record(op, body):
    return struct.pack("<BQ", op, len(body)) + body


def mstr(s):
    return struct.pack("<I", len(s)) + s.encode()


def mcap_file(messages, chunked=False):
    """An MCAP file (no summary) of (topic, schema name, time ns, payload)."""
    schemas, channels, records = {}, {}, b""
    for topic, schema, ns, payload in messages:
        if schema not in schemas:
            schemas[schema] = len(schemas) + 1
            records += mcap_record(0x03, struct.pack("<H", schemas[schema]) + mstr(schema) + mstr("ros2msg") + struct.pack("<I", 0))
        if topic not in channels:
            channels[topic] = len(channels)
            records += mcap_record(0x04, struct.pack("<HH", channels[topic], schemas[schema]) + mstr(topic) + mstr("cdr") + struct.pack("<I", 0))
        records += mcap_record(0x05, struct.pack("<HIQQ", channels[topic], 0, ns, ns) + payload)
    body = records
    if chunked:
        t = [m[2] for m in messages]
        chunk = struct.pack("<QQQI", min(t), max(t), len(records), 0) + mstr("") + struct.pack("<Q", len(records)) + records
        body = mcap_record(0x06, chunk)
    out = b"\x89MCAP0\r\n" + mcap_record(0x01, mstr("ros2") + mstr("pedscan seeds")) + body
    out += mcap_record(0x0F, struct.pack("<I", 0)) + mcap_record(0x02, struct.pack("<QQI", 0, 0, 0))
    return out + b"\x89MCAP0\r\n"


def rosbag_seeds():
    static = ("/tf_static", "tf2_msgs/msg/TFMessage", BAG_T0, tf_cdr([(BAG_T0, "base", "lidar", (0, 0, 1), (0, 0, 0, 1))]))
    moving = [("/tf", "tf2_msgs/msg/TFMessage", BAG_T0 + k * 10**8,
               tf_cdr([(BAG_T0 + k * 10**8, "odom", "base", (0.1 * k, 0, 0), (0, 0, math.sin(0.05 * k), math.cos(0.05 * k)))])) for k in range(4)]
    clouds = [("/points", "sensor_msgs/msg/PointCloud2", BAG_T0 + k * 10**8, cloud_cdr(BAG_T0 + k * 10**8)) for k in range(1, 3)]
    messages = [static] + sorted(moving + clouds, key=lambda m: m[2])
    put("rosbag", "tf.mcap", b"\0" + mcap_file(messages))
    put("rosbag", "chunked.mcap", b"\0" + mcap_file(messages, chunked=True))
    odom = [("/odom", "nav_msgs/msg/Odometry", BAG_T0 + k * 10**8, odometry_cdr(BAG_T0 + k * 10**8)) for k in range(4)]
    put("rosbag", "odometry.mcap", b"\4" + mcap_file([static] + sorted(odom + clouds, key=lambda m: m[2])))
    put("rosbag", "cloud-le.cdr", b"\1" + cloud_cdr(BAG_T0))
    put("rosbag", "cloud-be.cdr", b"\1" + cloud_cdr(BAG_T0, le=False))
    put("rosbag", "tf.cdr", b"\2" + moving[1][3])
    put("rosbag", "odometry.cdr", b"\3" + odometry_cdr(BAG_T0))


if __name__ == "__main__":
    pcap_seeds()
    pcd_seeds()
    kitti_seeds()
    track_seeds()
    toml_seeds()
    gltf_seeds()
    rosbag_seeds()
