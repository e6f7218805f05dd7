//! Raw Velodyne captures (`.pcap`): HDL-32E and VLP-16 data packets decoded into one [`Scan`]
//! per full turn of the sensor.
//!
//! # Container
//! Classic libpcap files in either byte order, with microsecond (`a1b2c3d4`) or nanosecond
//! (`a1b23c4d`) timestamps. Link types: Ethernet (1, with any number of 802.1Q / 802.1ad VLAN
//! tags), Linux cooked capture SLL (113) and raw IPv4 (101, 228). pcapng files are rejected
//! with a message saying so (`editcap -F pcap in.pcapng out.pcap` converts them). The file is
//! streamed through a buffered reader, one reused packet buffer, so captures of many GB only
//! cost the memory of the decoded scans.
//!
//! # Packets
//! Only unfragmented IPv4 UDP is looked at; the UDP port is not checked. A Velodyne data packet
//! is a UDP payload of exactly 1206 bytes: 12 blocks of 100 bytes (flag `0xFF 0xEE`, azimuth
//! u16 little endian in 0.01 degree below 36000, then 32 returns of distance u16 LE in 2 mm
//! units and reflectivity u8), a 4-byte sensor timestamp (microseconds past the hour) and two
//! factory bytes, return mode (`0x37` strongest, `0x38` last, `0x39` dual) and product id
//! (`0x21` HDL-32E, `0x22` VLP-16). The product id names the sensor unless the packets' own
//! timestamps say otherwise: a first pass over the first 256 data packets takes the median
//! step between their timestamps, and a step within 5 % of the other sensor's packet time
//! (HDL-32E 552.96 us, VLP-16 1327.1 us; half in dual-return mode) and not of the claimed one's
//! decodes the capture as the other sensor ([`PcapRecording::relabelled`]): some VLP-16
//! firmware writes the HDL-32E's id. Times themselves come from the pcap timestamps. Every other packet (position/GPS packets of
//! 512 bytes, other sizes, TCP, non-IPv4, IP fragments, bad block flags, an azimuth of 360
//! degrees or more, an unknown return mode or product id, frames cut short by the capture's
//! snap length) is skipped and counted in [`PcapRecording::foreign_packets`].
//!
//! # Decoding
//! - HDL-32E: the 32 returns of a block are lasers 0..31 in firing order, fired 1.152 us
//!   apart; a block (one firing of all lasers) lasts 46.08 us. VLP-16: returns 0..15 are the
//!   first firing sequence and 16..31 the second, laser id = return % 16, lasers 2.304 us
//!   apart, sequences 55.296 us apart, a block lasts 110.592 us. Vertical angles per laser id
//!   are [`VelodyneModel::elevation_deg`] (the factory tables; no per-unit calibration).
//! - Each return's azimuth is interpolated between its block's azimuth and the next firing's
//!   by its firing time (as the ROS `velodyne_pointcloud` decoder does for the VLP-16, so the
//!   VLP-16's second sequence sits halfway to the next block). The last firing of a packet
//!   uses the step of the one before; a step of more than 2 degrees per firing is a glitch
//!   and replaced by a neighbouring step of the same packet.
//! - Dual return (`0x39`): blocks come in pairs of one firing with the same azimuth; both
//!   returns are kept (the projection onto a beam grid keeps the nearest per cell).
//! - A distance of 0 means no return and is skipped.
//! - Velodyne azimuth `a` is clockwise from straight ahead seen from above, so in pedscan's
//!   frame (x forward, y left, z up), for elevation `el` and distance `d`:
//!   `x = d cos(el) cos(a)`, `y = -d cos(el) sin(a)`, `z = d sin(el)` (the same axes as the
//!   ROS decoder's `x = xy cos(a)`, `y = -xy sin(a)`).
//! - [`Scan::ring`] is the laser's rank by elevation, 0 = lowest (the ROS convention), and
//!   [`Scan::ring_elevation_deg`] the elevations sorted ascending, so
//!   `ring_elevation_deg[ring[i]]` is the elevation of point `i`'s laser.
//!
//! # Rotations
//! A rotation is cut where the (interpolated) azimuth crosses 180 degrees, straight behind
//! the sensor, which is the edge of pedscan's column 0: every scan is one full turn with its
//! seam behind. A crossing is a step back of more than half a turn in the azimuth measured
//! from 180 degrees; after a cut the next one is only accepted once the sensor has turned a
//! quarter turn on, so jitter at the seam cannot cut twice. The partial turn before the first
//! cut and the one after the last cut are dropped and counted in
//! [`PcapRecording::partial_rotations`] (a capture whose very first return lies exactly at
//! 180 degrees has no leading partial turn). [`Scan::time_s`] is the pcap timestamp, in
//! seconds, of the packet holding the rotation's first return. Gaps in the capture are not
//! detected: a turn with lost packets is still one scan, with fewer points.
//!
//! # Column times
//! Each scan also carries its own sweep, [`Scan::firing_times`]: per firing, its azimuth from
//! 180 degrees and its time, the packet's pcap timestamp taken as the packet's first firing
//! (as the sensor's own 4-byte packet timestamp is) plus the firing's documented offset
//! (46.08 us per firing on the HDL-32E, 110.592 us on the VLP-16); the return where the turn is
//! cut, at its laser's offset within the firing, closes one turn and opens the next. A
//! constant delay between firing and capture (the packet's own length, the network) cancels
//! out: the recording places column times relative to [`Scan::time_s`], which has the same
//! delay. [`crate::input::sweep::boundary_times`] turns the firings into the target
//! grid's column times, smoothing jitter and refusing clocks that step back or jump.
//!
//! # Errors
//! Bad input is an [`Error::input`] naming the file, and the packet (numbered from 1, as
//! Wireshark does) with the byte offset of its record header where one is at fault: a file
//! that is not classic pcap, an unsupported link type, a record header or packet cut short
//! (a truncated file: nothing partial is returned; a record longer than the rest of the file is
//! refused before its buffer is allocated), an implausible record length, data
//! packets of two different product ids (the first packet of the second kind is named), and
//! a capture without one complete rotation (`no complete rotation: N data packets, M foreign`).

