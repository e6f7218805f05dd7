//! Plots: what the pictures hold (bars as tall as their counts, text in the embedded font,
//! decade ticks), that odd inputs draw without panicking, and that the same plot gives the
//! same bytes.

use super::chart::{tick_label, ticks};
use super::text::FONT_TTF;
use super::*;

fn series(name: &str, points: Vec<(f64, f64)>, k: usize, draw: Draw) -> Series {
    Series { name: name.into(), points, colour: PALETTE[k % PALETTE.len()], draw }
}

/// Seconds per frame against error for a few method families, and their Pareto front.
fn example() -> Plot {
    let mut all = Vec::new();
    let mut list = Vec::new();
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
                (t * f * (1.0 + 0.4 * noise), e / f.powf(0.6) * (1.0 + 1.5 * noise))
            })
            .collect();
        all.extend(&pts);
        list.push(series(name, pts, k, Draw::Points(*marker)));
    }
    let front: Vec<(f64, f64)> = pareto_front(&all).into_iter().map(|i| all[i]).collect();
    list.push(Series { name: "Pareto front".into(), points: front, colour: [30, 30, 30], draw: Draw::Line(Marker::Circle) });
    Plot {
        title: "pedscan bench: time vs error".into(),
        x_label: "seconds per frame".into(),
        y_label: "mean range error (m)".into(),
        log_x: true,
        log_y: true,
        series: list,
        width: 800,
        height: 600,
    }
}

/// A histogram of `counts` (one bar per integer x) in colour 2.
fn histogram(counts: &[u64]) -> Plot {
    Plot {
        title: "a histogram".into(),
        x_label: "value".into(),
        y_label: "count".into(),
        series: vec![series("counts", counts.iter().enumerate().map(|(k, &c)| (k as f64, c as f64)).collect(), 2, Draw::Bars { width: 0.8 })],
        width: 640,
        height: 400,
        ..Plot::default()
    }
}

/// Dark pixels (text, axes) in the rectangle `x0..x1` x `y0..y1` of `img`.
pub(crate) fn ink(img: &RgbImage, (x0, x1): (u32, u32), (y0, y1): (u32, u32)) -> usize {
    (y0..y1).flat_map(|y| (x0..x1).map(move |x| (x, y))).filter(|&(x, y)| img.get_pixel(x, y).0.iter().all(|&c| c < 110)).count()
}

/// The bars of colour `colour` in `img`: for each run of adjacent columns holding it, the
/// left column and the tallest unbroken run of it in those columns.
pub(crate) fn bars(img: &RgbImage, colour: [u8; 3]) -> Vec<(u32, u32)> {
    let column = |x: u32| {
        let (mut best, mut run) = (0, 0);
        for y in 0..img.height() {
            run = if img.get_pixel(x, y).0 == colour { run + 1 } else { 0 };
            best = best.max(run);
        }
        best
    };
    let mut out: Vec<(u32, u32)> = Vec::new();
    let mut prev = 0;
    for x in 0..img.width() {
        let h = column(x);
        if h > 0 && prev == 0 {
            out.push((x, h));
        } else if h > 0 {
            let last = out.last_mut().expect("a bar started");
            last.1 = last.1.max(h);
        }
        prev = h;
    }
    out
}

#[test]
fn pareto_front_hand_cases() {
    assert!(pareto_front(&[]).is_empty());
    assert_eq!(pareto_front(&[(1.0, 1.0)]), vec![0]);
    // (2,2) is dominated by (1,1); front sorted by x.
    assert_eq!(pareto_front(&[(3.0, 0.5), (2.0, 2.0), (1.0, 1.0)]), vec![2, 0]);
    // A staircase with dominated points in between.
    let p = [(1.0, 5.0), (2.0, 3.0), (2.5, 4.0), (3.0, 1.0), (4.0, 1.0), (0.5, 9.0), (5.0, 0.5)];
    assert_eq!(pareto_front(&p), vec![5, 0, 1, 3, 6]);
    // Equal x: only the lower y survives; equal y: only the lower x.
    assert_eq!(pareto_front(&[(1.0, 2.0), (1.0, 1.0), (2.0, 1.0)]), vec![1]);
    // Exact duplicates: the lowest index wins, deterministically.
    assert_eq!(pareto_front(&[(1.0, 1.0), (0.5, 3.0), (1.0, 1.0)]), vec![1, 0]);
    // NaN and infinities are ignored.
    assert_eq!(pareto_front(&[(f64::NAN, 0.0), (1.0, f64::INFINITY), (2.0, 2.0)]), vec![2]);
}

