//! Draws [`Plot`]s with `plotters` into an RGB buffer: axes, ticks, grid, series and legend
//! are plotters'; what is decided here is the data range of each axis, the decade ticks of log
//! axes, the text sizes for the picture's size, and which corner the legend takes (the one
//! that covers the fewest data pixels).

use super::text::{font, Canvas};
use super::{Draw, Marker, Plot, Series};
use image::RgbImage;
use plotters::coord::combinators::BindKeyPoints;
use plotters::coord::ranged1d::{Ranged, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters_backend::{BackendCoord, DrawingErrorKind};

type Area<'a> = DrawingArea<Canvas<'a>, Shift>;
type Drawn = std::result::Result<(), Box<dyn std::error::Error>>;

const TEXT: RGBColor = RGBColor(20, 20, 20);

/// `plots` drawn into a `rows` x `cols` grid of `tile`-sized cells.
pub(super) fn render(plots: &[Plot], (rows, cols): (u32, u32), tile: (u32, u32)) -> RgbImage {
    let (w, h) = (cols * tile.0, rows * tile.1);
    let mut buf = vec![255u8; w as usize * h as usize * 3];
    if w > 0 && h > 0 {
        font(); // registered before plotters measures text
        let root = Canvas(BitMapBackend::with_buffer(&mut buf, (w, h))).into_drawing_area();
        for (plot, area) in plots.iter().zip(root.split_evenly((rows as usize, cols as usize))) {
            // No error is expected of an in-memory bitmap and the embedded font; in a release
            // build one would leave the tile as drawn so far rather than stop the command.
            if let Err(e) = draw(plot, &area) {
                debug_assert!(e.to_string().is_empty(), "drawing {:?}: {e}", plot.title);
            }
        }
        let _ = root.present(); // a bitmap on a caller's buffer has nothing to flush
    }
    RgbImage::from_raw(w, h, buf).expect("a buffer of w x h RGB pixels")
}

/// Text height in pixels of tick labels, axis titles and legend for a `w` x `h` picture.
fn text_px(w: u32, h: u32) -> f64 {
    (w.min(h) as f64 / 28.0).clamp(12.0, 64.0)
}

fn style(px: f64) -> TextStyle<'static> {
    ("sans-serif", px).into_font().color(&TEXT)
}

/// The drawable points of a series: within +-1e300, and at least 1e-300 on a log axis.
fn drawable(s: &Series, log_x: bool, log_y: bool) -> Vec<(f64, f64)> {
    let ok = |v: f64, log: bool| v.abs() <= 1e300 && (!log || v >= 1e-300);
    s.points.iter().copied().filter(|&(x, y)| ok(x, log_x) && ok(y, log_y)).collect()
}

/// The axis range over `values`: 5 % padding on a linear axis (a tiny or empty span widened),
/// whole decades on a log axis (so that at least two decades are labelled).
fn axis_range(values: impl Iterator<Item = f64>, log: bool) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    if lo > hi {
        return if log { (1.0, 10.0) } else { (0.0, 1.0) };
    }
    if log {
        let a = (lo.log10() - 0.01).floor().max(-300.0);
        let b = (hi.log10() + 0.01).ceil().min(300.0).max(a + 1.0);
        return (10f64.powi(a as i32), 10f64.powi(b as i32));
    }
    let span = hi - lo;
    if span <= 1e-9 * lo.abs().max(hi.abs()) || span == 0.0 {
        let (c, half) = ((lo + hi) / 2.0, if lo == 0.0 && hi == 0.0 { 1.0 } else { 0.1 * lo.abs().max(hi.abs()) });
        return (c - half, c + half);
    }
    (lo - 0.05 * span, hi + 0.05 * span)
}

/// Ticks of a log axis over `(lo, hi)` (both powers of ten): 1, 2 and 5 times each decade
/// over one or two decades, else every k-th decade so that at most 8 are labelled; and the
/// light grid of 2..9 times each decade when there are few.
fn log_ticks((lo, hi): (f64, f64)) -> (Vec<f64>, Vec<f64>) {
    let (a, b) = (lo.log10().round() as i32, hi.log10().round() as i32);
    let stride = ((b - a) as usize).div_ceil(7).max(1);
    let steps: &[f64] = if b - a <= 2 { &[1.0, 2.0, 5.0] } else { &[1.0] };
    let mut bold: Vec<f64> = (a..b).step_by(stride).flat_map(|e| steps.iter().map(move |k| k * 10f64.powi(e))).collect();
    bold.push(hi);
    let light = if b - a > 6 { vec![] } else { (a..b).flat_map(|e| (2..10).map(move |k| k as f64 * 10f64.powi(e))).collect() };
    (bold, light)
}

