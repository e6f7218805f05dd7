//! Integration tests of the output writers: HDF5 round trip, atomicity, reproducibility,
//! XML consistency, PNGs and `info`.

use pedscan::output::{
    info, Compression, FrameOutput, HumanMeta, HumanState, OutputSet, SequenceMeta, SequenceWriter,
    WriterOptions,
};
use pedscan::sensor::Sensor;
use std::path::{Path, PathBuf};

fn tiny_sensor() -> Sensor {
    Sensor {
        name: "tiny".into(),
        elevation_deg: vec![3.0, 1.0, -1.0, -3.0],
        columns: 16,
        rate_hz: 10.0,
        min_range_m: 0.5,
        max_range_m: 100.0,
    }
}

fn meta(index: usize, frames: usize, humans: usize, outputs: OutputSet) -> SequenceMeta {
    SequenceMeta {
        index,
        seed: 0xDEAD_BEEF_1234,
        sensor: tiny_sensor(),
        config_toml: "[scene]\nname = \"t<e>st & \\\"x\\\"\"\n".into(),
        frames,
        humans: (0..humans)
            .map(|k| HumanMeta {
                height_m: 1.6 + 0.1 * k as f32,
                weight_kg: 60.0 + 5.0 * k as f32,
                model: if k == 0 { "h1700_w60".into() } else { format!("odd<&\"'>{k}") },
                seat_m: (k == 1).then_some(0.45),
                pushing: None,
            })
            .collect(),
        movers: Vec::new(),
        outputs,
        rigid_velocity: false,
        provenance: vec![("background".into(), "recording <a&b>.pcap".into()), ("first_frame".into(), "7".into())],
    }
}

/// A deterministic frame: instance k occupies columns 2k..2k+2 of rows 1..3 when visible;
/// human 2 (if any) is hidden in odd frames.
fn frame(m: &SequenceMeta, t: usize) -> FrameOutput {
    let (rows, cols) = (m.sensor.rows(), m.sensor.columns);
    let n = rows * cols;
    let mut f = FrameOutput {
        range: vec![0.0; n],
        label: vec![0; n],
        instance: vec![0; n],
        intensity: (0..n).map(|i| (i % 13) as f32 * 0.05).collect(),
        column_time_s: (0..cols).map(|c| t as f64 * 0.1 + 0.1 * (c as f64 + 0.5) / cols as f64).collect(),
        time_s: t as f64 * 0.1,
        world_from_sensor: [
            [1.0, 0.0, 0.0, t as f64],
            [0.0, 1.0, 0.0, 2.0],
            [0.0, 0.0, 1.0, 1.8],
            [0.0, 0.0, 0.0, 1.0],
        ],
        ..Default::default()
    };
    for i in 0..n {
        // Leave a few no-returns.
        if i % 7 != 3 {
            f.range[i] = 5.0 + i as f32 * 0.25 + t as f32;
        }
    }
    for k in 1..=m.humans.len() {
        if k == 2 && t % 2 == 1 {
            continue;
        }
        for r in 1..3 {
            for c in 2 * k..2 * k + 2 {
                let i = r * cols + c;
                f.range[i] = 3.0 + k as f32;
                f.label[i] = 1;
                f.instance[i] = k as u16;
            }
        }
    }
    if m.outputs.xyz {
        f.xyz = (0..n).map(|i| [f.range[i], i as f32, -(t as f32)]).collect();
    }
    if m.outputs.velocity {
        f.velocity = (0..n).map(|i| [0.5, (i % 5) as f32 - 2.0, 0.0]).collect();
    }
    if m.outputs.background {
        f.background_range =
            (0..n).map(|i| if i % 7 != 3 { 20.0 + i as f32 } else { 0.0 }).collect();
    }
    f.humans = (0..m.humans.len())
        .map(|k| HumanState {
            position_m: [k as f64, t as f64 * 0.13, 0.0],
            heading_rad: 0.5 * k as f32,
            velocity_mps: [1.2, 0.1 * k as f32, 0.0],
            gait_phase: (t as f32 * 0.1 + 0.25 * k as f32).fract(),
        })
        .collect();
    f
}

