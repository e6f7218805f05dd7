//! Raw Ouster captures (`.pcap`) with the sensor's metadata JSON: lidar packets decoded into
//! one [`Scan`] per Ouster frame.
//!
//! # Metadata
//! The sensor metadata JSON that `ouster-cli` / the sensor's HTTP API write, in the flat
//! layout of firmware 2.x (`data_format`, `beam_altitude_angles`, ... at the top) or the nested
//! one of newer firmware (`lidar_data_format`, `config_params`, `beam_intrinsics`,
//! `lidar_intrinsics`, `sensor_info`). Read from it ([`OusterMeta`]):
//! * `columns_per_frame` (`data_format` / `lidar_data_format`, else the width of
//!   `lidar_mode`, `"1024x10"`), `pixels_per_column` (else the number of beams),
//!   `columns_per_packet` (else 16, as the SDK assumes), `column_window` (else every column);
//! * `udp_profile_lidar` (absent: `LEGACY`); decoded are `LEGACY`, `RNG19_RFL8_SIG16_NIR16`
//!   and `RNG15_RFL8_NIR8` (the low-bandwidth profile); any other profile, and the FUSA
//!   packet header (`header_type`), is an error naming the key;
//! * `beam_altitude_angles` and `beam_azimuth_angles` (one per pixel of a column, degrees),
//!   `lidar_origin_to_beam_origin_mm` or `beam_intrinsics.beam_to_lidar_transform`, and
//!   `lidar_to_sensor_transform` (row-major 4x4, translation in mm): all required;
//! * `prod_line` for messages.
//!
//! # Packets
//! Byte layouts as the ouster-sdk decodes them (`ouster_core/src/parsing.cpp`), little endian:
//! * `LEGACY`: no packet header; per column a 16-byte header (timestamp u64 ns at 0,
//!   measurement id u16 at 8, frame id u16 at 10, encoder count u32 at 12), 12 bytes per pixel
//!   (range: the low 20 bits of a u32, mm; reflectivity u8 at 4; signal u16 at 6; near-IR u16
//!   at 8), then a u32 column status;
//! * other profiles: a 32-byte packet header (packet type u16 at 0, frame id u16 at 2, init id
//!   24 bits at 4, serial number 40 bits at 7, ...), per column a 12-byte header (timestamp
//!   u64 ns at 0, measurement id u16 at 8, status u16 at 10) and the pixels, then a 32-byte
//!   packet footer. `RNG19_RFL8_SIG16_NIR16` pixels are 12 bytes (range: low 19 bits of a u32,
//!   mm; reflectivity u8 at 3; signal u16 at 4; near-IR u16 at 6; 4 bytes reserved);
//!   `RNG15_RFL8_NIR8` pixels are 4 bytes (range: low 15 bits of a u16 in 8 mm units;
//!   reflectivity u8 at 2; near-IR u8 at 3).
//!
//! A lidar packet is a UDP payload of exactly the size these give for the metadata
//! ([`OusterMeta::packet_len`]); the container is read as for Velodyne captures
//! ([`super::pcap`]: classic pcap, Ethernet / SLL / raw IPv4, UDP ports not checked). Smaller
//! payloads (IMU packets of 48 bytes, zone packets, other traffic) are skipped and counted in
//! [`OusterRecording::foreign_packets`]. A payload larger than any of those (over 1206 bytes)
//! that is not the predicted size means the metadata does not describe the capture: an error.
//!
//! # Decoding
//! A column whose status bit 0 is clear (columns outside `column_window`, a `LEGACY` status
//! other than `0xFFFFFFFF` has it clear too) or whose measurement id is not below
//! `columns_per_frame` is skipped, as the SDK does. A range of 0 is no return and skipped.
//! Each pixel's point follows the SDK's `make_xyz_lut` (`ouster_core/src/xyzlut.cpp`), in the
//! lidar frame, mm, with `w = columns_per_frame`, `m` the measurement id, `r` the range:
//! encoder angle `te = 2 pi (1 - m / w)`, `a = te - azimuth_deg[row]`, `phi = altitude[row]`,
//! `dir = (cos a cos phi, sin a cos phi, sin phi)`, `n` = the beam-to-lidar translation's x
//! (`lidar_origin_to_beam_origin_mm`), `bz` its z and `d = hypot(n, bz)`:
//! `p = r dir + (n cos te - d dir.x, n sin te - d dir.y, bz - d dir.z)`; then
//! `lidar_to_sensor_transform` takes it into Ouster's sensor frame (x forward, y left, z up,
//! which is pedscan's sensor frame; for most units a half turn about z and 36.18 mm up), and
//! the result is scaled to metres.
//!
//! * [`Scan::ring`] is the pixel's row ranked by altitude, 0 = lowest (Ouster's row 0 is the
//!   highest beam), [`Scan::ring_elevation_deg`] the altitudes sorted ascending.
//! * [`Scan::intensity`] is the reflectivity byte.
//! * [`Scan::time_s`] is the timestamp of the frame's first valid column, ns to s (the sensor's
//!   clock, as configured: internal oscillator, PTP or GPS time).
//! * [`Scan::firing_times`]: per valid column in capture order, its azimuth in the sensor frame
//!   as a fraction of a turn clockwise from straight behind (the encoder direction through the
//!   transform's rotation about z; measurement id 0 is straight behind for the usual
//!   half-turn transform, so it is `m / w`) and its own timestamp.
//!
//! # Frames
//! Frames are Ouster's own: a new frame begins where the frame id changes (the packet header's
//! frame id; for `LEGACY`, the column header's of valid columns). Lost packets leave a frame
//! with fewer columns; it is still a frame. The first frame is dropped when it lacks the first
//! packet of the column window (the capture started within it), the last when it lacks the
//! last packet's columns; both counted in [`OusterRecording::partial_frames`].
//!
//! # Errors
//! Bad input is an [`Error::input`]: metadata that is not JSON, lacks a required key, has a
//! value of the wrong kind or an inconsistent one (`pixels_per_column` not the number of beam
//! angles, a column window outside the frame, packets over 65535 bytes) names the JSON file and
//! the key; the container's errors and a lidar packet of the wrong size name the capture, the
//! packet (from 1) and its record's byte offset; a capture without one frame says how many
//! packets it held. Nothing is allocated from a length read in a file before it is checked
//! against the file's size.

