//! The built-in worlds end to end: `scene.background = "street"` / `"indoor"` in a config file
//! (a name, not a path beside it), each sequence its own recorded layout, `/class` agreeing with
//! `/label` and with the SemanticKITTI export, cars and cyclists driving with their own
//! instances and velocities, people who stand and walk in company, and the same bytes at any
//! thread count.

use crate::common::{expect_input_error, ok, pedscan, pedscan_with_env};
use std::path::Path;

fn u32s(path: &Path) -> Vec<u32> {
    std::fs::read(path).unwrap().chunks(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect()
}

fn world_of(xml: &Path) -> String {
    let text = std::fs::read_to_string(xml).unwrap();
    let at = text.find("world=\"").unwrap_or_else(|| panic!("{} records no world:\n{text}", xml.display()));
    text[at + 7..].split('"').next().unwrap().to_string()
}

#[test]
fn a_street_per_sequence_with_classes_that_agree_with_the_labels() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::create_dir(dir.join("cfg")).unwrap();
    std::fs::write(dir.join("cfg/s.toml"), "elevation_deg = [6.0, 2.0, 0.0, -2.0, -4.0, -7.0, -10.0, -15.0]\ncolumns = 512\n").unwrap();
    std::fs::write(
        dir.join("cfg/c.toml"),
        "sensor = \"s.toml\"\n[humans]\ncount = [6, 6]\nstanding = 0.5\ngroups = 0.5\nspawn_radius_m = 20.0\n[scene]\nbackground = \"street\"\nsensor_height_m = 1.73\nsensor_speed_mps = [2.0, 6.0]\n",
    )
    .unwrap();
    let args = |out: &str| -> Vec<String> {
        ["generate", "--config", "cfg/c.toml", "--backend", "raycast", "--sequences", "2", "--frames", "3", "--formats", "h5,semantickitti", "--out", out]
            .iter()
            .map(|s| s.to_string())
            .collect()
    };
    let a: Vec<String> = args("a");
    ok(&pedscan_with_env(&a.iter().map(String::as_str).collect::<Vec<_>>(), dir, &[("RAYON_NUM_THREADS", "1")]));
    let b: Vec<String> = args("b");
    ok(&pedscan_with_env(&b.iter().map(String::as_str).collect::<Vec<_>>(), dir, &[("RAYON_NUM_THREADS", "2")]));
    let (w0, w1) = (world_of(&dir.join("a/seq_000000.xml")), world_of(&dir.join("a/seq_000001.xml")));
    assert!(w0.starts_with("street (") && w0.contains("parked car") || w0.contains("tree"), "{w0}");
    assert_ne!(w0, w1, "each sequence its own layout");
    for f in ["seq_000000.h5", "seq_000001.h5", "seq_000000.xml"] {
        assert!(std::fs::read(dir.join("a").join(f)).unwrap() == std::fs::read(dir.join("b").join(f)).unwrap(), "{f} differs between 1 and 2 threads");
    }
    let mut seen = std::collections::BTreeSet::new();
    let beams = 8 * 512;
    for seq in 0..2 {
        let f = hdf5::File::open(dir.join(format!("a/seq_{seq:06}.h5"))).unwrap();
        let range: Vec<f32> = f.dataset("range").unwrap().read_raw().unwrap();
        let label: Vec<u8> = f.dataset("label").unwrap().read_raw().unwrap();
        let class: Vec<u16> = f.dataset("class").unwrap().read_raw().unwrap();
        let instance: Vec<u16> = f.dataset("instance").unwrap().read_raw().unwrap();
        let velocity: Vec<f32> = f.dataset("velocity").unwrap().read_raw().unwrap();
        let people = f.dataset("humans/height_m").unwrap().shape()[0];
        let kinds: Vec<hdf5::types::VarLenUnicode> = f.dataset("movers/kind").unwrap().read_raw().unwrap();
        let mover_velocity: Vec<f32> = f.dataset("movers/velocity_mps").unwrap().read_raw().unwrap();
        let sensor_velocity: Vec<f64> = f.dataset("sensor/velocity_mps").unwrap().read_raw().unwrap();
        let pose: Vec<f64> = f.dataset("sensor/world_from_sensor").unwrap().read_raw().unwrap();
        let movers = kinds.len();
        let mut mover_classes = std::collections::BTreeSet::new();
        for g in 0..range.len() {
            let person = class[g] == 30 || class[g] == 254;
            assert_eq!(label[g] == 1, person, "seq {seq} beam {g}: label {} class {}", label[g], class[g]);
            assert_eq!(range[g] == 0.0, class[g] == 0, "seq {seq} beam {g}: range {} class {}", range[g], class[g]);
            let k = instance[g] as usize;
            assert_eq!(person, (1..=people).contains(&k), "seq {seq} beam {g}: instance {k} of {people} people, class {}", class[g]);
            if k > people {
                // A mover's beam: a car or a cyclist (the rider not scored), moving with it.
                assert!(k <= people + movers, "instance {k}: {people} people, {movers} movers");
                let rider = class[g] == 31 || class[g] == 253;
                assert!(rider || [10, 252, 11].contains(&class[g]), "mover {k}: class {}", class[g]);
                assert_eq!(label[g] == 255, rider, "mover {k}: label {} class {}", label[g], class[g]);
                mover_classes.insert(class[g]);
                // Its velocity relative to the sensor: R^T (V_m - V_s), the street straight
                // (no yaw rate); within what the mover's braking changes over a sweep, and
                // upward within a crossing ramp's slope (0.12 m over 0.9 m: the beam sees the
                // mover when its column fires, the frame's record is at the frame's start).
                let (t, j) = (g / beams, k - people - 1);
                let v_m: Vec<f64> = (0..3).map(|a| mover_velocity[(t * movers + j) * 3 + a] as f64).collect();
                let rel: Vec<f64> = (0..3).map(|a| v_m[a] - sensor_velocity[t * 3 + a]).collect();
                for a in 0..3 {
                    let expect: f64 = (0..3).map(|r| pose[t * 16 + r * 4 + a] * rel[r]).sum();
                    let tolerance = if a == 2 { 0.5 + 0.14 * v_m[0].hypot(v_m[1]) } else { 0.5 };
                    assert!((velocity[g * 3 + a] as f64 - expect).abs() < tolerance, "mover {k} frame {t}: velocity[{a}] {} vs {expect}", velocity[g * 3 + a]);
                }
            } else if k == 0 {
                assert_eq!(label[g], 0, "seq {seq} beam {g}");
            }
            seen.insert(class[g]);
        }
        // Every street shows a car and a cyclist (its bicycle or its rider) driving.
        assert!(mover_classes.contains(&252) || mover_classes.contains(&10), "seq {seq}: mover classes {mover_classes:?}");
        assert!(mover_classes.iter().any(|c| [11, 31, 253].contains(c)), "seq {seq}: mover classes {mover_classes:?}");
        for t in 0..3 {
            let labels = u32s(&dir.join(format!("a/semantickitti/sequences/{seq:02}/labels/{t:06}.label")));
            let returned: Vec<u16> = (0..beams).filter(|&b| range[t * beams + b] > 0.0).map(|b| class[t * beams + b]).collect();
            assert_eq!(labels.iter().map(|l| (l & 0xffff) as u16).collect::<Vec<_>>(), returned, "seq {seq} frame {t}");
        }
    }
    for c in [40, 48, 50] {
        assert!(seen.contains(&c), "class {c} among {seen:?}");
    }
    assert!(seen.contains(&30) || seen.contains(&254), "people seen: {seen:?}");
    let yaml = std::fs::read_to_string(dir.join("a/semantickitti/pedscan.yaml")).unwrap();
    assert!(yaml.contains("40: \"road\"") && yaml.contains("  40: 1\n"), "{yaml}");
    ok(&pedscan(&["verify", "a"], dir));
}

