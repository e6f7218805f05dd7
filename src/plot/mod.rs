//! A small, dependency-free scatter/line plotter for PNG figures (e.g. the `bench` Pareto front
//! of run time against error): white background, axis box, "nice" ticks with labels (decades on
//! log axes), light grid lines, series drawn as anti-aliased markers and lines, a legend in the
//! emptiest corner, axis titles and a title, all in a built-in bitmap font ([`font`]).
//!
//! Rendering never panics: non-finite points, and zero/negative values on a log axis, are skipped;
//! empty plots, single points and all-equal values get a sensible default range.

mod axis;
mod draw;
pub mod font;

use axis::{to_axis, Axis};
use draw::*;

use std::path::Path;

use image::{Rgb, RgbImage};

use crate::{Error, Result};

/// Marker shape of a series.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Marker {
    Circle,
    Square,
    Triangle,
    Cross,
}

/// One named set of points.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// (x, y) data; non-finite points are skipped.
    pub points: Vec<(f64, f64)>,
    pub colour: [u8; 3],
    /// Connect the points with a line, in x order.
    pub line: bool,
    pub marker: Marker,
}

/// A 2-D plot rendered to an RGB image.
#[derive(Debug, Clone)]
pub struct Plot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub log_x: bool,
    pub log_y: bool,
    pub series: Vec<Series>,
    /// Image size in pixels (each clamped to at most [`MAX_SIDE`]).
    pub width: u32,
    pub height: u32,
}

/// Largest image side [`Plot::render`] produces; larger requests are clamped.
pub const MAX_SIDE: u32 = 16384;

/// Distinct, colour-blind-friendly series colours (Tableau 10).
pub const PALETTE: [[u8; 3]; 8] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
];

impl Default for Plot {
    fn default() -> Self {
        Plot {
            title: String::new(),
            x_label: String::new(),
            y_label: String::new(),
            log_x: false,
            log_y: false,
            series: Vec::new(),
            width: 800,
            height: 600,
        }
    }
}

/// Indices of the non-dominated points when minimising both coordinates (x = seconds per frame,
/// y = error), sorted by increasing x (so by decreasing y).
///
/// A point is dropped if another point is at most as large in both coordinates and strictly
/// smaller in one. Of exactly equal points only the one with the lowest index is kept. Points
/// with a NaN or infinite coordinate are ignored.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len())
        .filter(|&i| points[i].0.is_finite() && points[i].1.is_finite())
        .collect();
    order.sort_by(|&a, &b| {
        let (pa, pb) = (points[a], points[b]);
        pa.0.total_cmp(&pb.0)
            .then(pa.1.total_cmp(&pb.1))
            .then(a.cmp(&b))
    });
    let mut front = Vec::new();
    let mut best_y = f64::INFINITY;
    for i in order {
        // Sorted by x then y: a point survives only if it beats every earlier (no larger x) y.
        // -0.0 and 0.0 compare equal here, as they should.
        if points[i].1 < best_y {
            best_y = points[i].1;
            front.push(i);
        }
    }
    front
}

// ---------------------------------------------------------------------------------------------
// Layout
// ---------------------------------------------------------------------------------------------

/// Where everything goes, in pixels.
#[derive(Debug, Clone)]
struct Layout {
    /// Text scale of tick labels, axis titles and legend; the title uses `scale + 1`.
    scale: u32,
    /// Axis box, inclusive pixel bounds.
    left: i64,
    top: i64,
    right: i64,
    bottom: i64,
    /// Gap between the box and the ends of the axis ranges (keeps markers off the frame).
    inset: f64,
    /// The legend sits right of the axis box (every corner inside would cover data).
    legend_outside: bool,
    x: Axis,
    y: Axis,
}

impl Layout {
    fn px(&self, ax: f64) -> f64 {
        let (a, b) = (
            self.left as f64 + self.inset,
            self.right as f64 - self.inset,
        );
        let t = if self.x.hi > self.x.lo {
            (ax - self.x.lo) / (self.x.hi - self.x.lo)
        } else {
            0.5
        };
        (a + t * (b - a)).clamp(-1e6, 1e6)
    }
    fn py(&self, ay: f64) -> f64 {
        let (a, b) = (
            self.bottom as f64 - self.inset,
            self.top as f64 + self.inset,
        );
        let t = if self.y.hi > self.y.lo {
            (ay - self.y.lo) / (self.y.hi - self.y.lo)
        } else {
            0.5
        };
        (a + t * (b - a)).clamp(-1e6, 1e6)
    }
}

