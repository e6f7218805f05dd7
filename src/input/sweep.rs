//! A recorded turn's own sweep: the time of each column boundary of the target grid, from the
//! firings a capture recorded ([`crate::input::Scan::firing_times`]: azimuth and time of each
//! firing, in capture order). A recording turns them into its frames' column times; the rolling
//! shutter ([`crate::sensor_model::shutter::Sweep::recorded`]) poses each column at them.
//! Clocks that step back or jump are refused with the reason, so that the frame falls back to
//! the uniform sweep.

/// How far back in time one firing of a recorded sweep may lie behind an earlier one and still
/// count as the capture's timestamp jitter, s: a network card stamping several packets at once
/// puts a packet's later firings up to one packet (1.3 ms on a VLP-16) after the next packet's
/// first; more than this is a clock stepping back.
pub const SWEEP_JITTER_S: f64 = 2e-3;

/// A step between firings of a recorded sweep is a jump of its clock when it takes more than
/// this many times the sweep's median time per turn for its turn, plus [`SWEEP_JITTER_S`]
/// (lost packets take as long as the turn they miss; a halved rotation speed twice as long).
pub const SWEEP_JUMP_FACTOR: f64 = 4.0;

/// The time of each column boundary `u = 0..=columns` of a recorded sweep, from its firings in
/// capture order: `[turn, time_s]`, `turn` the azimuth as a fraction of a turn clockwise from
/// straight behind the sensor (`u / W`, in `[0, 1)`), `time_s` when it was fired.
///
/// The azimuth is unwrapped from the first firing (a step of more than half a turn is one back
/// across the seam), and a firing that does not turn past the last kept one is dropped. The
/// times are then made monotone by isotonic regression (runs that go back are pooled into their
/// mean at their mean azimuth), so timestamp jitter smooths out instead of folding the sweep;
/// between kept firings the time is linear in azimuth, and columns no firing reached (lost
/// packets) get times interpolated between their neighbours. The ends of the turn outside the
/// firings continue at the sweep's mean rate. The result is strictly increasing.
///
/// Refused, with the reason, so that the frame falls back to the uniform sweep: fewer than two
/// firings, non-finite values, firings that cover less than half the turn, a step back in time
/// of more than [`SWEEP_JITTER_S`], a step forward of more than [`SWEEP_JUMP_FACTOR`] times
/// the median rate's for its turn (plus the jitter), and any result that is not finite and
/// strictly increasing.
pub fn boundary_times(firings: &[[f64; 2]], columns: usize) -> std::result::Result<Vec<f64>, String> {
    if columns == 0 || firings.len() < 2 {
        return Err(format!("{} firings in the turn", firings.len()));
    }
    if let Some(f) = firings.iter().find(|f| !(f[0].is_finite() && f[1].is_finite())) {
        return Err(format!("a firing at azimuth {} (turns) and time {} s", f[0], f[1]));
    }
    // Unwrapped azimuth, kept only while it turns on; times checked for steps back.
    let mut kept: Vec<[f64; 2]> = Vec::with_capacity(firings.len());
    // A first firing just before the seam belongs to the start of the turn.
    let mut turn = if firings[0][0] > 0.5 { firings[0][0] - 1.0 } else { firings[0][0] };
    let mut latest = firings[0][1];
    kept.push([turn, latest]);
    for pair in firings.windows(2) {
        turn += (pair[1][0] - pair[0][0] + 0.5).rem_euclid(1.0) - 0.5;
        let t = pair[1][1];
        if t < latest - SWEEP_JITTER_S {
            return Err(format!("its timestamps go back by {:.3} ms", 1e3 * (latest - t)));
        }
        latest = latest.max(t);
        if turn > kept[kept.len() - 1][0] {
            kept.push([turn, t]);
        }
    }
    let (first, last) = (kept[0][0], kept[kept.len() - 1][0]);
    if last - first < 0.5 || first > 0.25 || last < 0.75 {
        return Err(format!("its firings cover the turn only from {:.3} to {:.3}", first, last));
    }
    // Isotonic regression of time on azimuth (pool adjacent violators): each block is
    // (summed azimuth, summed time, count); a block not later than the one before merges.
    let mut blocks: Vec<(f64, f64, f64)> = Vec::with_capacity(kept.len());
    for &[a, t] in &kept {
        blocks.push((a, t, 1.0));
        while blocks.len() > 1 {
            let (a1, t1, n1) = blocks[blocks.len() - 1];
            let (a0, t0, n0) = blocks[blocks.len() - 2];
            if t1 / n1 > t0 / n0 {
                break;
            }
            blocks.pop();
            *blocks.last_mut().expect("two blocks") = (a0 + a1, t0 + t1, n0 + n1);
        }
    }
    let knots: Vec<[f64; 2]> = blocks.iter().map(|&(a, t, n)| [a / n, t / n]).collect();
    let mean = if knots.len() > 1 {
        (knots[knots.len() - 1][1] - knots[0][1]) / (knots[knots.len() - 1][0] - knots[0][0])
    } else {
        0.0
    };
    if !(mean > 0.0 && mean.is_finite()) {
        return Err("its firings do not advance in time".into());
    }
    let mut rates: Vec<f64> = knots.windows(2).map(|k| (k[1][1] - k[0][1]) / (k[1][0] - k[0][0])).collect();
    let mid = rates.len() / 2;
    let median = *rates.select_nth_unstable_by(mid, f64::total_cmp).1;
    for k in knots.windows(2) {
        let (da, dt) = (k[1][0] - k[0][0], k[1][1] - k[0][1]);
        if dt > SWEEP_JUMP_FACTOR * median * da + SWEEP_JITTER_S {
            return Err(format!("its timestamps jump by {:.3} ms over {:.2} degrees", 1e3 * dt, 360.0 * da));
        }
    }
    let mut out = Vec::with_capacity(columns + 1);
    let mut j = 0;
    for c in 0..=columns {
        let a = c as f64 / columns as f64;
        let t = if a <= knots[0][0] {
            knots[0][1] - mean * (knots[0][0] - a)
        } else if a >= knots[knots.len() - 1][0] {
            knots[knots.len() - 1][1] + mean * (a - knots[knots.len() - 1][0])
        } else {
            while knots[j + 1][0] < a {
                j += 1;
            }
            let ([a0, t0], [a1, t1]) = (knots[j], knots[j + 1]);
            t0 + (t1 - t0) * (a - a0) / (a1 - a0)
        };
        out.push(t);
    }
    if !out.iter().all(|t| t.is_finite()) || !out.windows(2).all(|w| w[1] > w[0]) {
        return Err("its column times would not increase strictly".into());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Firings of a turn whose first half takes 60 ms and second 30 ms, every 0.1 degree.
    fn firings(time: impl Fn(f64) -> f64) -> Vec<[f64; 2]> {
        (0..=3600).map(|n| n as f64 / 3600.0).map(|a| [a.rem_euclid(1.0), time(a)]).collect()
    }

    fn two_speeds(a: f64) -> f64 {
        if a <= 0.5 { 0.12 * a } else { 0.06 + 0.06 * (a - 0.5) }
    }

    #[test]
    fn boundary_times_follow_the_firings_and_smooth_jitter() {
        let b = boundary_times(&firings(two_speeds), 1024).unwrap();
        assert_eq!(b.len(), 1025);
        for (c, t) in b.iter().enumerate() {
            assert!((t - two_speeds(c as f64 / 1024.0)).abs() < 1e-9, "boundary {c}: {t}");
        }
        // Jitter of up to 1 ms back (a batch of packets stamped late), lost firings and a
        // first firing just before the seam: still strictly increasing, within the jitter.
        let mut f = firings(two_speeds);
        for (n, x) in f.iter_mut().enumerate() {
            x[1] += [0.0, 0.4e-3, 0.9e-3, -0.6e-3][n % 4];
        }
        f.drain(1000..1400);
        f[0][0] = 0.9999;
        let b = boundary_times(&f, 1024).unwrap();
        assert!(b.windows(2).all(|w| w[1] > w[0]));
        // A firing repeated at the same azimuth a little later (a second return's packet) is
        // the same firing: the table does not change.
        let mut twice = f.clone();
        twice.insert(1801, [twice[1800][0], twice[1800][1] + 0.5e-3]);
        assert_eq!(boundary_times(&twice, 1024).unwrap(), b);
        for (c, t) in b.iter().enumerate() {
            assert!((t - two_speeds(c as f64 / 1024.0)).abs() < 1e-3, "boundary {c}: {t}");
        }
    }

    #[test]
    fn boundary_times_refuse_clocks_that_step_back_or_jump() {
        let mut back = firings(two_speeds);
        for x in &mut back[2000..2100] {
            x[1] -= 0.01;
        }
        assert!(boundary_times(&back, 1024).unwrap_err().contains("go back by 9.98"));
        let mut jump = firings(two_speeds);
        for x in &mut jump[2000..] {
            x[1] += 0.5;
        }
        assert!(boundary_times(&jump, 1024).unwrap_err().contains("jump"));
        // Lost packets over a twentieth of the turn take the time of the turn they miss (or
        // twice that, at half the speed): kept. The clock jumping over them by ten times the
        // median rate's time for that turn is refused.
        let steady = |gap_factor: f64| {
            let mut f: Vec<[f64; 2]> = (0..=3600).map(|n| n as f64 / 3600.0).map(|a| [a.rem_euclid(1.0), 0.1 * a]).collect();
            f.retain(|x| !(0.4 < x[0] && x[0] < 0.45));
            for x in f.iter_mut().filter(|x| x[1] > 0.0425) {
                x[1] += (gap_factor - 1.0) * 0.1 * 0.05;
            }
            boundary_times(&f, 1024)
        };
        assert!(steady(1.0).is_ok() && steady(2.0).is_ok());
        assert!(steady(10.0).unwrap_err().contains("jump"));
        let part: Vec<[f64; 2]> = firings(two_speeds)[..1000].to_vec();
        assert!(boundary_times(&part, 1024).unwrap_err().contains("cover"));
        let mut nan = firings(two_speeds);
        nan[7][1] = f64::NAN;
        let err = boundary_times(&nan, 1024).unwrap_err();
        assert!(err.starts_with("a firing at azimuth") && err.ends_with("and time NaN s"), "{err}");
        nan[7] = [f64::INFINITY, 0.01];
        assert!(boundary_times(&nan, 1024).unwrap_err().contains("azimuth inf (turns)"));
        assert!(boundary_times(&[], 1024).is_err());
        // Half the turn exactly (a quarter to three quarters, exact in binary) is enough;
        // any less is refused.
        let half: Vec<[f64; 2]> = (0..=512).map(|k| [0.25 + k as f64 / 1024.0, 0.025 + 0.1 * k as f64 / 1024.0]).collect();
        assert_eq!((half[0][0], half[512][0]), (0.25, 0.75));
        let out = boundary_times(&half, 1024).unwrap();
        assert!((out[512] - 0.05).abs() < 1e-12 && (out[0] - 0.0).abs() < 1e-12, "{} {}", out[0], out[512]);
        assert!(boundary_times(&half[..512], 1024).unwrap_err().contains("cover"));
        assert!(boundary_times(&half[1..], 1024).unwrap_err().contains("cover"));
        let still: Vec<[f64; 2]> = firings(|_| 1.0);
        assert!(boundary_times(&still, 1024).is_err());
    }

    /// Hostile firings (any azimuths, times that wander back and forth, repeats, huge and tiny
    /// values) never panic, and what is accepted is finite and strictly increasing.
    #[test]
    fn boundary_times_never_panic_and_accept_only_increasing_times() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut accepted = 0;
        for case in 0..2000 {
            let n = (next() * 300.0) as usize;
            let scale = [1e-9, 1e-3, 1.0, 1e9][case % 4];
            let f: Vec<[f64; 2]> = (0..n)
                .map(|i| {
                    let a = if case % 3 == 0 { next() } else { (i as f64 / n as f64 + 0.01 * (next() - 0.5)).rem_euclid(1.0) };
                    let t = if case % 5 == 0 { next() * scale } else { (i as f64 + 3.0 * (next() - 0.5)) * scale * 1e-3 };
                    [a, t]
                })
                .collect();
            if let Ok(b) = boundary_times(&f, 64 + case % 7) {
                accepted += 1;
                assert!(b.iter().all(|t| t.is_finite()) && b.windows(2).all(|w| w[1] > w[0]), "case {case}");
            }
        }
        assert!(accepted > 100, "{accepted}");
    }
}
