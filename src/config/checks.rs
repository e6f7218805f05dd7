//! The value checks of [`super::Config::validate`], each naming its key.

use crate::error::{Error, Result};

/// A sensor height over the floor that a scene can be built with (`scene.sensor_height_m`,
/// `--sensor-height`): finite and within a kilometre.
pub(crate) fn usable_sensor_height(h: f64) -> bool {
    h.is_finite() && h.abs() < 1000.0
}

pub(super) fn range_ok(key: &str, r: [f64; 2], lo: f64, hi: f64) -> Result<()> {
    if !(r[0].is_finite() && r[1].is_finite() && r[0] <= r[1] && r[0] >= lo && r[1] <= hi) {
        return Err(Error::input(
            format!("config key `{key}`"),
            format!("[{}, {}] must be finite, ordered and within [{lo}, {hi}]", r[0], r[1]),
        ));
    }
    Ok(())
}

pub(super) fn positive(key: &str, v: f64) -> Result<()> {
    if !(v.is_finite() && v > 0.0) {
        return Err(Error::input(format!("config key `{key}`"), format!("{v} must be a positive number")));
    }
    Ok(())
}

pub(super) fn non_negative(key: &str, v: f64) -> Result<()> {
    if !(v.is_finite() && v >= 0.0) {
        return Err(Error::input(format!("config key `{key}`"), format!("{v} must be a non-negative number")));
    }
    Ok(())
}
