#!/usr/bin/env python3
"""Independent check of the shipped humans: reads each data/humans/*.glb with numpy only
(own GLB parser, own glTF animation sampler + linear blend skinning, like a runtime) and prints
per variant: standing height, target, error %, triangles per LOD, recorded LOD error_m,
recorded and measured stride, cycle, foot slide, ground penetration.

    python check_humans.py [data/humans] [--png OUT.png]   # --png: side-view strip (needs matplotlib)

Exit status 1 if a hard requirement fails (height error > 1 %, rest min y not 0 within 1 mm,
first key != last key, missing extras)."""
import json
import math
import os
import struct
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_DIR = os.path.normpath(os.path.join(HERE, "..", "..", "data", "humans"))
CT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
NC = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def read_glb(path):
    b = open(path, "rb").read()
    magic, ver, total = struct.unpack_from("<III", b, 0)
    assert magic == 0x46546C67 and ver == 2 and total == len(b)
    jl, jt = struct.unpack_from("<II", b, 12)
    gl = json.loads(b[20:20 + jl])
    bl, bt = struct.unpack_from("<II", b, 20 + jl)
    blob = b[28 + jl:28 + jl + bl]

    def acc(i):
        a = gl["accessors"][i]
        v = gl["bufferViews"][a["bufferView"]]
        n = NC[a["type"]]
        dt = np.dtype(CT[a["componentType"]])
        off = v.get("byteOffset", 0) + a.get("byteOffset", 0)
        return np.frombuffer(blob, dtype=dt, count=a["count"] * n, offset=off).reshape(a["count"], n)
    return gl, acc


def quat_mat(q):
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def slerp(a, b, t):
    d = float(np.dot(a, b))
    if d < 0:
        b, d = -b, -d
    if d > 0.9995:
        q = a + t * (b - a)
        return q / np.linalg.norm(q)
    th = math.acos(d)
    return (math.sin((1 - t) * th) * a + math.sin(t * th) * b) / math.sin(th)


class Human:
    def __init__(self, path):
        gl, acc = read_glb(path)
        self.gl = gl
        self.extras = gl["scenes"][0]["extras"]["pedscan"]
        prim = gl["meshes"][0]["primitives"][0]
        self.P = acc(prim["attributes"]["POSITION"]).astype(np.float64)
        self.J = acc(prim["attributes"]["JOINTS_0"]).astype(np.int64)
        self.W = acc(prim["attributes"]["WEIGHTS_0"]).astype(np.float64)
        self.lods = [acc(m["primitives"][0]["indices"]).reshape(-1, 3) for m in gl["meshes"]]
        skin = gl["skins"][0]
        self.joints = skin["joints"]
        self.IBM = acc(skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1).astype(np.float64)
        nodes = gl["nodes"]
        self.parent = {}
        for i, n in enumerate(nodes):
            for c in n.get("children", []):
                self.parent[c] = i
        self.rest_t = {i: np.array(n.get("translation", [0, 0, 0]), float) for i, n in enumerate(nodes)}
        self.rest_r = {i: np.array(n.get("rotation", [0, 0, 0, 1]), float) for i, n in enumerate(nodes)}
        anim = [a for a in gl["animations"] if a["name"] == "walk"][0]
        self.ch = []
        for c in anim["channels"]:
            s = anim["samplers"][c["sampler"]]
            assert s.get("interpolation", "LINEAR") == "LINEAR"
            self.ch.append((c["target"]["node"], c["target"]["path"], acc(s["input"])[:, 0].astype(float),
                            acc(s["output"]).astype(float)))
        self.duration = max(c[2][-1] for c in self.ch)

    def loop_ok(self):
        return all(np.allclose(o[0], o[-1], atol=1e-6) for _, _, _, o in self.ch)

    def pose(self, t):
        t = t % self.duration
        T = dict(self.rest_t)
        R = dict(self.rest_r)
        for node, path, times, out in self.ch:
            k = min(int(np.searchsorted(times, t, side="right")) - 1, len(times) - 2)
            u = (t - times[k]) / (times[k + 1] - times[k])
            if path == "rotation":
                R[node] = slerp(out[k], out[k + 1], u)
            elif path == "translation":
                T[node] = out[k] * (1 - u) + out[k + 1] * u
        G = {}
        for j in sorted(self.joints):  # parents precede children in this file
            L = np.eye(4)
            L[:3, :3] = quat_mat(R[j])
            L[:3, 3] = T[j]
            G[j] = G[self.parent[j]] @ L if self.parent.get(j) in G else L
        return np.array([G[j] for j in self.joints])

    def skin(self, M, sel=slice(None)):
        S = np.einsum("nij,njk->nik", M, self.IBM)
        P, J, W = self.P[sel], self.J[sel], self.W[sel]
        ph = np.concatenate([P, np.ones((len(P), 1))], 1)
        out = np.zeros_like(P)
        for k in range(4):
            out += W[:, k:k + 1] * np.einsum("nij,nj->ni", S[J[:, k]], ph)[:, :3]
        return out

    def gait_check(self, nframes=240):
        """stance-foot speed in the world once the body moves at stride/cycle (+Z); stride
        measured as the median backward speed of ground-contact sole vertices in the body
        frame x cycle."""
        T = self.duration
        v = self.extras["stride_length_m"] / T
        sole = np.where(self.P[:, 1] < 0.02)[0]
        prev = None
        world, back, pen = [], [], 0.0
        dt = T / nframes
        for f in range(nframes + 1):
            X = self.skin(self.pose(f * dt), sole)
            pen = max(pen, -X[:, 1].min())
            if prev is not None:
                c = (X[:, 1] < 0.004) & (prev[:, 1] < 0.004)
                vz = (X[c, 2] - prev[c, 2]) / dt
                vx = (X[c, 0] - prev[c, 0]) / dt
                world.append(np.sqrt(vx ** 2 + (vz + v) ** 2))
                back.append(-vz)
            prev = X
        world, back = np.concatenate(world), np.concatenate(back)
        return dict(stride=float(np.median(back) * T), slide_mean=float(world.mean()),
                    slide_p95=float(np.percentile(world, 95)), v=v, pen=float(pen))


