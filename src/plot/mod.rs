//! Figures as PNG: the `bench` Pareto front of time against error, the `stats` histograms and
//! the `realism` curves. A [`Plot`] (title, axis titles, linear or log axes, series drawn as
//! markers, lines or bars) is drawn by the `plotters` crate ([`chart`]), with its text in the
//! font the repository ships (`data/fonts/LiberationSans-Regular.ttf`, SIL OFL 1.1, embedded
//! in the binary and rasterised by `ab_glyph`: no system font is looked up).
//!
//! [`font`] is the small bitmap font of the debug images (range, label and bird's-eye PNGs, the
//! contact sheet), which are drawn pixel by pixel and need no chart library.
//!
//! Rendering never panics and is deterministic (the same plot gives the same pixels):
//! non-finite points, points beyond +-1e300, and values below 1e-300 (zero, negative) on a log
//! axis are skipped; empty plots, single points and all-equal values get a sensible default
//! range; a picture too small for axes shows its title only.

mod chart;
pub mod font;
mod text;

use std::path::Path;

use image::RgbImage;

use crate::{Error, Result};

/// Marker shape of a series.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Marker {
    Circle,
    Square,
    Triangle,
    Cross,
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Draw {
    /// A marker at each point.
    Points(Marker),
    /// The points joined in x order, with small markers.
    Line(Marker),
    /// A bar from the axis (0 on a linear y axis, its bottom on a log one) up to each point,
    /// `width` x units wide and centred on the point's x.
    Bars { width: f64 },
}

/// One named set of points.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// (x, y) data; non-finite points are skipped.
    pub points: Vec<(f64, f64)>,
    pub colour: [u8; 3],
    pub draw: Draw,
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

/// Largest image side [`Plot::render`] and [`render_grid`] produce; larger requests are clamped.
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

impl Plot {
    /// Renders the plot.
    pub fn render(&self) -> RgbImage {
        render_grid(std::slice::from_ref(self), 1)
    }

    /// Renders and writes the plot as a PNG to `path` (see [`save_image`]).
    pub fn save(&self, path: &Path) -> Result<()> {
        save_image(&self.render(), path)
    }
}

/// `plots` as tiles of one picture, `columns` to a row, each tile the size of the first plot
/// (the whole clamped to [`MAX_SIDE`]).
pub fn render_grid(plots: &[Plot], columns: usize) -> RgbImage {
    let cols = columns.clamp(1, plots.len().max(1)) as u32;
    let rows = (plots.len() as u32).div_ceil(cols);
    let (tw, th) = plots.first().map_or((0, 0), |p| (p.width.min(MAX_SIDE / cols), p.height.min(MAX_SIDE / rows.max(1))));
    chart::render(plots, (rows, cols), (tw, th))
}

/// Indices of the non-dominated points when minimising both coordinates (x = seconds per frame,
/// y = error), sorted by increasing x (so by decreasing y).
///
/// A point is dropped if another point is at most as large in both coordinates and strictly
/// smaller in one. Of exactly equal points only the one with the lowest index is kept. Points
/// with a NaN or infinite coordinate are ignored.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len()).filter(|&i| points[i].0.is_finite() && points[i].1.is_finite()).collect();
    order.sort_by(|&a, &b| {
        let (pa, pb) = (points[a], points[b]);
        pa.0.total_cmp(&pb.0).then(pa.1.total_cmp(&pb.1)).then(a.cmp(&b))
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

#[cfg(test)]
pub(crate) mod tests;
