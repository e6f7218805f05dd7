//! The rolling shutter: a spinning sensor fires column by column over its period, so each
//! column sees the people, the environment and its own pose at its own time. The frame is cut
//! behind the sensor: column `c` is taken at `t_frame + (c + 0.5) / (W * rate)`, or, under a
//! recording that carries its own sweep (a Velodyne `.pcap`), at the time the capture's sensor
//! pointed there: a table of times at the column boundaries, linear in between
//! ([`Sweep::recorded`], from [`crate::input::sweep::boundary_times`]).
//!
//! The reference poses the whole frame at each column's time and casts that column alone
//! ([`crate::generator::Generator::reference_rolling_hits`]): exact, and ~W times the work.
//! The default ([`Sweep::warp_between`]) poses each person twice, at the first and last time
//! its bounding sphere spans, and moves every vertex to its own time by linear interpolation
//! between the two (linear blend skinning is linear in the joint matrices, so this is the
//! skinning at interpolated matrices); a vertex's time is that of the column its azimuth falls
//! in, found by one fixed-point step. A static environment under a moving sensor moves each
//! vertex by the sensor's pose at the vertex's own time. The error left is second order in the
//! person's column span (docs/sensor-model.md, for the measured figures); a person cut by
//! the frame's edge (behind the sensor) is unwrapped around its centre, so it is seen whole at
//! times just before the sweep instead of torn between its start and its end.

use crate::sensor::atan2_fast;
use glam::{DMat4, DVec3};

/// The timing of one sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct Sweep {
    /// Time of the frame (the start of the sweep), s from the sequence start.
    pub t0_s: f64,
    /// One revolution, s; 0 = every column at `t0_s` (no rolling shutter). With `boundaries`,
    /// their span (the last minus the first).
    pub period_s: f64,
    pub columns: usize,
    /// The time of each column boundary `u = 0..=W` (W + 1 entries, strictly increasing), s
    /// from the sequence start, when the sweep is a recording's own; `None`: uniform from
    /// `t0_s` over `period_s`.
    pub boundaries: Option<std::sync::Arc<[f64]>>,
}

impl Sweep {
    /// A sweep at a constant rate: `period_s` over the `columns` from `t0_s`.
    pub fn uniform(t0_s: f64, period_s: f64, columns: usize) -> Sweep {
        Sweep { t0_s, period_s, columns, boundaries: None }
    }

    /// A recorded sweep of frame time `t0_s`: `boundaries` holds the time of each column
    /// boundary (W + 1 entries, strictly increasing, as
    /// [`crate::input::sweep::boundary_times`] gives them).
    pub fn recorded(t0_s: f64, boundaries: std::sync::Arc<[f64]>) -> Sweep {
        let w = boundaries.len().saturating_sub(1);
        let period_s = if w > 0 { boundaries[w] - boundaries[0] } else { 0.0 };
        Sweep { t0_s, period_s, columns: w, boundaries: (w > 0).then_some(boundaries) }
    }