use super::Scan;
use crate::error::{Error, Result};
use std::io::{BufReader, Read};
use std::path::Path;

/// The Velodyne sensors whose data packets [`read_pcap`] decodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VelodyneModel {
    /// HDL-32E: 32 lasers, product id `0x21`.
    Hdl32e,
    /// VLP-16 (Puck): 16 lasers fired twice per block, product id `0x22`.
    Vlp16,
}

/// HDL-32E vertical angle per laser id (firing order), degrees.
const HDL32E_ELEVATION_DEG: [f64; 32] = [
    -30.67, -9.33, -29.33, -8.00, -28.00, -6.67, -26.67, -5.33, -25.33, -4.00, -24.00, -2.67,
    -22.67, -1.33, -21.33, 0.00, -20.00, 1.33, -18.67, 2.67, -17.33, 4.00, -16.00, 5.33, -14.67,
    6.67, -13.33, 8.00, -12.00, 9.33, -10.67, 10.67,
];

/// VLP-16 vertical angle per laser id (firing order), degrees.
const VLP16_ELEVATION_DEG: [f64; 16] =
    [-15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0, -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0];

impl VelodyneModel {
    /// Vertical angle of each laser id in firing order, degrees.
    pub fn elevation_deg(&self) -> &'static [f64] {
        match self {
            VelodyneModel::Hdl32e => &HDL32E_ELEVATION_DEG,
            VelodyneModel::Vlp16 => &VLP16_ELEVATION_DEG,
        }
    }

    /// The sensor's name as Velodyne writes it (`HDL-32E`, `VLP-16`).
    pub fn name(&self) -> &'static str {
        match self {
            VelodyneModel::Hdl32e => "HDL-32E",
            VelodyneModel::Vlp16 => "VLP-16",
        }
    }

    fn from_product_id(id: u8) -> Option<VelodyneModel> {
        match id {
            0x21 => Some(VelodyneModel::Hdl32e),
            0x22 => Some(VelodyneModel::Vlp16),
            _ => None,
        }
    }

    /// The time one block takes, us: one firing of every laser (HDL-32E) or two firing
    /// sequences (VLP-16).
    fn block_us(&self) -> f64 {
        match self {
            VelodyneModel::Hdl32e => HDL32E_FIRING_US,
            VelodyneModel::Vlp16 => VLP16_FIRING_US,
        }
    }

    /// Firing sequences a block holds, each at its own azimuth (the VLP-16 fires twice).
    pub fn sequences_per_block(&self) -> usize {
        match self {
            VelodyneModel::Hdl32e => 1,
            VelodyneModel::Vlp16 => 2,
        }
    }

    /// Firing time of return slot `ch` (0..32) of a block as a fraction of the time between
    /// two firings (one block; a block pair in dual-return mode).
    fn firing_fraction(&self, ch: usize) -> f64 {
        match self {
            VelodyneModel::Hdl32e => ch as f64 * HDL32E_LASER_US / HDL32E_FIRING_US,
            VelodyneModel::Vlp16 => {
                ((ch / 16) as f64 * VLP16_SEQUENCE_US + (ch % 16) as f64 * VLP16_LASER_US)
                    / VLP16_FIRING_US
            }
        }
    }
}