def main():
    args = [a for a in sys.argv[1:]]
    png = None
    if "--png" in args:
        i = args.index("--png")
        png = args[i + 1]
        del args[i:i + 2]
    d = args[0] if args else DEFAULT_DIR
    files = sorted(f for f in os.listdir(d) if f.endswith(".glb"))
    ok = True
    hdr = ("variant", "height", "target", "err%", "minY_mm", "LOD triangles", "LOD error_m (recorded)",
           "stride rec/meas", "cycle_s", "speed", "slide mean/p95 m/s", "pen_mm", "loop")
    print(" | ".join(hdr))
    humans = []
    for f in files:
        h = Human(os.path.join(d, f))
        e = h.extras
        H = h.P[:, 1].max() - h.P[:, 1].min()
        err = 100 * (H - e["height_m"]) / e["height_m"]
        tris = [len(t) for t in h.lods]
        rec_tris = [l["triangles"] for l in e["lods"]]
        g = h.gait_check()
        loop = h.loop_ok()
        good = abs(err) <= 1.0 and abs(h.P[:, 1].min()) <= 0.001 and loop and tris == rec_tris \
            and e["facing"] == "+Z" and abs(e["cycle_s"] - h.duration) < 1e-5
        ok &= good
        print("%s | %.4f | %.3f | %+.3f | %.2f | %s | %s | %.3f/%.3f | %.3f | %.2f | %.3f/%.3f | %.1f | %s%s" % (
            f[:-4], H, e["height_m"], err, 1000 * h.P[:, 1].min(), "/".join(map(str, tris)),
            "/".join("%.4f" % l["error_m"] for l in e["lods"]), e["stride_length_m"], g["stride"],
            e["cycle_s"], g["v"], g["slide_mean"], g["slide_p95"], 1000 * g["pen"], loop,
            "" if good else "  <-- FAIL"))
        humans.append((f[:-4], h))
    if png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        pick = [x for x in humans if x[0] in ("h1200_w20", "h1700_w60", "h1800_w90")] or humans[:1]
        phases = np.linspace(0, 1, 8, endpoint=False)
        fig, axes = plt.subplots(2 * len(pick), len(phases), figsize=(2 * len(phases), 4.2 * len(pick)))
        for r, (name, h) in enumerate(pick):
            lod = h.lods[2]
            for c, s in enumerate(phases):
                X = h.skin(h.pose(s * h.duration))
                for rr, (ix, lab) in enumerate(((2, "side (z fwd)"), (0, "front (x)"))):
                    ax = axes[2 * r + rr, c]
                    ax.triplot(X[:, ix], X[:, 1], lod, lw=0.15, color="k")
                    ax.axhline(0, color="g", lw=0.5)
                    ax.set_aspect("equal")
                    ax.set_xlim(-0.9, 0.9)
                    ax.set_ylim(-0.05, 1.9)
                    ax.set_xticks([])
                    ax.set_yticks([])
                    ax.set_title("%s %s s=%.2f" % (name, lab[:4], s), fontsize=6)
        fig.tight_layout()
        fig.savefig(png, dpi=110)
    print("all checks passed" if ok else "SOME CHECKS FAILED")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