    /// The time of continuous column coordinate `u` (column `c` spans `[c, c + 1)`; its beam
    /// sits at `c + 0.5`); `u` may lie outside `[0, W)` for a person unwrapped over the cut.
    /// A recorded sweep is linear between its column boundaries and continues beyond its ends
    /// at its mean rate.
    #[inline]
    pub fn time_at(&self, u: f64) -> f64 {
        let Some(b) = &self.boundaries else {
            return self.t0_s + self.period_s * u / self.columns as f64;
        };
        let w = self.columns;
        if u <= 0.0 {
            b[0] + self.period_s * u / w as f64
        } else if u >= w as f64 {
            b[w] + self.period_s * (u - w as f64) / w as f64
        } else {
            let c = (u as usize).min(w - 1);
            b[c] + (b[c + 1] - b[c]) * (u - c as f64)
        }
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
        (crate::sensor::turn_of(x, y) * w).rem_euclid(w)
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
        // The time (as a fraction of the span) of the column at `angle` from the centre's: a
        // constant rate per radian, or a recorded sweep's own table (its rate may change
        // within a person's span), taken at the whole column coordinates from where the span
        // starts to where it ends (beyond, the fraction is clamped anyway) and linear between.
        let columns_per_rad = (self.columns as f64 / std::f64::consts::TAU) as f32;
        let table: Option<(f32, Vec<f32>)> = self.boundaries.as_ref().map(|_| {
            let w = self.columns as f64;
            let (mut lo, mut hi) = (u_ref.floor(), u_ref.ceil() + 1.0);
            while self.time_at(lo) > ta && lo > u_ref - w {
                lo -= 1.0;
            }
            while self.time_at(hi) < tb && hi < u_ref + w {
                hi += 1.0;
            }
            let lambdas = (0..=(hi - lo) as usize).map(|i| ((self.time_at(lo + i as f64) - ta) / span) as f32).collect();
            ((u_ref - lo) as f32, lambdas)
        });
        match table {
            None => warp_with(a, keys, lambda_ref, angle, |x| lambda_ref - per_rad * x),
            Some((origin, lambdas)) => {
                let last = lambdas.len() - 1;
                let lambda_of = |angle: f32| -> f32 {
                    let x = origin - angle * columns_per_rad;
                    if !(x > 0.0) {
                        return lambdas[0];
                    }
                    let i = x as usize;
                    if i >= last {
                        return lambdas[last];
                    }
                    lambdas[i] + (lambdas[i + 1] - lambdas[i]) * (x - i as f32)
                };
                warp_with(a, keys, lambda_ref, angle, lambda_of)
            }
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

/// [`Sweep::warp_keys`]'s loop over the vertices, for one way of finding a vertex's time:
/// `lambda_of(angle)` is the time, as a fraction of the span, of the column at `angle` from
/// the centre's direction (a separate instance per way, so the uniform sweep's loop stays as
/// tight as it was).
#[inline]
fn warp_with<K: AsRef<[[f32; 3]]>>(
    a: &mut [[f32; 3]],
    keys: &[K],
    lambda_ref: f32,
    angle: impl Fn(glam::Vec3) -> f32,
    lambda_of: impl Fn(f32) -> f32,
) {
    let n = keys.len();
    if n == 1 {
        // Two poses (most people): straight-line code.
        let b = keys[0].as_ref();
        assert_eq!(a.len(), b.len(), "both poses hold every vertex");
        for (pa, pb) in a.iter_mut().zip(b) {
            let (qa, qb) = (glam::Vec3::from(*pa), glam::Vec3::from(*pb));
            let lambda = lambda_of(angle(qa.lerp(qb, lambda_ref))).clamp(0.0, 1.0);
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
        let lambda = lambda_of(angle(at(v, first, lambda_ref)));
        *pa = at(v, first, lambda).to_array();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sensor turning at w (counter-clockwise) sees a static point at world azimuth a0
    /// where its clockwise sweep meets the point's apparent azimuth a0 - w t: at column
    /// coordinate u = W (pi - a0) / (2 pi - w T) instead of W (pi - a0) / (2 pi).
    #[test]
    fn a_turning_sensor_skews_static_points_as_in_closed_form() {
        let s = Sweep::uniform(0.0, 0.1, 1024);
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
        let s = Sweep::uniform(2.0, 0.1, 1024);
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

    /// A sphere's span of columns in closed form: its centre's column plus and minus the half
    /// angle it subtends, asin(radius / horizontal distance), and one column of margin on each
    /// side; a sphere holding the sensor spans the whole turn around its centre.
    #[test]
    fn a_spheres_time_span_is_the_angle_it_subtends_plus_a_column() {
        let s = Sweep::uniform(1.0, 0.1, 1000);
        let col = 0.1 / 1000.0;
        // 10 m ahead (+x: column 500), 1 m in radius, 3 m up (the height does not count).
        let (ta, tb, u) = s.span_of_sphere(DVec3::new(10.0, 0.0, 3.0), 1.0);
        let du = 0.1f64.asin() / std::f64::consts::TAU * 1000.0;
        assert!((u - 500.0).abs() < 1e-9);
        assert!((ta - (1.0 + (500.0 - du - 1.0) * col)).abs() < 1e-12, "{ta}");
        assert!((tb - (1.0 + (500.0 + du + 1.0) * col)).abs() < 1e-12, "{tb}");
        // Every point of the sphere's horizontal outline lies inside the span.
        for k in 0..360 {
            let a = (k as f64).to_radians();
            let t = s.time_at(s.unwrap_near(s.u_of(10.0 + a.cos(), a.sin()), u));
            assert!(t > ta + 0.5 * col && t < tb - 0.5 * col, "{k} deg: {t}");
        }
        // 1.5 m away, 1 m in radius: near, but not holding the sensor (asin(2/3) each way).
        let (ta, tb, u) = s.span_of_sphere(DVec3::new(-1.5, 0.0, 0.0), 1.0);
        let du = (2.0f64 / 3.0).asin() / std::f64::consts::TAU * 1000.0;
        assert!((ta - s.time_at(u - du - 1.0)).abs() < 1e-12 && (tb - s.time_at(u + du + 1.0)).abs() < 1e-12, "{ta} {tb}");
        // Holding the sensor: half a turn each way, plus the margin.
        // (On its surface or just inside it, too: no arcsine of more than 1.)
        for centre in [DVec3::new(0.5, 0.2, 0.0), DVec3::new(0.0, -0.999, 0.0), DVec3::new(1.0, 0.0, 0.0), DVec3::new(0.0, 0.99995, 0.0)] {
            let (ta, tb, u) = s.span_of_sphere(centre, 1.0);
            assert!((ta - s.time_at(u - 501.0)).abs() < 1e-12 && (tb - s.time_at(u + 501.0)).abs() < 1e-12, "{centre}: {ta} {tb}");
        }
    }

    /// A segment moving sideways past the sensor: each vertex lands where the segment is at
    /// the time of its own column. The motion is linear, so what is left is the one
    /// fixed-point step's: the vertex's time is read where it is at the person's centre time,
    /// off by its motion over the span (about v^2: 0.3 mm at 1.5 m/s, 1.2 mm at 3 m/s, 4 m away).
    #[test]
    fn warp_between_puts_each_vertex_at_its_own_time() {
        let s = Sweep::uniform(0.0, 0.1, 1024);
        for (speed, tol) in [(1.5, 4e-4), (3.0, 1.5e-3)] {
            let (rest, v, warped) = warped_segment(&s, speed);
            for (k, &q) in warped.iter().enumerate() {
                // Where the segment's point k is when the column q lies in is fired.
                let t = s.time_at(s.u_of(q.x, q.y));
                let want = rest[k] + v * t;
                assert!((q - want).length() < tol, "{speed} m/s, vertex {k}: {q:?} vs {want:?}");
            }
        }
    }

    /// A sweep whose first half turns at half the speed of its second: 60 ms then 30 ms.
    fn uneven(t0: f64, columns: usize) -> Sweep {
        let w = columns as f64;
        let b: Vec<f64> = (0..=columns)
            .map(|c| {
                let u = c as f64;
                t0 + if u <= w / 2.0 { 0.06 * u / (w / 2.0) } else { 0.06 + 0.03 * (u - w / 2.0) / (w / 2.0) }
            })
            .collect();
        Sweep::recorded(t0, b.into())
    }

    #[test]
    fn a_recorded_sweep_is_linear_between_its_boundaries_and_continues_at_its_mean_rate() {
        let s = uneven(2.0, 1024);
        assert_eq!((s.columns, s.rolls()), (1024, true));
        assert!((s.period_s - 0.09).abs() < 1e-12);
        assert!((s.time_at(256.0) - 2.03).abs() < 1e-12);
        assert!((s.time_at(768.0) - 2.075).abs() < 1e-12);
        assert!((s.column_time(0) - (2.0 + 0.5 * 0.06 / 512.0)).abs() < 1e-12);
        // Beyond the ends (a person unwrapped over the cut), the mean rate: 0.09 s a turn.
        assert!((s.time_at(-10.0) - (2.0 - 10.0 * 0.09 / 1024.0)).abs() < 1e-12);
        assert!((s.time_at(1034.0) - (2.09 + 10.0 * 0.09 / 1024.0)).abs() < 1e-12);
        // The uniform sweep is as it was.
        let u = Sweep::uniform(2.0, 0.1, 1024);
        assert_eq!(u.time_at(300.0), 2.0 + 0.1 * 300.0 / 1024.0);
        assert!(u.rolls());
        // A sweep of no duration (every column fired at once) does not roll.
        let still = Sweep::uniform(2.0, 0.0, 1024);
        assert!(!still.rolls() && still.time_at(700.0) == 2.0);
    }

    /// A 2 m segment 4 m straight ahead moving right (toward later columns) at `speed`, warped
    /// over `s`: its points at time 0, its velocity and its warped vertices.
    fn warped_segment(s: &Sweep, speed: f64) -> (Vec<DVec3>, DVec3, Vec<DVec3>) {
        warped_segment_at(s, speed, DVec3::new(4.0, 0.0, 0.2))
    }

    /// [`warped_segment`] centred on `centre`, along y.
    fn warped_segment_at(s: &Sweep, speed: f64, centre: DVec3) -> (Vec<DVec3>, DVec3, Vec<DVec3>) {
        let v = DVec3::new(0.0, -speed, 0.0);
        let rest: Vec<DVec3> = (0..21).map(|k| centre + DVec3::new(0.0, -1.0 + 0.1 * k as f64, 0.0)).collect();
        let (ta, tb, u_c) = s.span_of_sphere(centre, 1.0);
        let at = |t: f64| rest.iter().map(|p| (*p + v * t).as_vec3().to_array()).collect::<Vec<_>>();
        let mut a = at(ta);
        s.warp_between(&mut a, &at(tb), ta, tb, u_c);
        (rest, v, a.iter().map(|p| glam::Vec3::from(*p).as_dvec3()).collect())
    }

    /// [`warp_between_puts_each_vertex_at_its_own_time`] on a recorded sweep whose rate
    /// changes inside the person's span: each vertex is where the segment is when its own
    /// column is fired by the table, which the uniform sweep of the same length misses.
    #[test]
    fn warp_on_a_recorded_sweep_puts_each_vertex_at_its_table_time() {
        let s = uneven(0.0, 1024);
        let uniform = Sweep::uniform(0.0, s.period_s, 1024);
        // Straight ahead, across the middle of the sweep where the rate doubles.
        let (rest, v, warped) = warped_segment(&s, 3.0);
        let mut worst_uniform = 0.0f64;
        for (k, &q) in warped.iter().enumerate() {
            let u = s.u_of(q.x, q.y);
            let want = rest[k] + v * s.time_at(u);
            assert!((q - want).length() < 1.5e-3, "vertex {k}: {q:?} vs {want:?}");
            worst_uniform = worst_uniform.max((q - (rest[k] + v * uniform.time_at(u))).length());
        }
        assert!(worst_uniform > 0.02, "the table's times differ from the uniform sweep's: {worst_uniform}");
        // Straight behind, across the cut: the table runs from before column 0 (the mean
        // rate beyond the ends) to past it, and each vertex's column is unwrapped near the
        // centre's.
        let centre = DVec3::new(-4.0, 0.1, 0.2);
        let (rest, v, warped) = warped_segment_at(&s, 3.0, centre);
        let u_c = s.u_of(centre.x, centre.y);
        assert!(u_c < 10.0 && warped.iter().any(|q| s.u_of(q.x, q.y) > 1000.0), "the segment crosses the cut");
        for (k, &q) in warped.iter().enumerate() {
            let want = rest[k] + v * s.time_at(s.unwrap_near(s.u_of(q.x, q.y), u_c));
            assert!((q - want).length() < 1.5e-3, "vertex {k} behind: {q:?} vs {want:?}");
        }
    }

    /// A recorded sweep whose boundaries are the uniform sweep's warps as the uniform sweep
    /// does (the table's interpolation between whole columns against the constant rate), to
    /// f32 rounding: a column's time is 0.1 ms, in which a vertex at 3 m/s moves 0.3 mm.
    #[test]
    fn a_recorded_sweep_at_a_constant_rate_warps_as_the_uniform_sweep() {
        let uniform = Sweep::uniform(0.0, 0.1, 1024);
        let table = Sweep::recorded(0.0, (0..=1024).map(|c| 0.1 * c as f64 / 1024.0).collect::<Vec<_>>().into());
        assert!(table.boundaries.is_some() && uniform.boundaries.is_none());
        for centre in [DVec3::new(4.0, 0.0, 0.2), DVec3::new(-4.0, 0.1, 0.2), DVec3::new(1.0, 3.0, 0.2)] {
            let (_, _, a) = warped_segment_at(&uniform, 3.0, centre);
            let (_, _, b) = warped_segment_at(&table, 3.0, centre);
            for (k, (p, q)) in a.iter().zip(&b).enumerate() {
                assert!((*p - *q).length() < 2e-6, "{centre}, vertex {k}: {p} vs {q}");
            }
        }
    }

    /// Over several keys, a vertex whose column lies beyond the span (its time before `ta` or
    /// after `tb`) stays at the first pose or takes the last key's.
    #[test]
    fn vertices_outside_the_span_take_the_first_pose_or_the_last_key() {
        let s = Sweep::uniform(0.0, 0.1, 1024);
        // A segment across straight ahead, keys over only the middle 20 columns' times: most
        // vertices lie outside.
        let rest: Vec<[f32; 3]> = (0..21).map(|k| [4.0, -1.0 + 0.1 * k as f32, 0.2]).collect();
        let moved = |dy: f32| rest.iter().map(|p| [p[0], p[1] + dy, p[2]]).collect::<Vec<_>>();
        let keys = [moved(0.01), moved(0.02), moved(0.03)];
        let (ta, tb) = (s.time_at(502.0), s.time_at(522.0));
        let mut a = rest.clone();
        s.warp_keys(&mut a, &keys, ta, tb, 512.0);
        let (mut before, mut after) = (0, 0);
        for (k, (q, p)) in a.iter().zip(&rest).enumerate() {
            let t = s.time_at(s.u_of(p[0] as f64, p[1] as f64));
            if t < ta - 1e-4 {
                assert_eq!(q, p, "vertex {k}: before the span");
                before += 1;
            } else if t > tb + 1e-4 {
                // (The last key's weight is clamped to 1 - 1e-4 / keys: a micrometre here.)
                let off = (glam::Vec3::from(*q) - glam::Vec3::from(keys[2][k])).length();
                assert!(off < 2e-6, "vertex {k}: after the span, {off} m from the last key");
                after += 1;
            }
        }
        assert!(before > 3 && after > 3, "{before} before, {after} after");
    }

    /// Nothing to warp between (no keys, or a span of no time): the vertices stay as given.
    #[test]
    fn warp_without_keys_or_time_leaves_the_vertices() {
        let s = Sweep::uniform(0.0, 0.1, 1024);
        let a0 = vec![[4.0f32, -0.5, 0.2], [4.0, 0.5, 0.2]];
        let mut a = a0.clone();
        s.warp_keys(&mut a, &[] as &[Vec<[f32; 3]>], 0.04, 0.06, 512.0);
        assert_eq!(a, a0);
        let b = vec![[4.0f32, -0.4, 0.2], [4.0, 0.6, 0.2]];
        for (ta, tb) in [(0.05, 0.05), (0.06, 0.04)] {
            s.warp_between(&mut a, &b, ta, tb, 512.0);
            assert_eq!(a, a0, "span {ta}..{tb}");
        }
    }
}