use super::pcap::{walk_packets, At};
use super::Scan;
use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// The Ouster lidar packet profiles [`read_ouster_pcap`] decodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Profile {
    /// `LEGACY`: 12-byte pixels, 16-byte column headers, a column status word.
    Legacy,
    /// `RNG19_RFL8_SIG16_NIR16`: single return, 12-byte pixels.
    Rng19Rfl8Sig16Nir16,
    /// `RNG15_RFL8_NIR8`: low bandwidth, 4-byte pixels, range in 8 mm units.
    Rng15Rfl8Nir8,
}

impl Profile {
    /// The profile's name as the metadata writes it.
    pub fn name(&self) -> &'static str {
        match self {
            Profile::Legacy => "LEGACY",
            Profile::Rng19Rfl8Sig16Nir16 => "RNG19_RFL8_SIG16_NIR16",
            Profile::Rng15Rfl8Nir8 => "RNG15_RFL8_NIR8",
        }
    }

    fn from_name(s: &str) -> Option<Profile> {
        [Profile::Legacy, Profile::Rng19Rfl8Sig16Nir16, Profile::Rng15Rfl8Nir8].into_iter().find(|p| p.name() == s)
    }

    /// Bytes per pixel.
    pub fn pixel_len(&self) -> usize {
        match self {
            Profile::Legacy | Profile::Rng19Rfl8Sig16Nir16 => 12,
            Profile::Rng15Rfl8Nir8 => 4,
        }
    }

    fn packet_header_len(&self) -> usize {
        if *self == Profile::Legacy { 0 } else { 32 }
    }

    fn packet_footer_len(&self) -> usize {
        self.packet_header_len()
    }

    fn col_header_len(&self) -> usize {
        if *self == Profile::Legacy { 16 } else { 12 }
    }

    fn col_footer_len(&self) -> usize {
        if *self == Profile::Legacy { 4 } else { 0 }
    }

    /// Range (mm) and reflectivity of the pixel at `p`.
    fn pixel(&self, p: &[u8]) -> (u32, u8) {
        match self {
            Profile::Legacy => (u32::from_le_bytes([p[0], p[1], p[2], p[3]]) & 0xF_FFFF, p[4]),
            Profile::Rng19Rfl8Sig16Nir16 => (u32::from_le_bytes([p[0], p[1], p[2], p[3]]) & 0x7_FFFF, p[3]),
            Profile::Rng15Rfl8Nir8 => ((u16::from_le_bytes([p[0], p[1]]) as u32 & 0x7FFF) << 3, p[2]),
        }
    }
}

