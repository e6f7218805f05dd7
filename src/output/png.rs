//! Debug images of one frame (stage 5, optional): range, label and velocity as RGB images,
//! and a bird's-eye view.
//!
//! In: row-major per-beam grids (`row * columns + col`, row 0 = highest beam). Out: an
//! [`RgbImage`] `columns` wide and `rows * row_scale` high (nearest-neighbour row repeat, so a
//! 32 x 1024 strip becomes readable); the range and velocity images carry a legend strip
//! [`LEGEND_H`] pixels high below the grid. Black always means "no return" (range 0).

use crate::error::{Error, Result};
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::RgbImage;
use std::path::Path;

/// Default vertical magnification of the debug PNGs (pixels per beam row).
pub const PNG_ROW_SCALE: u32 = 4;

/// Speed that maps to full brightness in [`velocity_png`], m/s.
pub const PNG_MAX_SPEED_MPS: f32 = 3.0;

/// Height of the legend strip under the range and velocity images, pixels.
pub const LEGEND_H: u32 = 40;

/// Side of the bird's-eye view, pixels, and the half-width it shows, metres.
pub const BEV_SIDE: u32 = 640;
pub const BEV_HALF_WIDTH_M: f64 = 20.0;

const LEGEND_BG: [u8; 3] = [255, 255, 255];
const LEGEND_INK: [u8; 3] = [0, 0, 0];

/// `img` with a white strip of [`LEGEND_H`] pixels added below, for `draw` to fill (its
/// origin is the strip's top-left corner).
fn with_legend(img: RgbImage, draw: impl FnOnce(&mut RgbImage, i64)) -> RgbImage {
    let (w, h) = img.dimensions();
    let mut out = RgbImage::from_pixel(w, h + LEGEND_H, image::Rgb(LEGEND_BG));
    image::imageops::replace(&mut out, &img, 0, 0);
    draw(&mut out, h as i64);
    out
}

fn fill_rect(img: &mut RgbImage, x0: i64, y0: i64, w: i64, h: i64, colour: [u8; 3]) {
    for y in y0.max(0)..(y0 + h).min(img.height() as i64) {
        for x in x0.max(0)..(x0 + w).min(img.width() as i64) {
            img.put_pixel(x as u32, y as u32, image::Rgb(colour));
        }
    }
}

/// The range scale: the Turbo bar on its log scale with ticks at 1-2-5 steps up to `max`.
fn range_legend(img: &mut RgbImage, top: i64, max_range_m: f32) {
    use crate::plot::font::{draw_text, text_width};
    let (x0, bar_w) = (8i64, (img.width() as i64 - 16).min(600).max(60));
    for x in 0..bar_w {
        let t = x as f32 / (bar_w - 1) as f32;
        fill_rect(img, x0 + x, top + 6, 1, 12, turbo(t));
    }
    let ln_max = (1.0 + max_range_m.max(0.0)).ln();
    for tick in [0.5f32, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0] {
        if tick > max_range_m {
            break;
        }
        let x = x0 + ((1.0 + tick).ln() / ln_max * (bar_w - 1) as f32).round() as i64;
        fill_rect(img, x, top + 18, 1, 4, LEGEND_INK);
        let label = format!("{tick}");
        draw_text(img, x - text_width(&label, 1) as i64 / 2, top + 24, &label, 1, LEGEND_INK);
    }
    draw_text(img, x0 + bar_w + 10, top + 10, "range, m (log scale); black: no return", 1, LEGEND_INK);
}

