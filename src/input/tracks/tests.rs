use super::*;
use std::path::PathBuf;

fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> PathBuf {
    let p = dir.path().join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn read(p: &Path, f: TrackFormat) -> Result<Vec<Track>> {
    read_tracks(p, f, &TrackOptions::default())
}

/// The error is an input error naming `FILE:LINE`.
fn expect_err(p: &Path, f: TrackFormat, line: usize, needle: &str) {
    let e = read(p, f).expect_err("must fail");
    assert!(e.is_input(), "{e}");
    let msg = e.to_string();
    assert!(
        msg.starts_with(&format!("{}:{line}:", p.display())),
        "{msg}"
    );
    assert!(msg.contains(needle), "{msg} lacks {needle}");
}

const ETH: &str = "\
   7.8000000e+02   1.0000000e+00   8.4568443e+00   0.0000000e+00   3.5880664e+00   1.6717144e+00   0.0000000e+00   1.7629183e-01
   7.8000000e+02   2.0000000e+00   1.0000000e+00   0.0000000e+00   2.0000000e+00   0.0   0.0   0.0
   7.9000000e+02   1.0000000e+00   9.1255301e+00   0.0000000e+00   3.6585832e+00   1.6628772e+00   0.0000000e+00   3.2672255e-01
   8.0000000e+02   1.0000000e+00   9.7871460e+00   0.0000000e+00   3.8494445e+00   1.6833339e+00   0.0000000e+00   3.7108399e-01
   7.7000000e+02   1.0000000e+00   7.8000000e+00   0.0000000e+00   3.5000000e+00   1.6   0.0   0.2
";

#[test]
fn eth_reader_groups_sorts_and_scales_frames() {
    let d = tempfile::tempdir().unwrap();
    let p = write(&d, "obsmat.txt", ETH);
    let tr = read(&p, TrackFormat::Eth).unwrap();
    assert_eq!(tr.len(), 2);
    assert_eq!(tr[0].id, 1);
    assert_eq!(
        tr[0].times_s,
        vec![770.0 * 0.04, 780.0 * 0.04, 790.0 * 0.04, 800.0 * 0.04]
    );
    assert_eq!(tr[0].xy_m[0], DVec2::new(7.8, 3.5));
    assert_eq!(
        tr[0].xy_m[1],
        DVec2::new(8.4568443, 3.5880664),
        "x and y, not z"
    );
    assert!(tr[0].heading_rad.is_none());
    assert_eq!(tr[1].id, 2);
    assert_eq!(tr[1].times_s.len(), 1);
    assert!((tr[0].duration_s() - 1.2).abs() < 1e-12);
    // seq_eth: 6 frame numbers per 0.4 s.
    let o = TrackOptions {
        frame_period_s: 0.4 / 6.0,
        ..Default::default()
    };
    let tr = read_tracks(&p, TrackFormat::Eth, &o).unwrap();
    assert!((tr[0].times_s[1] - 52.0).abs() < 1e-9);
}

#[test]
fn eth4_reader_tabs_and_spaces() {
    let d = tempfile::tempdir().unwrap();
    let p = write(
        &d,
        "biwi.txt",
        "0\t1.0\t1.41\t-5.68\n0\t2.0\t0.51\t-6.94\n\n10 1.0  1.5 -5.0\n20.0\t1.0\t1.6\t-4.5\n",
    );
    let tr = read(&p, TrackFormat::Eth4).unwrap();
    assert_eq!(tr.len(), 2);
    assert_eq!(tr[0].times_s, vec![0.0, 0.4, 0.8]);
    assert_eq!(
        tr[0].xy_m,
        vec![
            DVec2::new(1.41, -5.68),
            DVec2::new(1.5, -5.0),
            DVec2::new(1.6, -4.5)
        ]
    );
    assert_eq!(tr[1].xy_m, vec![DVec2::new(0.51, -6.94)]);
}

#[test]
fn atc_reader_mm_to_m_and_facing() {
    let d = tempfile::tempdir().unwrap();
    let text = "1351065600.025,9315700,-10000,2000,1650,1200,0.5,1.0\n\
                1351065600.055,9315700,-9964,2019,1650,1200,0.5,1.1\n\
                1351065600.085,9315700,-9928,2038,1650,1200,0.5,1.2\n\
                1351065600.025,9315800,100,200,1600,0,0,\n\
                1351065600.055,9315800,100,200,1600,0,0,\n";
    let p = write(&d, "atc-20121024.csv", text);
    let tr = read(&p, TrackFormat::Atc).unwrap();
    assert_eq!(tr.len(), 2);
    assert_eq!(tr[0].id, 9315700);
    assert_eq!(tr[0].xy_m[0], DVec2::new(-10.0, 2.0));
    assert!((tr[0].xy_m[1] - DVec2::new(-9.964, 2.019)).length() < 1e-12);
    assert_eq!(tr[0].heading_rad.as_deref(), Some(&[1.0, 1.1, 1.2][..]));
    assert!((tr[0].times_s[1] - tr[0].times_s[0] - 0.03).abs() < 1e-6);
    assert!(tr[1].heading_rad.is_none(), "empty facing angle");
    let mid = 0.5 * (tr[0].times_s[0] + tr[0].times_s[1]);
    let h = tr[0].sample(mid).unwrap().heading_rad;
    assert!((h - 1.05).abs() < 1e-3, "facing angle interpolated: {h}");
}

#[test]
fn csv_reader_with_and_without_heading() {
    let d = tempfile::tempdir().unwrap();
    let p = write(
        &d,
        "a.csv",
        "# pedscan tracks\nt_s,id,x_m,y_m\n0.0,7,1,2\n0.5, 7, 2, 2\n",
    );
    let tr = read(&p, TrackFormat::Csv).unwrap();
    assert_eq!(tr[0].id, 7);
    assert_eq!(tr[0].xy_m, vec![DVec2::new(1.0, 2.0), DVec2::new(2.0, 2.0)]);
    assert!(tr[0].heading_rad.is_none());
    let p = write(
        &d,
        "b.csv",
        "t_s,id,x_m,y_m,heading_rad\n0.0,1,0,0,3.0\n1.0,1,1,0,-3.0\n",
    );
    let tr = read(&p, TrackFormat::Csv).unwrap();
    assert_eq!(tr[0].heading_rad.as_deref(), Some(&[3.0, -3.0][..]));
    // Interpolated across ±π along the short arc.
    let h = tr[0].sample(0.5).unwrap().heading_rad;
    assert!((wrap_angle(h - PI)).abs() < 1e-9, "{h}");
}

#[test]
fn bad_input_names_file_and_line() {
    let d = tempfile::tempdir().unwrap();
    let eth_ok = "1 1 0 0 0 0 0 0\n";
    let cases: &[(TrackFormat, &str, usize, &str)] = &[
        (
            TrackFormat::Eth,
            "1 1 0 0 0 0 0 0\n2 1 0 0 0 0 0\n",
            2,
            "expected 8 columns",
        ),
        (
            TrackFormat::Eth,
            "1 1 0 0 0 0 0 0\n\n2 1 0 0 x 0 0 0\n",
            3,
            "column 5: `x` is not a number",
        ),
        (TrackFormat::Eth, "1 1 nan 0 0 0 0 0\n", 1, "not finite"),
        (TrackFormat::Eth, "1 1.5 0 0 0 0 0 0\n", 1, "not an integer"),
        (TrackFormat::Eth4, "0 1 0 0\n10 1 inf 0\n", 2, "not finite"),
        (TrackFormat::Eth4, "0 1 0 0 5\n", 1, "expected 4 columns"),
        (
            TrackFormat::Eth4,
            "0 1 0 0\n10 1 1 0\n0 1 2 0\n",
            3,
            "duplicate timestamp",
        ),
        (
            TrackFormat::Atc,
            "1.0,5,0,0,0,0,0,0\n1.0,5,0,0,0,0,0\n",
            2,
            "expected 8 comma-separated",
        ),
        (
            TrackFormat::Atc,
            "1.0,5,0,0,0,0,0,0\n2.0,5,0,0,0,0,0,NaN\n",
            2,
            "not finite",
        ),
        (
            TrackFormat::Atc,
            "1.0,5,0,0,0,0,0,0\n2.0,5,1e3,0,0,0,0,0\n1.0,5,0,0,0,0,0,0\n",
            3,
            "duplicate",
        ),
        (TrackFormat::Csv, "t,id,x,y\n", 1, "expected the header"),
        (
            TrackFormat::Csv,
            "t_s,id,x_m,y_m\n0,1,0,0\n1,1,0\n",
            3,
            "expected 4 columns",
        ),
        (
            TrackFormat::Csv,
            "t_s,id,x_m,y_m,heading_rad\n0,1,0,0,1\n1,1,0,0,abc\n",
            3,
            "column 5",
        ),
        (TrackFormat::Csv, "t_s,id,x_m,y_m\n0,a,0,0\n", 2, "column 2"),
    ];
    for (k, (f, text, line, needle)) in cases.iter().enumerate() {
        let p = write(&d, &format!("bad{k}.txt"), text);
        expect_err(&p, *f, *line, needle);
    }
    let p = write(&d, "ok.txt", eth_ok);
    assert!(read(&p, TrackFormat::Eth).is_ok());
    // Empty and record-less files.
    for (k, text) in ["", "\n# only a comment\n"].iter().enumerate() {
        let p = write(&d, &format!("empty{k}.txt"), text);
        let e = read(&p, TrackFormat::Eth4).unwrap_err();
        assert!(
            e.is_input() && e.to_string().contains(&p.display().to_string()),
            "{e}"
        );
        assert!(e.to_string().contains("no track record"), "{e}");
    }
    let p = write(&d, "header_only.csv", "t_s,id,x_m,y_m\n");
    assert!(read(&p, TrackFormat::Csv)
        .unwrap_err()
        .to_string()
        .contains("no track record"));
    // Missing file, bad options.
    assert!(read(&d.path().join("missing.txt"), TrackFormat::Eth)
        .unwrap_err()
        .is_input());
    let p = write(&d, "ok2.txt", eth_ok);
    let o = TrackOptions {
        frame_period_s: 0.0,
        ..Default::default()
    };
    assert!(read_tracks(&p, TrackFormat::Eth, &o)
        .unwrap_err()
        .is_input());
}

#[test]
fn duplicate_timestamp_names_both_lines() {
    let d = tempfile::tempdir().unwrap();
    let p = write(
        &d,
        "dup.csv",
        "t_s,id,x_m,y_m\n0,1,0,0\n0.4,1,1,0\n0.4,2,5,5\n0.4,1,1.1,0\n",
    );
    let e = read(&p, TrackFormat::Csv).unwrap_err().to_string();
    assert!(e.starts_with(&format!("{}:5:", p.display())), "{e}");
    assert!(e.contains("id 1") && e.contains("line 3"), "{e}");
}

/// A wiggly track with non-uniform times.
fn wiggly() -> Track {
    let times_s: Vec<f64> = (0..12)
        .map(|i| i as f64 * 0.4 + if i % 3 == 1 { 0.07 } else { 0.0 })
        .collect();
    let xy_m = times_s
        .iter()
        .map(|&t| DVec2::new(1.3 * t + 0.2 * (2.0 * t).sin(), 0.5 * (0.7 * t).cos()))
        .collect();
    Track {
        id: 3,
        times_s,
        xy_m,
        heading_rad: None,
    }
}

#[test]
fn reproduces_samples_and_velocity_is_the_derivative() {
    let d = tempfile::tempdir().unwrap();
    let tr = wiggly();
    let mut text = String::from("t_s,id,x_m,y_m\n");
    for (t, p) in tr.times_s.iter().zip(&tr.xy_m) {
        text += &format!("{t:?},3,{:?},{:?}\n", p.x, p.y);
    }
    let p = write(&d, "w.csv", &text);
    let tr = read(&p, TrackFormat::Csv).unwrap().remove(0);
    assert_eq!(tr.times_s, wiggly().times_s);
    for (t, p) in tr.times_s.iter().zip(&tr.xy_m) {
        let s = tr.sample(*t).unwrap();
        assert!((s.position_m - *p).length() <= 1e-9);
    }
    assert!(tr.sample(tr.times_s[0] - 1e-6).is_none());
    assert!(tr.sample(tr.times_s[11] + 1e-6).is_none());
    assert!(tr.sample(f64::NAN).is_none());
    // Velocity vs central differences of position (cubic: error O(eps^2) within a segment).
    let eps = 1e-5;
    let (t0, t1) = (tr.times_s[0], tr.times_s[11]);
    let mut worst = 0.0f64;
    for k in 1..400 {
        let t = t0 + (t1 - t0) * k as f64 / 400.0;
        // Acceleration jumps at the samples (C1, not C2): difference within one segment.
        if tr.times_s.iter().any(|&ts| (ts - t).abs() < 3.0 * eps) {
            continue;
        }
        let v = tr.sample(t).unwrap().velocity_mps;
        let fd = (tr.sample(t + eps).unwrap().position_m
            - tr.sample(t - eps).unwrap().position_m)
            / (2.0 * eps);
        worst = worst.max((v - fd).length());
    }
    assert!(worst < 1e-6, "velocity vs finite difference: {worst} m/s");
    // C1 at the samples: velocity from both sides agrees.
    for &t in &tr.times_s[1..11] {
        let a = tr.sample(t - 1e-9).unwrap().velocity_mps;
        let b = tr.sample(t + 1e-9).unwrap().velocity_mps;
        assert!((a - b).length() < 1e-6);
    }
}

#[test]
fn straight_constant_speed_gives_constant_velocity_exactly() {
    // Exactly representable samples: 0.5 s apart, 0.75 m along x and -0.25 m along y per step.
    let times_s: Vec<f64> = (0..8).map(|i| i as f64 * 0.5).collect();
    let xy_m: Vec<DVec2> = (0..8)
        .map(|i| DVec2::new(2.0 + 0.75 * i as f64, 1.0 - 0.25 * i as f64))
        .collect();
    let tr = Track {
        id: 0,
        times_s,
        xy_m,
        heading_rad: None,
    };
    let v = DVec2::new(1.5, -0.5);
    for k in 0..=350 {
        let t = k as f64 * 0.01;
        let s = tr.sample(t).unwrap();
        assert_eq!(s.velocity_mps, v, "t = {t}");
        assert!((s.position_m - (DVec2::new(2.0, 1.0) + v * t)).length() < 1e-12);
        assert_eq!(s.heading_rad, v.y.atan2(v.x));
    }
}

#[test]
fn heading_from_motion_is_held_while_standing() {
    // Walk +x, stand still (three equal positions), then walk +y.
    let times_s = vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
    let xy_m = [
        (0.0, 0.0),
        (1.0, 0.0),
        (2.0, 0.0),
        (2.0, 0.0),
        (2.0, 0.0),
        (2.0, 1.0),
        (2.0, 2.0),
    ]
    .iter()
    .map(|&(x, y)| DVec2::new(x, y))
    .collect();
    let tr = Track {
        id: 1,
        times_s,
        xy_m,
        heading_rad: None,
    };
    assert!((tr.sample(0.5).unwrap().heading_rad).abs() < 1e-9);
    let standing = tr.sample(3.0).unwrap();
    assert!(standing.velocity_mps.length() < 1e-12);
    // Standing: the last moving direction, +x (the limited tangents do not overshoot).
    let h = standing.heading_rad;
    assert!(h.abs() < 1e-9, "held heading {h}");
    assert_eq!(
        tr.sample(2.5).unwrap().position_m,
        DVec2::new(2.0, 0.0),
        "stays put"
    );
    for k in 0..=20 {
        let t = 2.5 + k as f64 * 0.05;
        let s = tr.sample(t).unwrap();
        if s.velocity_mps.length() < HEADING_HOLD_SPEED_MPS {
            assert!(s.heading_rad.abs() < 1e-9, "t = {t}: {}", s.heading_rad);
        }
    }
    assert!((tr.sample(5.5).unwrap().heading_rad - PI / 2.0).abs() < 1e-9);
    // Never moving: 0; standing first, then walking -y: the first direction of motion.
    let still = Track {
        id: 2,
        times_s: vec![0.0, 1.0],
        xy_m: vec![DVec2::ONE; 2],
        heading_rad: None,
    };
    assert_eq!(still.sample(0.5).unwrap().heading_rad, 0.0);
    let late = Track {
        id: 3,
        times_s: vec![0.0, 1.0, 2.0, 3.0],
        xy_m: vec![
            DVec2::ZERO,
            DVec2::ZERO,
            DVec2::new(0.0, -1.0),
            DVec2::new(0.0, -2.0),
        ],
        heading_rad: None,
    };
    assert!((late.sample(0.0).unwrap().heading_rad + PI / 2.0).abs() < 1e-6);
}

#[test]
fn heading_from_facing_angle_ignores_motion() {
    let tr = Track {
        id: 1,
        times_s: vec![0.0, 1.0, 2.0],
        xy_m: vec![DVec2::ZERO, DVec2::X, DVec2::new(2.0, 0.0)],
        heading_rad: Some(vec![1.0, 1.2, 1.6]),
    };
    assert_eq!(tr.sample(1.0).unwrap().heading_rad, 1.2);
    assert!((tr.sample(1.5).unwrap().heading_rad - 1.4).abs() < 1e-12);
}

#[test]
fn transform_is_applied_to_points_and_headings() {
    let d = tempfile::tempdir().unwrap();
    let p = write(
        &d,
        "t.csv",
        "t_s,id,x_m,y_m,heading_rad\n0,1,1,0,0\n1,1,1,1,0.5\n",
    );
    let o = TrackOptions {
        transform: Transform2 {
            rotation_deg: 90.0,
            translation_m: [10.0, -5.0],
            scale: 2.0,
        },
        ..Default::default()
    };
    let tr = read_tracks(&p, TrackFormat::Csv, &o).unwrap().remove(0);
    assert!(
        (tr.xy_m[0] - DVec2::new(10.0, -3.0)).length() < 1e-12,
        "{:?}",
        tr.xy_m
    );
    assert!(
        (tr.xy_m[1] - DVec2::new(8.0, -3.0)).length() < 1e-12,
        "{:?}",
        tr.xy_m
    );
    let h = tr.heading_rad.unwrap();
    assert!((h[0] - PI / 2.0).abs() < 1e-12 && (h[1] - (PI / 2.0 + 0.5)).abs() < 1e-12);
    let bad = TrackOptions {
        transform: Transform2 {
            scale: -1.0,
            ..Default::default()
        },
        ..Default::default()
    };
    assert!(read_tracks(&p, TrackFormat::Csv, &bad)
        .unwrap_err()
        .is_input());
}

#[test]
fn transforms_positions_and_times_out_of_range_are_refused() {
    let tf = |rotation_deg: f64, t: f64, scale: f64| Transform2 { rotation_deg, translation_m: [t, 0.0], scale };
    assert!(tf(90.0, -1e5, 1e-6).check().is_ok() && tf(-360.0, 0.0, 1e6).check().is_ok());
    for (bad, needle) in [
        (tf(0.0, 0.0, 1e308), "scale 1e308"),
        (tf(0.0, 0.0, 0.0), "scale 0.0"),
        (tf(0.0, 2e5, 1.0), "translation (200000.0, 0.0)"),
        (tf(f64::NAN, 0.0, 1.0), "rotation NaN"),
        (tf(400.0, 0.0, 1.0), "rotation 400.0"),
    ] {
        let m = bad.check().unwrap_err();
        assert!(m.contains(needle), "{m}");
    }
    // Positions that the transform sends beyond the bound, named by their line before
    // anything is sorted.
    let d = tempfile::tempdir().unwrap();
    let p = write(&d, "far.csv", "t_s,id,x_m,y_m\n1,1,0,0\n0,1,150,0\n");
    let o = TrackOptions { transform: tf(0.0, 0.0, 1000.0), ..Default::default() };
    let e = read_tracks(&p, TrackFormat::Csv, &o).unwrap_err();
    assert!(e.is_input() && e.to_string().starts_with(&format!("{}:3:", p.display())), "{e}");
    assert!(e.to_string().contains("150000.0"), "{e}");
    let p = write(&d, "raw.csv", "t_s,id,x_m,y_m\n0,1,0,1e300\n");
    expect_err(&p, TrackFormat::Csv, 2, "1e300");
    // Times: an ETH frame number that the frame period puts at 4e10 s, an ATC time of 1e11 s.
    let p = write(&d, "eth4.txt", "0 1 0 0\n1e12 1 1 0\n");
    expect_err(&p, TrackFormat::Eth4, 2, "time 40000000000.0 s is beyond the supported 1e10 s");
    let p = write(&d, "atc.csv", "1e11,1,0,0,0,0,0,\n");
    expect_err(&p, TrackFormat::Atc, 1, "1e10 s");
}

#[test]
fn a_byte_order_mark_is_skipped() {
    let d = tempfile::tempdir().unwrap();
    let p = write(&d, "bom.csv", "\u{feff}t_s,id,x_m,y_m\n0,1,0,0\n0.4,1,0.5,0\n");
    assert_eq!(read(&p, TrackFormat::Csv).unwrap()[0].xy_m, vec![DVec2::ZERO, DVec2::new(0.5, 0.0)]);
    let p = write(&d, "bom.txt", "\u{feff}10 1 0.5 2.0\n");
    assert_eq!(read(&p, TrackFormat::Eth4).unwrap()[0].times_s, vec![0.4]);
}

#[test]
fn windows_and_drop_short() {
    let a = Track {
        id: 1,
        times_s: vec![0.0, 2.0],
        xy_m: vec![DVec2::ZERO; 2],
        heading_rad: None,
    };
    let b = Track {
        id: 2,
        times_s: vec![5.0],
        xy_m: vec![DVec2::ZERO],
        heading_rad: None,
    };
    assert!(a.windows(2.0) && !a.windows(2.1));
    assert!(b.windows(0.0) && !b.windows(0.1));
    assert_eq!(b.sample(5.0).unwrap().velocity_mps, DVec2::ZERO);
    assert!(b.sample(5.1).is_none());
    let kept = drop_short(vec![a, b], 1.0);
    assert_eq!(kept.len(), 1);
    assert_eq!(kept[0].id, 1);
}

#[test]
fn format_names_are_kebab_case() {
    use clap::ValueEnum;
    assert_eq!(
        serde_json::to_string(&TrackFormat::Eth4).unwrap(),
        "\"eth4\""
    );
    assert_eq!(
        TrackFormat::from_str("atc", false).unwrap(),
        TrackFormat::Atc
    );
}
