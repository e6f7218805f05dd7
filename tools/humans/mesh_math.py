"""Rotations, quaternions and point-to-mesh distances for the human builder
(build_humans.py): the rig's frames and the walk's joint rotations, the LODs' Hausdorff
errors and the body's horizontal sections. Plain numpy (scipy where noted), no state."""
import math

import numpy as np


# ----------------------------------------------------------------------------- math


def rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def unit(v):
    return v / np.linalg.norm(v)


def ortho(p, e):
    return unit(p - np.dot(p, e) * e)


def frame(e1, p):
    e1 = unit(e1)
    e2 = ortho(p, e1)
    return np.stack([e1, e2, np.cross(e1, e2)], axis=1)


def align(a, b):
    """minimal rotation taking direction a to direction b"""
    a, b = unit(a), unit(b)
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    s = np.linalg.norm(v)
    if s < 1e-12:
        return np.eye(3)
    k = v / s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    ang = math.atan2(s, c)
    return np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * K @ K


def mat_to_quat(R):
    """xyzw"""
    t = np.trace(R)
    if t > 0:
        s = math.sqrt(t + 1.0) * 2
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2
        q = [0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s]
    elif R[1, 1] > R[2, 2]:
        s = math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2
        q = [(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s]
    else:
        s = math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2
        q = [(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    if q[3] < 0:
        q = -q
    return q


def quat_to_mat(q):
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def slerp(q0, q1, t):
    d = float(np.dot(q0, q1))
    if d < 0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + t * (q1 - q0)
        return q / np.linalg.norm(q)
    th = math.acos(d)
    return (math.sin((1 - t) * th) * q0 + math.sin(t * th) * q1) / math.sin(th)


def smooth(u):
    u = min(max(u, 0.0), 1.0)
    return u * u * u * (10 - 15 * u + 6 * u * u)


# ----------------------------------------------------------------------------- distances


def point_tri_dist(p, a, b, c):
    """vectorised closest distance point -> triangle (Ericson, Real-Time Collision Detection)"""
    ab, ac, ap = b - a, c - a, p - a
    d1 = np.einsum("ij,ij->i", ab, ap)
    d2 = np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3 = np.einsum("ij,ij->i", ab, bp)
    d4 = np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5 = np.einsum("ij,ij->i", ab, cp)
    d6 = np.einsum("ij,ij->i", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    res = np.empty_like(p)
    done = np.zeros(len(p), bool)

    def put(mask, val):
        m = mask & ~done
        res[m] = val[m]
        done[m] = True
    put((d1 <= 0) & (d2 <= 0), a)
    put((d3 >= 0) & (d4 <= d3), b)
    with np.errstate(divide="ignore", invalid="ignore"):
        v = d1 / (d1 - d3)
        put((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + v[:, None] * ab)
        put((d6 >= 0) & (d5 <= d6), c)
        w = d2 / (d2 - d6)
        put((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + w[:, None] * ac)
        w2 = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        put((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), b + w2[:, None] * (c - b))
        den = 1.0 / (va + vb + vc)
        v3, w3 = vb * den, vc * den
        put(np.ones(len(p), bool), a + v3[:, None] * ab + w3[:, None] * ac)
    return np.linalg.norm(p - res, axis=1)


def surface_samples(P, tris, per_tri=6):
    """vertices + deterministic barycentric samples inside each triangle"""
    bary = np.array([[1 / 3, 1 / 3, 1 / 3], [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6],
                     [1 / 6, 1 / 6, 2 / 3], [.5, .5, 0], [0, .5, .5], [.5, 0, .5]])[:per_tri + 1]
    a, b, c = P[tris[:, 0]], P[tris[:, 1]], P[tris[:, 2]]
    pts = [P[np.unique(tris)]]
    for w in bary:
        pts.append(w[0] * a + w[1] * b + w[2] * c)
    return np.concatenate(pts)


def dist_to_mesh(Q, P, tris, k=16):
    from scipy.spatial import cKDTree
    cent = P[tris].mean(1)
    tree = cKDTree(cent)
    _, cand = tree.query(Q, k=min(k, len(tris)))
    best = np.full(len(Q), np.inf)
    for j in range(cand.shape[1]):
        t = tris[cand[:, j]]
        d = point_tri_dist(Q, P[t[:, 0]], P[t[:, 1]], P[t[:, 2]])
        best = np.minimum(best, d)
    return best


def max_dist_to_mesh(Q, P, tris, k):
    """max over Q of dist_to_mesh(Q, P, tris, k), computed lazily: a cheap pass with 8
    candidates gives upper bounds; only points whose bound exceeds the running maximum are
    refined with k candidates (same result as the full k pass)."""
    d8 = dist_to_mesh(Q, P, tris, k=8)
    order = np.argsort(-d8, kind="stable")
    best = 0.0
    for i in range(0, len(order), 2048):
        ch = order[i:i + 2048]
        if d8[ch[0]] <= best:
            break
        best = max(best, float(dist_to_mesh(Q[ch], P, tris, k=k).max()))
    return best


def hausdorff(P, full, lod):
    d1 = max_dist_to_mesh(surface_samples(P, lod), P, full, 16)
    d2 = max_dist_to_mesh(surface_samples(P, full), P, lod, 48)
    return float(max(d1, d2))


# ----------------------------------------------------------------------------- measurements


def section(P, tris, J, yw):
    """horizontal section at height yw through the triangles whose vertices are all selected
    by the mask J (e.g. mainly skinned to non-arm bones): returns (tape circumference = convex
    hull perimeter, width x, depth z)."""
    from scipy.spatial import ConvexHull
    ys = P[tris][:, :, 1]
    cross = (ys.min(1) < yw) & (ys.max(1) > yw) & J[tris].all(1)
    pts = []
    for t in tris[cross]:
        for i in range(3):
            a, b = P[t[i]], P[t[(i + 1) % 3]]
            if (a[1] - yw) * (b[1] - yw) < 0:
                u = (yw - a[1]) / (b[1] - a[1])
                pts.append((a + u * (b - a))[[0, 2]])
    pts = np.array(pts)
    hull = ConvexHull(pts)
    hp = pts[hull.vertices]
    per = float(np.linalg.norm(hp - np.roll(hp, 1, 0), axis=1).sum())
    return per, float(np.ptp(pts[:, 0])), float(np.ptp(pts[:, 1]))