/// What [`read_ouster_pcap`] needs from the sensor metadata.
#[derive(Clone, Debug, PartialEq)]
pub struct OusterMeta {
    /// `prod_line`, e.g. `OS-1-128` (`Ouster` when absent).
    pub prod_line: String,
    pub profile: Profile,
    pub columns_per_frame: usize,
    pub pixels_per_column: usize,
    pub columns_per_packet: usize,
    /// First and last measurement id the sensor fires (inclusive; may wrap past the end).
    pub column_window: [usize; 2],
    /// Per row (Ouster's order, row 0 highest), degrees.
    pub altitude_deg: Vec<f64>,
    /// Per row, degrees.
    pub azimuth_deg: Vec<f64>,
    /// Beam origin offset: x (`lidar_origin_to_beam_origin_mm`) and z of the beam-to-lidar
    /// transform, mm.
    pub beam_origin_mm: [f64; 2],
    /// `lidar_to_sensor_transform`, row-major, translation in mm.
    pub lidar_to_sensor: [f64; 16],
}

/// Payloads larger than this that are not the predicted lidar packet size are an error: no
/// IMU, zone or Velodyne packet is this large.
const MAX_FOREIGN_LEN: usize = 1206;

impl OusterMeta {
    /// The UDP payload size of one lidar packet.
    pub fn packet_len(&self) -> usize {
        let p = self.profile;
        p.packet_header_len()
            + self.columns_per_packet * self.col_len()
            + p.packet_footer_len()
    }

    fn col_len(&self) -> usize {
        let p = self.profile;
        p.col_header_len() + self.pixels_per_column * p.pixel_len() + p.col_footer_len()
    }

    /// How many columns (measurement ids) the sensor fires a frame: those of `column_window`,
    /// which may wrap past the last id.
    pub fn window_len(&self) -> usize {
        let w = self.columns_per_frame;
        (self.column_window[1] + w - self.column_window[0]) % w + 1
    }

    /// The altitudes sorted descending (the recording sensor's rows for the target grid).
    pub fn elevation_deg_descending(&self) -> Vec<f64> {
        let mut el = self.altitude_deg.clone();
        el.sort_by(|a, b| b.total_cmp(a));
        el
    }

    /// Reads and checks a metadata JSON.
    pub fn read(path: &Path) -> Result<OusterMeta> {
        let text = super::read_text(path)?;
        OusterMeta::parse(&text, &path.display().to_string())
    }

