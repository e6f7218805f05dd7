//! End to end: runs the built `pedscan` binary on lavapipe (validation layer on) in a temporary
//! folder and reads the files back, checking the data contract of docs/outputs.md.

use crate::common::{expect_input_error, ok, pedscan, pedscan_with_env};
use std::path::Path;

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|r| r.filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().to_string())).collect())
        .unwrap_or_default();
    v.sort();
    v
}

struct Seq {
    rows: usize,
    cols: usize,
    frames: usize,
    range: Vec<f32>,
    bg: Vec<f32>,
    label: Vec<u8>,
    instance: Vec<u16>,
    velocity: Vec<f32>,
    xyz: Vec<f32>,
    time: Vec<f64>,
    pose: Vec<f64>,
    humans_pos: Vec<f64>,
    n_humans: usize,
}

fn read_seq(path: &Path) -> Seq {
    let f = hdf5::File::open(path).unwrap();
    let range = f.dataset("range").unwrap();
    let shape = range.shape();
    assert_eq!(shape.len(), 3);
    let n_humans = f.dataset("humans/height_m").unwrap().shape()[0];
    Seq {
        frames: shape[0],
        rows: shape[1],
        cols: shape[2],
        range: range.read_raw().unwrap(),
        bg: f.dataset("background/range").unwrap().read_raw().unwrap(),
        label: f.dataset("label").unwrap().read_raw().unwrap(),
        instance: f.dataset("instance").unwrap().read_raw().unwrap(),
        velocity: f.dataset("velocity").unwrap().read_raw().unwrap(),
        xyz: f.dataset("xyz").unwrap().read_raw().unwrap(),
        time: f.dataset("sensor/time_s").unwrap().read_raw().unwrap(),
        pose: f.dataset("sensor/world_from_sensor").unwrap().read_raw().unwrap(),
        humans_pos: f.dataset("humans/position_m").unwrap().read_raw().unwrap(),
        n_humans,
    }
}

#[test]
fn generate_writes_consistent_labeled_sequences() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // The raster path explicitly (the default `auto` picks the ray caster on lavapipe).
    let o = pedscan(
        &["generate", "--out", "out", "--frames", "5", "--sequences", "2", "--humans", "4..6", "--seed", "11", "--png", "--backend", "raster", "--sensor-model", "off"],
        dir,
    );
    ok(&o);
    let out = dir.join("out");
    let names = files_in(&out);
    for s in ["seq_000000", "seq_000001"] {
        assert!(names.contains(&format!("{s}.h5")), "{names:?}");
        assert!(names.contains(&format!("{s}.xml")), "{names:?}");
    }
    assert!(!names.iter().any(|n| n.contains("tmp")), "temporary files left: {names:?}");

    let s = read_seq(&out.join("seq_000000.h5"));
    assert_eq!((s.frames, s.rows, s.cols), (5, 32, 1024));
    assert!((4..=6).contains(&s.n_humans));
    let hw = s.rows * s.cols;
    let mut human_beams = 0;
    let mut filled_holes = 0;
    for t in 0..s.frames {
        // Sensor velocity from the poses by central differences: on the sampled arcs the
        // chord is parallel to the tangent at the middle and shorter by O((w dt)^2) ~ 1e-4.
        // Interior frames only: a one-sided difference is off by O(w dt).
        let p = |k: usize, i: usize| s.pose[k * 16 + i];
        let interior = t > 0 && t + 1 < s.frames;
        let (k0, k1) = if interior { (t - 1, t + 1) } else { (t, t) };
        let dt = (s.time[k1] - s.time[k0]).max(1e-9);
        let vw = [(p(k1, 3) - p(k0, 3)) / dt, (p(k1, 7) - p(k0, 7)) / dt, (p(k1, 11) - p(k0, 11)) / dt];
        // -R^T V_s: R rows are pose rows 0..3 (row-major 4x4).
        let mut vs = [0.0; 3];
        for (j, v) in vs.iter_mut().enumerate() {
            *v = (0..3).map(|i| p(t, i * 4 + j) * vw[i]).sum::<f64>();
        }
        for b in 0..hw {
            let i = t * hw + b;
            assert_eq!(s.label[i] == 1, s.instance[i] > 0, "label == (instance > 0) at {i}");
            assert!(s.instance[i] as usize <= s.n_humans);
            if s.label[i] == 0 {
                assert_eq!(s.range[i], s.bg[i], "non-human beam {i} equals the background");
                if s.range[i] > 0.0 && interior {
                    for k in 0..3 {
                        let v = s.velocity[3 * i + k] as f64;
                        assert!((v + vs[k]).abs() < 2e-3, "background velocity {v} vs -V_s {} at frame {t}", -vs[k]);
                    }
                }
            } else {
                human_beams += 1;
                assert!(s.range[i] > 0.0);
                if s.bg[i] == 0.0 {
                    filled_holes += 1;
                } else {
                    assert!(s.range[i] < s.bg[i], "a human beam is nearer than the background");
                }
            }
            // xyz = range * beam direction: its norm is the range.
            let n = (0..3).map(|k| (s.xyz[3 * i + k] as f64).powi(2)).sum::<f64>().sqrt();
            assert!((n - s.range[i] as f64).abs() < 1e-4 * (1.0 + n), "|xyz| {n} vs range {}", s.range[i]);
        }
    }
    assert!(human_beams > 100, "people are visible: {human_beams} human beams");
    eprintln!("{human_beams} human beams, {filled_holes} of them in front of a background hole");

    // The XML agrees with the HDF5: people per frame and their positions.
    let xml = std::fs::read_to_string(out.join("seq_000000.xml")).unwrap();
    assert_eq!(xml.matches("<frame ").count(), s.frames);
    let first_frame = xml.split("<frame ").nth(1).unwrap();
    let humans_attr = first_frame.split("humans=\"").nth(1).unwrap().split('"').next().unwrap();
    assert_eq!(humans_attr.parse::<usize>().unwrap(), s.n_humans);
    let x_attr: f64 = first_frame.split(" x=\"").nth(1).unwrap().split('"').next().unwrap().parse().unwrap();
    assert!((x_attr - s.humans_pos[0]).abs() < 1e-3, "XML x {x_attr} vs HDF5 {}", s.humans_pos[0]);

    // PNGs were written for every frame.
    let png_dir = out.join("seq_000000_png");
    let pngs = files_in(&png_dir);
    assert!(pngs.iter().filter(|n| n.starts_with("range_")).count() == 5, "{pngs:?}");
}

