//! Synthetic Ouster captures built here, byte by byte, after the layouts of the ouster-sdk's
//! `ouster_core/src/parsing.cpp`; expected points from the closed form of its
//! `ouster_core/src/xyzlut.cpp`, worked out for simple angles.

use super::*;
use crate::input::recording::RecordingOptions;
use crate::input::Recording;
use crate::sensor::Sensor;

/// The usual lidar-to-sensor transform of an OS1: half a turn about z, 36.18 mm up.
const OS1_TRANSFORM: [f64; 16] = [-1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 36.18, 0.0, 0.0, 0.0, 1.0];
const IDENTITY: [f64; 16] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];

/// A small sensor description for the tests.
#[derive(Clone)]
struct Spec {
    profile: Profile,
    w: usize,
    cpp: usize,
    altitude: Vec<f64>,
    azimuth: Vec<f64>,
    origin_mm: f64,
    transform: [f64; 16],
}

impl Spec {
    fn new(profile: Profile, w: usize, cpp: usize, altitude: &[f64]) -> Spec {
        Spec {
            profile,
            w,
            cpp,
            altitude: altitude.to_vec(),
            azimuth: vec![0.0; altitude.len()],
            origin_mm: 0.0,
            transform: IDENTITY,
        }
    }

    fn h(&self) -> usize {
        self.altitude.len()
    }

    /// The flat (firmware 2.x) metadata JSON.
    fn json(&self) -> String {
        let mut v = serde_json::json!({
            "prod_line": "OS-1-16",
            "lidar_mode": format!("{}x10", self.w),
            "data_format": {
                "columns_per_frame": self.w,
                "pixels_per_column": self.h(),
                "columns_per_packet": self.cpp,
                "column_window": [0, self.w - 1],
            },
            "beam_altitude_angles": self.altitude,
            "beam_azimuth_angles": self.azimuth,
            "lidar_origin_to_beam_origin_mm": self.origin_mm,
            "lidar_to_sensor_transform": self.transform,
        });
        if self.profile != Profile::Legacy {
            v["data_format"]["udp_profile_lidar"] = self.profile.name().into();
        }
        v.to_string()
    }

    fn meta(&self) -> OusterMeta {
        OusterMeta::parse(&self.json(), "os.json").unwrap()
    }
}

/// One column of a packet: measurement id, timestamp (ns), valid, and per row the raw range
/// field value and reflectivity.
struct Col {
    m: u16,
    ts: u64,
    valid: bool,
    pixels: Vec<(u32, u8)>,
}

/// A lidar packet of `spec` for frame `frame_id`.
fn packet(spec: &Spec, frame_id: u16, cols: &[Col]) -> Vec<u8> {
    assert_eq!(cols.len(), spec.cpp);
    let mut p = Vec::new();
    let legacy = spec.profile == Profile::Legacy;
    if !legacy {
        let mut header = [0u8; 32];
        header[..2].copy_from_slice(&1u16.to_le_bytes()); // packet type: lidar
        header[2..4].copy_from_slice(&frame_id.to_le_bytes());
        header[4..7].copy_from_slice(&[0x56, 0x34, 0x12]); // init id
        p.extend(header);
    }
    for c in cols {
        p.extend(c.ts.to_le_bytes());
        p.extend(c.m.to_le_bytes());
        if legacy {
            p.extend(frame_id.to_le_bytes());
            p.extend(0u32.to_le_bytes()); // encoder count
        } else {
            p.extend((c.valid as u16).to_le_bytes());
        }
        assert_eq!(c.pixels.len(), spec.h());
        for &(range, refl) in &c.pixels {
            let mut px = vec![0u8; spec.profile.pixel_len()];
            match spec.profile {
                Profile::Legacy => {
                    // Range in the low 20 bits; flags above must be masked off.
                    px[..4].copy_from_slice(&(range | 0xF000_0000).to_le_bytes());
                    px[4] = refl;
                    px[6..8].copy_from_slice(&999u16.to_le_bytes()); // signal
                }
                Profile::Rng19Rfl8Sig16Nir16 => {
                    // Range in bits 0..19, flags 19..24, reflectivity the top byte.
                    px[..4].copy_from_slice(&(range | (0x1F << 19) | ((refl as u32) << 24)).to_le_bytes());
                    px[4..6].copy_from_slice(&999u16.to_le_bytes()); // signal
                }
                Profile::Rng15Rfl8Nir8 => {
                    px[..2].copy_from_slice(&((range as u16) | 0x8000).to_le_bytes());
                    px[2] = refl;
                    px[3] = 77; // near-IR
                }
            }
            p.extend(px);
        }
        if legacy {
            p.extend(if c.valid { 0xFFFF_FFFFu32 } else { 0 }.to_le_bytes());
        }
    }
    if !legacy {
        p.extend([0u8; 32]);
    }
    assert_eq!(p.len(), spec.meta().packet_len());
    p
}

