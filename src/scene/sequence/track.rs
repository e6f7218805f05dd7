//! A recorded pedestrian track walked as a person's path ([`super::HumanPath::Track`]).

use crate::input::tracks::Track;
use glam::DVec2;
use std::sync::Arc;

/// A recorded pedestrian track as a person's path: the track's smooth interpolant, shifted so
/// that sequence time 0 is track time `t0_s`, standing on the floor at height `z_m`.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackPath {
    pub track: Arc<Track>,
    pub t0_s: f64,
    pub z_m: f64,
    /// Distance walked at k * 10 ms from time 0 (see [`TrackPath::new`]).
    walked_m: Vec<f64>,
}

/// Step of the distance integral along a track, s.
const TRACK_DISTANCE_STEP_S: f64 = 0.01;

impl TrackPath {
    /// Position, velocity and heading at sequence time `t_s`. Outside the track's span the
    /// end state is held (a window is only ever cut inside the span).
    pub(super) fn state(&self, t_s: f64) -> (DVec2, DVec2, f64) {
        let tr = &self.track;
        let (a, b) = (tr.times_s[0], *tr.times_s.last().unwrap_or(&tr.times_s[0]));
        let t = (self.t0_s + t_s).clamp(a, b);
        match tr.sample(t) {
            Some(s) => (s.position_m, if t == self.t0_s + t_s { s.velocity_mps } else { DVec2::ZERO }, s.heading_rad),
            None => (tr.xy_m[0], DVec2::ZERO, 0.0),
        }
    }

    /// A path along `track` from track time `t0_s`, with its distance table over the first
    /// `duration_s` seconds (so the gait phase of each frame costs O(1), not O(t)).
    pub fn new(track: Arc<Track>, t0_s: f64, z_m: f64, duration_s: f64) -> TrackPath {
        let mut p = TrackPath { track, t0_s, z_m, walked_m: Vec::new() };
        let steps = (duration_s.max(0.0) / TRACK_DISTANCE_STEP_S).ceil() as usize;
        let mut sum = 0.0;
        p.walked_m.push(0.0);
        for k in 0..steps {
            sum += p.simpson(k as f64 * TRACK_DISTANCE_STEP_S, (k + 1) as f64 * TRACK_DISTANCE_STEP_S);
            p.walked_m.push(sum);
        }
        p
    }

    /// Simpson's rule for the speed of the interpolant over [a, b].
    fn simpson(&self, a: f64, b: f64) -> f64 {
        let speed = |t: f64| self.state(t).1.length();
        (b - a) / 6.0 * (speed(a) + 4.0 * speed(0.5 * (a + b)) + speed(b))
    }

    /// Arc length walked from time 0 to `t_s`: Simpson's rule on the speed of the interpolant
    /// in steps of 10 ms (the interpolant is a piecewise cubic, so this is exact to well under
    /// a millimetre per metre): the table up to the last whole step, one step after it.
    pub(super) fn distance(&self, t_s: f64) -> f64 {
        if t_s <= 0.0 {
            return 0.0;
        }
        let k = ((t_s / TRACK_DISTANCE_STEP_S).floor() as usize).min(self.walked_m.len().saturating_sub(1));
        let (mut t, mut d) = match self.walked_m.get(k) {
            Some(&d) => (k as f64 * TRACK_DISTANCE_STEP_S, d),
            None => (0.0, 0.0),
        };
        // Past the table (or without one): whole steps, then the rest.
        while t_s - t > TRACK_DISTANCE_STEP_S {
            d += self.simpson(t, t + TRACK_DISTANCE_STEP_S);
            t += TRACK_DISTANCE_STEP_S;
        }
        if t_s > t {
            d += self.simpson(t, t_s);
        }
        d
    }

    /// The first time at which the distance walked is `d_m` (before 0 or past the table: at
    /// the speed there); None where the track stands still there.
    pub(super) fn time_at_distance(&self, d_m: f64) -> Option<f64> {
        let at_speed = |t0: f64, d0: f64, v: f64| (v > 1e-9).then(|| t0 + (d_m - d0) / v);
        let w = &self.walked_m;
        let last = w.len().saturating_sub(1);
        if d_m <= 0.0 || last == 0 {
            return at_speed(0.0, 0.0, self.state(0.0).1.length());
        }
        if d_m > w[last] {
            let t = last as f64 * TRACK_DISTANCE_STEP_S;
            return at_speed(t, w[last], self.state(t).1.length());
        }
        let i = w.partition_point(|&x| x < d_m).max(1);
        let f = if w[i] > w[i - 1] { (d_m - w[i - 1]) / (w[i] - w[i - 1]) } else { 0.0 };
        Some((i as f64 - 1.0 + f) * TRACK_DISTANCE_STEP_S)
    }
}