#[test]
fn log_axes_are_labelled_in_decades() {
    let labels = |r: (f64, f64)| ticks(r, true, 8).into_iter().map(tick_label).collect::<Vec<_>>();
    assert_eq!(labels((1e-4, 1e-1)), ["1e-4", "0.001", "0.01", "0.1"]);
    // One or two decades: 1-2-5 steps.
    assert_eq!(labels((100.0, 1000.0)), ["100", "200", "500", "1000"]);
    assert_eq!(labels((1e-7, 1e-5)), ["1e-7", "2e-7", "5e-7", "1e-6", "2e-6", "5e-6", "1e-5"]);
    assert_eq!(labels((1e-3, 1e2)), ["0.001", "0.01", "0.1", "1", "10", "100"]);
    // A huge range labels every k-th decade, at most 8.
    let huge = ticks((1e-300, 1e300), true, 8);
    assert!((2..=8).contains(&huge.len()), "{huge:?}");
    assert_eq!(tick_label(2.5e7), "2.5e7");
    assert_eq!(tick_label(-0.25), "-0.25");
    assert_eq!(tick_label(1234.0), "1234");
    assert_eq!(tick_label(0.30000000000000004), "0.3");
}

#[test]
fn linear_ticks_are_nice() {
    let labels: Vec<String> = ticks((0.0, 1.0), false, 6).into_iter().map(tick_label).collect();
    assert_eq!(labels, ["0", "0.2", "0.4", "0.6", "0.8", "1"]);
    for (lo, hi) in [(0.013, 0.37), (-5.0, 1234.0), (1e-9, 3e-9), (-1e300, 1e300)] {
        let t = ticks((lo, hi), false, 8);
        assert!((2..=8).contains(&t.len()), "{lo}..{hi}: {t:?}");
        let l: Vec<String> = t.into_iter().map(tick_label).collect();
        assert!(l.windows(2).all(|w| w[0] != w[1]), "{lo}..{hi}: duplicate labels {l:?}");
    }
}

#[test]
fn bars_are_as_tall_as_their_counts() {
    let counts = [0, 10, 20, 40, 20, 5];
    let img = histogram(&counts).render();
    assert_eq!(img.dimensions(), (640, 400));
    // The legend's sample is a short bar of the same colour: keep the data bars (taller).
    let found: Vec<(u32, u32)> = bars(&img, PALETTE[2]).into_iter().filter(|b| b.1 > 20).collect();
    assert_eq!(found.len(), 5, "{found:?}");
    let unit = found[2].1 as f64 / 40.0;
    for (&(_, h), &c) in found.iter().zip(&counts[1..]) {
        assert!((h as f64 - c as f64 * unit).abs() <= 2.0, "bar of {c} is {h} px, {unit} px per count: {found:?}");
    }
    // Left to right, one count apart.
    let gaps: Vec<u32> = found.windows(2).map(|w| w[1].0 - w[0].0).collect();
    assert!(gaps.iter().all(|&g| g.abs_diff(gaps[0]) <= 1), "{gaps:?}");
}