const BLACK: [u8; 3] = [0, 0, 0];
const TEXT: [u8; 3] = [20, 20, 20];
const GRID: [u8; 3] = [222, 222, 222];
const GRID_MINOR: [u8; 3] = [242, 242, 242];

impl Plot {
    /// The drawable points of each series, in axis space.
    fn axis_points(&self) -> Vec<Vec<(f64, f64)>> {
        self.series
            .iter()
            .map(|s| {
                s.points
                    .iter()
                    .filter_map(|&(x, y)| Some((to_axis(x, self.log_x)?, to_axis(y, self.log_y)?)))
                    .collect()
            })
            .collect()
    }

    fn layout(&self, pts: &[Vec<(f64, f64)>], w: u32, h: u32) -> Layout {
        let l = self.layout_reserving(pts, w, h, 0);
        match self.legend_size(l.scale) {
            // Move the legend out of the box when every corner inside covers data, if the
            // box keeps at least half the width.
            Some((bw, _)) if self.legend_corner(&l, pts).1 > 0 && (bw + 12 * l.scale as i64) < w as i64 / 2 => {
                let mut l = self.layout_reserving(pts, w, h, bw + 12 * l.scale as i64);
                l.legend_outside = true;
                l
            }
            _ => l,
        }
    }

    fn layout_reserving(&self, pts: &[Vec<(f64, f64)>], w: u32, h: u32, reserve_right: i64) -> Layout {
        let range = |f: fn(&(f64, f64)) -> f64| {
            pts.iter()
                .flatten()
                .map(f)
                .fold(None, |r: Option<(f64, f64)>, v| {
                    Some(r.map_or((v, v), |(a, b)| (a.min(v), b.max(v))))
                })
        };
        let x = Axis::new(range(|p| p.0), self.log_x);
        let y = Axis::new(range(|p| p.1), self.log_y);
        let scale = ((w.min(h) + 125) / 250).clamp(1, 4);
        let s = scale as i64;
        let pad = 6 * s;
        let th = font::text_height(scale) as i64;
        let tick_len = 5 * s;
        let ytick_w = y
            .ticks
            .iter()
            .map(|t| font::text_width(&t.label, scale))
            .max()
            .unwrap_or(0);
        let mut left = pad + tick_len + 3 * s + ytick_w as i64;
        if !self.y_label.trim().is_empty() {
            left += th + 2 * pad;
        }
        let mut top = 2 * pad;
        if !self.title.trim().is_empty() {
            top += font::text_height(scale + 1) as i64 + pad;
        }
        let mut bottom = pad + tick_len + 3 * s + th;
        if !self.x_label.trim().is_empty() {
            bottom += th + pad;
        }
        // The last x tick label is centred on the right edge of the box.
        let last_w = x
            .ticks
            .last()
            .map_or(0, |t| font::text_width(&t.label, scale)) as i64;
        let right = (last_w / 2 + pad).max(3 * pad);
        Layout {
            scale,
            left,
            top,
            right: w as i64 - 1 - right - reserve_right,
            bottom: h as i64 - 1 - bottom,
            inset: (6 * s + 2) as f64,
            legend_outside: false,
            x,
            y,
        }
    }