/// Everything decoded from one capture.
#[derive(Clone, Debug, PartialEq)]
pub struct PcapRecording {
    /// The sensor: the data packets' product id, unless their own timestamps say clearly that
    /// another sensor sent them (then `relabelled`).
    pub model: VelodyneModel,
    /// The product id the packets claim and their median spacing (us), when the spacing
    /// overruled it.
    pub relabelled: Option<(VelodyneModel, f64)>,
    /// One scan per complete turn, seam straight behind, in capture order.
    pub scans: Vec<Scan>,
    /// Velodyne data packets decoded (partial turns included).
    pub data_packets: usize,
    /// Packets skipped as not Velodyne data (GPS/position packets, other traffic).
    pub foreign_packets: usize,
    /// Partial turns dropped at the start and end of the capture.
    pub partial_rotations: usize,
}

const HDL32E_LASER_US: f64 = 1.152;
const HDL32E_FIRING_US: f64 = 46.08;
const VLP16_LASER_US: f64 = 2.304;
const VLP16_SEQUENCE_US: f64 = 55.296;
const VLP16_FIRING_US: f64 = 110.592;

const PACKET_LEN: usize = 1206;
const BLOCKS: usize = 12;
const BLOCK_LEN: usize = 100;
const RETURNS: usize = 32;
const RETURN_MODE_DUAL: u8 = 0x39;
/// Distance unit, metres.
const DISTANCE_M: f64 = 0.002;
/// Azimuth units (0.01 degree) per turn.
const TURN: f64 = 36000.0;
/// A larger azimuth step between two firings (2 degrees) is a glitch, not rotation.
const MAX_FIRING_STEP: u32 = 200;
/// Longest record accepted (pcap snap lengths are at most 256 KiB in practice).
const MAX_RECORD_LEN: usize = 1 << 24;