fn write_seq(dir: &Path, m: &SequenceMeta, opts: &WriterOptions) -> Vec<PathBuf> {
    let mut w = SequenceWriter::create(dir, m, opts).unwrap();
    for t in 0..m.frames {
        w.write_frame(&frame(m, t)).unwrap();
    }
    w.finish().unwrap().files
}

fn dir_names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn read_str_attr(f: &hdf5::File, k: &str) -> String {
    f.attr(k).unwrap().read_scalar::<hdf5::types::VarLenUnicode>().unwrap().as_str().to_string()
}

fn check_roundtrip(compression: Compression, humans: usize) {
    let dir = tempfile::tempdir().unwrap();
    let m = meta(3, 3, humans, OutputSet::default());
    let paths = write_seq(dir.path(), &m, &WriterOptions { png: false, compression, ..Default::default() });
    assert_eq!(paths, vec![dir.path().join("seq_000003.h5"), dir.path().join("seq_000003.xml")]);
    assert_eq!(dir_names(dir.path()), vec!["seq_000003.h5", "seq_000003.xml"]);

    let f = hdf5::File::open(&paths[0]).unwrap();
    let (t, h, w, n) = (3, 4, 16, humans);
    let frames: Vec<FrameOutput> = (0..t).map(|i| frame(&m, i)).collect();
    let cat =
        |g: &dyn Fn(&FrameOutput) -> Vec<f32>| frames.iter().flat_map(g).collect::<Vec<f32>>();

    let range = f.dataset("range").unwrap();
    assert_eq!(range.shape(), vec![t, h, w]);
    assert_eq!(range.chunk(), Some(vec![1, h, w]));
    assert_eq!(range.read_raw::<f32>().unwrap(), cat(&|f| f.range.clone()));
    let xyz = f.dataset("xyz").unwrap();
    assert_eq!(xyz.shape(), vec![t, h, w, 3]);
    assert_eq!(xyz.read_raw::<f32>().unwrap(), cat(&|f| f.xyz.iter().flatten().copied().collect()));
    let vel = f.dataset("velocity").unwrap();
    assert_eq!(vel.shape(), vec![t, h, w, 3]);
    assert_eq!(
        vel.read_raw::<f32>().unwrap(),
        cat(&|f| f.velocity.iter().flatten().copied().collect())
    );
    let bg = f.dataset("background/range").unwrap();
    assert_eq!(bg.shape(), vec![t, h, w]);
    assert_eq!(bg.read_raw::<f32>().unwrap(), cat(&|f| f.background_range.clone()));
    let label = f.dataset("label").unwrap();
    assert_eq!(label.shape(), vec![t, h, w]);
    let lab: Vec<u8> = frames.iter().flat_map(|f| f.label.clone()).collect();
    assert_eq!(label.read_raw::<u8>().unwrap(), lab);
    let inst: Vec<u16> = frames.iter().flat_map(|f| f.instance.clone()).collect();
    assert_eq!(f.dataset("instance").unwrap().read_raw::<u16>().unwrap(), inst);
    for name in ["range", "xyz", "label", "instance", "velocity", "background/range"] {
        let ds = f.dataset(name).unwrap();
        let units = read_str_attr_ds(&ds, "units");
        assert!(!units.is_empty(), "{name}");
        assert!(!read_str_attr_ds(&ds, "description").is_empty(), "{name}");
        let filters = ds.filters();
        match compression {
            Compression::None => assert!(filters.is_empty(), "{name}: {filters:?}"),
            Compression::Deflate(l) => {
                assert_eq!(filters.len(), 2, "{name}: {filters:?}");
                assert_eq!(filters[0], hdf5::filters::Filter::Shuffle);
                assert_eq!(filters[1], hdf5::filters::Filter::Deflate(l));
            }
        }
    }

    let ts = f.dataset("sensor/time_s").unwrap().read_raw::<f64>().unwrap();
    assert_eq!(ts, vec![0.0, 0.1, 0.2]);
    let pose = f.dataset("sensor/world_from_sensor").unwrap();
    assert_eq!(pose.shape(), vec![t, 4, 4]);
    let pose = pose.read_raw::<f64>().unwrap();
    assert_eq!(pose[16 * 2 + 3], 2.0);
    assert_eq!(pose[16 + 7], 2.0);
    let el = f.dataset("sensor/elevation_deg").unwrap().read_raw::<f32>().unwrap();
    assert_eq!(el, vec![3.0, 1.0, -1.0, -3.0]);
    let az = f.dataset("sensor/azimuth_deg").unwrap().read_raw::<f32>().unwrap();
    assert_eq!(az.len(), w);
    assert!((az[0] - (180.0 - 180.0 / 16.0)).abs() < 1e-4, "{}", az[0]);

    let hg = f.group("humans").unwrap();
    assert_eq!(hg.dataset("height_m").unwrap().shape(), vec![n]);
    assert_eq!(
        hg.dataset("weight_kg").unwrap().read_raw::<f32>().unwrap(),
        m.humans.iter().map(|h| h.weight_kg).collect::<Vec<_>>()
    );
    let models = hg.dataset("model").unwrap();
    assert_eq!(models.shape(), vec![n]);
    if n > 0 {
        let models = models.read_raw::<hdf5::types::VarLenUnicode>().unwrap();
        assert_eq!(models[1].as_str(), m.humans[1].model);
    }
    assert_eq!(hg.dataset("position_m").unwrap().shape(), vec![t, n, 3]);
    assert_eq!(hg.dataset("velocity_mps").unwrap().shape(), vec![t, n, 3]);
    assert_eq!(hg.dataset("heading_rad").unwrap().shape(), vec![t, n]);
    assert_eq!(hg.dataset("gait_phase").unwrap().shape(), vec![t, n]);
    let pos = hg.dataset("position_m").unwrap().read_raw::<f64>().unwrap();
    let want: Vec<f64> =
        frames.iter().flat_map(|f| f.humans.iter().flat_map(|h| h.position_m)).collect();
    assert_eq!(pos, want);
    let phase = hg.dataset("gait_phase").unwrap().read_raw::<f32>().unwrap();
    let want: Vec<f32> =
        frames.iter().flat_map(|f| f.humans.iter().map(|h| h.gait_phase)).collect();
    assert_eq!(phase, want);

    assert_eq!(read_str_attr(&f, "sensor"), "tiny");
    assert_eq!(read_str_attr(&f, "config"), m.config_toml);
    assert_eq!(read_str_attr(&f, "pedscan_version"), pedscan::version());
    assert_eq!(f.attr("seed").unwrap().read_scalar::<u64>().unwrap(), m.seed);
    assert_eq!(f.attr("frames").unwrap().read_scalar::<u64>().unwrap(), 3);
    assert_eq!(f.attr("rows").unwrap().read_scalar::<u64>().unwrap(), 4);
    assert_eq!(f.attr("columns").unwrap().read_scalar::<u64>().unwrap(), 16);
}