/// A tick label: plain decimals from 0.001 to 99999 (at most 4 significant digits), powers
/// of ten as "1e-5", anything else as "2.5e7".
pub(super) fn tick_label(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        return "0".into();
    }
    if (1e-3..1e5).contains(&a) {
        let decimals = (3 - a.log10().floor() as i32).max(0) as usize;
        let s = format!("{v:.decimals$}");
        return if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').into() } else { s };
    }
    let s = format!("{v:.2e}");
    let (mantissa, exp) = s.split_once('e').unwrap_or((&s, "0"));
    format!("{}e{exp}", mantissa.trim_end_matches('0').trim_end_matches('.'))
}

/// The bold (labelled) ticks of an axis over `range`.
pub(super) fn ticks(range: (f64, f64), log: bool, n: usize) -> Vec<f64> {
    if log {
        log_ticks(range).0
    } else {
        RangedCoordf64::from(range.0..range.1).key_points(n)
    }
}

/// The largest font size from `px` down to 8 at which `text` fits `max_w` pixels, and the
/// text, cut and ending in "..." if even 8 px is too wide.
fn fit(area: &Area, text: &str, px: f64, max_w: u32) -> (String, f64) {
    let width = |t: &str, px: f64| area.estimate_text_size(t, &style(px)).map_or(u32::MAX, |s| s.0);
    let mut px = px;
    while px > 8.0 && width(text, px) > max_w {
        px -= 1.0;
    }
    let (mut t, mut cut) = (text.to_string(), false);
    while !t.is_empty() && width(&format!("{t}{}", if cut { "..." } else { "" }), px) > max_w {
        t.pop();
        cut = true;
    }
    if cut {
        t = format!("{}...", t.trim_end());
    }
    (t, px)
}

fn draw(plot: &Plot, area: &Area) -> Drawn {
    area.fill(&WHITE)?;
    let (w, h) = area.dim_in_pixel();
    let px = text_px(w, h);
    let pad = (px / 2.0).round() as u32;
    // The title, centred at the top; the chart below it.
    let mut top = pad;
    if !plot.title.trim().is_empty() {
        let (title, tpx) = fit(area, plot.title.trim(), 1.3 * px, w.saturating_sub(2 * pad));
        area.draw_text(&title, &style(tpx).pos(Pos::new(HPos::Center, VPos::Top)), (w as i32 / 2, pad as i32))?;
        top += (1.5 * px) as u32 + pad;
    }
    let pts: Vec<Vec<(f64, f64)>> = plot.series.iter().map(|s| drawable(s, plot.log_x, plot.log_y)).collect();
    let all = || plot.series.iter().zip(&pts).flat_map(|(s, p)| p.iter().map(move |&q| (s.draw, q)));
    let half_bar = |d: Draw| if let Draw::Bars { width } = d { width.abs() / 2.0 } else { 0.0 };
    let x = axis_range(all().flat_map(|(d, (x, _))| [x - half_bar(d), x + half_bar(d)]).filter(|&v| !plot.log_x || v > 0.0), plot.log_x);
    let bars = plot.series.iter().any(|s| matches!(s.draw, Draw::Bars { .. }));
    let y = axis_range(all().map(|(_, (_, y))| y).chain((bars && !plot.log_y).then_some(0.0)), plot.log_y);

    // Room for the y tick labels (measured) and the axis titles.
    let n_x = ((w as f64 / (6.0 * px)) as usize).clamp(2, 10);
    let n_y = ((h as f64 / (3.0 * px)) as usize).clamp(2, 8);
    let label_w = |v: &f64| area.estimate_text_size(&tick_label(*v), &style(px)).map_or(0, |s| s.0);
    let widest_y = ticks(y, plot.log_y, n_y).iter().map(label_w).max().unwrap_or(0);
    let desc = |s: &str| if s.trim().is_empty() { 0 } else { (1.2 * px) as u32 + pad };
    let y_area = widest_y + pad + desc(&plot.y_label) + pad;
    let x_area = (1.2 * px) as u32 + pad + desc(&plot.x_label);
    if w < y_area + 3 * pad + 4 * px as u32 || h < x_area + top + 2 * pad + 3 * px as u32 {
        return Ok(()); // too small for axes: the title only
    }
    // The last x tick label is centred on the axis' end: room for its right half.
    let last_x = ticks(x, plot.log_x, n_x).last().map_or(0, label_w);
    let mut builder = ChartBuilder::on(area);
    builder.margin(pad).margin_top(top).margin_right((last_x / 2 + pad).max(2 * pad));
    builder.x_label_area_size(x_area).y_label_area_size(y_area);
    let frame = Frame { px, n_x, n_y, log_y_base: y.0 };
    let linear = |r: (f64, f64)| RangedCoordf64::from(r.0..r.1);
    let logarithmic = |r: (f64, f64)| {
        let (bold, light) = log_ticks(r);
        (r.0..r.1).log_scale().with_key_points(bold).with_light_points(light)
    };
    match (plot.log_x, plot.log_y) {
        (false, false) => frame.chart(plot, &pts, &mut builder, linear(x), linear(y)),
        (true, false) => frame.chart(plot, &pts, &mut builder, logarithmic(x), linear(y)),
        (false, true) => frame.chart(plot, &pts, &mut builder, linear(x), logarithmic(y)),
        (true, true) => frame.chart(plot, &pts, &mut builder, logarithmic(x), logarithmic(y)),
    }
}

