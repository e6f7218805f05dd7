//! `pedscan crosscheck` and `--export-geometry`, run as a user would (lavapipe, validation on).

use crate::common::{ok, pedscan};
use std::path::Path;

#[test]
fn crosscheck_writes_the_report_strip_and_geometry_and_exact_mode_agrees() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let o = pedscan(
        &["crosscheck", "--sequences", "1", "--frames", "3", "--humans", "4..4", "--seed", "5", "--json", "cc.json", "--strip-png", "cc.png", "--export-geometry", "geo"],
        dir,
    );
    ok(&o);
    let j: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("cc.json")).unwrap()).unwrap();
    assert_eq!(j["frames"], 3);
    for key in ["human_beam_agreement", "mask_iou", "range_error_m", "refined", "by_distance", "per_frame"] {
        assert!(j.get(key).is_some(), "missing key {key}");
    }
    for key in ["median", "p99", "max", "rms"] {
        assert!(j["range_error_m"][key].is_number() && j["refined"]["range_error_m"][key].is_number(), "{key}");
    }
    for bin in ["0-4", "4-8", "8+"] {
        assert!(j["by_distance"][bin]["human_beam_agreement"].is_number(), "{bin}");
    }
    assert_eq!(j["per_frame"].as_array().unwrap().len(), 3);
    // Exact refinement against the reference on the same triangles: beams at a silhouette or
    // depth step are cast exactly, so every human beam agrees (no tolerance; docs/accuracy.md),
    // and ranges agree within the f32 storage of a hit (p99 <= 1 mm).
    let agreement = j["refined"]["human_beam_agreement"].as_f64().unwrap();
    let p99 = j["refined"]["range_error_m"]["p99"].as_f64().unwrap();
    assert_eq!(agreement, 1.0, "exact agreement {agreement}");
    assert!(p99 <= 1e-3, "exact p99 {p99} m");
    assert!(j["refined"]["overall"]["both_human"].as_u64().unwrap() > 100, "people were seen");
    let png = image::open(dir.join("cc.png")).unwrap();
    assert_eq!(png.width(), 1024);
    for k in 0..3 {
        assert!(dir.join(format!("geo/seq_000000/frame_{k:06}.ply")).exists());
    }
}

#[test]
fn crosscheck_with_the_cylindrical_panorama_meets_the_same_acceptance() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let o = pedscan(&["crosscheck", "--projection", "cylinder", "--sequences", "1", "--frames", "3", "--humans", "4..4", "--seed", "5", "--json", "cc.json"], dir);
    ok(&o);
    let j: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("cc.json")).unwrap()).unwrap();
    assert_eq!(j["projection"], "cylinder");
    let agreement = j["refined"]["human_beam_agreement"].as_f64().unwrap();
    let p99 = j["refined"]["range_error_m"]["p99"].as_f64().unwrap();
    eprintln!("cylinder: exact agreement {agreement}, p99 {p99} m; unrefined {}", j["human_beam_agreement"]);
    assert_eq!(agreement, 1.0, "exact agreement {agreement}");
    assert!(p99 <= 1e-3, "exact p99 {p99} m");
    assert!(j["refined"]["overall"]["both_human"].as_u64().unwrap() > 100, "people were seen");
    assert_eq!(j["background_beam_agreement"].as_f64().unwrap(), 1.0, "background agreement");
}

struct Ply {
    verts: Vec<[f64; 3]>,
    faces: Vec<([usize; 3], i32)>,
}

fn read_ply(path: &Path) -> Ply {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let header = String::from_utf8_lossy(&bytes[..end]).to_string();
    let count = |what: &str| -> usize {
        header.lines().find(|l| l.starts_with(&format!("element {what} "))).unwrap().split_whitespace().nth(2).unwrap().parse().unwrap()
    };
    let (nv, nf) = (count("vertex"), count("face"));
    let mut p = end;
    let f32_at = |p: usize| f32::from_le_bytes(bytes[p..p + 4].try_into().unwrap()) as f64;
    let i32_at = |p: usize| i32::from_le_bytes(bytes[p..p + 4].try_into().unwrap());
    let mut verts = Vec::with_capacity(nv);
    for _ in 0..nv {
        verts.push([f32_at(p), f32_at(p + 4), f32_at(p + 8)]);
        p += 12;
    }
    let mut faces = Vec::with_capacity(nf);
    for _ in 0..nf {
        assert_eq!(bytes[p], 3);
        let f = [i32_at(p + 1) as usize, i32_at(p + 5) as usize, i32_at(p + 9) as usize];
        faces.push((f, i32_at(p + 13)));
        p += 17;
    }
    assert_eq!(p, bytes.len(), "PLY body length matches its header");
    Ply { verts, faces }
}