    /// Parses and checks metadata JSON `text`; `input` names it in errors.
    pub fn parse(text: &str, input: &str) -> Result<OusterMeta> {
        let bad = |key: &str, m: String| Error::input(input, format!("{key}: {m}"));
        let v: serde_json::Value =
            serde_json::from_str(text).map_err(|e| Error::input(input, format!("not JSON: {e}")))?;
        // The first of the key paths that is present, with its name for messages.
        let find = |paths: &[&[&str]]| -> Option<(String, &serde_json::Value)> {
            paths.iter().find_map(|p| p.iter().try_fold(&v, |x, k| x.get(*k)).map(|x| (p.join("."), x)))
        };
        let need = |paths: &[&[&str]]| {
            find(paths).ok_or_else(|| {
                Error::input(input, format!("{}: missing (an Ouster sensor metadata file has it)", paths[0].join(".")))
            })
        };
        let uint = |(key, x): (String, &serde_json::Value)| -> Result<usize> {
            x.as_u64()
                .and_then(|u| usize::try_from(u).ok())
                .ok_or_else(|| bad(&key, format!("{x} is not a whole number")))
        };
        let numbers = |(key, x): (String, &serde_json::Value)| -> Result<Vec<f64>> {
            let a = x.as_array().ok_or_else(|| bad(&key, "is not a list of numbers".into()))?;
            a.iter()
                .enumerate()
                .map(|(k, n)| {
                    n.as_f64().filter(|f| f.is_finite()).ok_or_else(|| bad(&format!("{key}[{k}]"), format!("{n} is not a finite number")))
                })
                .collect()
        };
        let df = |k: &'static str| -> [&'static [&'static str]; 2] {
            match k {
                "columns_per_frame" => [&["data_format", "columns_per_frame"], &["lidar_data_format", "columns_per_frame"]],
                "pixels_per_column" => [&["data_format", "pixels_per_column"], &["lidar_data_format", "pixels_per_column"]],
                "columns_per_packet" => [&["data_format", "columns_per_packet"], &["lidar_data_format", "columns_per_packet"]],
                _ => [&["data_format", "column_window"], &["lidar_data_format", "column_window"]],
            }
        };

        let altitude_deg = numbers(need(&[&["beam_altitude_angles"], &["beam_intrinsics", "beam_altitude_angles"]])?)?;
        let azimuth_deg = numbers(need(&[&["beam_azimuth_angles"], &["beam_intrinsics", "beam_azimuth_angles"]])?)?;
        if altitude_deg.is_empty() {
            return Err(bad("beam_altitude_angles", "is empty".into()));
        }
        if let Some((k, a)) = altitude_deg.iter().enumerate().find(|(_, a)| a.abs() > 90.0) {
            return Err(bad(&format!("beam_altitude_angles[{k}]"), format!("{a} degrees is beyond the pole")));
        }
        let columns_per_frame = match find(&df("columns_per_frame")) {
            Some(c) => uint(c)?,
            None => {
                let (key, m) = need(&[&["data_format", "columns_per_frame"], &["lidar_mode"], &["config_params", "lidar_mode"]])?;
                m.as_str()
                    .and_then(|m| m.split('x').next())
                    .and_then(|w| w.parse::<usize>().ok())
                    .ok_or_else(|| bad(&key, format!("{m} is not a lidar mode such as \"1024x10\"")))?
            }
        };
        if !(1..=MAX_COLUMNS).contains(&columns_per_frame) {
            return Err(bad("columns_per_frame", format!("{columns_per_frame} is not a column count (1 to {MAX_COLUMNS})")));
        }
        let pixels_per_column = match find(&df("pixels_per_column")) {
            Some(p) => uint(p)?,
            None => altitude_deg.len(),
        };
        if !(1..=crate::sensor::MAX_ROWS).contains(&pixels_per_column) {
            return Err(bad("pixels_per_column", format!("{pixels_per_column} is not a pixel count (1 to {})", crate::sensor::MAX_ROWS)));
        }
        if pixels_per_column != altitude_deg.len() || pixels_per_column != azimuth_deg.len() {
            return Err(bad(
                "pixels_per_column",
                format!(
                    "{pixels_per_column} pixels per column but {} beam_altitude_angles and {} beam_azimuth_angles",
                    altitude_deg.len(),
                    azimuth_deg.len()
                ),
            ));
        }
        let columns_per_packet = match find(&df("columns_per_packet")) {
            Some(c) => uint(c)?,
            None => 16,
        };
        if !(1..=columns_per_frame).contains(&columns_per_packet) {
            return Err(bad("columns_per_packet", format!("{columns_per_packet} is not between 1 and columns_per_frame ({columns_per_frame})")));
        }
        let column_window = match find(&df("column_window")) {
            Some((key, w)) => {
                let w = numbers((key.clone(), w))?;
                match w[..] {
                    [a, b] if [a, b].iter().all(|x| x.fract() == 0.0 && *x >= 0.0 && *x < columns_per_frame as f64) => {
                        [a as usize, b as usize]
                    }
                    _ => return Err(bad(&key, format!("{w:?} is not two column indices below {columns_per_frame}"))),
                }
            }
            None => [0, columns_per_frame - 1],
        };
        let profile = match find(&[
            &["data_format", "udp_profile_lidar"],
            &["lidar_data_format", "udp_profile_lidar"],
            &["config_params", "udp_profile_lidar"],
        ]) {
            None => Profile::Legacy,
            Some((key, p)) => {
                let name = p.as_str().ok_or_else(|| bad(&key, format!("{p} is not a profile name")))?;
                Profile::from_name(name).ok_or_else(|| {
                    bad(&key, format!("profile {name} is not supported (LEGACY, RNG19_RFL8_SIG16_NIR16 and RNG15_RFL8_NIR8 are)"))
                })?
            }
        };
        if let Some((key, h)) = find(&[&["lidar_data_format", "header_type"], &["data_format", "header_type"], &["config_params", "header_type"]]) {
            if h.as_str() != Some("STANDARD") && profile != Profile::Legacy {
                return Err(bad(&key, format!("{h} packet headers are not supported (STANDARD are)")));
            }
        }
        let beam_origin_mm = match find(&[&["beam_intrinsics", "beam_to_lidar_transform"], &["beam_to_lidar_transform"]]) {
            Some(t) => {
                let key = t.0.clone();
                let t = transform(numbers(t)?, &key, input)?;
                [t[3], t[11]]
            }
            None => {
                let (key, n) =
                    need(&[&["lidar_origin_to_beam_origin_mm"], &["beam_intrinsics", "lidar_origin_to_beam_origin_mm"]])?;
                let n = n.as_f64().filter(|f| f.is_finite()).ok_or_else(|| bad(&key, format!("{n} is not a finite number")))?;
                [n, 0.0]
            }
        };
        let t = need(&[&["lidar_to_sensor_transform"], &["lidar_intrinsics", "lidar_to_sensor_transform"]])?;
        let key = t.0.clone();
        let lidar_to_sensor = transform(numbers(t)?, &key, input)?;
        let prod_line = find(&[&["prod_line"], &["sensor_info", "prod_line"]])
            .and_then(|(_, n)| n.as_str())
            .unwrap_or("Ouster")
            .to_string();
        let meta = OusterMeta {
            prod_line,
            profile,
            columns_per_frame,
            pixels_per_column,
            columns_per_packet,
            column_window,
            altitude_deg,
            azimuth_deg,
            beam_origin_mm,
            lidar_to_sensor,
        };
        if meta.packet_len() > 65535 {
            return Err(bad(
                "columns_per_packet",
                format!("{} columns of {} pixels make {}-byte packets, over UDP's 65535", columns_per_packet, pixels_per_column, meta.packet_len()),
            ));
        }
        Ok(meta)
    }
}