/// A classic little-endian microsecond pcap, Ethernet, one IPv4 UDP record per payload.
fn pcap(payloads: &[Vec<u8>]) -> Vec<u8> {
    let mut f = Vec::new();
    f.extend(0xa1b2c3d4u32.to_le_bytes());
    f.extend(2u16.to_le_bytes());
    f.extend(4u16.to_le_bytes());
    f.extend([0u8; 8]);
    f.extend(65535u32.to_le_bytes());
    f.extend(1u32.to_le_bytes());
    for (k, p) in payloads.iter().enumerate() {
        let mut frame = vec![0u8; 12];
        frame.extend([0x08, 0x00]);
        let total = 20 + 8 + p.len();
        frame.extend([0x45, 0]);
        frame.extend((total as u16).to_be_bytes());
        frame.extend([0, 0, 0, 0, 64, 17, 0, 0, 10, 5, 5, 1, 10, 5, 5, 2]);
        frame.extend(7502u16.to_be_bytes());
        frame.extend(7502u16.to_be_bytes());
        frame.extend(((8 + p.len()) as u16).to_be_bytes());
        frame.extend([0, 0]);
        frame.extend(p);
        f.extend(1_700_000_000u32.to_le_bytes());
        f.extend((k as u32 * 100).to_le_bytes());
        f.extend((frame.len() as u32).to_le_bytes());
        f.extend((frame.len() as u32).to_le_bytes());
        f.extend(frame);
    }
    f
}

/// Every column of frame `frame_id` (ids `0..w`), `range(m, row)` raw, timestamps
/// `t0 + m * 1000` ns, as packets; `skip` packets left out (lost).
fn frame_packets(spec: &Spec, frame_id: u16, t0: u64, range: impl Fn(usize, usize) -> u32, skip: &[usize]) -> Vec<Vec<u8>> {
    (0..spec.w / spec.cpp)
        .filter(|k| !skip.contains(k))
        .map(|k| {
            let cols: Vec<Col> = (k * spec.cpp..(k + 1) * spec.cpp)
                .map(|m| Col {
                    m: m as u16,
                    ts: t0 + m as u64 * 1000,
                    valid: true,
                    pixels: (0..spec.h()).map(|r| (range(m, r), (10 * r + m) as u8)).collect(),
                })
                .collect();
            packet(spec, frame_id, &cols)
        })
        .collect()
}

fn decode_bytes(spec: &Spec, bytes: &[u8]) -> Result<OusterRecording> {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("x.pcap");
    std::fs::write(&p, bytes).unwrap();
    decode(&p, spec.meta())
}

/// The range field value for `mm` in `profile`.
fn raw(profile: Profile, mm: u32) -> u32 {
    if profile == Profile::Rng15Rfl8Nir8 { mm / 8 } else { mm }
}

fn close(a: [f32; 3], b: [f64; 3]) -> bool {
    a.iter().zip(b).all(|(&x, y)| (x as f64 - y).abs() < 1e-5)
}

#[test]
fn the_column_window_counts_its_ids_inclusively_and_may_wrap() {
    let mut m = Spec::new(Profile::Legacy, 1024, 16, &[0.0]).meta();
    assert_eq!(m.window_len(), 1024);
    for (window, fired) in [([100, 200], 101), ([5, 5], 1), ([1000, 23], 48), ([1023, 0], 2), ([0, 511], 512)] {
        m.column_window = window;
        assert_eq!(m.window_len(), fired, "{window:?}");
    }
}

