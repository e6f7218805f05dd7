//! Debug images of one frame (stage 5, optional): range, label and velocity as RGB images.
//!
//! In: row-major per-beam grids (`row * columns + col`, row 0 = highest beam). Out: an
//! [`RgbImage`] `columns` wide and `rows * row_scale` high (nearest-neighbour row repeat, so a
//! 32 x 1024 strip becomes readable). Black always means "no return" (range 0).

use crate::error::{Error, Result};
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::RgbImage;
use std::path::Path;

/// Default vertical magnification of the debug PNGs (pixels per beam row).
pub const PNG_ROW_SCALE: u32 = 4;

/// Speed that maps to full brightness in [`velocity_png`], m/s.
pub const PNG_MAX_SPEED_MPS: f32 = 3.0;

/// Google's Turbo colormap (polynomial fit, Mikhailov 2019); `t` in [0, 1], clamped.
pub fn turbo(t: f32) -> [u8; 3] {
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 } as f64;
    let t2 = t * t;
    let t3 = t2 * t;
    let t4 = t3 * t;
    let t5 = t4 * t;
    let r = 0.13572138 + 4.61539260 * t - 42.66032258 * t2 + 132.13108234 * t3 - 152.94239396 * t4
        + 59.28637943 * t5;
    let g = 0.09140261 + 2.19418839 * t + 4.84296658 * t2 - 14.18503333 * t3
        + 4.27729857 * t4
        + 2.82956604 * t5;
    let b = 0.10667330 + 12.64194608 * t - 60.58204836 * t2 + 110.36276771 * t3 - 89.90310912 * t4
        + 27.34824973 * t5;
    [to_u8(r), to_u8(g), to_u8(b)]
}

