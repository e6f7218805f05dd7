//! Fixtures shared by the tests of the raycast files: a seeded RNG, closed test meshes
//! (subdivided octahedron spheres, tessellated cubes), a triangle soup with every awkward
//! case the casters must agree on, and a bit-for-bit comparison of hit lists. One copy here,
//! so that each file's tests build the same scenes.

use super::Hit;
use crate::geometry::FrameGeometry;
use glam::DVec3;
use std::collections::HashMap;

/// SplitMix64: small, seeded, reproducible.
pub(crate) struct Rng(pub(crate) u64);
impl Rng {
    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub(crate) fn f(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub(crate) fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.f()
    }
    pub(crate) fn unit(&mut self) -> DVec3 {
        loop {
            let v = DVec3::new(self.range(-1.0, 1.0), self.range(-1.0, 1.0), self.range(-1.0, 1.0));
            let l = v.length();
            if l > 1e-3 && l <= 1.0 {
                return v / l;
            }
        }
    }
    pub(crate) fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

pub(crate) fn f32v(v: DVec3) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

pub(crate) fn dv(p: [f32; 3]) -> DVec3 {
    DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)
}

/// Octahedron subdivided into 8 * n^2 triangles, vertices normalised to the unit sphere
/// (then scaled and moved), wound outward. Vertices on the coordinate planes stay exactly
/// on them, so equator edges lie exactly in z = 0 (and likewise x = 0, y = 0).
pub(crate) fn octasphere(n: i32, scale: DVec3, centre: DVec3) -> (Vec<[f32; 3]>, Vec<u32>) {
    let mut pos = Vec::new();
    let mut map: HashMap<(i32, i32, i32), u32> = HashMap::new();
    let mut idx = Vec::new();
    let mut vert = |k: (i32, i32, i32), pos: &mut Vec<[f32; 3]>| -> u32 {
        *map.entry(k).or_insert_with(|| {
            let p = DVec3::new(k.0 as f64, k.1 as f64, k.2 as f64).normalize();
            pos.push(f32v(p * scale + centre));
            (pos.len() - 1) as u32
        })
    };
    for sx in [-1, 1] {
        for sy in [-1, 1] {
            for sz in [-1, 1] {
                // Corners A = sx*X, B = sy*Y, C = sz*Z; outward when sx*sy*sz > 0.
                let flip = sx * sy * sz < 0;
                let lat = |i: i32, j: i32| (sx * (n - i - j), sy * i, sz * j);
                for i in 0..n {
                    for j in 0..n - i {
                        let mut tris = vec![[lat(i, j), lat(i + 1, j), lat(i, j + 1)]];
                        if i + j + 1 < n {
                            tris.push([lat(i + 1, j), lat(i + 1, j + 1), lat(i, j + 1)]);
                        }
                        for t in tris {
                            let mut v = [vert(t[0], &mut pos), vert(t[1], &mut pos), vert(t[2], &mut pos)];
                            if flip {
                                v.swap(1, 2);
                            }
                            idx.extend_from_slice(&v);
                        }
                    }
                }
            }
        }
    }
    (pos, idx)
}

/// Cube [-1, 1]^3 with an n x n grid per face, rotated by `rot` (columns), moved by
/// `centre`, wound outward; shared vertices are shared exactly.
pub(crate) fn tess_cube(n: i32, rot: [DVec3; 3], centre: DVec3) -> (Vec<[f32; 3]>, Vec<u32>) {
    let mut pos = Vec::new();
    let mut map: HashMap<[i32; 3], u32> = HashMap::new();
    let mut idx = Vec::new();
    let mut vert = |k: [i32; 3], pos: &mut Vec<[f32; 3]>| -> u32 {
        *map.entry(k).or_insert_with(|| {
            let p = DVec3::new(k[0] as f64, k[1] as f64, k[2] as f64) * (2.0 / n as f64) - DVec3::ONE;
            pos.push(f32v(rot[0] * p.x + rot[1] * p.y + rot[2] * p.z + centre));
            (pos.len() - 1) as u32
        })
    };
    // (normal axis, side, u axis, v axis) with u x v = outward normal.
    let faces = [(0, n, 1, 2), (0, 0, 2, 1), (1, n, 2, 0), (1, 0, 0, 2), (2, n, 0, 1), (2, 0, 1, 0)];
    for (ax, side, ua, va) in faces {
        let key = |i: i32, j: i32| {
            let mut k = [0; 3];
            k[ax] = side;
            k[ua] = i;
            k[va] = j;
            k
        };
        for i in 0..n {
            for j in 0..n {
                let p00 = vert(key(i, j), &mut pos);
                let p10 = vert(key(i + 1, j), &mut pos);
                let p11 = vert(key(i + 1, j + 1), &mut pos);
                let p01 = vert(key(i, j + 1), &mut pos);
                idx.extend_from_slice(&[p00, p10, p11, p00, p11, p01]);
            }
        }
    }
    (pos, idx)
}