fn read_str_attr_ds(ds: &hdf5::Dataset, k: &str) -> String {
    ds.attr(k).unwrap().read_scalar::<hdf5::types::VarLenUnicode>().unwrap().as_str().to_string()
}

#[test]
fn roundtrip_deflate_two_humans() {
    check_roundtrip(Compression::Deflate(1), 2);
}

#[test]
fn roundtrip_uncompressed_two_humans() {
    check_roundtrip(Compression::None, 2);
}

#[test]
fn roundtrip_no_humans() {
    check_roundtrip(Compression::Deflate(6), 0);
}

#[test]
fn optional_outputs_absent_when_disabled() {
    let dir = tempfile::tempdir().unwrap();
    let m = meta(0, 2, 1, OutputSet { xyz: false, velocity: false, background: false, clean: false, class: false });
    let paths = write_seq(dir.path(), &m, &WriterOptions { png: true, ..Default::default() });
    let f = hdf5::File::open(&paths[0]).unwrap();
    assert!(f.dataset("range").is_ok());
    assert!(f.dataset("label").is_ok());
    assert!(f.dataset("instance").is_ok());
    assert!(f.dataset("xyz").is_err());
    assert!(f.dataset("velocity").is_err());
    assert!(f.group("background").is_err());
    // No velocity PNGs without velocity.
    let pngs = dir_names(&paths[2]);
    assert_eq!(
        pngs,
        vec!["bev_0000.png", "bev_0001.png", "intensity_0000.png", "intensity_0001.png", "label_0000.png", "label_0001.png", "range_0000.png", "range_0001.png"]
    );
    assert!(f.group("clean").is_err(), "no /clean without the sensor model");
}