    /// Renders the plot.
    pub fn render(&self) -> RgbImage {
        let (w, h) = (self.width.min(MAX_SIDE), self.height.min(MAX_SIDE));
        let mut img = RgbImage::from_pixel(w, h, Rgb([255; 3]));
        let pts = self.axis_points();
        let l = self.layout(&pts, w, h);
        let scale = l.scale;
        let s = scale as i64;
        let th = font::text_height(scale) as i64;

        // Title, centred over the image right of the vertical y-axis title.
        if !self.title.trim().is_empty() {
            let x0 = if self.y_label.trim().is_empty() { 0 } else { 6 * s + th + 2 * s };
            let (title, ts) = fit_text(&self.title, w as i64 - x0 - 4 * s, scale + 1);
            let tw = font::text_width(&title, ts) as i64;
            let y = 2 * s + 4 + (font::text_height(scale + 1) - font::text_height(ts)) as i64 / 2;
            font::draw_text(&mut img, x0 + (w as i64 - x0 - tw) / 2, y, &title, ts, TEXT);
        }
        let box_ok = l.right - l.left > 2 * l.inset as i64 && l.bottom - l.top > 2 * l.inset as i64;
        if !box_ok {
            return img; // too small for an axis box; title only
        }
        let clip = Clip {
            x0: l.left + 1,
            y0: l.top + 1,
            x1: l.right - 1,
            y1: l.bottom - 1,
        };

        // Grid: minor first, then major.
        for &m in &l.x.minor {
            let x = l.px(m).round() as i64;
            fill_rect(&mut img, &clip, x, l.top, x, l.bottom, GRID_MINOR);
        }
        for &m in &l.y.minor {
            let y = l.py(m).round() as i64;
            fill_rect(&mut img, &clip, l.left, y, l.right, y, GRID_MINOR);
        }
        for t in &l.x.ticks {
            let x = l.px(t.pos).round() as i64;
            fill_rect(&mut img, &clip, x, l.top, x, l.bottom, GRID);
        }
        for t in &l.y.ticks {
            let y = l.py(t.pos).round() as i64;
            fill_rect(&mut img, &clip, l.left, y, l.right, y, GRID);
        }

        // Series: lines under markers.
        let lw = 0.75 * s as f64 + 0.25;
        for (ser, p) in self.series.iter().zip(&pts) {
            if ser.line && p.len() > 1 {
                let mut sorted: Vec<(f64, f64)> =
                    p.iter().map(|&(x, y)| (l.px(x), l.py(y))).collect();
                sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
                for seg in sorted.windows(2) {
                    draw_segment(&mut img, &clip, seg[0], seg[1], lw, ser.colour);
                }
            }
        }
        for (ser, p) in self.series.iter().zip(&pts) {
            let r = marker_radius(scale, ser.line);
            for &(x, y) in p {
                draw_marker(
                    &mut img,
                    &clip,
                    ser.marker,
                    (l.px(x), l.py(y)),
                    r,
                    ser.colour,
                );
            }
        }

        // Axis box and ticks.
        let full = Clip {
            x0: 0,
            y0: 0,
            x1: w as i64 - 1,
            y1: h as i64 - 1,
        };
        fill_rect(&mut img, &full, l.left, l.top, l.right, l.top, BLACK);
        fill_rect(&mut img, &full, l.left, l.bottom, l.right, l.bottom, BLACK);
        fill_rect(&mut img, &full, l.left, l.top, l.left, l.bottom, BLACK);
        fill_rect(&mut img, &full, l.right, l.top, l.right, l.bottom, BLACK);
        let tick_len = 5 * s;
        let gap = 3 * s;

        // X tick labels, thinned if they would touch.
        let xs: Vec<i64> =
            l.x.ticks
                .iter()
                .map(|t| l.px(t.pos).round() as i64)
                .collect();
        let xw =
            l.x.ticks
                .iter()
                .map(|t| font::text_width(&t.label, scale))
                .max()
                .unwrap_or(0);
        let x_every = label_stride(&xs, xw as i64 + 3 * font::ADVANCE as i64 * s);
        for (k, (t, &x)) in l.x.ticks.iter().zip(&xs).enumerate() {
            fill_rect(
                &mut img,
                &full,
                x,
                l.bottom + 1,
                x,
                l.bottom + tick_len,
                BLACK,
            );
            if k % x_every == 0 {
                let tw = font::text_width(&t.label, scale) as i64;
                font::draw_text(
                    &mut img,
                    x - tw / 2,
                    l.bottom + tick_len + gap,
                    &t.label,
                    scale,
                    TEXT,
                );
            }
        }
        // Y tick labels, right-aligned, vertically centred on the tick.
        let ys: Vec<i64> =
            l.y.ticks
                .iter()
                .map(|t| l.py(t.pos).round() as i64)
                .collect();
        let y_every = label_stride(&ys, th + 2 * s);
        for (k, (t, &y)) in l.y.ticks.iter().zip(&ys).enumerate() {
            fill_rect(&mut img, &full, l.left - tick_len, y, l.left - 1, y, BLACK);
            if k % y_every == 0 {
                let tw = font::text_width(&t.label, scale) as i64;
                let x = l.left - tick_len - gap - tw;
                // Centre on the 7-row body, not the descender row.
                font::draw_text(&mut img, x, y - (7 * s) / 2, &t.label, scale, TEXT);
            }
        }

        // Axis titles.
        if !self.x_label.trim().is_empty() {
            let (label, ls) = fit_text(&self.x_label, w as i64 - 4 * s, scale);
            let tw = font::text_width(&label, ls) as i64;
            let y = l.bottom + tick_len + gap + th + 6 * s;
            let x = ((l.left + l.right - tw) / 2).clamp(0, (w as i64 - tw).max(0));
            font::draw_text(&mut img, x, y, &label, ls, TEXT);
        }
        if !self.y_label.trim().is_empty() {
            let (label, ls) = fit_text(&self.y_label, h as i64 - 4 * s, scale);
            let tw = font::text_width(&label, ls) as i64;
            let y = ((l.top + l.bottom + tw) / 2).clamp(tw.min(h as i64), h as i64);
            font::draw_text_up(&mut img, 6 * s, y, &label, ls, TEXT);
        }

        self.draw_legend(&mut img, &l, &pts);
        img
    }