/// Reads a raw Velodyne capture into one scan per complete turn; see the module docs.
pub fn read_pcap(path: &Path) -> Result<PcapRecording> {
    // First pass, over the first data packets only: how far apart the sensor stamps them.
    let mut stamps: Vec<(VelodyneModel, bool, u32)> = Vec::new();
    walk_packets(path, |_, payload, _| {
        if let Some((m, dual)) = payload.and_then(velodyne_packet) {
            let p = payload.expect("a data packet has a payload");
            stamps.push((m, dual, u32::from_le_bytes([p[1200], p[1201], p[1202], p[1203]])));
        }
        Ok(stamps.len() < SPACING_PACKETS)
    })?;
    let timing = packet_timing(&stamps);

    let name = path.display();
    let mut model: Option<(VelodyneModel, usize)> = None;
    let mut decoder: Option<Decoder> = None;
    let mut data_packets = 0usize;
    let mut foreign_packets = 0usize;
    let mut rotations = Rotations::new();
    walk_packets(path, |at, payload, time| {
        match payload.and_then(velodyne_packet) {
            None => foreign_packets += 1,
            Some((m, dual)) => {
                match model {
                    None => {
                        model = Some((m, at.packet));
                        decoder = Some(Decoder::new(timing.map_or(m, |t| t.decoded_as)));
                    }
                    Some((first, first_packet)) if first != m => {
                        return Err(Error::input(
                            at.describe(&name),
                            format!(
                                "{} data packet in a capture of {} data (from packet \
                                 {first_packet}); mixed sensors are not supported",
                                m.name(),
                                first.name()
                            ),
                        ));
                    }
                    Some(_) => {}
                }
                data_packets += 1;
                let dec = decoder.as_ref().expect("decoder is set with the model");
                rotations.packet(dec, payload.expect("a data packet has a payload"), dual, time);
            }
        }
        Ok(true)
    })?;

    let Some((claimed, _)) = model.filter(|_| !rotations.scans.is_empty()) else {
        return Err(Error::input(
            &name,
            format!("no complete rotation: {data_packets} data packets, {foreign_packets} foreign"),
        ));
    };
    let partial_rotations = rotations.partial + 1; // the turn after the last cut
    let (model, relabelled) = match timing {
        Some(t) if t.decoded_as != claimed => (t.decoded_as, Some((claimed, t.spacing_us))),
        _ => (claimed, None),
    };
    Ok(PcapRecording { model, relabelled, scans: rotations.scans, data_packets, foreign_packets, partial_rotations })
}

/// Data packets whose sensor timestamps the first pass reads.
const SPACING_PACKETS: usize = 256;

/// How far apart the sensor stamps its data packets, and so which sensor sent them.
#[derive(Clone, Copy, Debug)]
struct PacketTiming {
    /// Median step between consecutive data packets' own timestamps, microseconds.
    spacing_us: f64,
    /// The sensor whose packets come at that step.
    decoded_as: VelodyneModel,
}

/// The time one data packet covers: 12 blocks of one firing each (HDL-32E, 46.08 us) or of
/// two firing sequences (VLP-16, 110.592 us); half of that in dual-return mode, where blocks
/// come in pairs of one firing.
fn packet_us(model: VelodyneModel, dual: bool) -> f64 {
    BLOCKS as f64 * model.block_us() / if dual { 2.0 } else { 1.0 }
}

/// The sensor the packets' own timestamps say sent them, when they say it clearly: the
/// median step between consecutive data packets (microseconds past the hour, steps of 0 or
/// over 10 ms left out) within 5 % of one sensor's packet time and not of the other's.
/// Steps of an HDL-32E are 552.96 us (276.48 dual), of a VLP-16 1327.1 us (663.55 dual), so
/// a VLP-16 that writes the HDL-32E's product id (some firmware does) is still decoded as
/// what it is. `None` (the product id decides) when the stamps are absent, too few or fit
/// neither.
fn packet_timing(stamps: &[(VelodyneModel, bool, u32)]) -> Option<PacketTiming> {
    const HOUR_US: u32 = 3_600_000_000;
    let dual = stamps.first()?.1;
    let mut steps: Vec<f64> = stamps
        .windows(2)
        .map(|w| ((w[1].2 as u64 + HOUR_US as u64 - w[0].2 as u64) % HOUR_US as u64) as f64)
        .filter(|&d| d > 0.0 && d <= 10_000.0)
        .collect();
    if steps.len() < 16 {
        return None;
    }
    steps.sort_by(f64::total_cmp);
    let spacing_us = steps[steps.len() / 2];
    let fits = |m: VelodyneModel| (spacing_us / packet_us(m, dual) - 1.0).abs() <= 0.05;
    let fitting: Vec<VelodyneModel> = [VelodyneModel::Hdl32e, VelodyneModel::Vlp16].into_iter().filter(|&m| fits(m)).collect();
    match fitting[..] {
        [m] => Some(PacketTiming { spacing_us, decoded_as: m }),
        _ => None,
    }
}