#[test]
fn pngs_exist_decode_and_have_the_scaled_size() {
    let dir = tempfile::tempdir().unwrap();
    let m = meta(7, 2, 2, OutputSet::default());
    let paths = write_seq(dir.path(), &m, &WriterOptions { png: true, ..Default::default() });
    assert_eq!(paths[2], dir.path().join("seq_000007_png"));
    assert_eq!(dir_names(dir.path()), vec!["seq_000007.h5", "seq_000007.xml", "seq_000007_png"]);
    let names = dir_names(&paths[2]);
    assert_eq!(names.len(), 10, "{names:?}");
    // The grid at 4 pixels per row; range and velocity with their legend strip below.
    let legend = pedscan::output::png::LEGEND_H;
    let side = pedscan::output::png::BEV_SIDE;
    for (kind, size) in [
        ("range", (16, 4 * 4 + legend)),
        ("label", (16, 4 * 4)),
        ("intensity", (16, 4 * 4)),
        ("velocity", (16, 4 * 4 + legend)),
        ("bev", (side, side)),
    ] {
        for t in 0..2 {
            let p = paths[2].join(format!("{kind}_{t:04}.png"));
            let img = image::open(&p).unwrap().to_rgb8();
            assert_eq!(img.dimensions(), size, "{}", p.display());
        }
    }
    // Rerun into the same directory replaces the set cleanly.
    let paths2 = write_seq(dir.path(), &m, &WriterOptions { png: true, ..Default::default() });
    assert_eq!(paths, paths2);
    assert_eq!(dir_names(dir.path()), vec!["seq_000007.h5", "seq_000007.xml", "seq_000007_png"]);
}

#[test]
fn temp_files_exist_during_and_vanish_after_finish() {
    let dir = tempfile::tempdir().unwrap();
    let m = meta(1, 2, 1, OutputSet::default());
    let mut w =
        SequenceWriter::create(dir.path(), &m, &WriterOptions { png: true, ..Default::default() })
            .unwrap();
    w.write_frame(&frame(&m, 0)).unwrap();
    assert_eq!(
        dir_names(dir.path()),
        vec!["seq_000001.h5.tmp", "seq_000001.xml.tmp", "seq_000001_png.tmp"]
    );
    w.write_frame(&frame(&m, 1)).unwrap();
    w.finish().unwrap();
    assert_eq!(dir_names(dir.path()), vec!["seq_000001.h5", "seq_000001.xml", "seq_000001_png"]);
}

#[test]
fn dropped_writer_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let m = meta(2, 4, 2, OutputSet::default());
    {
        let mut w = SequenceWriter::create(
            dir.path(),
            &m,
            &WriterOptions { png: true, ..Default::default() },
        )
        .unwrap();
        w.write_frame(&frame(&m, 0)).unwrap();
        w.write_frame(&frame(&m, 1)).unwrap();
        // An error mid-sequence: the caller bails out with `?` and the writer is dropped.
    }
    assert!(dir_names(dir.path()).is_empty(), "{:?}", dir_names(dir.path()));
}

/// A bag whose own finish fails (its metadata cannot be written, as on a full disk) leaves
/// no temporary behind, nor the exports finished before it.
#[test]
fn a_failing_bag_finish_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let m = meta(3, 2, 2, OutputSet::default());
    let opts = WriterOptions { semantickitti: true, mcap: true, ..Default::default() };
    let mut w = SequenceWriter::create(dir.path(), &m, &opts).unwrap();
    w.write_frame(&frame(&m, 0)).unwrap();
    w.write_frame(&frame(&m, 1)).unwrap();
    std::fs::create_dir_all(dir.path().join("seq_000003_bag.tmp/metadata.yaml")).unwrap();
    let e = w.finish().unwrap_err();
    assert!(e.to_string().contains("metadata.yaml"), "{e}");
    // The SemanticKITTI tree's empty folders may stay (other sequences share them).
    let left: Vec<_> = walkdir(dir.path()).into_iter().filter(|p| !p.is_dir()).collect();
    assert!(left.is_empty(), "{left:?}");
    assert!(!dir.path().join("seq_000003_bag.tmp").exists() && !dir.path().join("seq_000003_bag").exists());
}