#[test]
fn same_seed_gives_bit_identical_files_whatever_the_thread_count() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // Both backends: the ray caster splits beams over threads, the raster path its CPU stages.
    for backend in ["raster", "raycast"] {
        let args = |out: &'static str| vec!["generate", "--out", out, "--frames", "3", "--humans", "3..3", "--seed", "3", "--backend", backend];
        let (a_dir, b_dir) = if backend == "raster" { ("a", "b") } else { ("c", "d") };
        ok(&pedscan_with_env(&args(a_dir), dir, &[("RAYON_NUM_THREADS", "1"), ("LP_NUM_THREADS", "1")]));
        ok(&pedscan_with_env(&args(b_dir), dir, &[("RAYON_NUM_THREADS", "2")]));
        for f in ["seq_000000.h5", "seq_000000.xml"] {
            let a = std::fs::read(dir.join(a_dir).join(f)).unwrap();
            let b = std::fs::read(dir.join(b_dir).join(f)).unwrap();
            assert!(a == b, "{backend}: {f} differs between 1 and 2 threads");
        }
    }
}

#[test]
fn bad_input_is_named_exits_2_and_leaves_no_files() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    expect_input_error(&["generate", "--out", "o1", "--frames", "0"], dir, "frames");
    expect_input_error(&["generate", "--out", "o2", "--humans", "5..2"], dir, "humans.count");
    expect_input_error(&["generate", "--out", "o3", "--config", "missing.toml"], dir, "missing.toml");
    std::fs::write(dir.join("typo.toml"), "frames = 2\nfrmaes = 3\n").unwrap();
    expect_input_error(&["generate", "--out", "o4", "--config", "typo.toml"], dir, "frmaes");
    std::fs::write(dir.join("broken.glb"), b"glTF\x02\x00\x00\x00garbage").unwrap();
    expect_input_error(&["generate", "--out", "o5", "--models", "broken.glb"], dir, "broken.glb");
    expect_input_error(&["generate", "--out", "o6", "--sensor", "nosuch.toml"], dir, "nosuch.toml");
    std::fs::write(dir.join("up.toml"), "elevation_deg = [89.5, 0.0]\ncolumns = 512\n").unwrap();
    expect_input_error(&["generate", "--out", "o7", "--sensor", "up.toml"], dir, "up.toml");
    expect_input_error(&["info", "broken.glb"], dir, "broken.glb");
    for o in ["o1", "o2", "o3", "o4", "o5", "o6", "o7"] {
        assert!(!dir.join(o).exists(), "{o} was created for a run that failed on its input");
    }
}

