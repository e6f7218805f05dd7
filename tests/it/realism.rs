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
    // Noise 2 cm and no per-laser bias; detection falling to none over 75-89 deg.
    std::fs::write(
        dir.join("model.toml"),
        "[sensor_model]\nrange_noise_m = 0.02\nlaser_bias_m = 0.0\ndropout_rate = 0.002\ngrazing_deg = [75.0, 89.0]\ngrazing_loss = 1.0\n",
    )
    .unwrap();
    ok(&pedscan(&[&common[..], &["--config", "model.toml", "--out", "model"]].concat(), dir));
    let r = report(dir, "clean", "model");
    // The clean hall is closed: every beam returns, and its ranges lie on planes (f32).
    assert_eq!(r["rec"]["holes"], 0);
    let noise = r["range_noise_by_range"]["points"].as_array().unwrap();
    let (mut clean_max, mut bins) = (0.0f64, 0);
    for p in noise {
        if p["rec_n"].as_u64().unwrap() >= 2000 && p["sim_n"].as_u64().unwrap() >= 2000 {
            bins += 1;
            clean_max = clean_max.max(rate(p, "rec"));
            // The range noise is 2 cm (sd); the hall's walls and floor are planes.
            let got = rate(p, "sim");
            assert!((got / 0.02 - 1.0).abs() < 0.1, "noise {got} in bin {}", p["lo"]);
        }
    }
    assert!(bins >= 2, "{noise:?}");
    assert!(clean_max < 0.002, "clean frames measure {clean_max} m of noise");
    // Holes at grazing incidence: none below 70 deg but the random dropout (0.2 %), many at
    // 80-85 deg (the linear fall over 75-89 deg).
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

/// A folder with one ascii PCD frame of x y z only (no intensity): an HDL-32E's beams on a
/// wall 6 m ahead.
fn wall_pcd(dir: &std::path::Path) {
    let s = pedscan::sensor::Sensor::hdl32e();
    let pts: Vec<String> = s
        .beam_dirs()
        .iter()
        .filter(|d| d.x > 0.05)
        .map(|d| {
            let p = *d * (6.0 / d.x);
            format!("{} {} {}", p.x as f32, p.y as f32, p.z as f32)
        })
        .collect();
    let header = format!(
        "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA ascii\n",
        n = pts.len()
    );
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("000000.pcd"), header + &pts.join("\n") + "\n").unwrap();
}

#[test]
fn a_fit_gives_back_the_terms_an_output_was_made_with() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // Divergence and laser bias off: holes only from dropout, grazing and detection, noise
    // only from the range noise.
    std::fs::write(
        dir.join("known.toml"),
        "[sensor_model]\ndropout_rate = 0.03\ngrazing_deg = [70.0, 90.0]\ngrazing_loss = 0.4\ndetection_range_m = 30.0\n\
         detection_softness = 0.5\nrange_noise_m = 0.01\nlaser_bias_m = 0.0\ndivergence_mrad = [0.0, 0.0]\n",
    )
    .unwrap();
    ok(&pedscan(&["generate", "--backend", "raycast", "--config", "known.toml", "--humans", "0..0", "--frames", "10", "--sequences", "2", "--out", "o"], dir));
    ok(&pedscan(&["sensor-fit", "o", "--out", "fit.toml"], dir));
    let text = std::fs::read_to_string(dir.join("fit.toml")).unwrap();
    let cfg: toml::Value = toml::from_str(&text).unwrap();
    let m = &cfg["sensor_model"];
    let f = |k: &str| m[k].as_float().unwrap();
    // Measured on this estimator (docs/sensor-model.md): dropout, the start of the grazing
    // fall, the softness and the noise come back; the loss at 90 deg and the detection range
    // trade against each other in a hall 36 m across and come back 25 % low.
    assert!((f("dropout_rate") - 0.03).abs() < 0.004, "{text}");
    assert!((m["grazing_deg"][0].as_float().unwrap() - 70.0).abs() < 4.0, "{text}");
    assert!((f("range_noise_m") / 0.01 - 1.0).abs() < 0.1, "{text}");
    assert!((f("detection_softness") / 0.5 - 1.0).abs() < 0.25, "{text}");
    assert!(f("grazing_loss") > 0.2 && f("grazing_loss") < 0.5, "{text}");
    assert!(text.contains("# not fitted") && text.contains("laser_bias_m:"), "{text}");
    // Nothing is blind behind the sensor in the hall: no platform.
    assert!(text.contains("# platform: none") && !text.contains("[[sensor_model.platform]]"), "{text}");
    // The file is a configuration pedscan takes.
    ok(&pedscan(&["generate", "--backend", "raycast", "--config", "fit.toml", "--frames", "1", "--humans", "0..0", "--out", "again"], dir));
}

#[test]
fn a_fit_refuses_what_the_recording_cannot_tell() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    wall_pcd(&dir.join("wall"));
    // realism compares what it can, and says the intensity is not compared.
    ok(&pedscan(&["generate", "--backend", "raycast", "--frames", "1", "--humans", "0..0", "--out", "hall"], dir));
    let o = pedscan(&["realism", "wall", "hall"], dir);
    ok(&o);
    assert!(String::from_utf8_lossy(&o.stdout).contains("wall: records no intensity"));
    let refused = |args: &[&str], needle: &str| {
        expect_input_error(&[&["sensor-fit"], args, &["--out", "fit.toml"][..]].concat(), dir, needle);
        assert!(!dir.join("fit.toml").exists(), "{args:?} wrote the fit");
    };
    refused(&["wall"], "wall: records no intensity");
    refused(&["nowhere"], "nowhere: no such file or folder");
    refused(&["hall", "--sensor", "vlp16"], "another sensor (hdl32e");
    refused(&["hall", "--max-frames", "0"], "--max-frames");
    refused(&["hall", "--intensity-scale=-1"], "--intensity-scale");
    refused(&["hall", "--intensity-scale=nan"], "--intensity-scale");
    // One VLP-16 frame: enough returns to measure (16,384 beams), too few to fit (20,000).
    ok(&pedscan(&["generate", "--backend", "raycast", "--frames", "1", "--humans", "0..0", "--sensor", "vlp16", "--out", "vlp"], dir));
    refused(&["vlp", "--sensor", "vlp16"], "too few to fit the detection terms (want 20000)");
}
