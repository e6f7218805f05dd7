//! The figures of the command line: `pedscan stats` draws its histograms as bars, with its text
//! in the font pedscan embeds. No system font is looked up: the binary links no font library,
//! and a run whose font configuration points nowhere draws the same bytes.

use crate::common::*;
use std::path::Path;

/// Dark pixels (text) in the rectangle `x0..x1` x `y0..y1`.
fn ink(img: &image::RgbImage, (x0, x1): (u32, u32), (y0, y1): (u32, u32)) -> usize {
    (y0..y1).flat_map(|y| (x0..x1).map(move |x| (x, y))).filter(|&(x, y)| img.get_pixel(x, y).0.iter().all(|&c| c < 110)).count()
}

#[test]
fn stats_draws_bars_and_text_in_the_embedded_font() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    ok(&pedscan(&["generate", "--backend", "raycast", "--sequences", "1", "--frames", "3", "--humans", "3..3", "--seed", "2", "--out", "o"], dir));
    ok(&pedscan(&["stats", "o", "--png", "s.png"], dir));
    // No font configuration, no font folders, a home without fonts.
    let nowhere = dir.join("nowhere");
    let nowhere = nowhere.to_str().unwrap();
    let bare = [("FONTCONFIG_FILE", nowhere), ("FONTCONFIG_PATH", nowhere), ("XDG_DATA_DIRS", nowhere), ("XDG_DATA_HOME", nowhere), ("HOME", nowhere)];
    ok(&pedscan_with_env(&["stats", "o", "--png", "bare.png"], dir, &bare));
    let bytes = std::fs::read(dir.join("s.png")).unwrap();
    assert_eq!(bytes, std::fs::read(dir.join("bare.png")).unwrap(), "the picture depends on the machine's fonts");

    let img = image::load_from_memory(&bytes).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (1280, 720));
    for (k, (x, y)) in [(0, 0), (640, 0), (0, 360), (640, 360)].into_iter().enumerate() {
        assert!(ink(&img, (x + 150, x + 490), (y, y + 28)) > 100, "tile {k} has no title text");
    }
    // People per frame (top left): 3 people in every frame, so one full bar of the scene's
    // colour (Tableau blue), from the axis at 0 up to a fraction of 1.
    let blue = [31, 119, 180];
    let columns: Vec<u32> = (0..640).filter(|&x| (0..360).filter(|&y| img.get_pixel(x, y).0 == blue).count() > 150).collect();
    assert!(columns.len() > 20, "no bar for 3 people: {columns:?}");
    assert!(columns.windows(2).all(|w| w[1] == w[0] + 1), "one bar: {columns:?}");
}

#[test]
fn the_binary_links_no_font_library() {
    let bin = std::fs::read(Path::new(env!("CARGO_BIN_EXE_pedscan"))).unwrap();
    for needle in [&b"libfontconfig"[..], b"libfreetype", b"font-kit"] {
        assert!(!bin.windows(needle.len()).any(|w| w == needle), "the binary names {}", String::from_utf8_lossy(needle));
    }
}