    /// Width and height of the legend box at text `scale` (None without series).
    fn legend_size(&self, scale: u32) -> Option<(i64, i64)> {
        if self.series.is_empty() {
            return None;
        }
        let s = scale as i64;
        let th = font::text_height(scale) as i64;
        let row = th + 4 * s;
        let (sample, pad) = (18 * s, 5 * s);
        let name_w = self.series.iter().map(|x| font::text_width(&x.name, scale)).max().unwrap_or(0);
        Some((pad + sample + pad + 2 * s + name_w as i64 + pad, 2 * pad + row * self.series.len() as i64 - 4 * s))
    }

    /// The corner of the axis box for the legend that covers the fewest data pixels, and how
    /// many it covers.
    fn legend_corner(&self, l: &Layout, pts: &[Vec<(f64, f64)>]) -> ((i64, i64), usize) {
        let Some((bw, bh)) = self.legend_size(l.scale) else { return ((l.left, l.top), 0) };
        let s = l.scale as i64;
        let m = 6 * s;
        // Top-right, top-left, bottom-right, bottom-left; first wins ties.
        let corners = [
            (l.right - m - bw, l.top + m),
            (l.left + m, l.top + m),
            (l.right - m - bw, l.bottom - m - bh),
            (l.left + m, l.bottom - m - bh),
        ];
        // Sample markers and line segments in pixel space.
        let mut probes: Vec<(f64, f64)> = Vec::new();
        for (ser, p) in self.series.iter().zip(pts) {
            let mut px: Vec<(f64, f64)> = p.iter().map(|&(x, y)| (l.px(x), l.py(y))).collect();
            probes.extend(&px);
            if ser.line {
                px.sort_by(|a, b| a.0.total_cmp(&b.0));
                for seg in px.windows(2) {
                    for k in 1..16 {
                        let t = k as f64 / 16.0;
                        probes.push((seg[0].0 + t * (seg[1].0 - seg[0].0), seg[0].1 + t * (seg[1].1 - seg[0].1)));
                    }
                }
            }
        }
        let margin = 4.0 * s as f64;
        let cost = |&(x0, y0): &(i64, i64)| {
            probes
                .iter()
                .filter(|&&(x, y)| {
                    x >= x0 as f64 - margin
                        && x <= (x0 + bw) as f64 + margin
                        && y >= y0 as f64 - margin
                        && y <= (y0 + bh) as f64 + margin
                })
                .count()
        };
        corners.iter().enumerate().map(|(i, c)| ((cost(c), i), *c)).min().map_or((corners[0], 0), |((n, _), c)| (c, n))
    }

