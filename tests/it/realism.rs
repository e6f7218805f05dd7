//! `pedscan realism`: pedscan's own outputs, whose sensor model is known, measured back by the
//! estimator through the command line; bad input refused with nothing written.

use crate::common::*;
use serde_json::Value;

fn report(dir: &std::path::Path, rec: &str, sim: &str) -> Value {
    ok(&pedscan(&["realism", rec, sim, "--json", "r.json", "--png", "r.png"], dir));
    assert!(image::open(dir.join("r.png")).unwrap().width() >= 1280);
    serde_json::from_str(&std::fs::read_to_string(dir.join("r.json")).unwrap()).unwrap()
}

fn rate(p: &Value, side: &str) -> f64 {
    p[side].as_f64().unwrap()
}

#[test]
fn the_sensor_models_noise_and_grazing_losses_are_measured_back() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let common = ["generate", "--backend", "raycast", "--sequences", "1", "--frames", "6", "--humans", "0..0", "--seed", "3"];
    ok(&pedscan(&[&common[..], &["--sensor-model", "off", "--out", "clean"]].concat(), dir));
    ok(&pedscan(&[&common[..], &["--out", "model"]].concat(), dir));
    let r = report(dir, "clean", "model");
    // The clean hall is closed: every beam returns, and its ranges lie on planes (f32).
    assert_eq!(r["rec"]["holes"], 0);
    let noise = r["range_noise_by_range"]["points"].as_array().unwrap();
    let (mut clean_max, mut bins) = (0.0f64, 0);
    for p in noise {
        if p["rec_n"].as_u64().unwrap() >= 2000 && p["sim_n"].as_u64().unwrap() >= 2000 {
            bins += 1;
            clean_max = clean_max.max(rate(p, "rec"));
            // The default range noise is 2 cm (sd); the hall's walls and floor are planes.
            let got = rate(p, "sim");
            assert!((got / 0.02 - 1.0).abs() < 0.15, "noise {got} in bin {}", p["lo"]);
        }
    }
    assert!(bins >= 2, "{noise:?}");
    assert!(clean_max < 0.002, "clean frames measure {clean_max} m of noise");
    // Holes at grazing incidence: none below 70 deg but the random dropout (0.2 %), many at
    // 80-85 deg (the model's linear fall over 75-89 deg).
    let inc = r["hole_rate_by_incidence"]["points"].as_array().unwrap();
    for p in inc {
        let (lo, n) = (p["lo"].as_f64().unwrap(), p["sim_n"].as_u64().unwrap());
        if n < 2000 {
            continue;
        }
        let sim = rate(p, "sim");
        if lo < 70.0 {
            assert!(sim < 0.01, "{sim} holes at {lo} deg");
        } else if lo == 80.0 {
            assert!(sim > 0.15, "{sim} holes at 80-85 deg");
        }
        assert_eq!(rate(p, "rec"), 0.0);
    }
    let text = String::from_utf8_lossy(&pedscan(&["realism", "clean", "model"], dir).stdout).to_string();
    assert!(text.contains("hole rate by incidence") && text.contains("largest gap:"), "{text}");
}

#[test]
fn people_are_left_out_of_an_outputs_statistics() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    ok(&pedscan(&["generate", "--backend", "raycast", "--sequences", "1", "--frames", "2", "--humans", "8..8", "--out", "o"], dir));
    ok(&pedscan(&["stats", "o", "--png", "s.png", "--json", "s.json"], dir));
    let s: Value = serde_json::from_str(&std::fs::read_to_string(dir.join("s.json")).unwrap()).unwrap();
    let humans = s["human_beams"].as_u64().unwrap();
    assert!(humans > 100);
    let r = report(dir, "o", "o");
    assert_eq!(r["sim"]["beams"].as_u64().unwrap(), s["beams"].as_u64().unwrap() - humans);
    assert_eq!(r["rec"]["beams"], r["sim"]["beams"]);
    // The same source on both sides: no gap anywhere.
    for c in ["hole_rate_by_incidence", "hole_rate_by_range", "range_noise_by_range", "hole_rate_by_row"] {
        for p in r[c]["points"].as_array().unwrap() {
            assert!(p["gap"].is_null() || p["gap"].as_f64().unwrap() == 0.0, "{c}: {p}");
        }
    }
}

#[test]
fn bad_inputs_are_refused_and_nothing_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let gen = |sensor: &str, out: &str| ok(&pedscan(&["generate", "--backend", "raycast", "--sequences", "1", "--frames", "1", "--humans", "0..0", "--sensor", sensor, "--out", out], dir));
    gen("hdl32e", "hdl");
    gen("vlp16", "vlp");
    std::fs::write(dir.join("tiny.toml"), "name = \"tiny\"\nelevation_deg = [-10.0, -12.0]\ncolumns = 64\n").unwrap();
    gen("tiny.toml", "tiny");
    let files = ["--json", "r.json", "--png", "r.png"];
    let refused = |args: &[&str], needle: &str| {
        expect_input_error(&[&["realism"], args, &files[..]].concat(), dir, needle);
        assert!(!dir.join("r.json").exists() && !dir.join("r.png").exists(), "{args:?} wrote a file");
    };
    refused(&["vlp", "hdl"], "another sensor (vlp16: 16 rows x 1024 columns");
    refused(&["nowhere", "hdl"], "nowhere: no such file or folder");
    refused(&["hdl", "nowhere"], "nowhere");
    refused(&["tiny", "tiny"], "too few to measure");
    std::fs::write(dir.join("junk.h5"), b"not hdf5").unwrap();
    refused(&["junk.h5", "hdl"], "junk.h5: not a readable HDF5 file");
    refused(&["hdl", "hdl", "--max-frames", "0"], "--max-frames");
}