/// An independent ray/triangle test (Moller-Trumbore, f64, both sides), not pedscan's.
fn hit(d: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> Option<f64> {
    let sub = |x: [f64; 3], y: [f64; 3]| [x[0] - y[0], x[1] - y[1], x[2] - y[2]];
    let cross = |x: [f64; 3], y: [f64; 3]| [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]];
    let dot = |x: [f64; 3], y: [f64; 3]| x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
    let (e1, e2) = (sub(b, a), sub(c, a));
    let p = cross(d, e2);
    let det = dot(e1, p);
    if det.abs() < 1e-15 {
        return None;
    }
    let s = [-a[0], -a[1], -a[2]];
    let u = dot(s, p) / det;
    let q = cross(s, e1);
    let v = dot(d, q) / det;
    let t = dot(e2, q) / det;
    (u >= -1e-9 && v >= -1e-9 && u + v <= 1.0 + 1e-9 && t > 0.0).then_some(t)
}

/// The exported triangles and the HDF5 beam table reproduce /range and /instance on the human
/// beams with an outside ray-caster: within 1 mm (f32 storage), same instance.
#[test]
fn exported_geometry_and_beam_table_reproduce_the_human_ranges() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // The exported meshes are what was cast; the sensor model would move the returns off them.
    ok(&pedscan(&["generate", "--out", "o", "--frames", "1", "--humans", "10..10", "--seed", "9", "--export-geometry", "geo", "--sensor-model", "off"], dir));
    let ply = read_ply(&dir.join("geo/seq_000000/frame_000000.ply"));
    let f = hdf5::File::open(dir.join("o/seq_000000.h5")).unwrap();
    let range: Vec<f32> = f.dataset("range").unwrap().read_raw().unwrap();
    let inst: Vec<u16> = f.dataset("instance").unwrap().read_raw().unwrap();
    let el: Vec<f32> = f.dataset("sensor/elevation_deg").unwrap().read_raw().unwrap();
    let az: Vec<f32> = f.dataset("sensor/azimuth_deg").unwrap().read_raw().unwrap();
    let w = az.len();
    let (mut checked, mut matching) = (0usize, 0usize);
    for (b, &k) in inst.iter().enumerate() {
        if k == 0 {
            continue;
        }
        let (e, a) = ((el[b / w] as f64).to_radians(), (az[b % w] as f64).to_radians());
        let d = [e.cos() * a.cos(), e.cos() * a.sin(), e.sin()];
        let mut best: Option<(f64, i32)> = None;
        for (t, id) in &ply.faces {
            if let Some(r) = hit(d, ply.verts[t[0]], ply.verts[t[1]], ply.verts[t[2]]) {
                if best.map_or(true, |(br, _)| r < br) {
                    best = Some((r, *id));
                }
            }
        }
        checked += 1;
        // f32 azimuth/elevation in the file: 1e-7 rad at <= 20 m is < 0.1 mm of lateral offset.
        if let Some((r, id)) = best {
            if (r - range[b] as f64).abs() < 1e-3 && id == k as i32 {
                matching += 1;
            } else {
                eprintln!("beam {b}: outside ray-cast {r} m instance {id}, file {} m instance {k}", range[b]);
            }
        } else {
            eprintln!("beam {b}: outside ray-cast misses, file {} m instance {k}", range[b]);
        }
    }
    // Every human beam: the file's ranges are exact casts of these very triangles.
    assert_eq!(matching, checked, "{matching} of {checked} human beams reproduced");
    assert!(checked > 200, "checked {checked} human beams");
}

/// The raster engine's accuracy acceptance on a small crowded sample: against the full
/// reference on the same posed triangles, every projection agrees on every human and every
/// background beam, mixes up no instance, and leaves no beam more than 1 mm off. Beams at a
/// silhouette or depth step are cast exactly; before that rule the cube disagreed on ~0.3 % of
/// human beams, with metre-scale outliers and instance mix-ups.
#[test]
fn crowded_crosscheck_is_exact_on_every_projection() {
    for (projection, oversample) in [("cube", "2"), ("cylinder", "1"), ("beams", "1")] {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let o = pedscan(
            &["crosscheck", "--projection", projection, "--oversample", oversample, "--sequences", "1", "--frames", "3", "--humans", "30", "--seed", "3", "--json", "cc.json"],
            dir,
        );
        ok(&o);
        let j: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("cc.json")).unwrap()).unwrap();
        let refined = &j["refined"]["overall"];
        let agreement = refined["human_beam_agreement"].as_f64().unwrap();
        let over_1mm = refined["range_error_m"]["over_1mm"].as_f64().unwrap();
        eprintln!("{projection}: exact agreement {agreement}, over 1 mm {over_1mm}, {refined}");
        assert!(refined["both_human"].as_u64().unwrap() > 2000, "{projection}: people were seen");
        assert_eq!(agreement, 1.0, "{projection}: exact agreement {agreement}");
        assert_eq!(refined["instance_mixups"].as_u64().unwrap(), 0, "{projection}: instance mix-ups");
        assert_eq!(over_1mm, 0.0, "{projection}: {over_1mm} of beams more than 1 mm off");
        assert_eq!(j["background_beam_agreement"].as_f64().unwrap(), 1.0, "{projection}: background agreement");
    }
}