#[test]
fn info_summarises_a_file() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    ok(&pedscan(&["generate", "--out", "o", "--frames", "2", "--humans", "2..2"], dir));
    let o = pedscan(&["info", "o/seq_000000.h5"], dir);
    ok(&o);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("hdl32e"), "{text}");
}

#[test]
fn outputs_not_asked_for_are_not_stored_and_unknown_ones_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    ok(&pedscan(&["generate", "--out", "o", "--frames", "2", "--humans", "2..2", "--outputs", "range,label,instance,velocity"], dir));
    let f = hdf5::File::open(dir.join("o/seq_000000.h5")).unwrap();
    assert!(f.dataset("velocity").is_ok());
    assert!(f.dataset("xyz").is_err(), "xyz was not asked for");
    assert!(f.group("background").is_err() || f.dataset("background/range").is_err(), "background was not asked for");
    expect_input_error(&["generate", "--out", "p", "--outputs", "range,colour"], dir, "colour");
}

/// Without an environment every beam behind a person is a hole: by default the person is
/// measured, with `--keep-holes` (the paper's choice) the hole stays and nobody is labelled.
#[test]
fn keep_holes_keeps_background_holes_in_front_of_which_people_stand() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let args = ["generate", "--frames", "2", "--humans", "4..4", "--environment", "none", "--seed", "2"];
    let mut filled = args.to_vec();
    filled.extend(["--out", "filled"]);
    let mut kept = args.to_vec();
    kept.extend(["--out", "kept", "--keep-holes"]);
    ok(&pedscan(&filled, dir));
    ok(&pedscan(&kept, dir));
    let a = read_seq(&dir.join("filled/seq_000000.h5"));
    let b = read_seq(&dir.join("kept/seq_000000.h5"));
    let humans_a = a.label.iter().filter(|l| **l == 1).count();
    assert!(humans_a > 50, "people are measured in front of holes: {humans_a}");
    assert!(a.bg.iter().all(|r| *r == 0.0), "no environment, no background");
    assert!(b.label.iter().all(|l| *l == 0) && b.range.iter().all(|r| *r == 0.0), "holes kept");
}

/// The CPU ray-cast backend writes the same kind of file and agrees with the raster path.
#[test]
fn raycast_backend_agrees_with_the_raster_backend() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let args = ["generate", "--frames", "3", "--humans", "12..12", "--seed", "8"];
    let mut raster = args.to_vec();
    raster.extend(["--out", "raster", "--backend", "raster"]);
    let mut cast = args.to_vec();
    cast.extend(["--out", "cast", "--backend", "raycast"]);
    ok(&pedscan(&raster, dir));
    ok(&pedscan(&cast, dir));
    let a = read_seq(&dir.join("raster/seq_000000.h5"));
    let b = read_seq(&dir.join("cast/seq_000000.h5"));
    assert_eq!((a.frames, a.rows, a.cols), (b.frames, b.rows, b.cols));
    let either = a.label.iter().zip(&b.label).filter(|(x, y)| **x == 1 || **y == 1).count();
    let both = a.label.iter().zip(&b.label).filter(|(x, y)| **x == 1 && **y == 1).count();
    assert!(either > 100, "people visible: {either}");
    // Both backends are exact (casts of the same posed triangles): every human beam agrees.
    assert!(either > 500, "people visible: {either}");
    assert_eq!(both, either, "{both} of {either} human beams agree");
    let bg_same = a.bg.iter().zip(&b.bg).filter(|(x, y)| (**x - **y).abs() <= 1e-4).count();
    assert_eq!(bg_same, a.bg.len(), "background ranges agree on {bg_same} of {}", a.bg.len());
}

/// The ray-cast backend needs no Vulkan at all: with no driver to be found it runs, and its
/// BVH caster (`debug.caster = "bvh"`, a debug key never recorded) writes the very same
/// bytes; the raster backend then fails with a message that says what it needs.
#[test]
fn the_ray_caster_runs_without_vulkan_and_raster_says_why_it_cannot() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let no_driver = [("VK_ICD_FILENAMES", "/nonexistent/icd.json"), ("VK_DRIVER_FILES", "/nonexistent/icd.json")];
    let args = ["generate", "--frames", "2", "--humans", "3..3", "--seed", "4", "--backend", "raycast"];
    let mut beams = args.to_vec();
    beams.extend(["--out", "beams"]);
    ok(&pedscan_with_env(&beams, dir, &no_driver));
    std::fs::write(dir.join("bvh.toml"), "[debug]\ncaster = \"bvh\"\noverlap_write = false\n").unwrap();
    let mut bvh = args.to_vec();
    bvh.extend(["--out", "bvh", "--config", "bvh.toml"]);
    ok(&pedscan_with_env(&bvh, dir, &no_driver));
    for f in ["seq_000000.h5", "seq_000000.xml"] {
        let (a, b) = (std::fs::read(dir.join("beams").join(f)).unwrap(), std::fs::read(dir.join("bvh").join(f)).unwrap());
        assert!(a == b, "{f}: the BVH caster's file differs from the binned caster's");
    }
    let o = pedscan_with_env(&["generate", "--frames", "1", "--out", "raster", "--backend", "raster"], dir, &no_driver);
    assert_eq!(o.status.code(), Some(1), "raster without a driver must fail");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("raster backend needs a Vulkan device") && err.contains("--backend raycast"), "{err}");
    assert!(!dir.join("raster").exists(), "nothing is created when the backend cannot start");
}