/// The most columns per frame accepted (Ouster's widest mode is 4096).
const MAX_COLUMNS: usize = 16384;

/// A 4x4 row-major transform: 16 numbers, last row `0 0 0 1`, translation within 10 m.
fn transform(v: Vec<f64>, key: &str, input: &str) -> Result<[f64; 16]> {
    let t: [f64; 16] = v
        .try_into()
        .map_err(|v: Vec<f64>| Error::input(input, format!("{key}: {} numbers, want 16 (a row-major 4x4 matrix)", v.len())))?;
    if t[12..] != [0.0, 0.0, 0.0, 1.0] || [t[3], t[7], t[11]].iter().any(|x| x.abs() > 1e4) {
        return Err(Error::input(input, format!("{key}: not a rigid transform in mm (last row 0 0 0 1, translation within 10 m)")));
    }
    Ok(t)
}

/// A decoded Ouster capture.
#[derive(Debug)]
pub struct OusterRecording {
    pub meta: OusterMeta,
    /// One scan per Ouster frame, in capture order.
    pub scans: Vec<Scan>,
    /// Lidar packets decoded (partial frames included).
    pub data_packets: usize,
    /// Packets skipped as not lidar data (IMU packets, other traffic).
    pub foreign_packets: usize,
    /// Frames dropped at the start and end of the capture because the capture cut them.
    pub partial_frames: usize,
    /// Columns skipped for a clear status bit or a measurement id beyond the frame, in the
    /// kept frames.
    pub invalid_columns: usize,
}