/// The velocity key: a colour wheel (hue = direction in the sensor frame, +x forward to the
/// right) and a speed bar from 0 to `max_speed_mps`.
fn velocity_legend(img: &mut RgbImage, top: i64, max_speed_mps: f32) {
    use crate::plot::font::{draw_text, text_width};
    let r = (LEGEND_H as i64 - 6) / 2;
    let (cx, cy) = (8 + r, top + 3 + r);
    for dy in -r..=r {
        for dx in -r..=r {
            let d = ((dx * dx + dy * dy) as f32).sqrt();
            if d <= r as f32 {
                // Image y grows downwards; the sensor's +y is left of +x, drawn upwards.
                let (vx, vy) = (dx as f32, -dy as f32);
                let s = d / r as f32;
                fill_rect(img, cx + dx, cy + dy, 1, 1, hsv(vy.atan2(vx) / std::f32::consts::TAU, s, 0.25 + 0.75 * s));
            }
        }
    }
    draw_text(img, cx + r + 4, cy - 4, "+x", 1, LEGEND_INK);
    let (x0, bar_w) = (cx + r + 24, 200i64);
    for x in 0..bar_w {
        let s = x as f32 / (bar_w - 1) as f32;
        fill_rect(img, x0 + x, top + 6, 1, 12, hsv(0.0, s, 0.25 + 0.75 * s));
    }
    for k in 0..=3 {
        let v = max_speed_mps * k as f32 / 3.0;
        let x = x0 + (k as i64 * (bar_w - 1)) / 3;
        fill_rect(img, x, top + 18, 1, 4, LEGEND_INK);
        let label = format!("{v:.1}");
        draw_text(img, x - text_width(&label, 1) as i64 / 2, top + 24, &label, 1, LEGEND_INK);
    }
    draw_text(img, x0 + bar_w + 10, top + 10, "speed over the ground, m/s (hue: direction, sensor frame)", 1, LEGEND_INK);
}

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
/// far), black = no return; a scale bar below.
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
    let grid = grid_image(rows, columns, row_scale, |i| {
        let r = range[i];
        if r > 0.0 {
            turbo(range_display(r, max_range_m))
        } else {
            [0, 0, 0]
        }
    });
    with_legend(grid, |img, top| range_legend(img, top, max_range_m))
}

/// Intensity image: each return's intensity in grey, white at the frame's 99th percentile of
/// returned intensities (people are not coloured: the point is whether they stand out),
/// black = no return.
///
/// Panics if a grid's length is not `rows * columns`.
pub fn intensity_png(intensity: &[f32], range: &[f32], rows: usize, columns: usize, row_scale: u32) -> RgbImage {
    check(intensity.len(), rows, columns, "intensity");
    check(range.len(), rows, columns, "range");
    let mut returned: Vec<f32> = intensity.iter().zip(range).filter(|(_, r)| **r > 0.0).map(|(i, _)| *i).collect();
    returned.sort_by(|a, b| a.total_cmp(b));
    let white = returned.get(returned.len() * 99 / 100).copied().filter(|w| *w > 0.0).unwrap_or(1.0);
    grid_image(rows, columns, row_scale, |i| {
        if range[i] > 0.0 {
            let g = (40.0 + 215.0 * (intensity[i] / white).clamp(0.0, 1.0)) as u8;
            [g, g, g]
        } else {
            [0, 0, 0]
        }
    })
}

/// Label image: returns in grey (bright = near, dark = far, log scale), each instance (a person,
/// a mover) in its own saturated colour ([`instance_colour`]), black = no return.
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