    /// The legend: inside the axis box in its emptiest corner, or right of it.
    fn draw_legend(&self, img: &mut RgbImage, l: &Layout, pts: &[Vec<(f64, f64)>]) {
        let Some((bw, bh)) = self.legend_size(l.scale) else { return };
        let scale = l.scale;
        let s = scale as i64;
        let th = font::text_height(scale) as i64;
        let row = th + 4 * s;
        let sample = 18 * s;
        let pad = 5 * s;
        let (x0, y0) = if l.legend_outside { (l.right + 6 * s, l.top) } else { self.legend_corner(l, pts).0 };
        let full = Clip {
            x0: 0,
            y0: 0,
            x1: img.width() as i64 - 1,
            y1: img.height() as i64 - 1,
        };
        fill_rect(img, &full, x0, y0, x0 + bw, y0 + bh, [255; 3]);
        for (a, b, c, d) in [
            (x0, y0, x0 + bw, y0),
            (x0, y0 + bh, x0 + bw, y0 + bh),
            (x0, y0, x0, y0 + bh),
            (x0 + bw, y0, x0 + bw, y0 + bh),
        ] {
            fill_rect(img, &full, a, b, c, d, [160; 3]);
        }
        let clip = Clip {
            x0: x0 + 1,
            y0: y0 + 1,
            x1: x0 + bw - 1,
            y1: y0 + bh - 1,
        };
        for (k, ser) in self.series.iter().enumerate() {
            let top = y0 + pad + k as i64 * row;
            let cy = (top + (7 * s) / 2) as f64;
            let (sx0, sx1) = ((x0 + pad) as f64, (x0 + pad + sample) as f64);
            if ser.line {
                draw_segment(
                    img,
                    &clip,
                    (sx0, cy),
                    (sx1, cy),
                    0.75 * s as f64 + 0.25,
                    ser.colour,
                );
            }
            let r = marker_radius(scale, ser.line);
            draw_marker(
                img,
                &clip,
                ser.marker,
                ((sx0 + sx1) / 2.0, cy),
                r,
                ser.colour,
            );
            font::draw_text(
                img,
                x0 + 2 * pad + 2 * s + sample,
                top,
                &ser.name,
                scale,
                TEXT,
            );
        }
    }

    /// Renders and writes the plot as a PNG to `path` (see [`save_image`]).
    pub fn save(&self, path: &Path) -> Result<()> {
        save_image(&self.render(), path)
    }
}

/// Writes `img` as a PNG to `path`, via `path.with_extension("png.tmp")` and a rename, so
/// readers never see a partial file.
pub fn save_image(img: &RgbImage, path: &Path) -> Result<()> {
    let tmp = path.with_extension("png.tmp");
    let write = || -> Result<()> {
        let file = std::fs::File::create(&tmp).map_err(|e| Error::io(path, e))?;
        let mut out = std::io::BufWriter::new(file);
        img.write_to(&mut out, image::ImageFormat::Png).map_err(|e| match e {
            image::ImageError::IoError(io) => Error::io(path, io),
            other => Error::io(path, std::io::Error::other(other.to_string())),
        })?;
        let file = out.into_inner().map_err(|e| Error::io(path, e.into_error()))?;
        file.sync_all().map_err(|e| Error::io(path, e))?;
        std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
    };
    let r = write();
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    r
}

/// `text` at the largest scale `<= scale` whose width fits `max_w` pixels; if even scale 1 is too
/// wide, the text is cut and ends in "..".
fn fit_text(text: &str, max_w: i64, scale: u32) -> (String, u32) {
    let mut sc = scale.max(1);
    while sc > 1 && font::text_width(text, sc) as i64 > max_w {
        sc -= 1;
    }
    if font::text_width(text, sc) as i64 <= max_w {
        return (text.to_string(), sc);
    }
    let fit = ((max_w + 1) / font::ADVANCE as i64).max(2) as usize;
    let cut: String = text.chars().take(fit.saturating_sub(2)).collect();
    (format!("{}..", cut.trim_end()), sc)
}