/// The GPU's people path, forced on lavapipe (`debug.people = "proxies"`): conservative proxies
/// drawn into the beam panorama and every covered beam cast exactly. Crowded (30 people, so
/// proxies overlap and occlude each other), validation on: every human and background beam
/// agrees with the reference and no instance is mixed up, on every projection, and with everyone
/// carrying something (`humans.carrying`). Without the key the same run takes the CPU path, so
/// `people_path` shows which one was checked.
#[test]
fn the_gpu_people_path_forced_on_a_cpu_device_is_exact() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("proxies.toml"), "[debug]\npeople = \"proxies\"\n").unwrap();
    // Everyone carrying a backpack or bags: the proxies cover what people carry too.
    std::fs::write(dir.join("carrying.toml"), "[humans]\ncarrying = 1.0\n[debug]\npeople = \"proxies\"\n").unwrap();
    for (projection, config) in [("beams", Some("proxies.toml")), ("cube", Some("proxies.toml")), ("beams", None), ("beams", Some("carrying.toml"))] {
        let mut args = vec!["crosscheck", "--projection", projection, "--sequences", "1", "--frames", "2", "--humans", "30", "--seed", "3", "--json", "cc.json"];
        if let Some(c) = config {
            args.extend(["--config", c]);
        }
        ok(&pedscan(&args, dir));
        let j: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("cc.json")).unwrap()).unwrap();
        let refined = &j["refined"]["overall"];
        eprintln!("{projection} {config:?}: {} {refined}", j["people_path"]);
        assert_eq!(j["people_path"], if config.is_some() { "proxies" } else { "cpu" }, "{projection}");
        assert!(refined["both_human"].as_u64().unwrap() > 2000, "{projection}: people were seen");
        assert_eq!(refined["human_beam_agreement"].as_f64().unwrap(), 1.0, "{projection}: {refined}");
        assert_eq!(refined["instance_mixups"].as_u64().unwrap(), 0, "{projection}: {refined}");
        assert_eq!(refined["range_error_m"]["over_1mm"].as_f64().unwrap(), 0.0, "{projection}: {refined}");
        assert_eq!(j["background_beam_agreement"].as_f64().unwrap(), 1.0, "{projection}: background");
    }
}

/// Every sensor preset, and a sensor whose beams reach +-80 deg, on both backends (the raster
/// one with the beam-grid view, the default): every human and background beam agrees with the
/// reference. The views that cannot cover a sensor refuse it by name: the cube faces past
/// +-35.26 deg, the cylindrical panorama and the people's proxy panorama past +-45.
#[test]
fn every_sensor_preset_and_a_steep_sensor_are_exact_on_both_backends() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let rows: Vec<String> = (0..33).map(|r| (80 - 5 * r).to_string()).collect();
    std::fs::write(dir.join("steep.toml"), format!("name = \"steep\"\nelevation_deg = [{}]\ncolumns = 512\n", rows.join(", "))).unwrap();
    let sensors: Vec<&str> = pedscan::sensor::Sensor::PRESETS.iter().copied().chain(["steep.toml"]).collect();
    for sensor in sensors {
        for backend in ["raster", "raycast"] {
            let args = ["crosscheck", "--sensor", sensor, "--backend", backend, "--sequences", "1", "--frames", "1", "--humans", "8", "--seed", "3", "--json", "cc.json"];
            ok(&pedscan(&args, dir));
            let j: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("cc.json")).unwrap()).unwrap();
            let refined = &j["refined"]["overall"];
            assert!(refined["both_human"].as_u64().unwrap() > 200, "{sensor} {backend}: people were seen: {refined}");
            assert_eq!(refined["human_beam_agreement"].as_f64().unwrap(), 1.0, "{sensor} {backend}: {refined}");
            assert_eq!(refined["instance_mixups"].as_u64().unwrap(), 0, "{sensor} {backend}: {refined}");
            assert_eq!(refined["range_error_m"]["over_1mm"].as_f64().unwrap(), 0.0, "{sensor} {backend}: {refined}");
            assert_eq!(j["background_beam_agreement"].as_f64().unwrap(), 1.0, "{sensor} {backend}: background");
        }
    }
    std::fs::write(dir.join("proxies.toml"), "[debug]\npeople = \"proxies\"\n").unwrap();
    for (args, bound) in [
        (&["--sensor", "os0-128", "--projection", "cube"][..], "past the +-35.26 deg the cube faces cover"),
        (&["--sensor", "steep.toml", "--projection", "cylinder"][..], "past the +-45 deg a cylindrical panorama covers"),
        (&["--sensor", "steep.toml", "--config", "proxies.toml"][..], "past the +-45 deg the people's proxy panorama"),
    ] {
        let o = pedscan(&[&["crosscheck", "--sequences", "1", "--frames", "1", "--humans", "1"][..], args].concat(), dir);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(bound), "{args:?}: {err}");
    }
}