#[test]
fn the_sensor_motion_is_stored_and_is_the_derivative_of_its_poses() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // A fast, turning sensor makes a wrong sign or frame obvious.
    std::fs::write(dir.join("c.toml"), "[scene]\nsensor_speed_mps = [1.5, 1.5]\nsensor_yaw_rate_rps = [0.3, 0.3]\n").unwrap();
    ok(&pedscan(&["generate", "--config", "c.toml", "--backend", "raycast", "--frames", "12", "--humans", "1..1", "--out", "o"], dir));
    let f = hdf5::File::open(dir.join("o/seq_000000.h5")).unwrap();
    let t: Vec<f64> = f.dataset("sensor/time_s").unwrap().read_raw().unwrap();
    let pose: Vec<f64> = f.dataset("sensor/world_from_sensor").unwrap().read_raw().unwrap();
    let v = f.dataset("sensor/velocity_mps").unwrap();
    assert_eq!(v.shape(), vec![t.len(), 3]);
    let v: Vec<f64> = v.read_raw().unwrap();
    let w: Vec<f64> = f.dataset("sensor/yaw_rate_rps").unwrap().read_raw().unwrap();
    let pos = |k: usize| [pose[16 * k + 3], pose[16 * k + 7], pose[16 * k + 11]];
    let yaw = |k: usize| pose[16 * k + 4].atan2(pose[16 * k]);
    for k in 1..t.len() - 1 {
        let dt = t[k + 1] - t[k - 1];
        let (a, b) = (pos(k - 1), pos(k + 1));
        for i in 0..3 {
            let fd = (b[i] - a[i]) / dt;
            assert!((fd - v[3 * k + i]).abs() < 0.02, "frame {k} axis {i}: stored {} vs poses {fd}", v[3 * k + i]);
        }
        let dyaw = pedscan::geometry::wrap_pi(yaw(k + 1) - yaw(k - 1));
        assert!((dyaw / dt - w[k]).abs() < 0.01, "frame {k}: yaw rate {} vs poses {}", w[k], dyaw / dt);
    }
    assert!(v.chunks(3).all(|c| (c[0].hypot(c[1]) - 1.5).abs() < 1e-9), "speed 1.5 m/s: {v:?}");
}

#[test]
fn stats_count_what_the_files_hold() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    ok(&pedscan(&["generate", "--backend", "raycast", "--sequences", "2", "--frames", "3", "--humans", "2..4", "--out", "o"], dir));
    ok(&pedscan(&["stats", "o", "--png", "s.png", "--json", "s.json"], dir));
    let s: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("s.json")).unwrap()).unwrap();
    let (mut frames, mut humans, mut near, mut people) = (0, 0u64, 0u64, 0u64);
    for f in ["o/seq_000000.h5", "o/seq_000001.h5"] {
        let q = read_seq(&dir.join(f));
        frames += q.frames;
        people += (q.frames * q.n_humans) as u64;
        for (r, k) in q.range.iter().zip(&q.instance) {
            if *k > 0 && *r > 0.0 {
                humans += 1;
                near += (*r < 4.0) as u64;
            }
        }
    }
    assert_eq!(s["frames"], frames);
    assert_eq!(s["human_beams"], humans);
    assert_eq!(s["human_beams_by_distance"][0], near);
    let speeds: u64 = s["speed_histogram"].as_array().unwrap().iter().map(|c| c.as_u64().unwrap()).sum();
    assert_eq!(speeds, people, "one walking speed per person and frame");
    assert!(image::open(dir.join("s.png")).unwrap().width() > 600);
    expect_input_error(&["stats", "nowhere"], dir, "nowhere");
    std::fs::create_dir(dir.join("empty")).unwrap();
    expect_input_error(&["stats", "empty"], dir, "no seq_*.h5");
}

