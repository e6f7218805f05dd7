#!/usr/bin/env python3
"""Writes pedscan's default environment, data/scene/hall.glb: an indoor hall with floor,
walls, ceiling, pillars and some furniture, as plain boxes and prisms.

Reproducible (no dependencies, same bytes on every run). glTF conventions: y up, metres;
pedscan converts to z up with (x, y, z)_world = (x, -z, y)_gltf, so the hall spans world
x in [-18, 18], y in [-12, 12], floor at z = 0. Everything is double-sided (walls are seen
from inside). scenes[0].extras.pedscan records what the generator placed, for people reading
the file; pedscan itself derives the walkable area from the geometry.

Usage: python3 tools/scene/make_hall.py [OUT.glb]
"""
import json
import math
import struct
import sys

HALL_X, HALL_Y, HALL_H = 18.0, 12.0, 5.0  # half extents in world x, y; ceiling height


def box(cx, cy, z0, sx, sy, sz):
    """Axis-aligned box in world coordinates (centre x, y; bottom z; full sizes), outward CCW."""
    x0, x1 = cx - sx / 2, cx + sx / 2
    y0, y1 = cy - sy / 2, cy + sy / 2
    z1 = z0 + sz
    v = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0),
         (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    return v, quads


def prism(cx, cy, z0, r, h, n=12):
    """Vertical n-gon prism (a round pillar or planter), outward CCW."""
    v = []
    for z in (z0, z0 + h):
        for i in range(n):
            a = 2 * math.pi * i / n
            v.append((cx + r * math.cos(a), cy + r * math.sin(a), z))
    quads = [(i, (i + 1) % n, n + (i + 1) % n, n + i) for i in range(n)]
    tris = [(0, (i + 1) % n, i) for i in range(1, n - 1)] + [(n, n + i, n + (i + 1) % n) for i in range(1, n - 1)]
    return v, quads, tris


class Mesh:
    def __init__(self):
        self.v, self.t = [], []

    def add(self, verts, quads=(), tris=()):
        b = len(self.v)
        self.v += verts
        for a, c, d, e in quads:
            self.t += [(b + a, b + c, b + d), (b + a, b + d, b + e)]
        for a, c, d in tris:
            self.t.append((b + a, b + c, b + d))


def build():
    objects = {}
    def tiles(z, facing_up):
        """The floor (facing up) or ceiling (facing down) as a 12 x 8 grid of 3 m tiles, so no
        triangle is huge."""
        m = Mesh()
        nx, ny = 12, 8
        for i in range(nx):
            for j in range(ny):
                x0 = -HALL_X + 2 * HALL_X * i / nx
                x1 = -HALL_X + 2 * HALL_X * (i + 1) / nx
                y0 = -HALL_Y + 2 * HALL_Y * j / ny
                y1 = -HALL_Y + 2 * HALL_Y * (j + 1) / ny
                if facing_up:
                    m.add([(x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)], [(0, 1, 2, 3)])
                else:
                    m.add([(x0, y0, z), (x0, y1, z), (x1, y1, z), (x1, y0, z)], [(0, 1, 2, 3)])
        return m

    objects["floor"] = tiles(0, True)
    objects["ceiling"] = tiles(HALL_H, False)
    walls = Mesh()
    t = 0.3
    walls.add(*box(0, HALL_Y + t / 2, 0, 2 * HALL_X + 2 * t, t, HALL_H))
    walls.add(*box(0, -HALL_Y - t / 2, 0, 2 * HALL_X + 2 * t, t, HALL_H))
    walls.add(*box(HALL_X + t / 2, 0, 0, t, 2 * HALL_Y, HALL_H))
    walls.add(*box(-HALL_X - t / 2, 0, 0, t, 2 * HALL_Y, HALL_H))
    objects["walls"] = walls
    pillars = Mesh()
    placed = []
    for px in (-10.0, 0.0, 10.0):
        for py in (-6.0, 6.0):
            if px == 0.0:
                v, q, tr = prism(px, py, 0, 0.35, HALL_H, 16)
                pillars.add(v, q, tr)
                placed.append({"kind": "round pillar", "x": px, "y": py, "radius": 0.35})
            else:
                pillars.add(*box(px, py, 0, 0.6, 0.6, HALL_H))
                placed.append({"kind": "pillar", "x": px, "y": py, "size": [0.6, 0.6]})
    objects["pillars"] = pillars
    furniture = Mesh()

    def table(cx, cy, sx, sy):
        furniture.add(*box(cx, cy, 0.72, sx, sy, 0.04))
        for dx in (-1, 1):
            for dy in (-1, 1):
                furniture.add(*box(cx + dx * (sx / 2 - 0.05), cy + dy * (sy / 2 - 0.05), 0, 0.05, 0.05, 0.72))
        placed.append({"kind": "table", "x": cx, "y": cy, "size": [sx, sy]})

    def solid(kind, cx, cy, sx, sy, h):
        furniture.add(*box(cx, cy, 0, sx, sy, h))
        placed.append({"kind": kind, "x": cx, "y": cy, "size": [sx, sy], "height": h})

    table(-14.0, 9.0, 1.6, 0.8)
    table(-14.0, 6.5, 1.6, 0.8)
    table(14.0, -9.0, 1.2, 1.2)
    solid("counter", 15.5, 6.0, 1.0, 5.0, 1.1)
    solid("bench", -5.0, -10.8, 3.0, 0.5, 0.45)
    solid("bench", 5.0, 10.8, 3.0, 0.5, 0.45)
    solid("cabinet", -17.3, -4.0, 0.8, 2.0, 1.8)
    solid("crate stack", 7.0, -2.0, 1.2, 1.2, 1.2)
    v, q, tr = prism(-6.0, 2.5, 0, 0.5, 0.9, 12)
    furniture.add(v, q, tr)
    placed.append({"kind": "planter", "x": -6.0, "y": 2.5, "radius": 0.5, "height": 0.9})
    objects["furniture"] = furniture
    return objects, placed


def to_gltf(p):
    x, y, z = p
    return (x, z, -y)  # world z-up -> glTF y-up; pedscan maps back with (x, -z, y)


#: Near-infrared (905 nm) reflectance per object, the sensor model's intensity and detection:
#: typical values of the materials, not measurements of one sample. A concrete floor, white
#: painted walls and ceiling, painted concrete pillars, wooden and laminate furniture.
REFLECTANCE = {"floor": 0.3, "ceiling": 0.7, "walls": 0.7, "pillars": 0.5, "furniture": 0.4}


def write_glb(path, objects, placed):
    bin_parts, buffer_views, accessors, meshes, nodes = [], [], [], [], []
    names = list(objects)
    offset = 0
    for name, m in objects.items():
        pos = [to_gltf(p) for p in m.v]
        pos_bytes = b"".join(struct.pack("<3f", *p) for p in pos)
        idx_bytes = b"".join(struct.pack("<3I", *t) for t in m.t)
        for data, target in ((pos_bytes, 34962), (idx_bytes, 34963)):
            buffer_views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(data), "target": target})
            bin_parts.append(data)
            offset += len(data)
            pad = (-offset) % 4
            bin_parts.append(b"\0" * pad)
            offset += pad
        mins = [min(struct.unpack("<f", struct.pack("<f", p[k]))[0] for p in pos) for k in range(3)]
        maxs = [max(struct.unpack("<f", struct.pack("<f", p[k]))[0] for p in pos) for k in range(3)]
        accessors.append({"bufferView": len(buffer_views) - 2, "componentType": 5126, "count": len(pos),
                          "type": "VEC3", "min": mins, "max": maxs})
        accessors.append({"bufferView": len(buffer_views) - 1, "componentType": 5125, "count": 3 * len(m.t),
                          "type": "SCALAR"})
        meshes.append({"name": name, "primitives": [{"attributes": {"POSITION": len(accessors) - 2},
                                                     "indices": len(accessors) - 1, "material": names.index(name)}]})
        nodes.append({"name": name, "mesh": len(meshes) - 1})
    doc = {
        "asset": {"version": "2.0", "generator": "pedscan tools/scene/make_hall.py"},
        "scene": 0,
        "scenes": [{"name": "hall", "nodes": list(range(len(nodes))), "extras": {"pedscan": {
            "kind": "environment", "extent_m": {"x": [-HALL_X, HALL_X], "y": [-HALL_Y, HALL_Y], "height": HALL_H},
            "objects": placed, "frame": "glTF y-up; world (x, y, z) = (x, -z, y)"}}}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": [{"name": name, "doubleSided": True, "extras": {"reflectance": REFLECTANCE[name]},
                       "pbrMetallicRoughness": {"baseColorFactor": [REFLECTANCE[name]] * 3 + [1.0], "metallicFactor": 0.0}}
                      for name in names],
        "accessors": accessors,
        "bufferViews": buffer_views,
        "buffers": [{"byteLength": offset}],
    }
    js = json.dumps(doc, separators=(",", ":"), sort_keys=True).encode()
    js += b" " * ((-len(js)) % 4)
    binary = b"".join(bin_parts)
    total = 12 + 8 + len(js) + 8 + len(binary)
    with open(path, "wb") as f:
        f.write(struct.pack("<III", 0x46546C67, 2, total))
        f.write(struct.pack("<II", len(js), 0x4E4F534A) + js)
        f.write(struct.pack("<II", len(binary), 0x004E4942) + binary)


if __name__ == "__main__":
    out = sys.argv[1] if len(sys.argv) > 1 else "data/scene/hall.glb"
    objects, placed = build()
    write_glb(out, objects, placed)
    tris = sum(len(m.t) for m in objects.values())
    print(f"wrote {out}: {len(objects)} meshes, {tris} triangles")