/// Sizes shared by the parts of one chart.
struct Frame {
    px: f64,
    n_x: usize,
    n_y: usize,
    /// Where bars start on a log y axis (its bottom).
    log_y_base: f64,
}

impl Frame {
    fn chart<X, Y>(&self, plot: &Plot, pts: &[Vec<(f64, f64)>], builder: &mut ChartBuilder<Canvas>, x: X, y: Y) -> Drawn
    where
        X: Ranged<ValueType = f64> + ValueFormatter<f64>,
        Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
    {
        let mut chart = builder.build_cartesian_2d(x, y)?;
        let label = |v: &f64| tick_label(*v);
        chart
            .configure_mesh()
            .x_labels(self.n_x)
            .y_labels(self.n_y)
            .x_label_formatter(&label)
            .y_label_formatter(&label)
            .label_style(style(self.px))
            .axis_desc_style(style(self.px))
            .x_desc(plot.x_label.trim())
            .y_desc(plot.y_label.trim())
            .bold_line_style(BLACK.mix(0.14))
            .light_line_style(BLACK.mix(0.05))
            .axis_style(BLACK)
            .draw()?;
        let base = if plot.log_y { self.log_y_base } else { 0.0 };
        let r = (self.px / 3.5).round() as i32;
        let sample = (2.0 * self.px) as i32;
        let mut probes: Vec<BackendCoord> = Vec::new();
        for (s, p) in plot.series.iter().zip(pts) {
            let colour = RGBColor(s.colour[0], s.colour[1], s.colour[2]);
            let anno = match s.draw {
                Draw::Points(m) => {
                    probes.extend(p.iter().map(|q| chart.backend_coord(q)));
                    chart.draw_series(p.iter().map(|&at| Elem { at, shape: Shape::Mark(m, r), colour }))?
                }
                Draw::Line(m) => {
                    let mut sorted = p.clone();
                    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
                    let line: Vec<BackendCoord> = sorted.iter().map(|q| chart.backend_coord(q)).collect();
                    probes.extend(segments(&line));
                    chart.draw_series(LineSeries::new(sorted, colour.stroke_width(self.line_w())))?;
                    chart.draw_series(p.iter().map(|&at| Elem { at, shape: Shape::Mark(m, (0.6 * r as f64).round() as i32), colour }))?
                }
                Draw::Bars { width } => {
                    for &(x, y) in p {
                        probes.extend(segments(&[chart.backend_coord(&(x, y)), chart.backend_coord(&(x, base))]));
                    }
                    let half = width.abs() / 2.0;
                    chart.draw_series(p.iter().map(|&(x, y)| Rectangle::new([(x - half, base), (x + half, y)], colour.filled())))?
                }
            };
            let (draw, lw) = (s.draw, self.line_w());
            anno.label(s.name.as_str()).legend(move |(x, y)| legend_sample(draw, colour, (x, y), sample, r, lw));
        }
        if plot.series.iter().all(|s| s.name.trim().is_empty()) {
            return Ok(());
        }
        let corner = self.legend_corner(plot, chart.plotting_area(), &probes, sample);
        chart
            .configure_series_labels()
            .position(corner)
            .margin((self.px / 2.0) as i32)
            .legend_area_size(sample + (self.px / 2.0) as i32)
            .label_font(style(self.px))
            .background_style(WHITE.mix(0.92))
            .border_style(RGBColor(160, 160, 160))
            .draw()?;
        Ok(())
    }

    fn line_w(&self) -> u32 {
        (self.px / 8.0).round().max(1.0) as u32
    }

