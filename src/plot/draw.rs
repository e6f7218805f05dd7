//! Raster primitives of the plotter: filled shapes, anti-aliased segments and markers, all
//! clipped, none can panic.

use super::Marker;
use image::{Rgb, RgbImage};

// ---------------------------------------------------------------------------------------------
// Raster primitives (all clipped, none can panic)
// ---------------------------------------------------------------------------------------------

/// Inclusive pixel rectangle that drawing is limited to.
pub(super) struct Clip {
    pub(super) x0: i64,
    pub(super) y0: i64,
    pub(super) x1: i64,
    pub(super) y1: i64,
}

impl Clip {
    /// `clip ∩ [x0, x1] × [y0, y1]` (inclusive), or `None` if empty.
    pub(super) fn range(
        &self,
        img: &RgbImage,
        x0: i64,
        y0: i64,
        x1: i64,
        y1: i64,
    ) -> Option<(i64, i64, i64, i64)> {
        let ax = x0.min(x1).max(self.x0).max(0);
        let bx = x0.max(x1).min(self.x1).min(img.width() as i64 - 1);
        let ay = y0.min(y1).max(self.y0).max(0);
        let by = y0.max(y1).min(self.y1).min(img.height() as i64 - 1);
        (ax <= bx && ay <= by).then_some((ax, ay, bx, by))
    }
}

pub(super) fn fill_rect(img: &mut RgbImage, clip: &Clip, x0: i64, y0: i64, x1: i64, y1: i64, c: [u8; 3]) {
    if let Some((ax, ay, bx, by)) = clip.range(img, x0, y0, x1, y1) {
        for y in ay..=by {
            for x in ax..=bx {
                img.put_pixel(x as u32, y as u32, Rgb(c));
            }
        }
    }
}

pub(super) fn blend(img: &mut RgbImage, x: i64, y: i64, c: [u8; 3], alpha: f64) {
    if alpha <= 0.0 {
        return;
    }
    let a = alpha.min(1.0);
    let p = img.get_pixel_mut(x as u32, y as u32);
    for k in 0..3 {
        p.0[k] = (p.0[k] as f64 * (1.0 - a) + c[k] as f64 * a).round() as u8;
    }
}

/// Fills the shape `inside(x, y)` (pixel-centre coordinates) within the bounding box
/// `[x0, x1] × [y0, y1]`, anti-aliased by 4×4 supersampling.
pub(super) fn fill_shape(
    img: &mut RgbImage,
    clip: &Clip,
    (x0, y0, x1, y1): (f64, f64, f64, f64),
    c: [u8; 3],
    inside: impl Fn(f64, f64) -> bool,
) {
    let Some((ax, ay, bx, by)) = clip.range(
        img,
        x0.floor() as i64,
        y0.floor() as i64,
        x1.ceil() as i64,
        y1.ceil() as i64,
    ) else {
        return;
    };
    for py in ay..=by {
        for px in ax..=bx {
            let mut hits = 0;
            for sy in 0..4 {
                for sx in 0..4 {
                    let x = px as f64 + (sx as f64 + 0.5) / 4.0 - 0.5;
                    let y = py as f64 + (sy as f64 + 0.5) / 4.0 - 0.5;
                    hits += inside(x, y) as u32;
                }
            }
            blend(img, px, py, c, hits as f64 / 16.0);
        }
    }
}

/// Distance from `p` to the segment `a`–`b`.
pub(super) fn seg_dist(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (qx, qy) = (a.0 + t * dx - p.0, a.1 + t * dy - p.1);
    (qx * qx + qy * qy).sqrt()
}

/// An anti-aliased line of half-width `hw` from `a` to `b`.
pub(super) fn draw_segment(
    img: &mut RgbImage,
    clip: &Clip,
    a: (f64, f64),
    b: (f64, f64),
    hw: f64,
    c: [u8; 3],
) {
    let m = hw + 1.0;
    let Some((ax, ay, bx, by)) = clip.range(
        img,
        (a.0.min(b.0) - m).floor() as i64,
        (a.1.min(b.1) - m).floor() as i64,
        (a.0.max(b.0) + m).ceil() as i64,
        (a.1.max(b.1) + m).ceil() as i64,
    ) else {
        return;
    };
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len = (dx * dx + dy * dy).sqrt();
    for py in ay..=by {
        // Only scan the columns near the line on this row, so long diagonals stay cheap.
        let (cx0, cx1) = if dy.abs() > 1e-9 {
            let t0 = ((py as f64 - m - a.1) / dy).clamp(0.0, 1.0);
            let t1 = ((py as f64 + m - a.1) / dy).clamp(0.0, 1.0);
            let (u, v) = (a.0 + t0 * dx, a.0 + t1 * dx);
            let slack = m * len / dy.abs().max(1e-9);
            (
                (u.min(v) - slack.min(1e6)).floor() as i64,
                (u.max(v) + slack.min(1e6)).ceil() as i64,
            )
        } else {
            (ax, bx)
        };
        for px in cx0.max(ax)..=cx1.min(bx) {
            let d = seg_dist((px as f64, py as f64), a, b);
            blend(img, px, py, c, hw + 0.5 - d);
        }
    }
}

pub(super) fn darker(c: [u8; 3]) -> [u8; 3] {
    c.map(|v| (v as f64 * 0.55) as u8)
}

/// A marker of radius `r` centred at `p`: a dark outline under a filled shape.
pub(super) fn draw_marker(img: &mut RgbImage, clip: &Clip, marker: Marker, p: (f64, f64), r: f64, c: [u8; 3]) {
    let (cx, cy) = p;
    let bbox = |r: f64| (cx - r - 1.0, cy - r - 1.0, cx + r + 1.0, cy + r + 1.0);
    let shape = |r: f64| {
        move |x: f64, y: f64| -> bool {
            let (dx, dy) = (x - cx, y - cy);
            match marker {
                Marker::Circle => dx * dx + dy * dy <= r * r,
                Marker::Square => dx.abs() <= r * 0.85 && dy.abs() <= r * 0.85,
                Marker::Triangle => {
                    // Upward equilateral triangle with circumradius 1.25 r, centred on p.
                    let rr = r * 1.25;
                    dy <= rr * 0.5 && dx.abs() <= (dy + rr) * 0.577_350_3
                }
                Marker::Cross => {
                    let hw = r * 0.32;
                    let a = r * 0.95;
                    seg_dist((x, y), (cx - a, cy - a), (cx + a, cy + a)) <= hw
                        || seg_dist((x, y), (cx - a, cy + a), (cx + a, cy - a)) <= hw
                }
            }
        }
    };
    let outline = 1.0 + 0.25 * r;
    if marker == Marker::Cross {
        fill_shape(img, clip, bbox(r + 1.0), c, shape(r));
    } else {
        fill_shape(
            img,
            clip,
            bbox(r + outline),
            darker(c),
            shape(r + outline * 0.6),
        );
        fill_shape(img, clip, bbox(r), c, shape(r - outline * 0.4));
    }
}