/// Every path under `dir`.
fn walkdir(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walkdir(&p));
        }
        out.push(p);
    }
    out
}

#[test]
fn bad_frames_are_internal_errors_and_early_finish_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let m = meta(4, 3, 2, OutputSet::default());
    let mut w = SequenceWriter::create(dir.path(), &m, &WriterOptions::default()).unwrap();
    let mut f = frame(&m, 0);
    f.range.pop();
    let e = w.write_frame(&f).unwrap_err();
    assert!(matches!(e, pedscan::Error::Internal(_)), "{e}");
    let mut f = frame(&m, 0);
    f.humans.pop();
    assert!(matches!(w.write_frame(&f).unwrap_err(), pedscan::Error::Internal(_)));
    let mut f = frame(&m, 0);
    f.instance[0] = 3;
    assert!(matches!(w.write_frame(&f).unwrap_err(), pedscan::Error::Internal(_)));
    w.write_frame(&frame(&m, 0)).unwrap();
    let e = w.finish().unwrap_err();
    assert!(matches!(e, pedscan::Error::Internal(_)), "{e}");
    assert!(dir_names(dir.path()).is_empty(), "{:?}", dir_names(dir.path()));
}

#[test]
fn reruns_are_bit_identical() {
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    let m = meta(5, 3, 2, OutputSet::default());
    let opts = WriterOptions { png: true, compression: Compression::Deflate(1), ..Default::default() };
    let pa = write_seq(a.path(), &m, &opts);
    // HDF5 timestamps have one-second resolution: make sure a clock tick separates the runs.
    std::thread::sleep(std::time::Duration::from_millis(1100));
    let pb = write_seq(b.path(), &m, &opts);
    for (x, y) in pa.iter().zip(&pb).take(2) {
        assert_eq!(std::fs::read(x).unwrap(), std::fs::read(y).unwrap(), "{}", x.display());
    }
    for name in dir_names(&pa[2]) {
        assert_eq!(
            std::fs::read(pa[2].join(&name)).unwrap(),
            std::fs::read(pb[2].join(&name)).unwrap(),
            "{name}"
        );
    }
}