/// Velocity image: each return's velocity over the ground, in the sensor frame: `velocity`
/// (relative to the sensor, as stored) plus `ego(i)`, the sensor's own contribution at beam i
/// (see [`ego_velocity`]), so the static world is dark grey and the people stand out however
/// fast the sensor moves. Hue = direction (red = +x, then counter-clockwise), saturation and
/// brightness grow with the speed up to `max_speed_mps`; no return is black; a colour wheel
/// and a speed bar below.
///
/// Panics if a grid's length is not `rows * columns`.
pub fn velocity_png(
    range: &[f32],
    velocity: &[[f32; 3]],
    ego: impl Fn(usize) -> [f32; 3],
    rows: usize,
    columns: usize,
    max_speed_mps: f32,
    row_scale: u32,
) -> RgbImage {
    check(range.len(), rows, columns, "range");
    check(velocity.len(), rows, columns, "velocity");
    let inv = if max_speed_mps > 0.0 { 1.0 / max_speed_mps } else { 0.0 };
    let grid = grid_image(rows, columns, row_scale, |i| {
        if range[i] > 0.0 {
            let (v, e) = (velocity[i], ego(i));
            let [vx, vy, vz] = [v[0] + e[0], v[1] + e[1], v[2] + e[2]];
            let speed = (vx * vx + vy * vy + vz * vz).sqrt();
            let s = if speed.is_finite() { (speed * inv).clamp(0.0, 1.0) } else { 1.0 };
            let hue = vy.atan2(vx) / std::f32::consts::TAU;
            hsv(hue, s, 0.25 + 0.75 * s)
        } else {
            [0, 0, 0]
        }
    });
    with_legend(grid, |img, top| velocity_legend(img, top, max_speed_mps))
}

/// What the sensor's own motion adds to a point's stored velocity to give its velocity over
/// the ground, sensor frame: `R^T V_s` (both velocity models), plus `w x p` for the `rigid`
/// model, which also subtracted the sensor's yaw rate w at the point p.
pub fn ego_velocity(world_from_sensor: &[[f64; 4]; 4], sensor_velocity_mps: [f64; 3], yaw_rate_rps: f64, rigid: bool, point: [f32; 3]) -> [f32; 3] {
    let m = world_from_sensor;
    let v = sensor_velocity_mps;
    // R^T v: column j of R dotted with v.
    let mut out = [0f64; 3];
    for (j, o) in out.iter_mut().enumerate() {
        *o = m[0][j] * v[0] + m[1][j] * v[1] + m[2][j] * v[2];
    }
    if rigid {
        let (px, py) = (point[0] as f64, point[1] as f64);
        out[0] += -yaw_rate_rps * py;
        out[1] += yaw_rate_rps * px;
    }
    [out[0] as f32, out[1] as f32, out[2] as f32]
}

