//! Axes of a plot: linear and log ranges with "nice" ticks and their labels.

// ---------------------------------------------------------------------------------------------
// Axes and ticks
// ---------------------------------------------------------------------------------------------

/// A tick at `pos` in axis space (log10 of the value on log axes).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Tick {
    pub(super) pos: f64,
    pub(super) label: String,
}

/// One axis: its range in axis space, labelled ticks and unlabelled minor grid positions.
#[derive(Debug, Clone)]
pub(super) struct Axis {
    pub(super) lo: f64,
    pub(super) hi: f64,
    pub(super) ticks: Vec<Tick>,
    pub(super) minor: Vec<f64>,
}

/// Largest magnitude kept on a linear axis, so spans stay finite.
pub(super) const LIN_LIMIT: f64 = 1e300;

/// `v` in axis space, or `None` if it cannot be drawn.
pub(super) fn to_axis(v: f64, log: bool) -> Option<f64> {
    if !v.is_finite() {
        None
    } else if log {
        (v > 0.0).then(|| v.log10())
    } else {
        Some(v.clamp(-LIN_LIMIT, LIN_LIMIT))
    }
}

impl Axis {
    /// An axis covering the axis-space values `lo ..= hi` (`None`: no data).
    pub(super) fn new(range: Option<(f64, f64)>, log: bool) -> Axis {
        if log {
            log_axis(range.unwrap_or((0.0, 1.0)))
        } else {
            linear_axis(range.unwrap_or((0.0, 1.0)))
        }
    }
}

pub(super) fn linear_axis((lo, hi): (f64, f64)) -> Axis {
    let (mut lo, mut hi) = (lo.min(hi), lo.max(hi));
    let mag = lo.abs().max(hi.abs());
    if hi - lo <= mag * 1e-9 || hi - lo < 1e-290 {
        // All equal (or indistinguishable): open a window around the value.
        let d = if mag < 1e-290 { 1.0 } else { mag * 0.1 };
        let mid = 0.5 * lo + 0.5 * hi;
        lo = mid - d;
        hi = mid + d;
        if mid == 0.0 {
            lo = 0.0; // [0, 1] rather than [-1, 1] for all-zero data
        }
    }
    let span = hi - lo;
    let base = 10f64.powf((span / 5.0).log10().floor());
    let mut pick = None;
    'outer: for scale in [0.1, 1.0, 10.0, 100.0] {
        for m in [1.0, 2.0, 5.0] {
            let step = m * scale * base;
            if !(step > 0.0 && step.is_finite()) {
                continue;
            }
            let a = (lo / step + 1e-9).floor();
            let b = (hi / step - 1e-9).ceil();
            if b - a <= 7.0 {
                pick = Some((step, a as i64, b as i64));
                break 'outer;
            }
        }
    }
    let Some((step, a, b)) = pick else {
        return Axis {
            lo,
            hi,
            ticks: Vec::new(),
            minor: Vec::new(),
        };
    };
    let maxabs = (a as f64 * step).abs().max((b as f64 * step).abs());
    let sci = maxabs >= 1e5 || maxabs < 1e-3;
    let step_exp = (step.log10() + 1e-9).floor() as i32;
    let decimals = (-step_exp).max(0) as usize;
    let ticks = (a..=b)
        .map(|i| {
            let v = i as f64 * step;
            let label = if sci && i == 0 {
                "0".to_string()
            } else if sci {
                let e = (v.abs().log10() + 1e-9).floor() as i32;
                sci_label(v, (e - step_exp).clamp(0, 6) as usize)
            } else {
                format!("{v:.decimals$}")
            };
            Tick { pos: v, label }
        })
        .collect();
    Axis {
        lo: a as f64 * step,
        hi: b as f64 * step,
        ticks,
        minor: Vec::new(),
    }
}

/// `v` as `1.5e-7`: `decimals` mantissa digits, trailing zeros trimmed.
pub(super) fn sci_label(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$e}");
    match s.split_once('e') {
        Some((m, e)) if m.contains('.') => {
            format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.'))
        }
        _ => s,
    }
}

pub(super) fn log_axis((lo, hi): (f64, f64)) -> Axis {
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    let mut e0 = (lo + 1e-9).floor() as i64;
    let mut e1 = (hi - 1e-9).ceil() as i64;
    if e1 <= e0 {
        e1 = e0 + 1;
    }
    let decades = e1 - e0;
    // (exponent, multiplier) of labelled ticks, and unlabelled minor grid positions.
    let mut major: Vec<(i64, u32)> = Vec::new();
    let mut minor = Vec::new();
    if decades <= 2 {
        // Too few decades for 4 ticks: label 1, 2, 5 in each.
        for e in e0..=e1 {
            for m in 1..=9u32 {
                if e == e1 && m > 1 {
                    break;
                }
                if matches!(m, 1 | 2 | 5) {
                    major.push((e, m));
                } else {
                    minor.push(e as f64 + (m as f64).log10());
                }
            }
        }
    } else {
        let mut stride = 1;
        while (e1.div_euclid(stride) + (e1.rem_euclid(stride) != 0) as i64) - e0.div_euclid(stride)
            > 7
        {
            stride += 1;
        }
        e0 = e0.div_euclid(stride) * stride;
        e1 = (e1.div_euclid(stride) + (e1.rem_euclid(stride) != 0) as i64) * stride;
        let mut e = e0;
        while e <= e1 {
            major.push((e, 1));
            e += stride;
        }
        for e in e0..e1 {
            if stride == 1 && decades <= 10 {
                minor.extend((2..=9).map(|m| e as f64 + (m as f64).log10()));
            } else if e % stride != 0 {
                minor.push(e as f64);
            }
        }
    }
    let plain = major.iter().all(|&(e, _)| (-3..=3).contains(&e));
    let ticks = major
        .into_iter()
        .map(|(e, m)| {
            let label = if plain {
                let d = (-e).max(0) as usize;
                format!("{:.d$}", m as f64 * 10f64.powi(e as i32))
            } else {
                format!("{m}e{e}")
            };
            Tick {
                pos: e as f64 + (m as f64).log10(),
                label,
            }
        })
        .collect();
    Axis {
        lo: e0 as f64,
        hi: e1 as f64,
        ticks,
        minor,
    }
}