/// Marker radius in pixels; markers on a line are smaller, so points of other series under a
/// line (e.g. a Pareto front drawn over the points it selects) stay visible.
fn marker_radius(scale: u32, line: bool) -> f64 {
    let r = 3.0 * scale as f64 + 0.5;
    if line {
        0.6 * r + 0.3
    } else {
        r
    }
}

/// Smallest k such that labelling every k-th of the tick positions `pos` keeps labels `size`
/// pixels apart.
fn label_stride(pos: &[i64], size: i64) -> usize {
    let gap = pos
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .min()
        .unwrap_or(i64::MAX);
    let mut k = 1usize;
    while (k as i64).saturating_mul(gap) < size && k < pos.len().max(1) {
        k += 1;
    }
    k
}

#[cfg(test)]
mod tests {
    use super::axis::{linear_axis, log_axis};
    use super::*;

    fn series(name: &str, points: Vec<(f64, f64)>, k: usize, line: bool, marker: Marker) -> Series {
        Series {
            name: name.into(),
            points,
            colour: PALETTE[k % PALETTE.len()],
            line,
            marker,
        }
    }

    fn example() -> Plot {
        // Seconds per frame against error for a few method families, and their Pareto front.
        let mut all = Vec::new();
        let mut series_list = Vec::new();
        let families: [(&str, Marker, f64, f64); 4] = [
            ("raster, nearest", Marker::Circle, 2.0e-3, 0.08),
            ("raster, bilinear", Marker::Square, 4.0e-3, 0.02),
            ("raster, exact", Marker::Triangle, 1.5e-2, 0.004),
            ("ray-cast (CPU)", Marker::Cross, 0.3, 0.0009),
        ];
        for (k, (name, marker, t, e)) in families.iter().enumerate() {
            let pts: Vec<(f64, f64)> = (0..6)
                .map(|i| {
                    let f = 1.7f64.powi(i);
                    let noise = ((i as usize * 37 + k * 11) % 7) as f64 / 6.0;
                    (
                        t * f * (1.0 + 0.4 * noise),
                        e / f.powf(0.6) * (1.0 + 1.5 * noise),
                    )
                })
                .collect();
            all.extend(&pts);
            series_list.push(series(name, pts, k, false, *marker));
        }
        let front: Vec<(f64, f64)> = pareto_front(&all).into_iter().map(|i| all[i]).collect();
        series_list.push(Series {
            name: "Pareto front".into(),
            points: front,
            colour: [30, 30, 30],
            line: true,
            marker: Marker::Circle,
        });
        Plot {
            title: "pedscan bench: time vs error".into(),
            x_label: "seconds per frame".into(),
            y_label: "mean range error (m)".into(),
            log_x: true,
            log_y: true,
            series: series_list,
            width: 800,
            height: 600,
        }
    }

    #[test]
    fn pareto_front_hand_cases() {
        assert!(pareto_front(&[]).is_empty());
        assert_eq!(pareto_front(&[(1.0, 1.0)]), vec![0]);
        // (2,2) is dominated by (1,1); front sorted by x.
        assert_eq!(
            pareto_front(&[(3.0, 0.5), (2.0, 2.0), (1.0, 1.0)]),
            vec![2, 0]
        );
        // A classic staircase with dominated points in between.
        let p = [
            (1.0, 5.0),
            (2.0, 3.0),
            (2.5, 4.0),
            (3.0, 1.0),
            (4.0, 1.0),
            (0.5, 9.0),
            (5.0, 0.5),
        ];
        assert_eq!(pareto_front(&p), vec![5, 0, 1, 3, 6]);
        // Equal x: only the lower y survives; equal y: only the lower x.
        assert_eq!(pareto_front(&[(1.0, 2.0), (1.0, 1.0), (2.0, 1.0)]), vec![1]);
        // Exact duplicates: the lowest index wins, deterministically.
        assert_eq!(
            pareto_front(&[(1.0, 1.0), (0.5, 3.0), (1.0, 1.0)]),
            vec![1, 0]
        );
        // NaN and infinities are ignored.
        assert_eq!(
            pareto_front(&[(f64::NAN, 0.0), (1.0, f64::INFINITY), (2.0, 2.0)]),
            vec![2]
        );
    }