/// Where a record lies in the capture, for error messages.
pub(crate) struct At {
    /// Numbered from 1, as Wireshark does.
    pub(crate) packet: usize,
    /// Byte offset of the record header.
    pub(crate) offset: u64,
}

impl At {
    pub(crate) fn describe(&self, name: &impl std::fmt::Display) -> String {
        format!("{name}: packet {} (byte {})", self.packet, self.offset)
    }
}

/// Streams the capture's records to `f(at, udp_payload, pcap_time_s)` until it returns
/// false or the file ends; the container's errors name the file, packet and offset.
pub(crate) fn walk_packets(path: &Path, mut f: impl FnMut(&At, Option<&[u8]>, f64) -> Result<bool>) -> Result<()> {
    let (file, file_len) = super::open_file(path)?;
    let mut reader = BufReader::with_capacity(1 << 20, file);
    let name = path.display();

    let mut header = [0u8; 24];
    let got = read_full(&mut reader, &mut header).map_err(|e| Error::io(path, e))?;
    if got >= 4 && header[..4] == [0x0A, 0x0D, 0x0D, 0x0A] {
        return Err(Error::input(
            &name,
            "pcapng captures are not supported, only classic pcap \
             (convert with `editcap -F pcap in.pcapng out.pcap`)",
        ));
    }
    if got == 0 {
        return Err(Error::input(&name, "empty file, not a pcap capture"));
    }
    let (big_endian, nanos) = match header[..4.min(got)] {
        [0xD4, 0xC3, 0xB2, 0xA1] => (false, false),
        [0xA1, 0xB2, 0xC3, 0xD4] => (true, false),
        [0x4D, 0x3C, 0xB2, 0xA1] => (false, true),
        [0xA1, 0xB2, 0x3C, 0x4D] => (true, true),
        _ => {
            return Err(Error::input(
                &name,
                format!("not a pcap capture (first bytes {:02x?})", &header[..4.min(got)]),
            ))
        }
    };
    if got < 24 {
        return Err(Error::input(&name, format!("truncated pcap header ({got} of 24 bytes)")));
    }
    let u16_at = |b: &[u8], i: usize| {
        let v = [b[i], b[i + 1]];
        if big_endian { u16::from_be_bytes(v) } else { u16::from_le_bytes(v) }
    };
    let u32_at = |b: &[u8], i: usize| {
        let v = [b[i], b[i + 1], b[i + 2], b[i + 3]];
        if big_endian { u32::from_be_bytes(v) } else { u32::from_le_bytes(v) }
    };
    let major = u16_at(&header, 4);
    if major != 2 {
        return Err(Error::input(&name, format!("pcap version {major} is not supported (2 is)")));
    }
    let link = match u32_at(&header, 20) & 0xFFFF {
        1 => Link::Ethernet,
        113 => Link::LinuxSll,
        101 | 228 => Link::RawIpv4,
        other => {
            return Err(Error::input(
                &name,
                format!(
                    "link type {other} is not supported (Ethernet 1, Linux cooked 113, \
                     raw IPv4 101 or 228 are)"
                ),
            ))
        }
    };
    let frac_s = if nanos { 1e-9 } else { 1e-6 };

    let mut rec = [0u8; 16];
    let mut buf = vec![0u8; 65536];
    let mut at = At { packet: 0, offset: 24 };
    loop {
        let got = read_full(&mut reader, &mut rec).map_err(|e| Error::io(path, e))?;
        if got == 0 {
            return Ok(());
        }
        at.packet += 1;
        if got < 16 {
            return Err(Error::input(at.describe(&name), format!("truncated record header ({got} of 16 bytes)")));
        }
        let ts_sec = u32_at(&rec, 0);
        let ts_frac = u32_at(&rec, 4);
        let len = u32_at(&rec, 8) as usize;
        if len > MAX_RECORD_LEN {
            return Err(Error::input(at.describe(&name), format!("implausible record length {len} bytes")));
        }
        // Checked against the file before the packet buffer grows to it.
        let left = file_len.saturating_sub(at.offset + 16);
        if len as u64 > left {
            return Err(Error::input(
                at.describe(&name),
                format!("packet cut short: the record says {len} bytes but only {left} are left in the file"),
            ));
        }
        if buf.len() < len {
            buf.resize(len, 0);
        }
        let frame = &mut buf[..len];
        let got = read_full(&mut reader, frame).map_err(|e| Error::io(path, e))?;
        if got < len {
            return Err(Error::input(at.describe(&name), format!("packet cut short ({got} of {len} bytes)")));
        }
        let time = ts_sec as f64 + ts_frac as f64 * frac_s;
        if !f(&at, udp_payload(link, frame), time)? {
            return Ok(());
        }
        at.offset += 16 + len as u64;
    }
}