#[test]
fn xml_is_well_formed_and_matches_the_frames() {
    use quick_xml::events::Event;
    let dir = tempfile::tempdir().unwrap();
    let m = meta(9, 3, 2, OutputSet::default());
    let paths = write_seq(dir.path(), &m, &WriterOptions::default());
    let text = std::fs::read_to_string(&paths[1]).unwrap();
    let mut r = quick_xml::Reader::from_str(&text);
    let attr = |e: &quick_xml::events::BytesStart, k: &str| -> String {
        let a = e.try_get_attribute(k).unwrap().unwrap_or_else(|| panic!("attribute {k}"));
        a.normalized_value(quick_xml::XmlVersion::Explicit1_0).unwrap().into_owned()
    };
    let mut frames_seen = 0;
    let mut in_frame: Option<usize> = None;
    let mut beams_in_frame: Vec<u32> = Vec::new();
    let mut models = Vec::new();
    let mut depth = 0;
    let mut provenance = 0;
    let mut seated = Vec::new();
    loop {
        let ev = r.read_event().unwrap();
        let (e, empty) = match &ev {
            Event::Start(e) => (e.clone(), false),
            Event::Empty(e) => (e.clone(), true),
            Event::End(e) => {
                depth -= 1;
                if e.name().into_inner() == "frame" {
                    let t = in_frame.take().unwrap();
                    let f = frame(&m, t);
                    let want: Vec<u32> = (1..=2u16)
                        .map(|k| f.instance.iter().filter(|&&i| i == k).count() as u32)
                        .collect();
                    assert_eq!(beams_in_frame, want, "frame {t}");
                    beams_in_frame.clear();
                }
                continue;
            }
            Event::Eof => break,
            _ => continue,
        };
        if !empty {
            depth += 1;
        }
        match e.name().into_inner() {
            "sequence" => {
                assert_eq!(attr(&e, "index"), "9");
                assert_eq!(attr(&e, "frames"), "3");
                assert_eq!(attr(&e, "sensor"), "tiny");
                assert_eq!(attr(&e, "seed"), m.seed.to_string());
            }
            "frame" => {
                let t: usize = attr(&e, "index").parse().unwrap();
                assert_eq!(t, frames_seen);
                frames_seen += 1;
                let f = frame(&m, t);
                assert_eq!(attr(&e, "humans"), "2");
                let visible = (1..=2u16).filter(|k| f.instance.contains(k)).count();
                assert_eq!(attr(&e, "visible_humans"), visible.to_string(), "frame {t}");
                assert_eq!(attr(&e, "time_s"), format!("{:.6}", f.time_s));
                in_frame = Some(t);
            }
            "human" => {
                if let Some(t) = in_frame {
                    let k: usize = attr(&e, "id").parse().unwrap();
                    let f = frame(&m, t);
                    let x: f64 = attr(&e, "y").parse().unwrap();
                    assert!((x - f.humans[k - 1].position_m[1]).abs() < 1e-3);
                    let v = f.humans[k - 1].velocity_mps.map(|c| c as f64);
                    let speed: f64 = attr(&e, "speed_mps").parse().unwrap();
                    assert!((speed - v[0].hypot(v[1]).hypot(v[2])).abs() <= 5e-4, "speed of person {k}: {speed}");
                    assert_eq!(attr(&e, "height_m"), format!("{:.3}", m.humans[k - 1].height_m));
                    beams_in_frame.push(attr(&e, "beams").parse().unwrap());
                } else {
                    models.push(attr(&e, "model"));
                    // Seated people say on what (`humans.sitting`), the others nothing.
                    seated.push(e.try_get_attribute("seated_m").unwrap().map(|_| attr(&e, "seated_m")));
                }
            }
            "provenance" => {
                provenance += 1;
                // Escaped on write, unescaped on read: the values round-trip.
                assert_eq!(attr(&e, "background"), "recording <a&b>.pcap");
                assert_eq!(attr(&e, "first_frame"), "7");
            }
            other => panic!("unexpected element {:?}", other),
        }
    }
    assert_eq!(depth, 0);
    assert_eq!(frames_seen, 3);
    assert_eq!(provenance, 1, "one <provenance> element");
    assert_eq!(models, m.humans.iter().map(|h| h.model.clone()).collect::<Vec<_>>());
    assert_eq!(seated, [None, Some("0.450".to_string())]);
}

#[test]
fn info_summarises_a_sequence() {
    let dir = tempfile::tempdir().unwrap();
    let m = meta(3, 3, 2, OutputSet::default());
    let paths = write_seq(dir.path(), &m, &WriterOptions::default());
    let s = info(&paths[0]).unwrap();
    for want in [
        "frames:    3",
        "4 rows x 16 columns",
        "tiny",
        "h1700_w60",
        "/xyz",
        "Deflate(1)",
        "median",
        "human:",
    ] {
        assert!(s.contains(want), "missing {want:?} in\n{s}");
    }
    // The numbers, from the frames written: returns, human beams, the median range (the
    // ceil(n/2)-th smallest return, reported at the centre of its 1 cm bin), the extremes,
    // and the range's compression ratio from the file's own storage size.
    let frames: Vec<FrameOutput> = (0..3).map(|t| frame(&m, t)).collect();
    let mut ranges: Vec<f32> = frames.iter().flat_map(|f| f.range.iter().copied()).filter(|&r| r > 0.0).collect();
    ranges.sort_by(f32::total_cmp);
    let beams = 3 * 4 * 16;
    let human: usize = frames.iter().map(|f| f.label.iter().filter(|&&l| l == 1).count()).sum();
    assert!(human > 0 && human < ranges.len());
    let returns = ranges.len();
    let pct = |a: usize, b: usize| 100.0 * a as f64 / b as f64;
    let median = ((ranges[returns.div_ceil(2) - 1] as f64 / 0.01).floor() + 0.5) * 0.01;
    let stored = hdf5::File::open(&paths[0]).unwrap().dataset("range").unwrap().storage_size();
    let ratio = (beams * 4) as f64 / stored as f64;
    for want in [
        format!("returns:   {returns} of {beams} beams ({:.1} %)", pct(returns, beams)),
        format!("human:     {human} beams ({:.3} % of beams, {:.3} % of returns)", pct(human, beams), pct(human, returns)),
        format!("range:     min {:.3} m, median {median:.2} m, max {:.3} m", ranges[0], ranges[returns - 1]),
        format!("({} stored, {ratio:.2}x)", if stored < 1024 { format!("{stored} B") } else { format!("{:.1} KiB", stored as f64 / 1024.0) }),
    ] {
        assert!(s.contains(&want), "missing {want:?} in\n{s}");
    }
}