/// Decodes an Ouster capture with its metadata JSON.
pub fn read_ouster_pcap(pcap: &Path, metadata: &Path) -> Result<OusterRecording> {
    let meta = OusterMeta::read(metadata)?;
    decode(pcap, meta)
}

/// One frame being filled.
#[derive(Default)]
struct Frame {
    id: u16,
    points: Vec<[f32; 3]>,
    ring: Vec<u16>,
    intensity: Vec<f32>,
    firings: Vec<[f64; 2]>,
    time_s: Option<f64>,
    /// Smallest and largest position of a valid column in the column window.
    span: Option<(usize, usize)>,
    invalid: usize,
}

/// Per-row constants of the xyz formula.
struct Row {
    cos_phi: f64,
    sin_phi: f64,
    cos_az: f64,
    sin_az: f64,
    ring: u16,
}

/// Decodes the lidar packets of `pcap` described by `meta`.
pub fn decode(pcap: &Path, meta: OusterMeta) -> Result<OusterRecording> {
    let name = pcap.display();
    let w = meta.columns_per_frame;
    let h = meta.pixels_per_column;
    let packet_len = meta.packet_len();
    let col_len = meta.col_len();
    let profile = meta.profile;

    let mut order: Vec<usize> = (0..h).collect();
    order.sort_by(|&a, &b| meta.altitude_deg[a].total_cmp(&meta.altitude_deg[b]).then(b.cmp(&a)));
    let mut ring = vec![0u16; h];
    for (rank, &row) in order.iter().enumerate() {
        ring[row] = rank as u16;
    }
    let ring_elevation_deg: Vec<f64> = order.iter().map(|&r| meta.altitude_deg[r]).collect();
    let rows: Vec<Row> = (0..h)
        .map(|r| {
            let phi = meta.altitude_deg[r].to_radians();
            let az = -meta.azimuth_deg[r].to_radians();
            Row { cos_phi: phi.cos(), sin_phi: phi.sin(), cos_az: az.cos(), sin_az: az.sin(), ring: ring[r] }
        })
        .collect();
    let [n, bz] = meta.beam_origin_mm;
    let d = if bz != 0.0 { n.hypot(bz) } else { n };
    let t = &meta.lidar_to_sensor;
    // The sensor-frame yaw of the lidar's x axis: a column's azimuth from the encoder angle.
    let yaw_turns = t[4].atan2(t[0]) / std::f64::consts::TAU;
    let window_len = meta.window_len();
    let cpp = meta.columns_per_packet;

    let mut frames: Vec<Frame> = Vec::new();
    let mut current: Option<Frame> = None;
    let mut data_packets = 0usize;
    let mut foreign_packets = 0usize;
    walk_packets(pcap, |at: &At, payload, _time| {
        let Some(p) = payload.filter(|p| p.len() == packet_len) else {
            match payload {
                Some(p) if p.len() > MAX_FOREIGN_LEN => {
                    return Err(Error::input(
                        at.describe(&name),
                        format!(
                            "a {}-byte UDP packet, but the metadata ({} {}, {} columns of {} pixels per packet) \
                             gives {packet_len}-byte lidar packets: does the metadata belong to this capture?",
                            p.len(),
                            meta.prod_line,
                            profile.name(),
                            cpp,
                            h
                        ),
                    ))
                }
                _ => foreign_packets += 1,
            }
            return Ok(true);
        };
        data_packets += 1;
        let packet_frame = (profile != Profile::Legacy).then(|| u16::from_le_bytes([p[2], p[3]]));
        let body = &p[profile.packet_header_len()..];
        for col in body.chunks_exact(col_len).take(cpp) {
            let ts = u64::from_le_bytes(col[..8].try_into().expect("8 bytes"));
            let m = u16::from_le_bytes([col[8], col[9]]) as usize;
            let (valid, frame_id) = match packet_frame {
                Some(f) => (col[10] & 1 != 0, f),
                None => {
                    let s = u32::from_le_bytes(col[col_len - 4..].try_into().expect("4 bytes"));
                    (s & 1 != 0, u16::from_le_bytes([col[10], col[11]]))
                }
            };
            // LEGACY frame ids come from valid columns only; the packet's for other profiles.
            if (valid || packet_frame.is_some()) && current.as_ref().is_none_or(|f| f.id != frame_id) {
                frames.extend(current.take());
                current = Some(Frame { id: frame_id, ..Frame::default() });
            }
            let Some(f) = current.as_mut() else { continue };
            if !valid || m >= w {
                f.invalid += 1;
                continue;
            }
            let pos = (m + w - meta.column_window[0]) % w;
            f.span = Some(f.span.map_or((pos, pos), |(a, b)| (a.min(pos), b.max(pos))));
            let time = ts as f64 * 1e-9;
            f.time_s.get_or_insert(time);
            let mut u = (m as f64 / w as f64 - 0.5 - yaw_turns).rem_euclid(1.0) + 0.0; // no -0
            if u >= 1.0 {
                u = 0.0;
            }
            f.firings.push([u, time]);
            let te = std::f64::consts::TAU * (1.0 - m as f64 / w as f64);
            let (sin_te, cos_te) = te.sin_cos();
            let pixels = &col[profile.col_header_len()..col_len - profile.col_footer_len()];
            for (row, px) in rows.iter().zip(pixels.chunks_exact(profile.pixel_len())) {
                let (range_mm, reflectivity) = profile.pixel(px);
                if range_mm == 0 {
                    continue;
                }
                let r = range_mm as f64;
                // cos/sin of te + azimuth offset by the angle sum.
                let cos_a = cos_te * row.cos_az - sin_te * row.sin_az;
                let sin_a = sin_te * row.cos_az + cos_te * row.sin_az;
                let dir = [cos_a * row.cos_phi, sin_a * row.cos_phi, row.sin_phi];
                let l = [
                    r * dir[0] + n * cos_te - d * dir[0],
                    r * dir[1] + n * sin_te - d * dir[1],
                    r * dir[2] + bz - d * dir[2],
                ];
                let s = |i: usize| (t[4 * i] * l[0] + t[4 * i + 1] * l[1] + t[4 * i + 2] * l[2] + t[4 * i + 3]) * 1e-3;
                f.points.push([s(0) as f32, s(1) as f32, s(2) as f32]);
                f.ring.push(row.ring);
                f.intensity.push(reflectivity as f32);
            }
        }
        Ok(true)
    })?;
    frames.extend(current.take());

    // Frames that hold no valid column are no frames; the capture's first and last are dropped
    // when the capture cut them.
    frames.retain(|f| f.span.is_some());
    let mut partial_frames = 0;
    if frames.first().is_some_and(|f| f.span.is_some_and(|(a, _)| a >= cpp)) {
        frames.remove(0);
        partial_frames += 1;
    }
    if frames.last().is_some_and(|f| f.span.is_some_and(|(_, b)| b + cpp < window_len)) {
        frames.pop();
        partial_frames += 1;
    }
    if frames.is_empty() {
        return Err(Error::input(
            &name,
            format!(
                "no complete Ouster frame: {data_packets} lidar packets of {packet_len} bytes ({} {}), {foreign_packets} other packets",
                meta.prod_line,
                profile.name()
            ),
        ));
    }
    let invalid_columns = frames.iter().map(|f| f.invalid).sum();
    let scans = frames
        .into_iter()
        .map(|f| Scan {
            points: f.points,
            ring: Some(f.ring),
            ring_elevation_deg: Some(ring_elevation_deg.clone()),
            time_s: f.time_s,
            intensity: Some(f.intensity),
            firing_times: Some(f.firings),
        })
        .collect();
    Ok(OusterRecording { meta, scans, data_packets, foreign_packets, partial_frames, invalid_columns })
}

