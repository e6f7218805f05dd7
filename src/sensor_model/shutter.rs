//! The rolling shutter: a spinning sensor fires column by column over its period, so each
//! column sees the people, the environment and its own pose at its own time. The frame is cut
//! behind the sensor: column `c` is taken at `t_frame + (c + 0.5) / (W * rate)`.
//!
//! The reference poses the whole frame at each column's time and casts that column alone
//! ([`crate::generator::Generator::reference_rolling_hits`]): exact, and ~W times the work.
//! The default ([`Sweep::warp_between`]) poses each person twice, at the first and last time
//! its bounding sphere spans, and moves every vertex to its own time by linear interpolation
//! between the two (linear blend skinning is linear in the joint matrices, so this is the
//! skinning at interpolated matrices); a vertex's time is that of the column its azimuth falls
//! in, found by one fixed-point step. A static environment under a moving sensor moves each
//! vertex by the sensor's pose at the vertex's own time. The error left is second order in the
//! person's column span (README, "Sensor model", for the measured figures); a person cut by
//! the frame's edge (behind the sensor) is unwrapped around its centre, so it is seen whole at
//! times just before the sweep instead of torn between its start and its end.

use glam::{DMat4, DVec3};

/// The timing of one sweep.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sweep {
    /// Time of the frame (the start of the sweep), s from the sequence start.
    pub t0_s: f64,
    /// One revolution, s; 0 = every column at `t0_s` (no rolling shutter).
    pub period_s: f64,
    pub columns: usize,
}

impl Sweep {
    /// The time of continuous column coordinate `u` (column `c` spans `[c, c + 1)`; its beam
    /// sits at `c + 0.5`); `u` may lie outside `[0, W)` for a person unwrapped over the cut.
    #[inline]
    pub fn time_at(&self, u: f64) -> f64 {
        self.t0_s + self.period_s * u / self.columns as f64
    }

    /// The time column `c`'s beams are fired.
    pub fn column_time(&self, c: usize) -> f64 {
        self.time_at(c as f64 + 0.5)
    }

    /// Whether columns differ in time.
    pub fn rolls(&self) -> bool {
        self.period_s > 0.0
    }

    /// The continuous column coordinate of a sensor-frame direction, in `[0, W)`:
    /// `0.5 * (1 - atan2(y, x) / pi) * W` (the sensor's column convention, unfloored).
    #[inline]
    pub fn u_of(&self, x: f64, y: f64) -> f64 {
        let w = self.columns as f64;
        (0.5 * (1.0 - y.atan2(x) / std::f64::consts::PI) * w).rem_euclid(w)
    }

    /// `u` moved by whole revolutions to within half a revolution of `reference`.
    #[inline]
    pub fn unwrap_near(&self, u: f64, reference: f64) -> f64 {
        let w = self.columns as f64;
        reference + (u - reference + 0.5 * w).rem_euclid(w) - 0.5 * w
    }

    /// The time span `[ta, tb]` of the columns a sphere (sensor frame) covers, unwrapped
    /// around its centre, and the centre's column coordinate. A sphere holding the sensor
    /// spans the whole sweep around its centre.
    pub fn span_of_sphere(&self, centre: DVec3, radius: f64) -> (f64, f64, f64) {
        let u_c = self.u_of(centre.x, centre.y);
        let d = centre.truncate().length();
        let half_w = if d > radius * 1.0001 { (radius / d).asin() } else { std::f64::consts::PI };
        let du = half_w / std::f64::consts::TAU * self.columns as f64;
        // One column beyond on each side: a vertex's own motion may carry it slightly out.
        (self.time_at(u_c - du - 1.0), self.time_at(u_c + du + 1.0), u_c)
    }

    /// Moves each of `a` (a person's vertices posed in the sensor frame at time `ta`) to its
    /// own time: `b` holds the same vertices posed at `tb`; a vertex at time t is
    /// `a + (b - a) (t - ta) / (tb - ta)` (clamped to the span), and t is the time of the
    /// column the vertex lies in at the person's centre time, measured as an angle from the
    /// centre's direction `u_ref` (so a person across the frame's cut stays whole). One step
    /// suffices: a vertex moves a centimetre or so over its span, which changes its time by
    /// tens of microseconds and its place by a tenth of a millimetre at walking speeds.
    pub fn warp_between(&self, a: &mut [[f32; 3]], b: &[[f32; 3]], ta: f64, tb: f64, u_ref: f64) {
        self.warp_keys(a, std::slice::from_ref(&b), ta, tb, u_ref);
    }