#[test]
fn info_rejects_missing_garbage_and_foreign_files() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope.h5");
    let e = info(&missing).unwrap_err();
    assert!(e.is_input() && e.to_string().contains("nope.h5"), "{e}");

    let garbage = dir.path().join("garbage.h5");
    std::fs::write(&garbage, b"this is not an HDF5 file at all, just some bytes\n").unwrap();
    let e = info(&garbage).unwrap_err();
    assert!(e.is_input() && e.to_string().contains("garbage.h5"), "{e}");

    let foreign = dir.path().join("foreign.h5");
    {
        let f = hdf5::File::create(&foreign).unwrap();
        f.new_dataset::<f32>().shape([3]).create("other").unwrap();
    }
    let e = info(&foreign).unwrap_err();
    assert!(e.is_input() && e.to_string().contains("/range"), "{e}");

    // A truncated real file.
    let m = meta(0, 2, 1, OutputSet::default());
    let paths = write_seq(dir.path(), &m, &WriterOptions::default());
    let bytes = std::fs::read(&paths[0]).unwrap();
    let cut = dir.path().join("cut.h5");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = info(&cut).unwrap_err();
    assert!(e.to_string().contains("cut.h5"), "{e}");
}

/// A bag's clouds beam by beam against the frames written, reading the CDR by the
/// PointCloud2 layout the bag declares (ROS 2's sensor_msgs definition): x, y, z, intensity,
/// ring (0 = lowest beam), instance, time from the frame's stamp, velocity, label; a beam
/// without a return is NaN with zero velocity; `is_dense` only when every beam returned.
#[test]
fn a_bags_points_hold_each_beam_of_the_frames() {
    let dir = tempfile::tempdir().unwrap();
    let m = meta(0, 2, 2, OutputSet::default());
    let opts = WriterOptions { h5: false, mcap: true, png: false, ..Default::default() };
    let mut frames = vec![frame(&m, 0), frame(&m, 1)];
    for r in frames[1].range.iter_mut() {
        if *r <= 0.0 {
            *r = 42.0;
        }
    }
    let mut w = SequenceWriter::create(dir.path(), &m, &opts).unwrap();
    for f in &frames {
        w.write_frame(f).unwrap();
    }
    w.finish().unwrap();
    let bytes = std::fs::read(dir.path().join("seq_000000_bag/seq_000000.mcap")).unwrap();
    let (rows, cols) = (4usize, 16usize);
    let mut seen = 0;
    for msg in mcap::MessageStream::new(&bytes).unwrap() {
        let msg = msg.unwrap();
        if msg.channel.topic != "/pedscan/points" {
            continue;
        }
        let f = &frames[seen];
        seen += 1;
        let d = &msg.data;
        let u32_at = |at: usize| u32::from_le_bytes(d[at..at + 4].try_into().unwrap());
        // After the header (stamp 8 bytes, frame id) and height, width, the fields; the data's
        // length precedes the points, and is_dense follows them.
        let n = rows * cols * 40;
        let start = d.len() - 1 - n;
        assert_eq!(u32_at(start - 4) as usize, n, "the data's length");
        assert_eq!(d[d.len() - 1], (seen == 2) as u8, "is_dense of frame {}", seen - 1);
        for b in 0..rows * cols {
            let p = &d[start + 40 * b..start + 40 * (b + 1)];
            let f32_at = |at: usize| f32::from_le_bytes(p[at..at + 4].try_into().unwrap());
            let u16_at = |at: usize| u16::from_le_bytes(p[at..at + 2].try_into().unwrap());
            let returned = f.range[b] > 0.0;
            for k in 0..3 {
                let want = if returned { f.xyz[b][k] } else { f32::NAN };
                assert_eq!(f32_at(4 * k).to_bits(), want.to_bits(), "beam {b} coordinate {k}");
                let v = if returned { f.velocity[b][k] } else { 0.0 };
                assert_eq!(f32_at(24 + 4 * k), v, "beam {b} velocity {k}");
            }
            assert_eq!(f32_at(12), f.intensity[b], "beam {b} intensity");
            assert_eq!(u16_at(16) as usize, rows - 1 - b / cols, "beam {b} ring");
            assert_eq!(u16_at(18), f.instance[b], "beam {b} instance");
            assert_eq!(f32_at(20), (f.column_time_s[b % cols] - f.time_s) as f32, "beam {b} time");
            assert_eq!(p[36], f.label[b], "beam {b} label");
        }
    }
    assert_eq!(seen, 2);
}