/// Fills `buf` as far as the stream allows; returns the bytes read (short only at the end).
fn read_full(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

#[derive(Clone, Copy)]
enum Link {
    Ethernet,
    LinuxSll,
    RawIpv4,
}

fn be16(b: &[u8], i: usize) -> Option<u16> {
    Some(u16::from_be_bytes([*b.get(i)?, *b.get(i + 1)?]))
}

/// The UDP payload of an unfragmented IPv4 packet in `frame`, if it is one.
fn udp_payload(link: Link, frame: &[u8]) -> Option<&[u8]> {
    const IPV4: u16 = 0x0800;
    let ip = match link {
        Link::Ethernet => {
            let mut at = 12;
            let mut ethertype = be16(frame, at)?;
            while ethertype == 0x8100 || ethertype == 0x88A8 {
                at += 4;
                ethertype = be16(frame, at)?;
            }
            if ethertype != IPV4 {
                return None;
            }
            &frame[at + 2..]
        }
        Link::LinuxSll => {
            if be16(frame, 14)? != IPV4 {
                return None;
            }
            &frame[16..]
        }
        Link::RawIpv4 => frame,
    };
    if ip.len() < 20 || ip[0] >> 4 != 4 {
        return None;
    }
    let header_len = (ip[0] & 0x0F) as usize * 4;
    let total_len = be16(ip, 2)? as usize;
    let fragment = be16(ip, 6)? & 0x3FFF; // more-fragments flag and fragment offset
    if header_len < 20 || total_len < header_len + 8 || total_len > ip.len() || fragment != 0 || ip[9] != 17 {
        return None;
    }
    let udp = &ip[header_len..total_len];
    let udp_len = be16(udp, 4)? as usize;
    if udp_len < 8 || udp_len > udp.len() {
        return None;
    }
    Some(&udp[8..udp_len])
}

/// The sensor and dual-return flag of a Velodyne data packet, `None` for anything else.
fn velodyne_packet(p: &[u8]) -> Option<(VelodyneModel, bool)> {
    if p.len() != PACKET_LEN {
        return None;
    }
    for b in 0..BLOCKS {
        let blk = &p[b * BLOCK_LEN..];
        if blk[0] != 0xFF || blk[1] != 0xEE || u16::from_le_bytes([blk[2], blk[3]]) >= 36000 {
            return None;
        }
    }
    let dual = match p[PACKET_LEN - 2] {
        0x37 | 0x38 => false,
        RETURN_MODE_DUAL => true,
        _ => return None,
    };
    Some((VelodyneModel::from_product_id(p[PACKET_LEN - 1])?, dual))
}

/// Per return slot of a block: the laser's elevation, ring and firing time.
#[derive(Clone, Copy, Default)]
struct Slot {
    sin_el: f64,
    cos_el: f64,
    ring: u16,
    /// Firing time as a fraction of the time between two firings.
    fraction: f64,
}

struct Decoder {
    slots: [Slot; RETURNS],
    ring_elevation_deg: Vec<f64>,
    /// The time between two firings (one block; a block pair in dual-return mode), s.
    firing_s: f64,
}

impl Decoder {
    fn new(model: VelodyneModel) -> Decoder {
        let el = model.elevation_deg();
        let mut ring_elevation_deg = el.to_vec();
        ring_elevation_deg.sort_by(f64::total_cmp);
        let mut slots = [Slot::default(); RETURNS];
        for (ch, slot) in slots.iter_mut().enumerate() {
            let laser = ch % el.len();
            let rad = el[laser].to_radians();
            *slot = Slot {
                sin_el: rad.sin(),
                cos_el: rad.cos(),
                ring: el.iter().filter(|&&e| e < el[laser]).count() as u16,
                fraction: model.firing_fraction(ch),
            };
        }
        Decoder { slots, ring_elevation_deg, firing_s: model.block_us() * 1e-6 }
    }
}

/// Cuts the stream of returns into turns at 180 degrees.
struct Rotations {
    scans: Vec<Scan>,
    /// The turn being filled (only once the first cut has been seen).
    points: Vec<[f32; 3]>,
    ring: Vec<u16>,
    /// Each return's reflectivity byte.
    intensity: Vec<f32>,
    /// Per firing: azimuth from 180 degrees in turns and firing time (`Scan::firing_times`).
    firings: Vec<[f64; 2]>,
    time_s: f64,
    started: bool,
    /// Azimuth of the last return slot measured from 180 degrees, 0.01 degree, in [0, 36000).
    last_s: Option<f64>,
    /// False right after a cut until the sensor has turned a quarter turn on.
    armed: bool,
    /// Partial turns dropped so far (the leading one).
    partial: usize,
}

impl Rotations {
    fn new() -> Rotations {
        Rotations {
            scans: Vec::new(),
            points: Vec::new(),
            ring: Vec::new(),
            intensity: Vec::new(),
            firings: Vec::new(),
            time_s: 0.0,
            started: false,
            last_s: None,
            armed: true,
            partial: 0,
        }
    }

    /// Decodes one data packet (already validated).
    fn packet(&mut self, dec: &Decoder, p: &[u8], dual: bool, time: f64) {
        let per_firing = if dual { 2 } else { 1 };
        let firings = BLOCKS / per_firing;
        let azimuth = |f: usize| {
            let blk = &p[f * per_firing * BLOCK_LEN..];
            u16::from_le_bytes([blk[2], blk[3]]) as u32
        };
        // Azimuth step from each firing to the next, 0.01 degree; the last firing and glitches
        // take the nearest valid step before (else after) them in this packet.
        let mut step = [None::<u32>; BLOCKS];
        for (f, s) in step.iter_mut().enumerate().take(firings - 1) {
            let d = (azimuth(f + 1) + 36000 - azimuth(f)) % 36000;
            *s = (d <= MAX_FIRING_STEP).then_some(d);
        }
        let mut last = None;
        for s in step.iter_mut().take(firings) {
            *s = s.or(last);
            last = *s;
        }
        let mut next = None;
        for s in step[..firings].iter_mut().rev() {
            *s = s.or(next);
            next = *s;
        }

        let rad_per_h = std::f64::consts::PI / 18000.0;
        let mut cos_a = [0f64; RETURNS];
        let mut sin_a = [0f64; RETURNS];
        for f in 0..firings {
            let a0 = azimuth(f) as f64;
            // The pcap timestamp is taken as the packet's first firing (the sensor's own
            // packet timestamp marks that firing too); firings and lasers follow at their
            // documented intervals.
            let t_f = time + f as f64 * dec.firing_s;
            let da = step[f].unwrap_or(0) as f64;
            let (sin0, cos0) = (a0 * rad_per_h).sin_cos();
            // Where this firing crosses 180 degrees, if it does, and whether that crossing is
            // the very first return of the capture (then there is no leading partial turn).
            let mut cut = None;
            for (ch, slot) in dec.slots.iter().enumerate() {
                // a0 < 36000 and the step is at most 200: one wrap at most (no fmod).
                let mut s = a0 + da * slot.fraction - 18000.0;
                if s < 0.0 {
                    s += TURN;
                } else if s >= TURN {
                    s -= TURN;
                }
                let crossing = match self.last_s {
                    None => s == 0.0,
                    Some(prev) => self.armed && s + 18000.0 < prev,
                };
                let t = t_f + slot.fraction * dec.firing_s;
                if crossing {
                    // The turn ends and the next begins at this return (the closing firing
                    // is unwrapped past the seam by `boundary_times`).
                    cut = Some((ch, self.last_s.is_none(), [s / TURN, t]));
                    if self.started {
                        self.firings.push([s / TURN, t]);
                    }
                    self.armed = false;
                } else if !self.armed && (9000.0..27000.0).contains(&s) {
                    self.armed = true;
                }
                if ch == 0 && !crossing && self.started {
                    self.firings.push([s / TURN, t]);
                }
                self.last_s = Some(s);
                // sin/cos of a0 + delta by the angle sum, delta (at most 2 degrees) by its
                // series: exact to about 1e-14, one sin_cos per firing instead of per return.
                let delta = da * slot.fraction * rad_per_h;
                let d2 = delta * delta;
                let cos_d = 1.0 - d2 * (1.0 / 2.0 - d2 * (1.0 / 24.0 - d2 * (1.0 / 720.0)));
                let sin_d = delta * (1.0 - d2 * (1.0 / 6.0 - d2 * (1.0 / 120.0 - d2 * (1.0 / 5040.0))));
                cos_a[ch] = cos0 * cos_d - sin0 * sin_d;
                sin_a[ch] = sin0 * cos_d + cos0 * sin_d;
            }
            let blocks = &p[f * per_firing * BLOCK_LEN..(f + 1) * per_firing * BLOCK_LEN];
            match cut {
                None => self.emit(dec, blocks, 0..RETURNS, &cos_a, &sin_a),
                Some((k, at_start, opening)) => {
                    self.emit(dec, blocks, 0..k, &cos_a, &sin_a);
                    self.cut(dec, time, at_start);
                    self.firings.push(opening);
                    self.emit(dec, blocks, k..RETURNS, &cos_a, &sin_a);
                }
            }
        }
    }

    /// Appends the returns of slots `chs` of the blocks of one firing to the current turn.
    fn emit(
        &mut self,
        dec: &Decoder,
        blocks: &[u8],
        chs: std::ops::Range<usize>,
        cos_a: &[f64; RETURNS],
        sin_a: &[f64; RETURNS],
    ) {
        if !self.started {
            return;
        }
        for ch in chs {
            let slot = &dec.slots[ch];
            for blk in blocks.chunks_exact(BLOCK_LEN) {
                let i = 4 + 3 * ch;
                let raw = u16::from_le_bytes([blk[i], blk[i + 1]]);
                if raw == 0 {
                    continue;
                }
                let d = raw as f64 * DISTANCE_M;
                let xy = d * slot.cos_el;
                self.points.push([
                    (xy * cos_a[ch]) as f32,
                    (-xy * sin_a[ch]) as f32,
                    (d * slot.sin_el) as f32,
                ]);
                self.ring.push(slot.ring);
                self.intensity.push(blk[i + 2] as f32);
            }
        }
    }

    /// Closes the current turn (or drops the leading partial one, unless the crossing is the
    /// capture's very first return) at a 180-degree crossing in the packet captured at `time`.
    fn cut(&mut self, dec: &Decoder, time: f64, at_start: bool) {
        if self.started {
            let cap = self.points.len() + self.points.len() / 8;
            let firing_cap = self.firings.len() + 16;
            self.scans.push(Scan {
                points: std::mem::replace(&mut self.points, Vec::with_capacity(cap)),
                ring: Some(std::mem::replace(&mut self.ring, Vec::with_capacity(cap))),
                ring_elevation_deg: Some(dec.ring_elevation_deg.clone()),
                time_s: Some(self.time_s),
                intensity: Some(std::mem::replace(&mut self.intensity, Vec::with_capacity(cap))),
                firing_times: Some(std::mem::replace(&mut self.firings, Vec::with_capacity(firing_cap))),
            });
        } else if !at_start {
            self.partial += 1;
        }
        self.started = true;
        self.time_s = time;
    }
}

#[cfg(test)]
mod tests;