    /// [`Sweep::warp_between`] over several keys: `a` holds the vertices at `ta` and
    /// `keys[j]` at `ta + (tb - ta) (j + 1) / keys.len()`; each vertex is interpolated between
    /// the two keys around its own time.
    pub fn warp_keys<K: AsRef<[[f32; 3]]>>(&self, a: &mut [[f32; 3]], keys: &[K], ta: f64, tb: f64, u_ref: f64) {
        let span = tb - ta;
        let n = keys.len();
        if n == 0 || !(span > 0.0) {
            return;
        }
        let az_ref = std::f64::consts::PI * (1.0 - 2.0 * u_ref / self.columns as f64);
        let (sin_r, cos_r) = (az_ref.sin() as f32, az_ref.cos() as f32);
        let lambda_ref = ((self.time_at(u_ref) - ta) / span) as f32;
        let per_rad = (self.period_s / std::f64::consts::TAU / span) as f32;
        // The angle from the centre's direction of a point, counter-clockwise.
        let angle = |q: glam::Vec3| atan2_fast(q.y * cos_r - q.x * sin_r, q.x * cos_r + q.y * sin_r);
        if n == 1 {
            // Two poses (most people): straight-line code.
            let b = keys[0].as_ref();
            assert_eq!(a.len(), b.len(), "both poses hold every vertex");
            for (pa, pb) in a.iter_mut().zip(b) {
                let (qa, qb) = (glam::Vec3::from(*pa), glam::Vec3::from(*pb));
                let lambda = (lambda_ref - per_rad * angle(qa.lerp(qb, lambda_ref))).clamp(0.0, 1.0);
                *pa = qa.lerp(qb, lambda).to_array();
            }
            return;
        }
        let keys: Vec<&[[f32; 3]]> = keys.iter().map(|k| k.as_ref()).collect();
        assert!(keys.iter().all(|k| k.len() == a.len()), "every key holds every vertex");
        let at = |v: usize, first: glam::Vec3, lambda: f32| -> glam::Vec3 {
            let x = (lambda.clamp(0.0, 1.0) * n as f32).min(n as f32 - 1e-4);
            let j = x as usize;
            let from = if j == 0 { first } else { glam::Vec3::from(keys[j - 1][v]) };
            from.lerp(glam::Vec3::from(keys[j][v]), x - j as f32)
        };
        for (v, pa) in a.iter_mut().enumerate() {
            let first = glam::Vec3::from(*pa);
            let lambda = lambda_ref - per_rad * angle(at(v, first, lambda_ref));
            *pa = at(v, first, lambda).to_array();
        }
    }

    /// Places static world points into the sensor frame at each point's own column time:
    /// `sensor_from_world(t)` gives the sensor's pose at t; fixed-point steps from the
    /// sweep's middle, iterated to the point's own column.
    /// The pose is sampled at every column boundary and interpolated linearly in between
    /// (over 0.1 ms the pose moves by well under a micrometre from its chord).
    pub fn place_static(&self, world: &[DVec3], sensor_from_world: impl Fn(f64) -> DMat4 + Sync, out: &mut Vec<[f32; 3]>) {
        use rayon::prelude::*;
        let w = self.columns;
        let table: Vec<DMat4> = (0..=w).into_par_iter().map(|c| sensor_from_world(self.time_at(c as f64))).collect();
        let at = |u: f64| -> DMat4 {
            let u = u.clamp(0.0, w as f64);
            let c = (u.floor() as usize).min(w - 1);
            let f = u - c as f64;
            table[c] * (1.0 - f) + table[c + 1] * f
        };
        let mid = table[w / 2];
        world
            .par_iter()
            .map(|p| {
                // The fixed point of "where the point is when its column is fired": each step
                // shrinks the error by the sensor's turn over a sweep over a full turn (w T /
                // 2 pi, a few percent), so a handful of steps reach a micro-column.
                let mut q = mid.transform_point3(*p);
                let mut u = self.u_of(q.x, q.y);
                for _ in 0..8 {
                    q = at(u).transform_point3(*p);
                    let next = self.u_of(q.x, q.y);
                    let done = (next - u).abs() < 1e-6;
                    u = next;
                    if done {
                        break;
                    }
                }
                q.as_vec3().to_array()
            })
            .collect_into_vec(out);
    }
}