#[test]
fn indoor_runs_and_bad_behaviour_shares_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let o = pedscan(&["generate", "--background", "indoor", "--sensor", "vlp16", "--backend", "raycast", "--sequences", "1", "--frames", "2", "--humans", "4", "--outputs", "range,label,instance,class", "--out", "o"], dir);
    ok(&o);
    let world = world_of(&dir.join("o/seq_000000.xml"));
    assert!(world.starts_with("indoor (") && world.contains("service aisle 1"), "{world}");
    let f = hdf5::File::open(dir.join("o/seq_000000.h5")).unwrap();
    let class: Vec<u16> = f.dataset("class").unwrap().read_raw().unwrap();
    assert!(class.contains(&49) && class.contains(&50), "floor and walls");
    assert!(f.dataset("xyz").is_err(), "--outputs leaves xyz out");
    // Its robots and carts: each a mover with its own instance after the people's, SemanticKITTI's
    // other-vehicle (20, or 259 while it drives), background to the person label.
    let kinds: Vec<hdf5::types::VarLenUnicode> = f.dataset("movers/kind").unwrap().read_raw().unwrap();
    assert!(!kinds.is_empty() && kinds.iter().all(|k| ["robot", "cart"].contains(&k.as_str())), "{kinds:?}");
    let instance: Vec<u16> = f.dataset("instance").unwrap().read_raw().unwrap();
    let label: Vec<u8> = f.dataset("label").unwrap().read_raw().unwrap();
    let people = f.dataset("humans/height_m").unwrap().shape()[0];
    for g in (0..class.len()).filter(|&g| instance[g] as usize > people) {
        assert!(instance[g] as usize <= people + kinds.len() && [20, 259].contains(&class[g]) && label[g] == 0, "beam {g}: instance {} class {} label {}", instance[g], class[g], label[g]);
    }
    std::fs::write(dir.join("bad.toml"), "[humans]\nstanding = 1.5\n").unwrap();
    expect_input_error(&["generate", "--config", "bad.toml", "--out", "x"], dir, "humans.standing");
    assert!(!dir.join("x").exists(), "nothing written");
}