/// Whether a `.pcap` is an Ouster capture, and its metadata: `Some(json)` when its first 256
/// UDP packets hold no Velodyne-sized (1206-byte) payload and the metadata (`given`, else the
/// `.json` beside it with the same stem) predicts the size of some of them. `None` leaves the
/// capture to the Velodyne reader (which reports what is wrong with it, a broken container
/// too). An error when the packets look like an Ouster lidar's (larger than any Velodyne
/// packet) but the JSON is missing, unreadable or predicts another size, and when metadata is
/// given for a capture of Velodyne packets or does not exist.
pub fn ouster_metadata_for(pcap: &Path, given: Option<&Path>) -> Result<Option<PathBuf>> {
    let mut sizes: Vec<usize> = Vec::new();
    let walked = walk_packets(pcap, |_, payload, _| {
        if let Some(p) = payload {
            sizes.push(p.len());
        }
        Ok(sizes.len() < SNIFF_PACKETS && !sizes.contains(&1206))
    });
    if let Some(g) = given {
        if std::fs::symlink_metadata(g).is_err() {
            return Err(Error::input(g.display(), "Ouster metadata (scene.ouster_metadata) does not exist"));
        }
        if walked.is_ok() && sizes.contains(&1206) {
            return Err(Error::input(
                g.display(),
                format!("Ouster metadata given for {}, a capture of Velodyne data packets", pcap.display()),
            ));
        }
    }
    if walked.is_err() || sizes.contains(&1206) {
        return Ok(None);
    }
    let large = sizes.iter().copied().find(|&s| s > MAX_FOREIGN_LEN);
    let json = given.map_or_else(|| pcap.with_extension("json"), Path::to_path_buf);
    if std::fs::symlink_metadata(&json).is_err() {
        let Some(large) = large else { return Ok(None) };
        return Err(Error::input(
            pcap.display(),
            format!(
                "holds no Velodyne data packets but {large}-byte UDP packets, as an Ouster lidar sends: an Ouster \
                 capture is read with its sensor metadata JSON, given by --ouster-metadata FILE \
                 (scene.ouster_metadata) or lying beside it with the same name, {} (not found)",
                json.display()
            ),
        ));
    }
    // The metadata matters only when the packets may be Ouster's: small packets alone are left
    // to the Velodyne reader's messages.
    let meta = match OusterMeta::read(&json) {
        Ok(meta) => meta,
        Err(e) => return if large.is_some() { Err(e) } else { Ok(None) },
    };
    if sizes.contains(&meta.packet_len()) {
        return Ok(Some(json));
    }
    let Some(large) = large else { return Ok(None) };
    Err(Error::input(
        pcap.display(),
        format!(
            "holds no Velodyne data packets and none of the {}-byte lidar packets its metadata {} predicts \
             ({} {}); its first large UDP packet has {large} bytes",
            meta.packet_len(),
            json.display(),
            meta.prod_line,
            meta.profile.name()
        ),
    ))
}

/// UDP packets [`ouster_metadata_for`] looks at.
const SNIFF_PACKETS: usize = 256;

#[cfg(test)]
mod tests;