/// atan2 to within 1e-5 rad (a minimax polynomial on [0, 1] and the octant symmetries):
/// 1e-5 rad of azimuth is 0.2 microseconds of a 10 Hz sweep.
#[inline]
pub fn atan2_fast(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let (lo, hi) = (ax.min(ay), ax.max(ay));
    if hi == 0.0 {
        return 0.0;
    }
    let t = lo / hi;
    let t2 = t * t;
    // atan(t) on [0, 1], max error ~1e-5 rad.
    let mut r = t * (0.999_866 + t2 * (-0.330_299_5 + t2 * (0.180_141 + t2 * (-0.085_133 + t2 * 0.020_835_1))));
    if ay > ax {
        r = std::f32::consts::FRAC_PI_2 - r;
    }
    if x < 0.0 {
        r = std::f32::consts::PI - r;
    }
    if y < 0.0 {
        -r
    } else {
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atan2_fast_is_within_its_bound() {
        let mut worst = 0.0f64;
        for k in 0..100_000 {
            let a = k as f64 * 0.000_062_831_9 - std::f64::consts::PI;
            for r in [0.3f64, 7.0, 80.0] {
                let (y, x) = ((r * a.sin()) as f32, (r * a.cos()) as f32);
                let want = (y as f64).atan2(x as f64);
                let mut d = (super::atan2_fast(y, x) as f64 - want).abs();
                d = d.min((d - std::f64::consts::TAU).abs());
                worst = worst.max(d);
            }
        }
        assert!(worst < 2e-5, "{worst}");
    }


    /// A sensor turning at w (counter-clockwise) sees a static point at world azimuth a0
    /// where its clockwise sweep meets the point's apparent azimuth a0 - w t: at column
    /// coordinate u = W (pi - a0) / (2 pi - w T) instead of W (pi - a0) / (2 pi).
    #[test]
    fn a_turning_sensor_skews_static_points_as_in_closed_form() {
        let s = Sweep { t0_s: 0.0, period_s: 0.1, columns: 1024 };
        let w = 3.0; // rad/s: 0.3 rad over the sweep
        let pose = |t: f64| DMat4::from_rotation_z(w * t).inverse();
        for a0 in [-2.5f64, -1.0, 0.3, 1.7, 2.9] {
            let p = DVec3::new(8.0 * a0.cos(), 8.0 * a0.sin(), 0.5);
            let mut out = Vec::new();
            s.place_static(&[p], pose, &mut out);
            let q = glam::Vec3::from(out[0]).as_dvec3();
            let u = s.u_of(q.x, q.y);
            let pi = std::f64::consts::PI;
            let want = 1024.0 * (pi - a0) / (2.0 * pi - w * s.period_s);
            let still = 1024.0 * (pi - a0) / (2.0 * pi);
            assert!((u - want).abs() < 1e-3, "a0 {a0}: column {u} vs {want}");
            assert!((want - still).abs() > 1.0, "the skew is visible");
            assert!((q.length() - p.length()).abs() < 1e-5, "a turn keeps the range");
        }
    }

    #[test]
    fn column_times_follow_the_sweep_from_the_cut_behind_the_sensor() {
        let s = Sweep { t0_s: 2.0, period_s: 0.1, columns: 1024 };
        assert!((s.column_time(0) - (2.0 + 0.05 / 1024.0)).abs() < 1e-15);
        assert!((s.column_time(1023) - (2.1 - 0.05 / 1024.0)).abs() < 1e-12);
        // Straight ahead (+x) is the middle of the sweep; left (+y) a quarter in.
        assert!((s.u_of(1.0, 0.0) - 512.0).abs() < 1e-9);
        assert!((s.u_of(0.0, 1.0) - 256.0).abs() < 1e-9);
        // Behind: just left of the cut is the start, just right the end.
        assert!(s.u_of(-1.0, 1e-9) < 1e-3 && s.u_of(-1.0, -1e-9) > 1023.99);
        assert!((s.unwrap_near(1023.5, 0.5) - (-0.5)).abs() < 1e-12);
        assert!((s.unwrap_near(3.0, 1020.0) - 1027.0).abs() < 1e-12);
    }

    /// A segment moving sideways past the sensor: each vertex lands where the segment is at
    /// the time of its own column. The motion is linear, so what is left is the one
    /// fixed-point step's: the vertex's time is read where it is at the person's centre time,
    /// off by its motion over the span (about v^2: 0.3 mm at 1.5 m/s, 1.2 mm at 3 m/s, 4 m away).
    #[test]
    fn warp_between_puts_each_vertex_at_its_own_time() {
        let s = Sweep { t0_s: 0.0, period_s: 0.1, columns: 1024 };
        for (speed, tol) in [(1.5, 4e-4), (3.0, 1.5e-3)] {
            let v = DVec3::new(0.0, -speed, 0.0); // moving right (toward later columns)
            let rest: Vec<DVec3> = (0..21).map(|k| DVec3::new(4.0, -1.0 + 0.1 * k as f64, 0.2)).collect();
            let centre = DVec3::new(4.0, 0.0, 0.2);
            let (ta, tb, u_c) = s.span_of_sphere(centre, 1.0);
            let at = |t: f64| rest.iter().map(|p| (*p + v * t).as_vec3().to_array()).collect::<Vec<_>>();
            let mut a = at(ta);
            s.warp_between(&mut a, &at(tb), ta, tb, u_c);
            for (k, p) in a.iter().enumerate() {
                let q = glam::Vec3::from(*p).as_dvec3();
                // Where the segment's point k is when the column q lies in is fired.
                let t = s.time_at(s.u_of(q.x, q.y));
                let want = rest[k] + v * t;
                assert!((q - want).length() < tol, "{speed} m/s, vertex {k}: {q:?} vs {want:?}");
            }
        }
    }
}