#[test]
fn a_known_range_decodes_to_the_documented_xyz_in_every_profile() {
    for profile in [Profile::Legacy, Profile::Rng19Rfl8Sig16Nir16, Profile::Rng15Rfl8Nir8] {
        // Row 0 level, row 1 10 degrees down; 8 columns, 4 per packet.
        let spec = Spec::new(profile, 8, 4, &[0.0, -10.0]);
        // Only column 2 returns: 10 m on row 0, 4 m on row 1.
        let range = |m: usize, r: usize| if m == 2 { raw(profile, [10_000, 4_000][r]) } else { 0 };
        let mut ps = Vec::new();
        for f in 0..3 {
            ps.extend(frame_packets(&spec, f, 1_000_000 * f as u64, range, &[]));
        }
        let rec = decode_bytes(&spec, &pcap(&ps)).unwrap();
        assert_eq!(rec.scans.len(), 3, "{profile:?}");
        let s = &rec.scans[0];
        assert_eq!(s.points.len(), 2, "{profile:?}");
        // Encoder angle of column 2 of 8: 2 pi (1 - 2/8) = 270 degrees, so the beam points
        // along -y of the lidar frame (identity transform: the sensor frame).
        let te = 1.5 * std::f64::consts::PI;
        assert!(close(s.points[0], [10.0 * te.cos(), 10.0 * te.sin(), 0.0]), "{profile:?} {:?}", s.points);
        assert!(close(s.points[0], [0.0, -10.0, 0.0]));
        let el = (-10f64).to_radians();
        assert!(close(s.points[1], [4.0 * el.cos() * te.cos(), 4.0 * el.cos() * te.sin(), 4.0 * el.sin()]), "{profile:?}");
        // Row 1 is the lowest: ring 0.
        assert_eq!(s.ring.as_deref(), Some(&[1u16, 0][..]));
        assert_eq!(s.ring_elevation_deg.as_deref(), Some(&[-10.0, 0.0][..]));
        assert_eq!(s.intensity.as_deref(), Some(&[2.0f32, 12.0][..]));
        assert_eq!(rec.data_packets, 6);
        assert_eq!(rec.meta.profile, profile);
    }
}

#[test]
fn the_lidar_to_sensor_transform_turns_the_lidar_frame_about_z_and_lifts_it() {
    let mut spec = Spec::new(Profile::Rng19Rfl8Sig16Nir16, 8, 4, &[0.0]);
    spec.transform = OS1_TRANSFORM;
    // Column 0 (encoder angle 2 pi: the lidar's +x) and column 2 (lidar -y) at 5 m.
    let range = |m: usize, _| if m == 0 || m == 2 { 5_000 } else { 0 };
    let mut ps = Vec::new();
    for f in 0..2 {
        ps.extend(frame_packets(&spec, f, 1_000_000 * f as u64, range, &[]));
    }
    let s = &decode_bytes(&spec, &pcap(&ps)).unwrap().scans[0];
    // The lidar's +x is the sensor's -x (straight behind), its -y the sensor's +y (left).
    assert!(close(s.points[0], [-5.0, 0.0, 0.03618]), "{:?}", s.points);
    assert!(close(s.points[1], [0.0, 5.0, 0.03618]), "{:?}", s.points);
    // Firings: column m at m / 8 of a turn clockwise from straight behind, at its own time.
    let f = s.firing_times.as_ref().unwrap();
    assert_eq!(f.len(), 8);
    for (m, &[u, t]) in f.iter().enumerate() {
        assert!((u - m as f64 / 8.0).abs() < 1e-12, "{f:?}");
        assert!((t - m as f64 * 1e-6).abs() < 1e-15, "{f:?}");
    }
    // Column 2 (u = 0.25) is a quarter turn clockwise from behind: to the left, as decoded.
    let sensor = Sensor::from_ouster_json(&spec.json(), "os.json").unwrap();
    assert_eq!(sensor.column_of(s.points[1][0] as f64, s.points[1][1] as f64), 2);
    assert_eq!(s.time_s, Some(0.0));
}

#[test]
fn a_beam_origin_offset_starts_the_beam_off_the_lidar_axis() {
    let mut spec = Spec::new(Profile::Legacy, 8, 4, &[30.0]);
    spec.origin_mm = 15.806;
    let range = |m: usize, _| if m == 0 { 2_000 } else { 0 };
    let mut ps = Vec::new();
    for f in 0..2 {
        ps.extend(frame_packets(&spec, f, 0, range, &[]));
    }
    let s = &decode_bytes(&spec, &pcap(&ps)).unwrap().scans[0];
    // The beam leaves from (n, 0, 0) on the lidar's +x (column 0) and covers the range less n
    // along its direction, 30 degrees up.
    let (n, r, el) = (0.015806, 2.0, 30f64.to_radians());
    assert!(close(s.points[0], [n + (r - n) * el.cos(), 0.0, (r - n) * el.sin()]), "{:?}", s.points);
}