    /// The corner of the plotting area whose legend box (estimated as plotters lays it out)
    /// covers the fewest `probes`; the first of upper right, upper left, lower right, lower
    /// left on a tie.
    fn legend_corner<CT: plotters::coord::CoordTranslate>(&self, plot: &Plot, area: &DrawingArea<Canvas, CT>, probes: &[BackendCoord], sample: i32) -> SeriesLabelPosition {
        use SeriesLabelPosition::*;
        let m = (self.px / 2.0) as i32;
        let names = plot.series.iter().map(|s| area.estimate_text_size(&s.name, &style(self.px)).map_or((0, 0), |(w, h)| (w as i32, h as i32)));
        let (tw, th) = names.fold((0, 0), |(w, h), (a, b)| (w.max(a), h + b));
        let (bw, bh) = (tw + sample + m + 2 * m, th + 2 * m);
        let (xr, yr) = area.get_pixel_range();
        let (left, top) = (xr.start + 5, yr.start + 5);
        let (right, bottom) = (xr.end - 5 - bw, yr.end - 5 - bh);
        let corners = [(UpperRight, right, top), (UpperLeft, left, top), (LowerRight, right, bottom), (LowerLeft, left, bottom)];
        let covered = |x0: i32, y0: i32| probes.iter().filter(|&&(x, y)| x >= x0 - m && x <= x0 + bw + m && y >= y0 - m && y <= y0 + bh + m).count();
        let best = corners.iter().enumerate().min_by_key(|(k, (_, x, y))| (covered(*x, *y), *k));
        best.map_or(UpperRight, |(_, c)| c.0.clone())
    }
}

/// Pixels along the polyline `line`, for the legend's choice of corner.
fn segments(line: &[BackendCoord]) -> Vec<BackendCoord> {
    let mut out = line.to_vec();
    for s in line.windows(2) {
        let ((x0, y0), (x1, y1)) = (s[0], s[1]);
        let n = ((x1 - x0).abs().max((y1 - y0).abs()) / 4).clamp(1, 256);
        out.extend((1..n).map(|k| (x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n)));
    }
    out
}

/// What an [`Elem`] draws at its point.
#[derive(Clone, Copy)]
enum Shape {
    /// A marker of this radius, centred on the point.
    Mark(Marker, i32),
    /// A horizontal line of this length and stroke width, from the point rightwards.
    Line(i32, u32),
    /// A filled box of this width and height, from the point rightwards, centred vertically.
    Bar(i32, i32),
}

/// A data marker (`C` = the chart's coordinates) or a legend sample (`C` = pixels).
struct Elem<C> {
    at: C,
    shape: Shape,
    colour: RGBColor,
}

impl<'a, C> plotters::element::PointCollection<'a, C> for &'a Elem<C> {
    type Point = &'a C;
    type IntoIter = std::iter::Once<&'a C>;
    fn point_iter(self) -> Self::IntoIter {
        std::iter::once(&self.at)
    }
}

impl<C, DB: DrawingBackend> plotters::element::Drawable<DB> for Elem<C> {
    fn draw<I: Iterator<Item = BackendCoord>>(&self, mut pos: I, backend: &mut DB, _: (u32, u32)) -> Result<(), DrawingErrorKind<DB::ErrorType>> {
        let Some((x, y)) = pos.next() else { return Ok(()) };
        let fill = self.colour.filled();
        match self.shape {
            Shape::Mark(Marker::Circle, r) => backend.draw_circle((x, y), r.max(1) as u32, &fill, true),
            Shape::Mark(Marker::Square, r) => backend.draw_rect((x - r, y - r), (x + r, y + r), &fill, true),
            Shape::Mark(Marker::Triangle, r) => backend.fill_polygon([(x, y - r - 1), (x - r - 1, y + r), (x + r + 1, y + r)], &fill),
            Shape::Mark(Marker::Cross, r) => {
                let stroke = self.colour.stroke_width(2);
                backend.draw_line((x - r, y - r), (x + r, y + r), &stroke)?;
                backend.draw_line((x - r, y + r), (x + r, y - r), &stroke)
            }
            Shape::Line(len, w) => backend.draw_line((x, y), (x + len, y), &self.colour.stroke_width(w)),
            Shape::Bar(w, h) => backend.draw_rect((x, y - h / 2), (x + w, y + h / 2), &fill, true),
        }
    }
}

/// A series' legend sample, `sample` pixels wide, starting at `(x, y)` (the left end of its
/// row's middle line).
fn legend_sample(draw: Draw, colour: RGBColor, (x, y): BackendCoord, sample: i32, r: i32, line_w: u32) -> Elem<BackendCoord> {
    let (at, shape) = match draw {
        Draw::Points(m) => ((x + sample / 2, y), Shape::Mark(m, r)),
        Draw::Line(_) => ((x, y), Shape::Line(sample, line_w)),
        Draw::Bars { .. } => ((x + sample / 4, y), Shape::Bar(sample / 2, 2 * r + 2)),
    };
    Elem { at, shape, colour }
}
