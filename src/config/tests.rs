//! The configuration's unit tests: defaults, TOML round trips, validation, the flags over it.

use super::*;

#[test]
fn defaults_validate_and_round_trip_through_toml() {
    let c = Config::default();
    c.validate().unwrap();
    let back: Config = toml::from_str(&c.to_toml()).unwrap();
    assert_eq!(back, c);
}

#[test]
fn bundled_inputs_are_recorded_by_name_and_resolved_back() {
    let humans = data_dir().join("humans");
    assert_eq!(recorded_path(&humans), PathBuf::from("bundled:humans"));
    assert_eq!(recorded_path(&data_dir().join("scene/hall.glb")), PathBuf::from("bundled:scene/hall.glb"));
    assert_eq!(resolve_bundled(Path::new("bundled:humans")), humans);
    assert_eq!(recorded_path(Path::new("/elsewhere/people")), PathBuf::from("/elsewhere/people"));
    assert_eq!(resolve_bundled(Path::new("people/bundled:x")), PathBuf::from("people/bundled:x"));
    let recorded = Config::default().to_recorded_toml();
    assert!(recorded.contains("models = [\"bundled:humans\"]") && recorded.contains("background = \"bundled:scene/hall.glb\""), "{recorded}");
    // A recorded configuration read back names the same bundled files.
    let dir = std::env::temp_dir().join(format!("pedscan-config-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("c.toml"), &recorded).unwrap();
    let back = Config::from_file(&dir.join("c.toml")).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(back.humans.models, vec![humans]);
    assert_eq!(back.scene.background, data_dir().join("scene/hall.glb"));
    assert_eq!(back.to_recorded_toml(), recorded);
}

#[test]
fn debug_keys_are_read_but_never_recorded() {
    let c: Config =
        toml::from_str("[debug]\ncaster = \"bvh\"\nbvh_refit = false\noverlap_write = false\nvalidation = true\npeople = \"proxies\"\nkill = \"3:rename-2\"\n").unwrap();
    let kill = Some(KillPoint { sequence: 3, at: crate::debug::KillStage::Rename(2) });
    assert_eq!(c.debug, DebugConfig { caster: Caster::Bvh, bvh_refit: false, overlap_write: false, validation: true, people: PeoplePath::Proxies, kill });
    assert!(c.to_toml().contains("[debug]"));
    let recorded = c.to_recorded_toml();
    assert!(!recorded.contains("debug") && !recorded.contains("caster"), "{recorded}");
    assert_eq!(recorded, Config::default().to_recorded_toml());
    assert!(toml::from_str::<Config>("[debug]\ncaster = \"embree\"\n").is_err());
    assert!(toml::from_str::<Config>("[debug]\npeople = \"gpu\"\n").is_err());
    // `debug.kill` is read through its text form (`crate::debug`'s tests hold every case).
    for bad in ["1", "1:frame-x"] {
        let e = toml::from_str::<Config>(&format!("[debug]\nkill = \"{bad}\"\n")).unwrap_err();
        assert!(e.to_string().contains("S:frame-K"), "{bad}: {e}");
    }
}

#[test]
fn an_ouster_captures_metadata_is_recorded_only_when_given_and_hashed_either_way() {
    // Unset, it is left out of the record: every earlier run's hash stays the same.
    assert!(!Config::default().to_recorded_toml().contains("ouster_metadata"));
    let d = tempfile::tempdir().unwrap();
    let (pcap, beside, given) = (d.path().join("x.pcap"), d.path().join("x.json"), d.path().join("meta.json"));
    std::fs::write(&pcap, b"capture").unwrap();
    let mut c = Config::default();
    c.humans.count = [0, 0];
    c.scene.background = pcap.clone();
    let names = |c: &Config| {
        let mut n = c.input_digests().unwrap().into_iter().map(|(n, _)| n).collect::<Vec<_>>();
        n.sort();
        n
    };
    let path = |p: &Path| p.display().to_string();
    assert_eq!(names(&c), [path(&pcap)]);
    // The JSON beside the capture is read, so it is an input; one given instead replaces it.
    std::fs::write(&beside, b"{}").unwrap();
    assert_eq!(names(&c), [path(&beside), path(&pcap)]);
    std::fs::write(&given, b"{}").unwrap();
    let flags = crate::config::flags::Flags { ouster_metadata: Some(given.clone()), ..Default::default() };
    assert_eq!(flags.config().unwrap().scene.ouster_metadata, given);
    c.scene.ouster_metadata = given.clone();
    assert_eq!(names(&c), [path(&given), path(&pcap)]);
    assert!(c.to_recorded_toml().contains(&format!("ouster_metadata = \"{}\"", given.display())));
    // A sensor given as Ouster metadata is an input too.
    c.sensor = path(&given);
    assert!(c.to_recorded_toml().contains(&format!("sensor = \"{}\"", given.display())));
}

#[test]
fn the_sensor_height_flag_replaces_the_key_and_refuses_what_is_no_height() {
    use crate::config::flags::Flags;
    let at = |h: f64| Flags { sensor_height: Some(h), ..Default::default() }.config();
    assert_eq!(Config::default().scene.sensor_height_m, 0.8);
    assert_eq!(at(2.33).unwrap().scene.sensor_height_m, 2.33);
    for h in [f64::NAN, f64::INFINITY, 1e4, -1.0, 0.0] {
        let e = at(h).unwrap_err().to_string();
        assert!(e.contains("--sensor-height"), "{e}");
    }
}

#[test]
fn the_host_share_is_recorded_only_when_set_and_bounded() {
    // The default is left out of the record: every earlier run's hash stays the same.
    assert!(!Config::default().to_recorded_toml().contains("host_cast_beams"));
    let c: Config = toml::from_str("[render]\nhost_cast_beams = 0\n").unwrap();
    assert_eq!(c.render.host_cast_beams, 0);
    c.validate().unwrap();
    let recorded = c.to_recorded_toml();
    assert!(recorded.contains("host_cast_beams = 0"), "{recorded}");
    let back = toml::from_str::<Config>(&recorded).unwrap();
    assert_eq!(back.render.host_cast_beams, 0);
    assert_eq!(back.to_recorded_toml(), recorded);
    let mut c = Config::default();
    c.render.host_cast_beams = u64::MAX;
    let e = c.validate().unwrap_err();
    assert!(e.is_input() && e.to_string().contains("render.host_cast_beams"), "{e}");
}

#[test]
fn projection_is_a_render_key() {
    let c: Config = toml::from_str("[render]\nprojection = \"cylinder\"\n").unwrap();
    assert_eq!(c.render.projection, Projection::Cylinder);
    assert_eq!(Config::default().render.projection, Projection::Beams);
    let c: Config = toml::from_str("[render]\nprojection = \"beams\"\n").unwrap();
    assert_eq!(c.render.projection, Projection::Beams);
    assert!(toml::from_str::<Config>("[render]\nprojection = \"sphere\"\n").is_err());
}

#[test]
fn unknown_keys_and_impossible_values_are_rejected() {
    let e = toml::from_str::<Config>("frames = 3\nfrmaes = 4\n").unwrap_err();
    assert!(e.to_string().contains("frmaes"), "{e}");
    let mut c = Config::default();
    c.humans.count = [5, 2];
    let e = c.validate().unwrap_err();
    assert!(e.is_input() && e.to_string().contains("humans.count"), "{e}");
    let mut c = Config::default();
    c.frames = 0;
    assert!(c.validate().unwrap_err().to_string().contains("frames"));
    // Sequence indices that would wrap round (u64::MAX + 2 was 1: nothing written), or reach
    // past a billion; the last index itself is taken.
    for (first, n) in [(usize::MAX, 2), (usize::MAX - 1, 3), (MAX_SEQUENCE_INDEX, 2)] {
        let mut c = Config::default();
        (c.first_sequence, c.sequences) = (first, n);
        let e = c.validate().unwrap_err();
        assert!(e.is_input() && e.to_string().contains("first_sequence"), "{first} + {n}: {e}");
    }
    let mut c = Config::default();
    (c.first_sequence, c.sequences) = (MAX_SEQUENCE_INDEX, 1);
    c.validate().unwrap();
    let mut c = Config::default();
    c.scene.sensor_speed_mps = [-1.0, 1.0];
    assert!(c.validate().unwrap_err().to_string().contains("sensor_speed_mps"));
    // The street's shares of lots: each in 0..1, markets and side streets together too; side
    // streets recorded only when asked for (every earlier run's hash stays the same).
    assert!(!Config::default().to_recorded_toml().contains("side_streets"));
    let c: Config = toml::from_str("[scene]\nside_streets = 0.2\n").unwrap();
    let recorded = c.to_recorded_toml();
    assert!(recorded.contains("side_streets = 0.2"), "{recorded}");
    assert_eq!(toml::from_str::<Config>(&recorded).unwrap().scene.side_streets, 0.2);
    for (markets, side_streets, ok) in [(0.1, -0.1, false), (0.1, f64::NAN, false), (0.0, 1.5, false), (0.6, 0.5, false), (0.5, 0.5, true), (0.0, 1.0, true)] {
        let mut c = Config::default();
        (c.scene.markets, c.scene.side_streets) = (markets, side_streets);
        match c.validate() {
            Ok(()) => assert!(ok, "{markets} + {side_streets} taken"),
            Err(e) => assert!(!ok && e.is_input() && e.to_string().contains("scene.side_streets"), "{markets} + {side_streets}: {e}"),
        }
    }
    let mut c = Config::default();
    c.humans.speed_mps = [f64::NAN, 1.0];
    assert!(c.validate().is_err());
    // Clothes thicker than 15 cm, unordered or NaN are no clothes.
    for clothes in [[0.0, 0.2], [0.05, 0.01], [f64::NAN, 0.05], [-0.01, 0.05]] {
        let mut c = Config::default();
        c.humans.clothes_m = clothes;
        let e = c.validate().unwrap_err();
        assert!(e.is_input() && e.to_string().contains("humans.clothes_m"), "{clothes:?}: {e}");
    }
    // The track transform within its documented ranges only (a scale of 1e308 sent every
    // track position to infinity).
    let mut c = Config::default();
    c.humans.tracks_transform.scale = 1e308;
    let e = c.validate().unwrap_err();
    assert!(e.is_input() && e.to_string().contains("humans.tracks_transform") && e.to_string().contains("1e308"), "{e}");
    // The sensor model: each impossible term named by its key.
    let e = toml::from_str::<Config>("[sensor_model]
range_noise = 0.1
").unwrap_err();
    assert!(e.to_string().contains("range_noise"), "{e}");
    let bad: [(&str, fn(&mut SensorModelConfig)); 8] = [
        ("range_noise_m", |m| m.range_noise_m = f64::NAN),
        ("laser_bias_m", |m| m.laser_bias_m = 2.0),
        ("dropout_rate", |m| m.dropout_rate = 1.5),
        ("divergence_mrad", |m| m.divergence_mrad = [-1.0, 1.0]),
        ("divergence_mrad", |m| m.divergence_mrad = [f64::NAN, 1.5]),
        ("divergence_mrad", |m| m.divergence_mrad = [1.5, f64::NAN]),
        ("skin_reflectance", |m| m.skin_reflectance = [0.2, 1.2]),
        ("intensity_scale", |m| m.intensity_scale = Some(0.0)),
    ];
    for (key, spoil) in bad {
        let mut c = Config::default();
        spoil(&mut c.sensor_model);
        let e = c.validate().unwrap_err();
        assert!(e.is_input() && e.to_string().contains(&format!("sensor_model.{key}")), "{key}: {e}");
    }
}

#[test]
fn a_scenes_options_reach_the_recording() {
    let mut scene = Config::default().scene;
    let none = scene.recording_options();
    assert!(none.poses.is_none() && none.ouster_metadata.is_none());
    assert!(none.bag.topic.is_none() && none.bag.world_frame.is_none() && none.bag.poses_topic.is_none());
    scene.poses = "p.txt".into();
    scene.ouster_metadata = "m.json".into();
    scene.topic = "/points".into();
    scene.world_frame = "map".into();
    scene.poses_topic = "/odom".into();
    let o = scene.recording_options();
    assert_eq!((o.poses, o.ouster_metadata), (Some(Path::new("p.txt")), Some(Path::new("m.json"))));
    assert_eq!((o.bag.topic.as_deref(), o.bag.world_frame.as_deref(), o.bag.poses_topic.as_deref()), (Some("/points"), Some("map"), Some("/odom")));
}