#[test]
fn a_beam_azimuth_offset_turns_the_pixel_against_the_encoder() {
    let mut spec = Spec::new(Profile::Rng19Rfl8Sig16Nir16, 8, 4, &[0.0]);
    spec.azimuth = vec![3.0];
    let range = |m: usize, _| if m == 0 { 1_000 } else { 0 };
    let mut ps = Vec::new();
    for f in 0..2 {
        ps.extend(frame_packets(&spec, f, 0, range, &[]));
    }
    let s = &decode_bytes(&spec, &pcap(&ps)).unwrap().scans[0];
    // The SDK's theta_a = -azimuth: 3 degrees clockwise seen from above.
    let a = (-3f64).to_radians();
    assert!(close(s.points[0], [a.cos(), a.sin(), 0.0]), "{:?}", s.points);
}

#[test]
fn frames_are_cut_by_frame_id_and_lost_packets_leave_fewer_columns() {
    let spec = Spec::new(Profile::Rng19Rfl8Sig16Nir16, 12, 4, &[0.0, 2.0]);
    let range = |_, _| 3_000;
    let mut ps = Vec::new();
    // Frame 40 joined in its last packet (the capture started within it): dropped.
    ps.extend(frame_packets(&spec, 40, 0, range, &[0, 1]));
    // A 48-byte IMU packet between: skipped.
    ps.push(vec![0u8; 48]);
    ps.extend(frame_packets(&spec, 41, 100_000_000, range, &[]));
    ps.extend(frame_packets(&spec, 42, 200_000_000, range, &[1])); // middle packet lost
    ps.extend(frame_packets(&spec, 43, 300_000_000, range, &[]));
    ps.extend(frame_packets(&spec, 44, 400_000_000, range, &[2])); // capture ends in it: dropped
    let rec = decode_bytes(&spec, &pcap(&ps)).unwrap();
    assert_eq!(rec.scans.len(), 3);
    assert_eq!(rec.partial_frames, 2);
    assert_eq!(rec.foreign_packets, 1);
    assert_eq!(rec.data_packets, 11);
    let cols: Vec<usize> = rec.scans.iter().map(|s| s.firing_times.as_ref().unwrap().len()).collect();
    assert_eq!(cols, [12, 8, 12]);
    assert_eq!(rec.scans.iter().map(|s| s.points.len()).collect::<Vec<_>>(), [24, 16, 24]);
    let times: Vec<f64> = rec.scans.iter().map(|s| s.time_s.unwrap()).collect();
    assert!(times.iter().zip([0.1, 0.2, 0.3]).all(|(a, b)| (a - b).abs() < 1e-12), "{times:?}");
    // The lost packet's columns (4..8) are missing from frame 42's firings.
    let u: Vec<f64> = rec.scans[1].firing_times.as_ref().unwrap().iter().map(|f| f[0]).collect();
    let want = [0, 1, 2, 3, 8, 9, 10, 11].map(|m| (m as f64 / 12.0 - 0.5).rem_euclid(1.0));
    assert!(u.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-12) && u.len() == 8, "{u:?}");
}

#[test]
fn invalid_columns_and_zero_ranges_are_skipped() {
    for profile in [Profile::Legacy, Profile::Rng19Rfl8Sig16Nir16] {
        let spec = Spec::new(profile, 8, 4, &[0.0]);
        let col = |m: u16, valid: bool, range: u32| Col { m, ts: 1000 + m as u64, valid, pixels: vec![(range, 1)] };
        let mut ps = Vec::new();
        for f in 0..2u16 {
            ps.push(packet(&spec, f, &[col(0, true, 1000), col(1, false, 1000), col(2, true, 0), col(3, true, 1000)]));
            ps.push(packet(&spec, f, &[col(4, true, 1000), col(5, true, 1000), col(6, true, 1000), col(99, true, 1000)]));
        }
        let rec = decode_bytes(&spec, &pcap(&ps)).unwrap();
        assert_eq!(rec.scans.len(), 2, "{profile:?}");
        // Column 1 is invalid, 99 beyond the frame; column 2 has no return.
        assert_eq!(rec.scans[0].points.len(), 5, "{profile:?}");
        assert_eq!(rec.scans[0].firing_times.as_ref().unwrap().len(), 6, "{profile:?}");
        assert_eq!(rec.invalid_columns, 4, "{profile:?}");
    }
}