/// What no sequence can be is refused before anything is written: a deflate level past 9, no
/// frames, a grid without rows or without columns, more people than u16 instance ids.
#[test]
fn a_writer_refuses_what_no_sequence_can_be() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let m = meta(0, 2, 1, OutputSet::default());
    let refused = |m: &SequenceMeta, opts: &WriterOptions| SequenceWriter::create(&out, m, opts).err().expect("refused");
    let e = refused(&m, &WriterOptions { compression: Compression::Deflate(10), ..Default::default() });
    assert!(e.to_string().contains("deflate level 10"), "{e}");
    assert!(SequenceWriter::create(&out, &m, &WriterOptions { compression: Compression::Deflate(9), ..Default::default() }).is_ok(), "level 9 is deflate's best");
    assert!(refused(&SequenceMeta { frames: 0, ..m.clone() }, &WriterOptions::default()).to_string().contains("at least one frame"));
    let mut no_columns = m.clone();
    no_columns.sensor.columns = 0;
    let mut no_rows = m.clone();
    no_rows.sensor.elevation_deg.clear();
    for bad in [no_columns, no_rows] {
        assert!(matches!(refused(&bad, &WriterOptions::default()), pedscan::Error::Internal(_)));
    }
    let mut crowd = m.clone();
    crowd.humans = vec![m.humans[0].clone(); u16::MAX as usize + 1];
    assert!(refused(&crowd, &WriterOptions::default()).to_string().contains("65536 humans"));
    crowd.humans.pop();
    if let Err(e) = SequenceWriter::create(&out, &crowd, &WriterOptions::default()) {
        panic!("65,535 people fit: {e}");
    }
    assert!(!out.exists() || dir_names(&out).is_empty(), "left in the output folder: {:?}", dir_names(&out));
}

/// The bird's-eye view shows people in the sensor frame however the sensor is turned: under a
/// sensor pitched so that its +x is the world's +z, a person 10 m above the sensor is drawn
/// 10 m ahead (160 px above the centre of the 640 px view, 16 px a metre).
#[test]
fn the_birds_eye_view_takes_people_into_a_tilted_sensors_frame() {
    let dir = tempfile::tempdir().unwrap();
    let m = meta(0, 1, 1, OutputSet::default());
    let mut f = frame(&m, 0);
    let t = [f.world_from_sensor[0][3], f.world_from_sensor[1][3], f.world_from_sensor[2][3]];
    // Columns: the sensor's axes in the world: x -> +z, y -> +y, z -> -x.
    f.world_from_sensor = [[0.0, 0.0, -1.0, t[0]], [0.0, 1.0, 0.0, t[1]], [1.0, 0.0, 0.0, t[2]], [0.0, 0.0, 0.0, 1.0]];
    f.humans[0].position_m = [t[0], t[1], t[2] + 10.0];
    f.humans[0].velocity_mps = [0.0; 3];
    let opts = WriterOptions { png: true, ..Default::default() };
    let mut w = SequenceWriter::create(dir.path(), &m, &opts).unwrap();
    w.write_frame(&f).unwrap();
    w.finish().unwrap();
    let bev = image::open(dir.path().join("seq_000000_png/bev_0000.png")).unwrap().to_rgb8();
    let colour = pedscan::output::png::instance_colour(1);
    assert_eq!(bev.get_pixel(320, 160).0, colour, "the person 10 m ahead");
    assert_ne!(bev.get_pixel(320, 102).0, colour);
}