/// Two copies of pedscan, binary and bundled data, at different paths (two clones, or two
/// nodes that install it in different places) write the same bytes and the same config hash
/// for the same seed and configuration: bundled inputs are recorded by name and content
/// digest (`bundled:humans/...`), never by where they lie. A changed model is another
/// configuration.
#[test]
fn copies_at_different_paths_write_the_same_bytes_and_config_hash() {
    let tmp = tempfile::tempdir_in(env!("CARGO_TARGET_TMPDIR")).unwrap();
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("data");
    let install = |root: &Path| {
        for sub in ["humans", "scene"] {
            std::fs::create_dir_all(root.join("data").join(sub)).unwrap();
            for e in std::fs::read_dir(data.join(sub)).unwrap() {
                let p = e.unwrap().path();
                if p.is_file() {
                    std::fs::copy(&p, root.join("data").join(sub).join(p.file_name().unwrap())).unwrap();
                }
            }
        }
        std::fs::create_dir_all(root.join("bin")).unwrap();
        std::fs::copy(env!("CARGO_BIN_EXE_pedscan"), root.join("bin/pedscan")).unwrap();
    };
    let generate = |root: &Path| {
        let o = std::process::Command::new(root.join("bin/pedscan"))
            .args(["generate", "--backend", "raycast", "--frames", "2", "--humans", "3", "--seed", "7", "--out", "out"])
            .current_dir(root)
            .output()
            .unwrap();
        ok(&o);
        let h5 = std::fs::read(root.join("out/seq_000000.h5")).unwrap();
        let manifest: serde_json::Value = serde_json::from_str(std::fs::read_to_string(root.join("out/manifest.jsonl")).unwrap().lines().next().unwrap()).unwrap();
        (h5, manifest["config_hash"].as_str().unwrap().to_string())
    };
    let (a, b) = (tmp.path().join("one"), tmp.path().join("two/levels down"));
    install(&a);
    install(&b);
    let (h5_a, hash_a) = generate(&a);
    let (h5_b, hash_b) = generate(&b);
    assert_eq!(hash_a, hash_b, "config hashes differ between the copies");
    assert!(h5_a == h5_b, "the copies wrote different bytes");
    let config = hdf5::File::open(a.join("out/seq_000000.h5")).unwrap().attr("config").unwrap().read_scalar::<hdf5::types::VarLenUnicode>().unwrap().to_string();
    assert!(config.contains("models = [\"bundled:humans\"]") && config.contains("# bundled:scene/hall.glb "), "{config}");
    assert!(!config.contains(&*tmp.path().to_string_lossy()), "the copy's path is recorded: {config}");
    // The same copy with one model changed by a byte: another configuration.
    let model = b.join("data/humans/h1700_w60.glb");
    let mut bytes = std::fs::read(&model).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 0x20; // inside the binary chunk's padding or data: still a loadable model
    std::fs::write(&model, bytes).unwrap();
    std::fs::remove_dir_all(b.join("out")).unwrap();
    let (_, hash_changed) = generate(&b);
    assert_ne!(hash_changed, hash_a, "a changed model left the config hash as it was");
}

/// `bench`'s per-stage table: one row per workload, each stage a difference of `--timings`'
/// counters over the round's frames (so never negative), the frame thread their sum; its
/// temporary folder is gone after. Timings are read, never compared with a bound.
#[test]
fn bench_stage_table_accounts_every_stage_of_a_round() {
    let mut base = pedscan::config::Config::default();
    base.humans.count = [1, 2];
    let rows = pedscan::commands::bench::stage_costs(&base, 2, 2).unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r.variant.as_str()).collect();
    assert_eq!(names, ["as configured", "sensor model off", "30 people"]);
    for r in &rows {
        assert!(r.ms.iter().all(|m| m.is_finite() && *m >= 0.0), "{r:?}");
        // Medians of sums and sums of medians differ; with two rounds the median is their mean,
        // which is linear, so the frame thread equals the sum of the six stage medians.
        let sum: f64 = r.ms[..6].iter().sum();
        assert!((sum - r.ms[7]).abs() <= 1e-9 * sum.max(1.0), "{r:?}");
        assert!(r.ms[1] > 0.0 && r.ms[5] > 0.0 && r.ms[6] > 0.0, "pose, post and write ran: {r:?}");
    }
    let table = pedscan::commands::bench::stages_markdown(&rows, 2, 2);
    assert_eq!(table.lines().filter(|l| l.starts_with("| ") && !l.starts_with("| workload")).count(), 3, "{table}");
    let dir = std::env::temp_dir().join(format!("pedscan-bench-{}", std::process::id())).join("stages");
    assert!(!dir.exists());
}