#[test]
fn flat_and_nested_metadata_read_the_same() {
    let mut spec = Spec::new(Profile::Rng15Rfl8Nir8, 1024, 16, &[10.0, 0.0, -10.0]);
    spec.azimuth = vec![4.0, 1.0, -4.0];
    spec.origin_mm = 15.8;
    spec.transform = OS1_TRANSFORM;
    let nested = serde_json::json!({
        "sensor_info": {"prod_line": "OS-1-16"},
        "config_params": {"lidar_mode": "1024x10", "udp_profile_lidar": "RNG15_RFL8_NIR8"},
        "lidar_data_format": {"columns_per_frame": 1024, "pixels_per_column": 3, "columns_per_packet": 16,
                              "column_window": [0, 1023], "header_type": "STANDARD"},
        "beam_intrinsics": {"beam_altitude_angles": [10.0, 0.0, -10.0], "beam_azimuth_angles": [4.0, 1.0, -4.0],
                            "lidar_origin_to_beam_origin_mm": 15.8},
        "lidar_intrinsics": {"lidar_to_sensor_transform": OS1_TRANSFORM},
    });
    let a = spec.meta();
    let b = OusterMeta::parse(&nested.to_string(), "os.json").unwrap();
    assert_eq!(a, b);
    assert_eq!(a.packet_len(), 32 + 16 * (12 + 3 * 4) + 32);
    assert_eq!(a.elevation_deg_descending(), [10.0, 0.0, -10.0]);
    // Without udp_profile_lidar: LEGACY.
    let legacy = Spec::new(Profile::Legacy, 1024, 16, &[0.0; 64]);
    let m = legacy.meta();
    assert_eq!((m.profile, m.packet_len()), (Profile::Legacy, 16 * (16 + 64 * 12 + 4)));
}

#[test]
fn bad_metadata_names_the_key() {
    let spec = Spec::new(Profile::Rng19Rfl8Sig16Nir16, 8, 4, &[1.0, 0.0]);
    let base: serde_json::Value = serde_json::from_str(&spec.json()).unwrap();
    let check = |edit: &dyn Fn(&mut serde_json::Value), want: &str| {
        let mut v = base.clone();
        edit(&mut v);
        let e = OusterMeta::parse(&v.to_string(), "os.json").unwrap_err();
        assert!(e.is_input(), "{e}");
        assert!(e.to_string().starts_with("os.json: ") && e.to_string().contains(want), "{e} (want {want})");
    };
    check(&|v| drop(v.as_object_mut().unwrap().remove("beam_azimuth_angles")), "beam_azimuth_angles: missing");
    check(&|v| drop(v.as_object_mut().unwrap().remove("lidar_to_sensor_transform")), "lidar_to_sensor_transform: missing");
    check(&|v| drop(v.as_object_mut().unwrap().remove("lidar_origin_to_beam_origin_mm")), "lidar_origin_to_beam_origin_mm: missing");
    check(
        &|v| {
            v["data_format"].as_object_mut().unwrap().remove("columns_per_frame");
            v.as_object_mut().unwrap().remove("lidar_mode");
        },
        "data_format.columns_per_frame: missing",
    );
    check(&|v| v["data_format"]["pixels_per_column"] = 3.into(), "pixels_per_column: 3 pixels per column but 2 beam_altitude_angles");
    check(&|v| v["beam_altitude_angles"] = serde_json::json!([1.0, 0.0, -1.0]), "but 3 beam_altitude_angles");
    check(&|v| v["beam_altitude_angles"][1] = "x".into(), "beam_altitude_angles[1]: \"x\" is not a finite number");
    check(&|v| v["data_format"]["udp_profile_lidar"] = "RNG19_RFL8_SIG16_NIR16_DUAL".into(), "data_format.udp_profile_lidar: profile RNG19_RFL8_SIG16_NIR16_DUAL is not supported");
    check(&|v| v["data_format"]["columns_per_packet"] = 9.into(), "columns_per_packet: 9 is not between 1");
    check(&|v| v["data_format"]["column_window"] = serde_json::json!([0, 8]), "data_format.column_window");
    check(&|v| v["lidar_to_sensor_transform"] = serde_json::json!([1, 0, 0]), "lidar_to_sensor_transform: 3 numbers, want 16");
    check(&|v| v["data_format"]["pixels_per_column"] = (-1).into(), "data_format.pixels_per_column: -1 is not a whole number");
    check(&|v| *v = serde_json::json!([1]), "beam_altitude_angles: missing");
    let e = OusterMeta::parse("{", "os.json").unwrap_err();
    assert!(e.is_input() && e.to_string().contains("not JSON"), "{e}");
    // Packets over UDP's limit are refused before anything is sized from them.
    let big = Spec::new(Profile::Legacy, 1024, 64, &[0.0; 128]);
    let e = OusterMeta::parse(&big.json(), "os.json").unwrap_err();
    assert!(e.to_string().contains("over UDP's 65535"), "{e}");
}