fn to_u8(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// HSV (all in [0, 1], hue wraps) to 8-bit RGB.
pub fn hsv(h: f32, s: f32, v: f32) -> [u8; 3] {
    let h = (h.rem_euclid(1.0)) * 6.0;
    let i = h.floor();
    let f = h - i;
    let (s, v) = (s.clamp(0.0, 1.0) as f64, v.clamp(0.0, 1.0) as f64);
    let f = f as f64;
    let p = v * (1.0 - s);
    let q = v * (1.0 - s * f);
    let t = v * (1.0 - s * (1.0 - f));
    let (r, g, b) = match i as i32 % 6 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [to_u8(r), to_u8(g), to_u8(b)]
}

/// A distinct saturated colour for instance `k >= 1` (golden-ratio hue steps).
pub fn instance_colour(k: u16) -> [u8; 3] {
    let h = (k as f32 * 0.618_034).fract();
    hsv(h, 1.0, 1.0)
}

fn check(len: usize, rows: usize, columns: usize, what: &str) {
    assert_eq!(len, rows * columns, "{what}: {len} values for a {rows} x {columns} grid");
}

/// Builds the image by evaluating `colour(index)` once per beam and repeating each row.
fn grid_image(
    rows: usize,
    columns: usize,
    row_scale: u32,
    colour: impl Fn(usize) -> [u8; 3],
) -> RgbImage {
    let scale = row_scale.max(1) as usize;
    let mut buf = vec![0u8; rows * scale * columns * 3];
    let line = columns * 3;
    for r in 0..rows {
        let first = r * scale * line;
        {
            let dst = &mut buf[first..first + line];
            for c in 0..columns {
                dst[c * 3..c * 3 + 3].copy_from_slice(&colour(r * columns + c));
            }
        }
        for k in 1..scale {
            buf.copy_within(first..first + line, first + k * line);
        }
    }
    RgbImage::from_raw(columns as u32, (rows * scale) as u32, buf)
        .expect("buffer size matches the image size")
}

/// Where range `r` falls on the display scale in [0, 1]: logarithmic, `ln(1 + r) / ln(1 + max)`,
/// so near people (2 m), the room (10 m) and far walls (40 m) all stay distinguishable.
pub fn range_display(r: f32, max_range_m: f32) -> f32 {
    if max_range_m <= 0.0 {
        return 0.0;
    }
    ((1.0 + r.max(0.0)).ln() / (1.0 + max_range_m).ln()).clamp(0.0, 1.0)
}

/// Range image: Turbo over `0..max_range_m` on a log scale ([`range_display`]; blue near, red
/// far), black = no return.
///
/// Panics if `range.len() != rows * columns`.
pub fn range_png(
    range: &[f32],
    rows: usize,
    columns: usize,
    max_range_m: f32,
    row_scale: u32,
) -> RgbImage {
    check(range.len(), rows, columns, "range");
    grid_image(rows, columns, row_scale, |i| {
        let r = range[i];
        if r > 0.0 {
            turbo(range_display(r, max_range_m))
        } else {
            [0, 0, 0]
        }
    })
}

/// Label image: returns in grey (bright = near, dark = far, log scale), each human instance in its own
/// saturated colour ([`instance_colour`]), black = no return.
///
/// Panics if a grid's length is not `rows * columns`.
pub fn label_png(
    range: &[f32],
    instance: &[u16],
    rows: usize,
    columns: usize,
    max_range_m: f32,
    row_scale: u32,
) -> RgbImage {
    check(range.len(), rows, columns, "range");
    check(instance.len(), rows, columns, "instance");
    grid_image(rows, columns, row_scale, |i| {
        let r = range[i];
        let k = instance[i];
        if k > 0 {
            instance_colour(k)
        } else if r > 0.0 {
            let g = to_u8((1.0 - 0.8 * range_display(r, max_range_m)) as f64 * 0.9);
            [g, g, g]
        } else {
            [0, 0, 0]
        }
    })
}

/// Velocity image (sensor frame): hue = direction of the xy velocity (red = +x, then
/// counter-clockwise), saturation and brightness grow with the speed up to `max_speed_mps`;
/// a return at rest is dark grey, no return is black.
///
/// Panics if a grid's length is not `rows * columns`.
pub fn velocity_png(
    range: &[f32],
    velocity: &[[f32; 3]],
    rows: usize,
    columns: usize,
    max_speed_mps: f32,
    row_scale: u32,
) -> RgbImage {
    check(range.len(), rows, columns, "range");
    check(velocity.len(), rows, columns, "velocity");
    let inv = if max_speed_mps > 0.0 { 1.0 / max_speed_mps } else { 0.0 };
    grid_image(rows, columns, row_scale, |i| {
        if range[i] > 0.0 {
            let [vx, vy, vz] = velocity[i];
            let speed = (vx * vx + vy * vy + vz * vz).sqrt();
            let s = if speed.is_finite() { (speed * inv).clamp(0.0, 1.0) } else { 1.0 };
            let hue = vy.atan2(vx) / std::f32::consts::TAU;
            hsv(hue, s, 0.25 + 0.75 * s)
        } else {
            [0, 0, 0]
        }
    })
}

/// Writes `img` as a PNG (fast compression) to `path`.
pub fn save_png(img: &RgbImage, path: &Path) -> Result<()> {
    let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    let enc = PngEncoder::new_with_quality(
        std::io::BufWriter::new(file),
        CompressionType::Fast,
        FilterType::Adaptive,
    );
    img.write_with_encoder(enc).map_err(|e| match e {
        image::ImageError::IoError(io) => Error::io(path, io),
        other => Error::Internal(format!("{}: PNG encoding failed: {other}", path.display())),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn images_have_scaled_size_and_black_for_no_return() {
        let (rows, cols) = (4, 16);
        let mut range = vec![0.0f32; rows * cols];
        range[5] = 10.0;
        let img = range_png(&range, rows, cols, 50.0, 4);
        assert_eq!(img.dimensions(), (16, 16));
        assert_eq!(img.get_pixel(0, 0).0, [0, 0, 0]);
        assert_ne!(img.get_pixel(5, 0).0, [0, 0, 0]);
        assert_eq!(img.get_pixel(5, 3).0, img.get_pixel(5, 0).0);
        assert_eq!(img.get_pixel(5, 4).0, [0, 0, 0]);
        let mut inst = vec![0u16; rows * cols];
        inst[5] = 1;
        let lab = label_png(&range, &inst, rows, cols, 50.0, 2);
        assert_eq!(lab.get_pixel(5, 1).0, instance_colour(1));
        let vel = velocity_png(&range, &vec![[1.0, 0.0, 0.0]; rows * cols], rows, cols, 3.0, 1);
        assert_eq!(vel.get_pixel(0, 0).0, [0, 0, 0]);
        let p = vel.get_pixel(5, 0).0;
        assert!(p[0] > p[1] && p[0] > p[2], "+x is red-ish: {p:?}");
    }

    #[test]
    fn instance_colours_differ() {
        let cs: Vec<_> = (1..=8).map(instance_colour).collect();
        for i in 0..cs.len() {
            for j in i + 1..cs.len() {
                assert_ne!(cs[i], cs[j]);
            }
        }
    }
}