    #[test]
    fn log_ticks_are_decades() {
        let a = log_axis((1e-4f64.log10(), 1e-1f64.log10()));
        let labels: Vec<&str> = a.ticks.iter().map(|t| t.label.as_str()).collect();
        assert_eq!(labels, ["1e-4", "1e-3", "1e-2", "1e-1"]);
        let pos: Vec<f64> = a.ticks.iter().map(|t| t.pos).collect();
        assert_eq!(pos, [-4.0, -3.0, -2.0, -1.0]);
        let a = log_axis((1e-3f64.log10(), 10f64.log10()));
        let labels: Vec<&str> = a.ticks.iter().map(|t| t.label.as_str()).collect();
        assert_eq!(labels, ["0.001", "0.01", "0.1", "1", "10"]);
        // One decade gets 1-2-5 ticks; a huge range gets a decade stride; both 4..=8 ticks.
        assert_eq!(log_axis((0.3, 0.9)).ticks.len(), 4);
        let huge = log_axis((-300.0, 300.0));
        assert!((4..=8).contains(&huge.ticks.len()), "{:?}", huge.ticks);
    }

    #[test]
    fn linear_ticks_are_nice() {
        for (lo, hi) in [
            (0.0, 1.0),
            (0.013, 0.37),
            (-5.0, 1234.0),
            (1e-9, 3e-9),
            (7.0, 7.0),
            (0.0, 0.0),
            (-1e300, 1e300),
            (1e9, 1e9 + 1e-6),
        ] {
            let a = linear_axis((lo, hi));
            assert!(
                (4..=8).contains(&a.ticks.len()),
                "{lo}..{hi}: {:?}",
                a.ticks
            );
            assert!(
                a.lo <= lo.min(hi) && a.hi >= hi.max(lo) || lo == hi,
                "{lo}..{hi}: {a:?}"
            );
            let labels: Vec<&String> = a.ticks.iter().map(|t| &t.label).collect();
            for w in labels.windows(2) {
                assert_ne!(w[0], w[1], "{lo}..{hi}: duplicate labels {labels:?}");
            }
        }
        let labels: Vec<String> = linear_axis((0.0, 1.0))
            .ticks
            .into_iter()
            .map(|t| t.label)
            .collect();
        assert_eq!(labels, ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]);
    }

    #[test]
    fn render_has_requested_size_and_tick_text() {
        let mut p = example();
        p.series = vec![series(
            "a",
            vec![(1e-4, 1.0), (1e-1, 2.0)],
            0,
            true,
            Marker::Circle,
        )];
        p.width = 640;
        p.height = 480;
        let img = p.render();
        assert_eq!(img.dimensions(), (640, 480));
        let pts = p.axis_points();
        let l = p.layout(&pts, 640, 480);
        let labels: Vec<&str> = l.x.ticks.iter().map(|t| t.label.as_str()).collect();
        assert_eq!(labels, ["1e-4", "1e-3", "1e-2", "1e-1"]);
        // Under the "1e-3" tick, where its label goes, there is dark ink; between ticks a bit
        // lower down there is none.
        let x = l.px(-3.0).round() as i64;
        let s = l.scale as i64;
        let tw = font::text_width("1e-3", l.scale) as i64;
        let y0 = l.bottom + 8 * s;
        let ink = |x0: i64, x1: i64, y0: i64, y1: i64| {
            let mut n = 0;
            for y in y0..y1 {
                for x in x0..x1 {
                    n += (img.get_pixel(x as u32, y as u32).0[0] < 100) as usize;
                }
            }
            n
        };
        let dark = ink(x - tw / 2, x + tw / 2 + 1, y0, y0 + 8 * s);
        assert!(dark > 30, "only {dark} dark pixels under the 1e-3 tick");
        assert_eq!(ink(x + tw / 2 + 3 * s, x + tw, y0, y0 + 8 * s), 0);
        // The background is white and the box corner black.
        assert_eq!(img.get_pixel(639, 0).0, [255; 3]);
        assert_eq!(img.get_pixel(l.left as u32, l.bottom as u32).0, [0; 3]);
    }

    #[test]
    fn long_text_shrinks_then_is_cut() {
        assert_eq!(fit_text("abc", 100, 3), ("abc".to_string(), 3));
        let (t, sc) = fit_text("abcdefghij", 70, 3); // 59 px at scale 1, 118 at 2
        assert_eq!((t.as_str(), sc), ("abcdefghij", 1));
        let (t, sc) = fit_text("abcdefghij", 40, 2);
        assert_eq!(sc, 1);
        assert!(t.ends_with("..") && font::text_width(&t, 1) <= 40, "{t}");
    }

    #[test]
    fn degenerate_inputs_do_not_panic() {
        let nan = f64::NAN;
        let inf = f64::INFINITY;
        let cases: Vec<Vec<(f64, f64)>> = vec![
            vec![],
            vec![(1.0, 1.0)],
            vec![(2.0, 3.0); 5],
            vec![(nan, nan), (inf, -inf), (nan, 1.0)],
            vec![(0.0, 0.0), (-1.0, -5.0), (1.0, 1.0)],
            vec![(-1.0, -1.0), (0.0, 0.0)],
            vec![
                (1e-300, 1e-300),
                (1e300, 1e300),
                (f64::MIN_POSITIVE / 1e10, f64::MAX),
            ],
            vec![(-f64::MAX, f64::MAX), (f64::MAX, -f64::MAX)],
            vec![(1e9, 1.0), (1e9 + 1e-7, 1.0 + 1e-15)],
        ];
        for (i, pts) in cases.into_iter().enumerate() {
            for (log_x, log_y) in [(false, false), (true, true), (true, false)] {
                for (w, h) in [(800, 600), (120, 90), (1, 1), (0, 0), (3000, 40)] {
                    let p = Plot {
                        title: "t".into(),
                        x_label: "x".into(),
                        y_label: "y".into(),
                        log_x,
                        log_y,
                        series: vec![
                            series("s", pts.clone(), i, true, Marker::Triangle),
                            series("empty", vec![], i + 1, true, Marker::Cross),
                        ],
                        width: w,
                        height: h,
                    };
                    assert_eq!(p.render().dimensions(), (w, h));
                }
            }
        }
        let p = Plot {
            series: vec![],
            ..Plot::default()
        };
        assert_eq!(p.render().dimensions(), (800, 600));
    }

    #[test]
    fn save_writes_decodable_png_and_no_tmp() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("front.png");
        let p = example();
        p.save(&path).unwrap();
        assert!(!path.with_extension("png.tmp").exists());
        let back = image::open(&path).unwrap().to_rgb8();
        assert_eq!(back.dimensions(), (800, 600));
        assert_eq!(back, p.render());
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
        // A missing folder is an I/O error naming the path, not a panic.
        let bad = dir.path().join("missing").join("x.png");
        let err = p.save(&bad).unwrap_err();
        assert!(
            matches!(&err, Error::Io { path, .. } if path == &bad),
            "{err}"
        );
    }

    /// Writes `$TMPDIR/pedscan-plot-example.png` for a person to look at.
    #[test]
    #[ignore]
    fn save_example_plot() {
        let path = std::env::temp_dir().join("pedscan-plot-example.png");
        example().save(&path).unwrap();
        let mut lin = example();
        lin.log_x = false;
        lin.log_y = false;
        lin.width = 640;
        lin.height = 420;
        lin.title = "same data, linear axes".into();
        lin.save(&std::env::temp_dir().join("pedscan-plot-example-linear.png"))
            .unwrap();
        let small = Plot {
            title: "one point, a NaN, a negative on log y".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            log_y: true,
            series: vec![series(
                "only",
                vec![(3.0, 0.02), (f64::NAN, 1.0), (4.0, -1.0)],
                2,
                true,
                Marker::Square,
            )],
            width: 400,
            height: 300,
            ..Plot::default()
        };
        small
            .save(&std::env::temp_dir().join("pedscan-plot-example-small.png"))
            .unwrap();
        eprintln!("wrote {}", path.display());
    }
}