#[test]
fn bad_captures_name_the_file_packet_and_offset() {
    let spec = Spec::new(Profile::Rng19Rfl8Sig16Nir16, 8, 4, &[0.0; 32]);
    let range = |_, _| 1_000;
    let mut ps = Vec::new();
    for f in 0..2 {
        ps.extend(frame_packets(&spec, f, 0, range, &[]));
    }
    let good = pcap(&ps);
    let record = 16 + 14 + 28 + spec.meta().packet_len();
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("x.pcap");
    let err = |bytes: &[u8]| {
        std::fs::write(&p, bytes).unwrap();
        let e = decode(&p, spec.meta()).unwrap_err();
        assert!(e.is_input(), "{e}");
        e.to_string()
    };
    // A file cut within its last packet.
    let e = err(&good[..good.len() - 10]);
    let at = format!("{}: packet 4 (byte {})", p.display(), 24 + 3 * record);
    assert!(e.starts_with(&at) && e.contains("packet cut short"), "{e}");
    // A packet of the wrong size for the metadata (a large UDP payload).
    let mut wrong = ps.clone();
    wrong[1].truncate(1300);
    let e = err(&pcap(&wrong));
    let at = format!("{}: packet 2 (byte {})", p.display(), 24 + record);
    assert!(e.starts_with(&at) && e.contains("1300-byte UDP packet") && e.contains("metadata"), "{e}");
    // No complete frame.
    let e = err(&pcap(&ps[..1]));
    assert!(e.contains("no complete Ouster frame: 1 lidar packets"), "{e}");
    // Not a capture at all.
    let e = err(b"hello");
    assert!(e.contains("not a pcap capture"), "{e}");
}