#[test]
fn text_is_drawn_in_the_embedded_font() {
    // The font parses, and it is what plotters measures text with.
    assert!(FONT_TTF.len() > 100_000 && &FONT_TTF[..4] == b"\0\x01\0\0");
    let mut titled = histogram(&[1, 2, 3]);
    titled.series.clear();
    let mut plain = titled.clone();
    plain.title.clear();
    let (a, b) = (titled.render(), plain.render());
    // The title's band (top 30 px, centred) has ink; without a title it is blank.
    assert!(ink(&a, (200, 440), (0, 30)) > 100, "no title text");
    assert_eq!(ink(&b, (200, 440), (0, 30)), 0);
    // Tick labels and the axis titles: ink left of and under the axes.
    assert!(ink(&a, (0, 40), (100, 300)) > 50, "no y label text");
    assert!(ink(&a, (200, 440), (370, 400)) > 50, "no x label text");
}

#[test]
fn the_same_plot_gives_the_same_png_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let (p, q) = (dir.path().join("a.png"), dir.path().join("b.png"));
    example().save(&p).unwrap();
    example().save(&q).unwrap();
    assert_eq!(std::fs::read(&p).unwrap(), std::fs::read(&q).unwrap());
}

#[test]
fn a_grid_holds_each_plot_in_its_tile() {
    let tiles = [histogram(&[1, 2]), histogram(&[3]), histogram(&[4, 4, 4])];
    let img = render_grid(&tiles, 2);
    assert_eq!(img.dimensions(), (1280, 800));
    // The empty fourth tile stays white; the third (bottom left) is the three-bar histogram.
    assert!(img.enumerate_pixels().filter(|(x, y, _)| *x >= 640 && *y >= 400).all(|(_, _, p)| p.0 == [255; 3]));
    let bottom_left = image::imageops::crop_imm(&img, 0, 400, 640, 400).to_image();
    assert_eq!(bars(&bottom_left, PALETTE[2]).into_iter().filter(|b| b.1 > 20).count(), 3);
}

#[test]
fn degenerate_inputs_do_not_panic() {
    let (nan, inf) = (f64::NAN, f64::INFINITY);
    let cases: Vec<Vec<(f64, f64)>> = vec![
        vec![],
        vec![(1.0, 1.0)],
        vec![(2.0, 3.0); 5],
        vec![(nan, nan), (inf, -inf), (nan, 1.0)],
        vec![(0.0, 0.0), (-1.0, -5.0), (1.0, 1.0)],
        vec![(-1.0, -1.0), (0.0, 0.0)],
        vec![(1e-300, 1e-300), (1e300, 1e300), (f64::MIN_POSITIVE / 1e10, f64::MAX)],
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
                        series("s", pts.clone(), i, Draw::Line(Marker::Triangle)),
                        series("b", pts.clone(), i + 1, Draw::Bars { width: 0.5 }),
                        series("empty", vec![], i + 2, Draw::Points(Marker::Cross)),
                    ],
                    width: w,
                    height: h,
                };
                assert_eq!(p.render().dimensions(), (w, h));
            }
        }
    }
    assert_eq!(Plot::default().render().dimensions(), (800, 600));
    let long = Plot { title: "a title far too long for its picture ".repeat(8), width: 300, height: 200, ..Plot::default() };
    assert_eq!(long.render().dimensions(), (300, 200));
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
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names.len(), 1, "{names:?}");
    // A missing folder is an I/O error naming the path, not a panic.
    let bad = dir.path().join("missing").join("x.png");
    let err = p.save(&bad).unwrap_err();
    assert!(matches!(&err, Error::Io { path, .. } if path == &bad), "{err}");
}

/// Writes `$TMPDIR/pedscan-plot-example*.png` for a person to look at.
#[test]
#[ignore]
fn save_example_plot() {
    let tmp = std::env::temp_dir();
    example().save(&tmp.join("pedscan-plot-example.png")).unwrap();
    let mut lin = example();
    (lin.log_x, lin.log_y, lin.width, lin.height) = (false, false, 640, 420);
    lin.title = "same data, linear axes".into();
    lin.save(&tmp.join("pedscan-plot-example-linear.png")).unwrap();
    histogram(&[0, 10, 20, 40, 20, 5]).save(&tmp.join("pedscan-plot-example-bars.png")).unwrap();
    eprintln!("wrote {}", tmp.join("pedscan-plot-example*.png").display());
}