/// Bird's-eye view of a frame, sensor frame, +x up, +y left, [`BEV_HALF_WIDTH_M`] around the
/// sensor: background returns grey, each person's (and mover's) returns in their instance
/// colour, each person's ground velocity as an arrow from their position (1 s of walking), the sensor as a
/// white triangle with its own velocity arrow. `people` holds per person (sensor frame) the
/// position and the velocity over the ground.
pub fn bev_png(xyz: &[[f32; 3]], range: &[f32], instance: &[u16], people: &[([f64; 3], [f64; 3])], sensor_velocity: [f64; 3]) -> RgbImage {
    let side = BEV_SIDE as i64;
    let mut img = RgbImage::from_pixel(BEV_SIDE, BEV_SIDE, image::Rgb([16, 16, 16]));
    let scale = side as f64 / (2.0 * BEV_HALF_WIDTH_M);
    let to_px = |x: f64, y: f64| ((side as f64 / 2.0 - y * scale).round() as i64, (side as f64 / 2.0 - x * scale).round() as i64);
    // Rings every 5 m.
    for ring in (5..=BEV_HALF_WIDTH_M as i64).step_by(5) {
        let r = ring as f64 * scale;
        for k in 0..720 {
            let a = k as f64 / 720.0 * std::f64::consts::TAU;
            let (u, v) = (side as f64 / 2.0 + r * a.cos(), side as f64 / 2.0 + r * a.sin());
            fill_rect(&mut img, u as i64, v as i64, 1, 1, [48, 48, 48]);
        }
    }
    // Background first, people over it.
    for pass in [false, true] {
        for (i, p) in xyz.iter().enumerate() {
            let human = instance[i] > 0;
            if range[i] <= 0.0 || human != pass {
                continue;
            }
            let (u, v) = to_px(p[0] as f64, p[1] as f64);
            let c = if human { instance_colour(instance[i]) } else { [150, 150, 150] };
            fill_rect(&mut img, u, v, 1 + human as i64, 1 + human as i64, c);
        }
    }
    let arrow = |img: &mut RgbImage, from: (f64, f64), v: [f64; 3], colour: [u8; 3]| {
        let (a, b) = (to_px(from.0, from.1), to_px(from.0 + v[0], from.1 + v[1]));
        let n = (a.0 - b.0).abs().max((a.1 - b.1).abs()).max(1);
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let (u, w) = (a.0 as f64 + t * (b.0 - a.0) as f64, a.1 as f64 + t * (b.1 - a.1) as f64);
            fill_rect(img, u as i64, w as i64, 2, 2, colour);
        }
        fill_rect(img, b.0 - 2, b.1 - 2, 5, 5, colour);
    };
    for (k, (pos, vel)) in people.iter().enumerate() {
        let c = instance_colour(k as u16 + 1);
        let (u, v) = to_px(pos[0], pos[1]);
        fill_rect(&mut img, u - 3, v - 3, 7, 7, c);
        arrow(&mut img, (pos[0], pos[1]), *vel, c);
    }
    let (u, v) = to_px(0.0, 0.0);
    for dy in 0..8 {
        fill_rect(&mut img, u - dy / 2, v - 4 + dy, dy + 1, 1, [255, 255, 255]);
    }
    arrow(&mut img, (0.0, 0.0), sensor_velocity, [255, 255, 255]);
    crate::plot::font::draw_text(&mut img, 6, 6, &format!("bird's-eye view, +x up, rings every 5 m, arrows: 1 s of motion over the ground"), 1, [220, 220, 220]);
    img
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
    fn a_moving_sensor_leaves_the_static_world_grey_and_the_people_coloured() {
        // The sensor drives at 4.9 m/s along world +y, turned 90 degrees (its +x is world +y):
        // stored background velocity is -4.9 m/s along its +x; a person walks 1.3 m/s along
        // world +x (the sensor's -y).
        let pose = [[0.0, -1.0, 0.0, 5.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
        let vs = [0.0, 4.9, 0.0];
        let ego = |_: usize| ego_velocity(&pose, vs, 0.0, false, [0.0; 3]);
        assert_eq!(ego(0), [4.9, 0.0, 0.0]);
        let velocity = [[-4.9, 0.0, 0.0], [-4.9, -1.3, 0.0]];
        let img = velocity_png(&[5.0, 5.0], &velocity, ego, 1, 2, 3.0, 1);
        assert_eq!(img.get_pixel(0, 0).0, hsv(0.0, 0.0, 0.25), "static world: dark grey");
        let person = img.get_pixel(1, 0).0;
        assert_eq!(person, hsv(-0.25, 1.3 / 3.0, 0.25 + 0.75 * 1.3 / 3.0), "the person's own walk, sensor -y");
        // The rigid model also subtracted w x p: added back.
        let e = ego_velocity(&pose, [0.0; 3], 0.5, true, [2.0, 0.0, 0.0]);
        assert!((e[1] - 1.0).abs() < 1e-6 && e[0].abs() < 1e-6, "{e:?}");
        // Every component of the ego term is added back: a static return seen while the sensor
        // moves sideways and down is grey too.
        let img = velocity_png(&[5.0], &[[0.0, -2.0, 0.5]], |_| [0.0, 2.0, -0.5], 1, 1, 3.0, 1);
        assert_eq!(img.get_pixel(0, 0).0, hsv(0.0, 0.0, 0.25));
    }

    #[test]
    fn the_birds_eye_view_puts_points_and_people_where_they_are() {
        let xyz = [[10.0, 0.0, 0.0], [0.0, 10.0, 0.0], [50.0, 0.0, 0.0]];
        let img = bev_png(&xyz, &[10.0, 10.0, 50.0], &[1, 0, 0], &[([10.0, 0.0, 0.0], [0.0, 0.0, 0.0])], [0.0; 3]);
        let (c, s) = (BEV_SIDE as f64 / 2.0, BEV_SIDE as f64 / (2.0 * BEV_HALF_WIDTH_M));
        // +x forward is up, +y left is left.
        assert_eq!(img.get_pixel(c as u32, (c - 10.0 * s) as u32).0, instance_colour(1));
        assert_eq!(img.get_pixel((c - 10.0 * s) as u32, c as u32).0, [150, 150, 150]);
        // A person's return away from any person's mark is drawn in its colour, two pixels wide.
        let img = bev_png(&[[0.0, -10.0, 0.0]], &[10.0], &[2], &[], [0.0; 3]);
        let (u, v) = ((c + 10.0 * s) as u32, c as u32);
        for (du, dv) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            assert_eq!(img.get_pixel(u + du, v + dv).0, instance_colour(2), "+({du}, {dv})");
        }
    }

    #[test]
    fn images_have_scaled_size_and_black_for_no_return() {
        let (rows, cols) = (4, 16);
        let mut range = vec![0.0f32; rows * cols];
        range[5] = 10.0;
        let img = range_png(&range, rows, cols, 50.0, 4);
        assert_eq!(img.dimensions(), (16, 16 + LEGEND_H));
        assert_eq!(img.get_pixel(0, 0).0, [0, 0, 0]);
        assert_ne!(img.get_pixel(5, 0).0, [0, 0, 0]);
        assert_eq!(img.get_pixel(5, 3).0, img.get_pixel(5, 0).0);
        assert_eq!(img.get_pixel(5, 4).0, [0, 0, 0]);
        let mut inst = vec![0u16; rows * cols];
        inst[5] = 1;
        let lab = label_png(&range, &inst, rows, cols, 50.0, 2);
        assert_eq!(lab.get_pixel(5, 1).0, instance_colour(1));
        let vel = velocity_png(&range, &vec![[1.0, 0.0, 0.0]; rows * cols], |_| [0.0; 3], rows, cols, 3.0, 1);
        assert_eq!(vel.get_pixel(0, 0).0, [0, 0, 0]);
        let p = vel.get_pixel(5, 0).0;
        assert!(p[0] > p[1] && p[0] > p[2], "+x is red-ish: {p:?}");
    }

    /// Turbo is Mikhailov's published degree-5 polynomial: here evaluated by Horner's rule
    /// (another order of operations than `turbo`'s powers), within one 8-bit step, and at the
    /// points whose colours the map is known for (dark blue, cyan, green-yellow, orange, dark
    /// red), clamped outside [0, 1].
    #[test]
    fn turbo_is_the_published_polynomial() {
        let coefficients: [[f64; 6]; 3] = [
            [0.13572138, 4.61539260, -42.66032258, 132.13108234, -152.94239396, 59.28637943],
            [0.09140261, 2.19418839, 4.84296658, -14.18503333, 4.27729857, 2.82956604],
            [0.10667330, 12.64194608, -60.58204836, 110.36276771, -89.90310912, 27.34824973],
        ];
        for k in 0..=100 {
            let t = k as f64 / 100.0;
            let got = turbo(t as f32);
            for (c, coef) in coefficients.iter().enumerate() {
                let v = coef.iter().rev().fold(0.0, |acc, &a| acc * t + a);
                let want = (v.clamp(0.0, 1.0) * 255.0).round();
                assert!((got[c] as f64 - want).abs() <= 1.0, "turbo({t}) channel {c}: {} against {want}", got[c]);
            }
        }
        assert_eq!(turbo(0.0), [35, 23, 27]);
        assert_eq!(turbo(0.25), [38, 189, 225]);
        assert_eq!(turbo(0.5), [150, 250, 80]);
        assert_eq!(turbo(0.75), [255, 128, 29]);
        assert_eq!(turbo(1.0), [144, 13, 0]);
        assert_eq!(turbo(-3.0), turbo(0.0));
        assert_eq!(turbo(7.0), turbo(1.0));
        assert_eq!(turbo(f32::NAN), turbo(0.0));
    }

    /// Whether `text` is written in black at (x, y) of `img`: every pixel of its box is black
    /// exactly where the font draws it.
    fn written(img: &RgbImage, x: i64, y: i64, text: &str) -> bool {
        use crate::plot::font::{draw_text, text_width, GLYPH_H};
        let mut want = RgbImage::from_pixel(img.width(), img.height(), image::Rgb(LEGEND_BG));
        draw_text(&mut want, x, y, text, 1, LEGEND_INK);
        let inked = |im: &RgbImage, px: i64, py: i64| im.get_pixel(px as u32, py as u32).0 == LEGEND_INK;
        let xs = x.max(0)..(x + text_width(text, 1) as i64).min(img.width() as i64);
        let ys = y.max(0)..(y + GLYPH_H as i64).min(img.height() as i64);
        ys.clone().all(|py| xs.clone().all(|px| inked(img, px, py) == inked(&want, px, py)))
            && ys.clone().any(|py| xs.clone().any(|px| inked(&want, px, py)))
    }

    /// Black columns of row `y` between `x0` and `x1` (exclusive).
    fn black_columns(img: &RgbImage, y: u32, x0: u32, x1: u32) -> Vec<u32> {
        (x0..x1).filter(|&x| img.get_pixel(x, y).0 == [0, 0, 0]).collect()
    }

    /// The range key: the Turbo bar from its first to its last pixel (8 px from the left,
    /// the image's width less 16, at most 600), and a tick at every 1-2-5 step up to and
    /// including the maximum range, where ln(1 + tick) / ln(1 + max) puts it.
    #[test]
    fn the_range_key_has_its_ticks_on_the_log_scale() {
        let (w, max) = (1000u32, 50.0f32);
        let img = range_png(&vec![0.0; w as usize], 1, w as usize, max, 1);
        let top = 1;
        let bar_w = (w - 16).min(600) as i64;
        for (x, t) in [(0, 0.0), (bar_w - 1, 1.0), ((bar_w - 1) / 2, ((bar_w - 1) / 2) as f32 / (bar_w - 1) as f32)] {
            for y in top + 6..top + 18 {
                assert_eq!(img.get_pixel(8 + x as u32, y).0, turbo(t), "bar at x {x}, y {y}");
            }
        }
        assert_eq!(img.get_pixel(8 + bar_w as u32, top + 10).0, LEGEND_BG, "the bar ends at its width");
        let want: Vec<u32> = [0.5f64, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0]
            .iter()
            .map(|&tick| 8 + ((1.0 + tick).ln() / (1.0 + max as f64).ln() * (bar_w - 1) as f64).round() as u32)
            .collect();
        for y in top + 18..top + 22 {
            assert_eq!(black_columns(&img, y, 0, w), want, "tick marks in row {y}");
        }
        assert!(black_columns(&img, top + 22, 0, w).is_empty(), "tick marks are 4 px long");
        for (x, label) in want.iter().zip(["0.5", "1", "2", "5", "10", "20", "50"]) {
            let half = crate::plot::font::text_width(label, 1) as i64 / 2;
            assert!(written(&img, *x as i64 - half, top as i64 + 24, label), "tick label {label}");
        }
        assert!(written(&img, 8 + bar_w + 10, top as i64 + 10, "range, m (log scale); black: no return"), "caption");
    }

    /// The velocity key: a colour wheel of radius 17 centred 25 px from the left, hue the
    /// direction (+x red to the right, +y drawn upwards, then cyan and violet), saturation and
    /// brightness growing from dark grey at the centre; a 200 px speed bar 24 px to its right,
    /// with four ticks at thirds of the maximum speed.
    #[test]
    fn the_velocity_key_is_a_direction_wheel_and_a_speed_bar() {
        let img = velocity_png(&[0.0; 400], &[[0.0; 3]; 400], |_| [0.0; 3], 1, 400, 3.0, 1);
        let (r, cx, cy) = (17u32, 25u32, 1 + 3 + 17u32);
        assert_eq!(img.get_pixel(cx, cy).0, [64, 64, 64], "centre: no speed");
        assert_eq!(img.get_pixel(cx + r, cy).0, [255, 0, 0], "+x");
        assert_eq!(img.get_pixel(cx, cy - r).0, [128, 255, 0], "+y, drawn upwards");
        assert_eq!(img.get_pixel(cx - r, cy).0, [0, 255, 255], "-x");
        assert_eq!(img.get_pixel(cx, cy + r).0, [128, 0, 255], "-y");
        assert_eq!(img.get_pixel(cx + r - 1, cy - r + 1).0, LEGEND_BG, "outside the wheel");
        let halfway = img.get_pixel(cx + r / 2 + 1, cy).0;
        assert_eq!(halfway, hsv(0.0, 9.0 / 17.0, 0.25 + 0.75 * 9.0 / 17.0), "saturation grows with the radius");
        let x0 = cx + r + 24;
        assert_eq!(img.get_pixel(x0, 1 + 6).0, [64, 64, 64], "speed 0");
        assert_eq!(img.get_pixel(x0 + 199, 1 + 17).0, [255, 0, 0], "full speed");
        assert_eq!(img.get_pixel(x0 + 200, 1 + 10).0, LEGEND_BG, "the bar is 200 px wide");
        for y in 1 + 18..1 + 22 {
            assert_eq!(black_columns(&img, y, x0 - 2, x0 + 202), vec![x0, x0 + 66, x0 + 132, x0 + 199], "speed ticks in row {y}");
        }
        for (x, label) in [(x0, "0.0"), (x0 + 66, "1.0"), (x0 + 132, "2.0"), (x0 + 199, "3.0")] {
            let half = crate::plot::font::text_width(label, 1) as i64 / 2;
            assert!(written(&img, x as i64 - half, 1 + 24, label), "speed label {label}");
        }
        assert!(written(&img, (cx + r + 4) as i64, cy as i64 - 4, "+x"), "the wheel's +x");
        assert!(written(&img, (x0 + 210) as i64, 1 + 10, "speed over the ground, m/s (hue: direction, sensor frame)"), "caption");
    }

    /// The rigid model's `w x p` about the vertical: (-w p_y, w p_x).
    #[test]
    fn the_rigid_ego_term_is_the_yaw_rate_crossed_with_the_point() {
        let identity = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
        assert_eq!(ego_velocity(&identity, [0.0; 3], 0.5, true, [4.0, 2.0, 1.0]), [-1.0, 2.0, 0.0]);
        assert_eq!(ego_velocity(&identity, [0.0; 3], 0.5, false, [4.0, 2.0, 1.0]), [0.0, 0.0, 0.0]);
        assert_eq!(ego_velocity(&identity, [1.0, -2.0, 3.0], 0.0, true, [4.0, 2.0, 1.0]), [1.0, -2.0, 3.0]);
    }

    /// 16 px a metre around the centre (320, 320): rings every 5 m all the way round, and a
    /// person at (10, 0) m walking (1, 2) m/s has its 1 s arrow from (320, 160) to (288, 144),
    /// through (304, 152), and nothing on the mirrored side.
    #[test]
    fn the_birds_eye_view_draws_rings_and_arrows() {
        let img = bev_png(&[], &[], &[], &[([10.0, 0.0, 0.0], [1.0, 2.0, 0.0])], [0.0; 3]);
        for (u, v) in [(400, 320), (320, 400), (240, 320), (320, 240)] {
            assert_eq!(img.get_pixel(u, v).0, [48, 48, 48], "the 5 m ring at ({u}, {v})");
        }
        let c = instance_colour(1);
        assert_eq!(img.get_pixel(320, 160).0, c, "the person");
        assert_eq!(img.get_pixel(304, 152).0, c, "the arrow's middle");
        assert_eq!(img.get_pixel(288, 144).0, c, "the arrow's head");
        for (u, v) in [(352, 144), (336, 152), (304, 168), (288, 176)] {
            assert_eq!(img.get_pixel(u, v).0, [16, 16, 16], "nothing at ({u}, {v})");
        }
        assert_eq!(img.get_pixel(317, 157).0, c, "the person's 7 px square, top left");
        assert_eq!(img.get_pixel(323, 163).0, c, "the person's 7 px square, bottom right");
        for (u, v) in [(320, 316), (317, 323), (324, 323)] {
            assert_eq!(img.get_pixel(u, v).0, [255, 255, 255], "the sensor's triangle, pointing up, at ({u}, {v})");
        }
        assert_eq!(img.get_pixel(317, 317).0, [16, 16, 16], "beside the triangle's tip");
    }

    #[test]
    fn the_range_scale_is_logarithmic_from_zero_to_the_maximum() {
        let e = std::f32::consts::E;
        assert_eq!(range_display(0.0, 50.0), 0.0);
        assert_eq!(range_display(50.0, 50.0), 1.0);
        assert!((range_display(e - 1.0, e * e - 1.0) - 0.5).abs() < 1e-6);
        assert_eq!(range_display(80.0, 50.0), 1.0, "clamped beyond the maximum");
        assert_eq!(range_display(-2.0, 50.0), 0.0);
        assert_eq!(range_display(5.0, 0.0), 0.0, "no scale without a maximum");
    }

    /// Intensity: grey from 40 to 255 at the 99th percentile of the *returned* intensities
    /// (a no-return beam's intensity, however bright, neither counts nor shows); label: people
    /// in their colour, the rest grey by range, no return black.
    #[test]
    fn only_returns_are_shaded_and_only_people_coloured() {
        let (rows, cols) = (1, 200);
        let range: Vec<f32> = (0..cols).map(|c| if c < 100 { 10.0 } else { 0.0 }).collect();
        let intensity: Vec<f32> = (0..cols).map(|c| if c < 100 { c as f32 / 99.0 } else { 100.0 }).collect();
        let img = intensity_png(&intensity, &range, rows, cols, 1);
        // The 99th percentile of the 100 returns is the 100th smallest: 1.0.
        assert_eq!(img.get_pixel(99, 0).0, [255, 255, 255]);
        assert_eq!(img.get_pixel(0, 0).0, [40, 40, 40]);
        let g = (40.0 + 215.0 * (49.0f32 / 99.0)) as u8;
        assert_eq!(img.get_pixel(49, 0).0, [g, g, g]);
        assert_eq!(img.get_pixel(150, 0).0, [0, 0, 0], "no return: black");
        // Of 200 returns the 99th percentile is the 199th smallest (index 198), not the largest.
        let many: Vec<f32> = (0..200).map(|c| 3.0 * c as f32 / 198.0).collect();
        let img = intensity_png(&many, &[10.0; 200], 1, 200, 1);
        assert_eq!(img.get_pixel(198, 0).0, [255, 255, 255]);
        let g = (40.0 + 215.0 * (3.0 * 99.0 / 198.0) / 3.0f32) as u8;
        assert_eq!(img.get_pixel(99, 0).0, [g, g, g]);
        let mut instance = vec![0u16; cols];
        instance[3] = 2;
        let lab = label_png(&range, &instance, rows, cols, 50.0, 1);
        assert_eq!(lab.get_pixel(3, 0).0, instance_colour(2));
        let grey = to_u8((1.0 - 0.8 * range_display(10.0, 50.0)) as f64 * 0.9);
        assert_eq!(lab.get_pixel(4, 0).0, [grey, grey, grey], "background: grey by range");
        assert_eq!(lab.get_pixel(150, 0).0, [0, 0, 0], "no return: black");
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