pub(crate) fn rotation(rng: &mut Rng) -> [DVec3; 3] {
    let a = rng.unit();
    let b = (rng.unit() - a * a.dot(rng.unit())).normalize();
    let b = (b - a * a.dot(b)).normalize();
    [a, b, a.cross(b)]
}

pub(crate) fn geom_of(meshes: &[(&[[f32; 3]], &[u32], u32, bool)]) -> FrameGeometry {
    let mut g = FrameGeometry::default();
    for (p, i, inst, ds) in meshes {
        g.push_mesh(p, i, *inst, *ds);
    }
    g
}


pub(crate) fn same(a: &[Hit], b: &[Hit]) -> Result<(), String> {
    assert_eq!(a.len(), b.len());
    for (k, (x, y)) in a.iter().zip(b).enumerate() {
        if x.triangle != y.triangle || x.range_m.to_bits() != y.range_m.to_bits() {
            return Err(format!("ray {k}: {x:?} vs {y:?}"));
        }
    }
    Ok(())
}

/// A soup: big, small, thin (sliver), grazing (plane through the origin), shared-edge
/// fans, exact duplicates (ties) and rotated duplicates; several meshes with mixed
/// culling and instances. Returns the geometry and rays aimed at vertices/edges plus
/// random ones.
pub(crate) fn soup(seed: u64, n: usize) -> (FrameGeometry, Vec<DVec3>) {
    let mut rng = Rng(seed);
    let mut g = FrameGeometry::default();
    let mut aims = Vec::new();
    for mesh in 0..4 {
        let mut pos: Vec<[f32; 3]> = Vec::new();
        let mut idx: Vec<u32> = Vec::new();
        let tri = |a: DVec3, b: DVec3, c: DVec3, pos: &mut Vec<[f32; 3]>, idx: &mut Vec<u32>| {
            let base = pos.len() as u32;
            pos.extend([f32v(a), f32v(b), f32v(c)]);
            idx.extend([base, base + 1, base + 2]);
        };
        while idx.len() / 3 < n / 4 {
            let c = DVec3::new(rng.range(-20.0, 20.0), rng.range(-20.0, 20.0), rng.range(-5.0, 5.0));
            let s = 10f64.powf(rng.range(-2.0, 0.7));
            match rng.below(7) {
                0 | 1 => tri(c + rng.unit() * s, c + rng.unit() * s, c + rng.unit() * s, &mut pos, &mut idx),
                2 => {
                    // sliver
                    let a = c + rng.unit() * s;
                    let b = a + rng.unit() * s * 1e-5;
                    tri(a, b, c + rng.unit() * s * 3.0, &mut pos, &mut idx);
                }
                3 => {
                    // grazing: the plane contains the origin
                    let a = c + rng.unit() * s;
                    let b = c + rng.unit() * s;
                    tri(a, b, a * rng.range(0.5, 1.5), &mut pos, &mut idx);
                }
                4 => {
                    // fan with shared edges (vertices shared by index)
                    let base = pos.len() as u32;
                    pos.push(f32v(c));
                    let k = 3 + rng.below(5);
                    for j in 0..k {
                        let ang = j as f64 * std::f64::consts::TAU / k as f64;
                        pos.push(f32v(c + (rot_dir(ang) + rng.unit() * 0.2) * s));
                    }
                    for j in 0..k as u32 {
                        idx.extend([base, base + 1 + j, base + 1 + (j + 1) % k as u32]);
                    }
                    aims.push(dv(pos[base as usize]));
                }
                5 if idx.len() >= 3 => {
                    // exact duplicate of an earlier triangle (same vertex order): tie
                    let t = rng.below(idx.len() / 3);
                    let i3 = [idx[3 * t], idx[3 * t + 1], idx[3 * t + 2]];
                    idx.extend(i3);
                }
                _ if idx.len() >= 3 => {
                    // rotated duplicate (b, c, a)
                    let t = rng.below(idx.len() / 3);
                    let i3 = [idx[3 * t + 1], idx[3 * t + 2], idx[3 * t]];
                    idx.extend(i3);
                }
                _ => {}
            }
        }
        for _ in 0..n / 8 {
            let t = rng.below(idx.len() / 3);
            let a = dv(pos[idx[3 * t] as usize]);
            let b = dv(pos[idx[3 * t + 1] as usize]);
            aims.push(if rng.below(2) == 0 { a } else { (a + b) * 0.5 });
        }
        g.push_mesh(&pos, &idx, mesh as u32, mesh % 2 == 1);
    }
    let mut dirs: Vec<DVec3> = (0..n).map(|_| rng.unit()).collect();
    dirs.extend(aims.iter().map(|a| a.normalize()));
    dirs.extend(aims); // non-unit, exactly through the point
    (g, dirs)
}

fn rot_dir(a: f64) -> DVec3 {
    DVec3::new(a.cos(), a.sin(), 0.3 * (3.0 * a).sin())
}