#[test]
fn a_recording_opens_an_ouster_capture_with_the_json_beside_it() {
    let mut spec = Spec::new(Profile::Rng19Rfl8Sig16Nir16, 32, 8, &[4.0, 2.0, 0.0, -2.0, -4.0, -6.0, -8.0, -10.0, -12.0, -14.0, -16.0, -18.0, -20.0, -22.0, -24.0, -26.0]);
    spec.transform = OS1_TRANSFORM;
    spec.origin_mm = 15.806;
    // Measurement id m fires at m / 32 of a turn, the edge of grid column m; a beam azimuth
    // offset of half a column (clockwise) puts every return in the middle of its column.
    spec.azimuth = vec![180.0 / 32.0; 16];
    let range = |_, r: usize| 2_000 + 500 * r as u32;
    let mut ps = Vec::new();
    for f in 0..4 {
        ps.extend(frame_packets(&spec, f, 5_000_000_000 + 100_000_000 * f as u64, range, &[]));
    }
    assert!(ps[0].len() > 1206);
    let d = tempfile::tempdir().unwrap();
    let pcap_path = d.path().join("x.pcap");
    std::fs::write(&pcap_path, pcap(&ps)).unwrap();
    let target = Sensor::from_ouster_json(&spec.json(), "os.json").unwrap();
    // Without its metadata: an error naming both paths.
    let json_path = d.path().join("x.json");
    let e = Recording::open(&pcap_path, None, &target).err().unwrap();
    assert!(e.is_input(), "{e}");
    let e = e.to_string();
    assert!(e.starts_with(&pcap_path.display().to_string()) && e.contains(&json_path.display().to_string()) && e.contains("metadata JSON"), "{e}");
    // With metadata that predicts another packet size: an error naming both.
    let mut other = spec.clone();
    other.cpp = 16;
    std::fs::write(&json_path, other.json()).unwrap();
    let e = Recording::open(&pcap_path, None, &target).err().unwrap().to_string();
    assert!(e.contains(&json_path.display().to_string()) && e.contains("predicts"), "{e}");

    // A capture of small packets only is left to the Velodyne reader, whatever JSON lies
    // beside it.
    let small = d.path().join("small.pcap");
    std::fs::write(&small, pcap(&[vec![0u8; 48], vec![0u8; 512]])).unwrap();
    std::fs::write(d.path().join("small.json"), "{").unwrap();
    let e = Recording::open(&small, None, &target).err().unwrap().to_string();
    assert!(e.contains("no complete rotation: 0 data packets, 2 foreign"), "{e}");

    // Metadata given elsewhere, under another name (ouster-sdk names a capture and its JSON
    // apart): read with it, whatever lies beside the capture; a given file that does not exist,
    // or metadata given for a Velodyne capture, is named.
    let elsewhere = tempfile::tempdir().unwrap();
    let given = elsewhere.path().join("OS-1-16_metadata.json");
    std::fs::write(&given, spec.json()).unwrap();
    assert_eq!(Recording::open_with(&pcap_path, &RecordingOptions { ouster_metadata: Some(&given), ..Default::default() }, &target).unwrap().len(), 4);
    let missing = elsewhere.path().join("nope.json");
    let e = Recording::open_with(&pcap_path, &RecordingOptions { ouster_metadata: Some(&missing), ..Default::default() }, &target).err().unwrap().to_string();
    assert!(e.starts_with(&missing.display().to_string()) && e.contains("does not exist"), "{e}");
    let velodyne = d.path().join("velodyne.pcap");
    std::fs::write(&velodyne, pcap(&[vec![0u8; 1206]])).unwrap();
    let e = Recording::open_with(&velodyne, &RecordingOptions { ouster_metadata: Some(&given), ..Default::default() }, &target).err().unwrap().to_string();
    assert!(e.starts_with(&given.display().to_string()) && e.contains("a capture of Velodyne data packets"), "{e}");

    std::fs::write(&json_path, spec.json()).unwrap();
    let rec = Recording::open(&pcap_path, None, &target).unwrap();
    assert_eq!(rec.len(), 4);
    assert_eq!(
        rec.description,
        "OS-1-16 capture (Ouster, RNG19_RFL8_SIG16_NIR16): 4 frames of 32 columns x 16 pixels from 16 lidar packets \
         (0 other packets skipped, 0 partial frames dropped, 0 invalid columns skipped)"
    );
    assert!(rec.times_s.iter().zip([5.0, 5.1, 5.2, 5.3]).all(|(a, b)| (a - b).abs() < 1e-9), "{:?}", rec.times_s);
    assert_eq!(rec.source_elevation_deg.as_deref(), Some(&spec.altitude[..]));
    assert!(rec.coverage_warning.is_none() && rec.sweep_warning.is_none(), "{:?} {:?}", rec.coverage_warning, rec.sweep_warning);
    // Its 32 columns a turn on a grid of 64: half the columns get no return of their own.
    let wide = Sensor { columns: 64, ..target.clone() };
    let w = Recording::open(&pcap_path, None, &wide).unwrap().coverage_warning.unwrap();
    assert!(w.starts_with("the OS-1-16 fired 32 times a turn, fewer than the grid's 64 columns: at least 50.0 %"), "{w}");
    assert!(rec.column_offsets(0).is_some());
    // Every beam of the grid sees its return, at about its range (the beam origin offset and
    // the 36 mm lift move it by a few cm).
    let mut ranges = Vec::new();
    rec.frame_ranges(1, &mut ranges).unwrap();
    assert_eq!(ranges.len(), 16 * 32);
    for (i, &r) in ranges.iter().enumerate() {
        let want = 2.0 + 0.5 * (i / 32) as f32;
        assert!((r - want).abs() < 0.05, "beam {i}: {r} m, want about {want}");
    }
}
