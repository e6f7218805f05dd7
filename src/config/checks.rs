//! The value checks of [`super::Config::validate`], each naming its key.

use super::MAX_PLATFORM_BOXES;
use crate::error::{Error, Result};

/// A sensor height over the floor that a scene can be built with (`scene.sensor_height_m`,
/// `--sensor-height`): above the floor (a sensor under it sees nothing of the world) and
/// within a kilometre.
pub(crate) fn usable_sensor_height(h: f64) -> bool {
    h.is_finite() && h > 0.0 && h < 1000.0
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

impl super::SensorModelConfig {
    /// Each term of the sensor model within its documented range, named by its key.
    pub(super) fn validate(&self) -> Result<()> {
        let m = self;
        non_negative("sensor_model.range_noise_m", m.range_noise_m)?;
        non_negative("sensor_model.laser_bias_m", m.laser_bias_m)?;
        for (key, v) in [("sensor_model.range_noise_m", m.range_noise_m), ("sensor_model.laser_bias_m", m.laser_bias_m)] {
            if v > 1.0 {
                return Err(Error::input(format!("config key `{key}`"), format!("{v} m must be at most 1 m")));
            }
        }
        range_ok("sensor_model.dropout_rate", [m.dropout_rate, m.dropout_rate], 0.0, 1.0)?;
        positive("sensor_model.detection_range_m", m.detection_range_m)?;
        non_negative("sensor_model.detection_softness", m.detection_softness)?;
        range_ok("sensor_model.grazing_deg", m.grazing_deg, 0.0, 90.0)?;
        range_ok("sensor_model.grazing_loss", [m.grazing_loss, m.grazing_loss], 0.0, 1.0)?;
        // Either order (horizontal, vertical), each checked itself: min/max would drop a NaN.
        for d in m.divergence_mrad {
            range_ok("sensor_model.divergence_mrad", [d, d], 0.0, 50.0)?;
        }
        non_negative("sensor_model.mixed_return_m", m.mixed_return_m)?;
        for (key, r) in [
            ("sensor_model.skin_reflectance", m.skin_reflectance),
            ("sensor_model.upper_reflectance", m.upper_reflectance),
            ("sensor_model.lower_reflectance", m.lower_reflectance),
            ("sensor_model.shoe_reflectance", m.shoe_reflectance),
        ] {
            range_ok(key, r, 0.0, 1.0)?;
        }
        if let Some(s) = m.intensity_scale {
            positive("sensor_model.intensity_scale", s)?;
        }
        if m.platform.len() > MAX_PLATFORM_BOXES {
            return Err(Error::input("config key `sensor_model.platform`", format!("{} boxes: at most {MAX_PLATFORM_BOXES}", m.platform.len())));
        }
        for (k, b) in m.platform.iter().enumerate() {
            let key = format!("config key `sensor_model.platform[{k}]`");
            if !(0..3).all(|i| b.min_m[i].is_finite() && b.max_m[i].is_finite() && b.min_m[i] < b.max_m[i]) {
                return Err(Error::input(key, format!("min_m {:?} and max_m {:?} must be finite with min < max on every axis", b.min_m, b.max_m)));
            }
            if (0..3).all(|i| b.min_m[i] <= 0.0 && b.max_m[i] >= 0.0) {
                return Err(Error::input(key, "the box holds the sensor (the origin): every beam would be hidden"));
            }
        }
        Ok(())
    }
}