/// `scene.side_streets` reaches the street's builder: every lot a side street (the markets none)
/// shows in the recorded layout; shares that add up to more than the lots are refused.
#[test]
fn side_streets_are_built_when_asked_and_impossible_shares_named() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("c.toml"), "[scene]\nbackground = \"street\"\nmarkets = 0.0\nside_streets = 1.0\n").unwrap();
    ok(&pedscan(&["generate", "--config", "c.toml", "--sensor", "vlp16", "--backend", "raycast", "--sequences", "1", "--frames", "1", "--humans", "2", "--outputs", "range,label", "--out", "o"], dir));
    let world = world_of(&dir.join("o/seq_000000.xml"));
    assert!(world.contains("side street ") && !world.contains("plaza") && !world.contains("market"), "{world}");
    std::fs::write(dir.join("bad.toml"), "[scene]\nbackground = \"street\"\nmarkets = 0.5\nside_streets = 0.6\n").unwrap();
    expect_input_error(&["generate", "--config", "bad.toml", "--out", "x"], dir, "scene.side_streets");
    assert!(!dir.join("x").exists(), "nothing written");
}

/// `humans.pushing`: people push strollers through the street. Each stroller is a mover of its
/// own (`/movers/pushed_by` its pusher, the XML's `pushing`), held at its pusher's heading a
/// fixed distance ahead; its beams are other-object (99), not a person; its turning rate
/// (`/movers/yaw_rate_rps`) turns its heading from frame to frame; its per-beam velocity (the rigid model) is
/// its centre's plus its turn about the centre, exactly (the rolling shutter off: every beam at
/// the frame's time). Some beams' turn term is large, so
/// a velocity without it fails. The same bytes at 1 and 2 threads. Indoors people push
/// trolleys.
#[test]
fn people_push_strollers_that_move_and_turn_with_them() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("s.toml"), "elevation_deg = [4.0, 2.0, 0.0, -2.0, -4.0, -6.0, -8.0, -11.0]\ncolumns = 1024\n").unwrap();
    std::fs::write(dir.join("c.toml"), "sensor = \"s.toml\"\n[humans]\ncount = [8, 8]\npushing = 1.0\nspawn_radius_m = 15.0\n[scene]\nbackground = \"street\"\nsensor_height_m = 1.2\nsensor_speed_mps = [0.5, 1.0]\n[output]\nvelocity = \"rigid\"\n").unwrap();
    let run = |out: &'static str| ["generate", "--config", "c.toml", "--backend", "raycast", "--rolling-shutter", "off", "--sequences", "2", "--frames", "60", "--seed", "3", "--out", out];
    ok(&pedscan_with_env(&run("o"), dir, &[("RAYON_NUM_THREADS", "2")]));
    ok(&pedscan_with_env(&run("o1"), dir, &[("RAYON_NUM_THREADS", "1")]));
    for f in ["seq_000000.h5", "seq_000001.h5", "seq_000000.xml", "seq_000001.xml"] {
        assert!(std::fs::read(dir.join("o").join(f)).unwrap() == std::fs::read(dir.join("o1").join(f)).unwrap(), "{f} differs between 1 and 2 threads");
    }
    let (mut strollers, mut turned, mut checked, mut turning) = (0, 0, 0, 0);
    let beams = 8 * 1024;
    for seq in 0..2 {
        let xml = std::fs::read_to_string(dir.join(format!("o/seq_{seq:06}.xml"))).unwrap();
        let f = hdf5::File::open(dir.join(format!("o/seq_{seq:06}.h5"))).unwrap();
        let read_f32 = |k: &str| -> Vec<f32> { f.dataset(k).unwrap().read_raw().unwrap() };
        let read_f64 = |k: &str| -> Vec<f64> { f.dataset(k).unwrap().read_raw().unwrap() };
        let kinds: Vec<hdf5::types::VarLenUnicode> = f.dataset("movers/kind").unwrap().read_raw().unwrap();
        let pushed_by: Vec<u32> = f.dataset("movers/pushed_by").unwrap().read_raw().unwrap();
        let (class, label, instance): (Vec<u16>, Vec<u8>, Vec<u16>) = (f.dataset("class").unwrap().read_raw().unwrap(), f.dataset("label").unwrap().read_raw().unwrap(), f.dataset("instance").unwrap().read_raw().unwrap());
        let (xyz, velocity, range) = (read_f32("xyz"), read_f32("velocity"), read_f32("range"));
        let (hp, hh) = (read_f64("humans/position_m"), read_f32("humans/heading_rad"));
        let (mp, mh, mv, mw) = (read_f64("movers/position_m"), read_f32("movers/heading_rad"), read_f32("movers/velocity_mps"), read_f32("movers/yaw_rate_rps"));
        let (pose, sv, sw) = (read_f64("sensor/world_from_sensor"), read_f64("sensor/velocity_mps"), read_f64("sensor/yaw_rate_rps"));
        let (people, movers, frames) = (hh.len() / 60, kinds.len(), 60);
        let pushed: Vec<usize> = (0..movers).filter(|&j| kinds[j].as_str() == "stroller").collect();
        assert_eq!(pushed.iter().map(|&j| pushed_by[j] > 0).filter(|&b| b).count(), pushed.len(), "seq {seq}: every stroller has its pusher");
        assert!((0..movers).all(|j| (pushed_by[j] > 0) == pushed.contains(&j)), "seq {seq}: only strollers are pushed: {kinds:?} {pushed_by:?}");
        assert!(pushed.is_empty() || xml.contains(&format!("stroller pushed {}", pushed.len())), "seq {seq}");
        assert_eq!(xml.matches("pushing=\"stroller\"").count(), pushed.len(), "seq {seq}");
        strollers += pushed.len();
        for &j in &pushed {
            let i = pushed_by[j] as usize - 1;
            let ahead = |t: usize| (mp[(t * movers + j) * 3] - hp[(t * people + i) * 3]).hypot(mp[(t * movers + j) * 3 + 1] - hp[(t * people + i) * 3 + 1]);
            let a = ahead(0);
            assert!((0.6..1.5).contains(&a), "seq {seq}: stroller {j} {a} m ahead");
            for t in 0..frames {
                let h = hh[t * people + i] as f64;
                let d = [mp[(t * movers + j) * 3] - hp[(t * people + i) * 3], mp[(t * movers + j) * 3 + 1] - hp[(t * people + i) * 3 + 1]];
                // Within a centimetre and 0.01 rad: the thing's pose is tabled every 0.05 s, the
                // frames half a step off the rows, where a turn that sets in mid-step bends it.
                assert!((d[0] - a * h.cos()).abs() < 0.01 && (d[1] - a * h.sin()).abs() < 0.01, "seq {seq} frame {t}: stroller {j} not {a} m ahead of its pusher at {h}: {d:?}");
                let dh = (mh[t * movers + j] as f64 - h).rem_euclid(std::f64::consts::TAU);
                assert!(dh.min(std::f64::consts::TAU - dh) < 0.01, "seq {seq} frame {t}: heading {dh} off the pusher's");
                // The heading's change over a frame against the turning rates: the frames fall
                // mid-step of the 0.05 s pose table, so a frame's change is a quarter of a frame
                // at each end's rate and half a frame at the step's between them.
                let w = |t: usize| mw[t * movers + j] as f64;
                if t + 1 < frames {
                    let turn = pedscan::geometry::wrap_pi(mh[(t + 1) * movers + j] as f64 - mh[t * movers + j] as f64);
                    let ends = 0.025 * (w(t) + w(t + 1));
                    let (lo, hi) = (ends + 0.05 * w(t).min(w(t + 1)), ends + 0.05 * w(t).max(w(t + 1)));
                    assert!(turn > lo - 0.002 && turn < hi + 0.002, "seq {seq} frame {t}: stroller {j} turns {turn} rad, its rates {} and {} rad/s", w(t), w(t + 1));
                    turning += usize::from(w(t).abs() > 0.05);
                }
            }
        }
        for g in 0..range.len() {
            let k = instance[g] as usize;
            if k <= people || !pushed.contains(&(k - people - 1)) {
                continue;
            }
            assert!(class[g] == 99 && label[g] == 0, "seq {seq} beam {g}: class {} label {}", class[g], label[g]);
            let (t, j) = (g / beams, k - people - 1);
            let m = &pose[t * 16..t * 16 + 16];
            let at = |r: usize| (0..3).map(|c| m[r * 4 + c] * xyz[g * 3 + c] as f64).sum::<f64>() + m[r * 4 + 3];
            let hit = [at(0), at(1), at(2)];
            let (c, w) = (&mp[(t * movers + j) * 3..], mw[t * movers + j] as f64);
            let r = [hit[0] - c[0], hit[1] - c[1]];
            let s = [m[3], m[7]];
            let turn = [-w * r[1], w * r[0], 0.0];
            let own = [-sw[t] * (hit[1] - s[1]), sw[t] * (hit[0] - s[0]), 0.0];
            let rel: Vec<f64> = (0..3).map(|a| mv[(t * movers + j) * 3 + a] as f64 + turn[a] - sv[t * 3 + a] - own[a]).collect();
            for a in 0..3 {
                let expect: f64 = (0..3).map(|row| m[row * 4 + a] * rel[row]).sum();
                assert!((velocity[g * 3 + a] as f64 - expect).abs() < 0.02, "seq {seq} beam {g}: velocity[{a}] {} vs {expect}", velocity[g * 3 + a]);
            }
            checked += 1;
            turned += usize::from(turn[0].hypot(turn[1]) > 0.05);
        }
    }
    assert!(strollers >= 2 && checked >= 50 && turned >= 10 && turning >= 5, "{strollers} strollers, {checked} beams, {turned} of them turning, {turning} frames of a stroller turning");
    ok(&pedscan(&["generate", "--config", "c.toml", "--background", "indoor", "--backend", "raycast", "--sequences", "1", "--frames", "2", "--outputs", "range,label,instance", "--out", "i"], dir));
    let xml = std::fs::read_to_string(dir.join("i/seq_000000.xml")).unwrap();
    assert!(xml.contains("trolley pushed ") && xml.contains("pushing=\"trolley\""), "{}", world_of(&dir.join("i/seq_000000.xml")));
}
