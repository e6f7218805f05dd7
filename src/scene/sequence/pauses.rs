//! Stops along a walk (`humans.stop_and_go`, and a long sequence's walks from a wait to a goal).

/// When a person who walks a path stops: stops `[start, end)` in sequence time, each entered
/// and left over [`Pauses::RAMP_S`] at a pace falling (rising) linearly between 1 and 0, so
/// the speed, and with it the blend to the standing pose, change smoothly. A stop may begin at
/// minus infinity (the walk starts from standing: its time 0 is where the stop ends, its pace
/// rising from there) and end at infinity (the walk ends standing where the stop begins).
#[derive(Clone, Debug, PartialEq)]
pub struct Pauses {
    /// Sorted, each at least two ramps after the one before.
    stops: Vec<(f64, f64)>,
}

impl Pauses {
    /// Time to slow down from the walk to a stop, and to get going again, s.
    pub const RAMP_S: f64 = 0.6;

    /// Stops `[start, end)`, kept in order and apart (a stop that would begin within two
    /// ramps of the previous one's end is dropped). A stop from minus infinity must end at 0 or
    /// later.
    pub fn new(mut stops: Vec<(f64, f64)>) -> Pauses {
        stops.retain(|&(a, b)| a < f64::INFINITY && b > a && (a.is_finite() || b >= 0.0));
        stops.sort_by(|p, q| p.0.total_cmp(&q.0));
        let mut kept: Vec<(f64, f64)> = Vec::new();
        for s in stops {
            if kept.last().is_none_or(|k| s.0 - Pauses::RAMP_S >= k.1 + Pauses::RAMP_S) {
                kept.push(s);
            }
        }
        Pauses { stops: kept }
    }

    /// The pace at `t_s`: 1 walking, 0 stopped, linear over the ramps.
    pub fn pace(&self, t_s: f64) -> f64 {
        let r = Pauses::RAMP_S;
        for &(a, b) in &self.stops {
            if t_s >= a - r && t_s < a {
                return (a - t_s) / r;
            }
            if t_s >= a && t_s < b {
                return 0.0;
            }
            if t_s >= b && t_s < b + r {
                return (t_s - b) / r;
            }
        }
        1.0
    }

    /// The time along the walked path at sequence time `t_s`: `t_s` less what the stops have
    /// held back so far (the integral of 1 - pace from the first ramp; a stop from minus
    /// infinity holds back from time 0 only).
    pub fn walked_time(&self, t_s: f64) -> f64 {
        let r = Pauses::RAMP_S;
        let mut lost = 0.0;
        for &(a, b) in &self.stops {
            if t_s <= a - r {
                break;
            }
            if a.is_finite() {
                // Slowing: 1 - pace = (s - a + r) / r over [a - r, a].
                let x = t_s.min(a) - (a - r);
                lost += x * x / (2.0 * r);
                if t_s > a {
                    lost += t_s.min(b) - a;
                }
            } else {
                // Standing from the start: held at time 0 until b.
                lost += t_s.min(b);
            }
            if t_s > b {
                // Getting going: 1 - pace = 1 - (s - b) / r over [b, b + r].
                let y = t_s.min(b + r) - b;
                lost += y - y * y / (2.0 * r);
            }
        }
        t_s - lost
    }

    /// The first sequence time at which the walked time is `u` (the inverse of
    /// [`Pauses::walked_time`], which never decreases), by bisection to 1 us; None past where
    /// a stop that never ends begins.
    pub fn time_walked(&self, u: f64) -> Option<f64> {
        let r = Pauses::RAMP_S;
        let mut hi = u + 1e-9;
        for &(a, b) in &self.stops {
            if b == f64::INFINITY {
                if u > self.walked_time(a) {
                    return None;
                }
                hi = hi.min(a);
            } else {
                let from = if a.is_finite() { a } else { 0.0 };
                hi += b - from + r;
            }
        }
        let mut lo = u.min(hi);
        if self.walked_time(lo) >= u {
            return Some(lo);
        }
        while hi - lo > 1e-6 {
            let mid = 0.5 * (lo + hi);
            if self.walked_time(mid) < u { lo = mid } else { hi = mid }
        }
        Some(hi)
    }

    pub fn stops(&self) -> &[(f64, f64)] {
        &self.stops
    }
}

