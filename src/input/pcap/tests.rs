use super::*;
use std::path::Path;

const HDL: u8 = 0x21;
const VLP: u8 = 0x22;
const STRONGEST: u8 = 0x37;
const DUAL: u8 = 0x39;

/// A classic pcap file being written.
struct PcapWriter {
    big_endian: bool,
    nanos: bool,
    bytes: Vec<u8>,
}

impl PcapWriter {
    fn new(big_endian: bool, nanos: bool, link: u32) -> PcapWriter {
        let mut w = PcapWriter { big_endian, nanos, bytes: Vec::new() };
        w.u32(if nanos { 0xA1B2_3C4D } else { 0xA1B2_C3D4 });
        w.u16(2);
        w.u16(4);
        w.u32(0);
        w.u32(0);
        w.u32(65535);
        w.u32(link);
        w
    }
    fn u16(&mut self, v: u16) {
        let b = if self.big_endian { v.to_be_bytes() } else { v.to_le_bytes() };
        self.bytes.extend_from_slice(&b);
    }
    fn u32(&mut self, v: u32) {
        let b = if self.big_endian { v.to_be_bytes() } else { v.to_le_bytes() };
        self.bytes.extend_from_slice(&b);
    }
    /// One record at `sec` + `micros` microseconds.
    fn record(&mut self, sec: u32, micros: u32, frame: &[u8]) {
        self.u32(sec);
        self.u32(if self.nanos { micros * 1000 } else { micros });
        self.u32(frame.len() as u32);
        self.u32(frame.len() as u32);
        self.bytes.extend_from_slice(frame);
    }
}

fn write_file(bytes: &[u8]) -> tempfile::NamedTempFile {
    let mut f = tempfile::Builder::new().suffix(".pcap").tempfile().unwrap();
    std::io::Write::write_all(&mut f, bytes).unwrap();
    f
}

/// An IPv4 packet carrying `payload` as protocol `proto` (17 = UDP gets a UDP header).
fn ipv4(proto: u8, payload: &[u8], fragment: u16) -> Vec<u8> {
    let mut l4 = Vec::new();
    match proto {
        17 => {
            l4.extend_from_slice(&2368u16.to_be_bytes());
            l4.extend_from_slice(&2368u16.to_be_bytes());
            l4.extend_from_slice(&((payload.len() + 8) as u16).to_be_bytes());
            l4.extend_from_slice(&[0, 0]);
        }
        6 => {
            let mut tcp = [0u8; 20];
            tcp[12] = 5 << 4;
            l4.extend_from_slice(&tcp);
        }
        _ => {}
    }
    l4.extend_from_slice(payload);
    let mut ip = vec![0x45, 0];
    ip.extend_from_slice(&((20 + l4.len()) as u16).to_be_bytes());
    ip.extend_from_slice(&[0, 0]);
    ip.extend_from_slice(&fragment.to_be_bytes());
    ip.extend_from_slice(&[64, proto, 0, 0, 192, 168, 1, 201, 255, 255, 255, 255]);
    ip.extend_from_slice(&l4);
    ip
}

fn ethernet(ethertype: u16, body: &[u8]) -> Vec<u8> {
    let mut f = vec![0xFF; 6];
    f.extend_from_slice(&[0x60, 0x76, 0x88, 0x20, 0x12, 0x6E]);
    f.extend_from_slice(&ethertype.to_be_bytes());
    f.extend_from_slice(body);
    f
}

fn udp_frame(payload: &[u8]) -> Vec<u8> {
    ethernet(0x0800, &ipv4(17, payload, 0))
}

/// A data packet: block azimuths (0.01 deg) and distances (2 mm units) per block and slot.
fn data_packet(product: u8, mode: u8, azimuth: [u16; 12], dist: impl Fn(usize, usize) -> u16) -> Vec<u8> {
    let mut p = Vec::with_capacity(PACKET_LEN);
    for (b, az) in azimuth.iter().enumerate() {
        p.extend_from_slice(&[0xFF, 0xEE]);
        p.extend_from_slice(&az.to_le_bytes());
        for ch in 0..32 {
            p.extend_from_slice(&dist(b, ch).to_le_bytes());
            p.push(100);
        }
    }
    p.extend_from_slice(&[0x10, 0x20, 0x30, 0x00, mode, product]);
    assert_eq!(p.len(), PACKET_LEN);
    p
}

/// `packets` data packets of a sensor turning `step` (0.01 deg) per firing from azimuth
/// `a0`; `dist(firing, block_of_firing, slot)` with firings counted over the whole capture.
fn spin(
    product: u8,
    mode: u8,
    a0: u32,
    step: u32,
    packets: usize,
    dist: impl Fn(usize, usize, usize) -> u16,
) -> Vec<Vec<u8>> {
    let per = if mode == DUAL { 2 } else { 1 };
    (0..packets)
        .map(|k| {
            let firing = |b: usize| k * 12 / per + b / per;
            let az = std::array::from_fn(|b| ((a0 + step * firing(b) as u32) % 36000) as u16);
            data_packet(product, mode, az, |b, ch| dist(firing(b), b % per, ch))
        })
        .collect()
}

/// Packet `k` is captured at 1000 s + k ms.
fn capture(packets: &[Vec<u8>]) -> PcapWriter {
    let mut w = PcapWriter::new(false, false, 1);
    for (k, p) in packets.iter().enumerate() {
        w.record(1000, 1000 * k as u32, &udp_frame(p));
    }
    w
}

fn expected(d: f64, el_deg: f64, az_deg: f64) -> [f64; 3] {
    let (el, az) = (el_deg.to_radians(), az_deg.to_radians());
    [d * el.cos() * az.cos(), -d * el.cos() * az.sin(), d * el.sin()]
}

fn assert_point(p: [f32; 3], want: [f64; 3]) {
    for i in 0..3 {
        assert!((p[i] as f64 - want[i]).abs() < 2e-5, "{p:?} vs {want:?}");
    }
}

fn read(bytes: &[u8]) -> Result<PcapRecording> {
    let f = write_file(bytes);
    read_pcap(f.path())
}

/// Velodyne azimuth of a decoded point, degrees in [0, 360).
fn azimuth_deg(p: [f32; 3]) -> f64 {
    (-p[1] as f64).atan2(p[0] as f64).to_degrees().rem_euclid(360.0)
}

#[test]
fn a_recorded_hdl32e_turn_fills_the_hdl32e_grid_row_to_row() {
    // 0.2 degree per firing (1800 firings a turn, more than the 1024 columns); laser `ch`
    // measures 4 m + 0.25 m * ch, so every cell says which laser filled it.
    let packets = spin(0x21, 0x37, 17_000, 20, 400, |_, _, ch| ((4.0 + 0.25 * ch as f64) / 0.002).round() as u16);
    let rec = read(&capture(&packets).bytes).unwrap();
    assert!(!rec.scans.is_empty());
    let target = crate::sensor::Sensor::hdl32e();
    let projector = crate::input::project::Projector::new(&target);
    let mut ranges = Vec::new();
    let stats = projector.project(&rec.scans[0], &mut ranges);
    assert!(stats.ring_mapped);
    assert_eq!(stats.outside_band, 0);
    let laser_el = VelodyneModel::Hdl32e.elevation_deg();
    for (row, el) in target.elevation_deg.iter().enumerate() {
        let ch = laser_el.iter().position(|e| (e - el).abs() < 1e-9).expect("every target row is a laser");
        let want = (((4.0 + 0.25 * ch as f64) / 0.002).round() * 0.002) as f32;
        for col in 0..target.columns {
            let r = ranges[row * target.columns + col];
            assert!((r - want).abs() < 1e-4, "row {row} col {col}: {r} vs laser {ch}'s {want}");
        }
    }
}

#[test]
fn hdl32e_returns_decode_to_exact_xyz_with_ring() {
    // 1 degree per firing from 90 degrees: turns start at firings 90 and 450.
    let dist = |f: usize, _: usize, ch: usize| match (f, ch) {
        (100, 0) => 5000,  // 10 m, laser 0 (-30.67 deg), azimuth 190
        (100, 31) => 2500, // 5 m, laser 31 (10.67 deg), 31 * 1.152 us later
        (107, 20) => 1000, // 2 m, last block of packet 8: extrapolated step
        (360, 15) => 500,  // 1 m at azimuth 90 (to the right), laser 15 (0 deg)
        _ => 0,
    };
    let rec = read(&capture(&spin(HDL, STRONGEST, 9000, 100, 70, dist)).bytes).unwrap();
    assert_eq!(rec.model, VelodyneModel::Hdl32e);
    assert_eq!(rec.model.name(), "HDL-32E");
    assert_eq!((rec.data_packets, rec.foreign_packets, rec.partial_rotations), (70, 0, 2));
    assert_eq!(rec.scans.len(), 2);
    let s = &rec.scans[0];
    assert_eq!(s.points.len(), 4);
    assert_point(s.points[0], expected(10.0, -30.67, 190.0));
    assert_point(s.points[1], expected(5.0, 10.67, 190.0 + 31.0 * 1.152 / 46.08));
    assert_point(s.points[2], expected(2.0, -17.33, 197.0 + 20.0 * 1.152 / 46.08));
    assert_point(s.points[3], expected(1.0, 0.0, 90.0 + 15.0 * 1.152 / 46.08));
    // Clockwise from ahead: 90 degrees is to the right, -y in pedscan's frame.
    assert!(s.points[3][1] < -0.99 && s.points[3][0].abs() < 0.01);
    let ring = s.ring.as_ref().unwrap();
    assert_eq!(ring, &vec![0, 31, 10, 23]);
    // Each return's reflectivity byte (the packets here say 100 everywhere).
    assert_eq!(s.intensity.as_deref(), Some(&[100.0f32; 4][..]));
    let re = s.ring_elevation_deg.as_ref().unwrap();
    assert_eq!(re.len(), 32);
    assert!(re.windows(2).all(|w| w[0] < w[1]));
    for (i, el) in [-30.67, 10.67, -17.33, 0.0].iter().enumerate() {
        assert_eq!(re[ring[i] as usize], *el);
    }
    // The second turn has no returns at all: still a turn.
    assert!(rec.scans[1].points.is_empty());
    assert_eq!(rec.scans[1].ring_elevation_deg.as_ref(), Some(re));
}

#[test]
fn vlp16_second_firing_sequence_is_halfway_to_the_next_block() {
    let dist = |f: usize, _: usize, ch: usize| match (f, ch) {
        (100, 3) => 5000,  // laser 3 (3 deg), first sequence
        (100, 16) => 4000, // laser 0 (-15 deg), second sequence: halfway
        (100, 21) => 3000, // laser 5 (5 deg), second sequence
        _ => 0,
    };
    let rec = read(&capture(&spin(VLP, STRONGEST, 9000, 100, 70, dist)).bytes).unwrap();
    assert_eq!(rec.model, VelodyneModel::Vlp16);
    assert_eq!(rec.model.name(), "VLP-16");
    assert_eq!(rec.scans.len(), 2);
    let s = &rec.scans[0];
    assert_eq!(s.points.len(), 3);
    assert_point(s.points[0], expected(10.0, 3.0, 190.0 + 3.0 * 2.304 / 110.592));
    assert_point(s.points[1], expected(8.0, -15.0, 190.5));
    assert_point(s.points[2], expected(6.0, 5.0, 190.5 + 5.0 * 2.304 / 110.592));
    assert_eq!(s.ring.as_ref().unwrap(), &vec![9, 0, 10]);
    let re = s.ring_elevation_deg.as_ref().unwrap();
    assert_eq!(re, &(0..16).map(|i| -15.0 + 2.0 * i as f64).collect::<Vec<_>>());
    assert_eq!(VelodyneModel::Vlp16.elevation_deg().len(), 16);
    assert_eq!(VelodyneModel::Hdl32e.elevation_deg().len(), 32);
}

/// `packets` with the sensor's own timestamp of packet k at `t0 + k * step_us` (wrapping at the hour).
fn stamped(mut packets: Vec<Vec<u8>>, t0: u64, step_us: f64) -> Vec<Vec<u8>> {
    for (k, p) in packets.iter_mut().enumerate() {
        let us = ((t0 as f64 + k as f64 * step_us).round() as u64 % 3_600_000_000) as u32;
        p[1200..1204].copy_from_slice(&us.to_le_bytes());
    }
    packets
}

#[test]
fn a_vlp16_that_writes_the_hdl32es_product_id_is_told_by_its_packet_spacing() {
    // The VLP-16 test above, its packets claiming 0x21 (HDL-32E) but stamped 1327.104 us
    // apart, across the hour's wrap: decoded as a VLP-16, the same points.
    let dist = |f: usize, _: usize, ch: usize| match (f, ch) {
        (100, 3) => 5000,
        (100, 16) => 4000,
        _ => 0,
    };
    let vlp_packet_us = 12.0 * VLP16_FIRING_US;
    let truth = read(&capture(&spin(VLP, STRONGEST, 9000, 100, 70, dist)).bytes).unwrap();
    let rec = read(&capture(&stamped(spin(HDL, STRONGEST, 9000, 100, 70, dist), 3_599_990_000, vlp_packet_us)).bytes).unwrap();
    assert_eq!(rec.model, VelodyneModel::Vlp16);
    let (claimed, us) = rec.relabelled.unwrap();
    assert_eq!(claimed, VelodyneModel::Hdl32e);
    assert!((us - vlp_packet_us).abs() <= 1.0, "{us}");
    assert_eq!(rec.scans, truth.scans);
    assert!(truth.relabelled.is_none());
    // Its own id and its own spacing; an HDL-32E at an HDL-32E's spacing (dual return: half);
    // stamps that fit neither sensor, or too few of them: the product id decides.
    for (id, mode, step, want) in [
        (VLP, STRONGEST, vlp_packet_us, VelodyneModel::Vlp16),
        (HDL, STRONGEST, 12.0 * HDL32E_FIRING_US, VelodyneModel::Hdl32e),
        (HDL, DUAL, 6.0 * HDL32E_FIRING_US, VelodyneModel::Hdl32e),
        (HDL, STRONGEST, 1000.0, VelodyneModel::Hdl32e),
        (VLP, STRONGEST, 12.0 * HDL32E_FIRING_US * 1.08, VelodyneModel::Vlp16),
    ] {
        let n = if mode == DUAL { 140 } else { 70 };
        let rec = read(&capture(&stamped(spin(id, mode, 9000, 100, n, |_, _, _| 1000), 5, step)).bytes).unwrap();
        assert_eq!((rec.model, rec.relabelled), (want, None), "id {id:#x}, {step} us");
    }
    // A VLP-16 dual-return capture claiming the HDL-32E's id: 663.552 us apart.
    let rec = read(&capture(&stamped(spin(HDL, DUAL, 9000, 100, 140, |_, _, _| 1000), 5, vlp_packet_us / 2.0)).bytes).unwrap();
    assert_eq!(rec.model, VelodyneModel::Vlp16);
    // Only the first packets' stamps are read, and 16 steps are needed: fewer decide nothing.
    let mut few = stamped(spin(HDL, STRONGEST, 9000, 100, 70, |_, _, _| 1000), 5, vlp_packet_us);
    for p in few.iter_mut().skip(16) {
        p[1200..1204].copy_from_slice(&[0; 4]);
    }
    assert_eq!(read(&capture(&few).bytes).unwrap().model, VelodyneModel::Hdl32e);
    few[16][1200..1204].copy_from_slice(&((5.0 + 16.0 * vlp_packet_us).round() as u32).to_le_bytes());
    assert_eq!(read(&capture(&few).bytes).unwrap().model, VelodyneModel::Vlp16);
}

#[test]
fn a_capture_that_fires_fewer_times_a_turn_than_the_grid_has_columns_is_warned_of() {
    // 0.1 degree a firing: 3,600 firings a turn, enough for 1024 columns, not for 4096.
    let f = write_file(&capture(&spin(HDL, STRONGEST, 9000, 10, 700, |_, _, _| 1000)).bytes);
    let open = |columns: usize| {
        let target = crate::sensor::Sensor { columns, ..crate::sensor::Sensor::hdl32e() };
        crate::input::recording::Recording::open(f.path(), None, &target).unwrap()
    };
    assert!(open(1024).coverage_warning.is_none() && open(3600).coverage_warning.is_none());
    let w = open(3601).coverage_warning.unwrap();
    assert!(w.contains("fired 3600 times a turn, fewer than the grid's 3601 columns"), "{w}");
    let w = open(4096).coverage_warning.unwrap();
    assert!(w.contains("fired 3600 times a turn, fewer than the grid's 4096 columns: at least 12.1 %"), "{w}");
    // A VLP-16 fires two sequences a block: 0.2 degree a block is 3,600 firings a turn too.
    let f = write_file(&capture(&spin(VLP, STRONGEST, 9000, 20, 400, |_, _, _| 1000)).bytes);
    let target = crate::sensor::Sensor { columns: 4096, ..crate::sensor::Sensor::vlp16() };
    let w = crate::input::recording::Recording::open(f.path(), None, &target).unwrap().coverage_warning.unwrap();
    assert!(w.starts_with("the VLP-16 fired 3600 times a turn, fewer than the grid's 4096 columns"), "{w}");
}

#[test]
fn turns_are_cut_at_180_degrees_and_partial_turns_counted() {
    // Blocks at ...51: the crossing falls inside a block, at slot 20 (17951 + 20 * 2.5).
    // Slot 7 never returns: zero distances are skipped.
    let dist = |f: usize, _: usize, ch: usize| if ch == 7 { 0 } else { 1000 + (f % 100) as u16 };
    let rec = read(&capture(&spin(HDL, STRONGEST, 9051, 100, 80, dist)).bytes).unwrap();
    // Crossings at firings 89, 449 and 809 (packets 7, 37, 67): two whole turns.
    assert_eq!(rec.scans.len(), 2);
    assert_eq!(rec.partial_rotations, 2);
    assert_eq!(rec.data_packets, 80);
    let times: Vec<f64> = rec.scans.iter().map(|s| s.time_s.unwrap()).collect();
    assert!((times[0] - 1000.007).abs() < 1e-9 && (times[1] - 1000.037).abs() < 1e-9, "{times:?}");
    for s in &rec.scans {
        assert_eq!(s.points.len(), 360 * 31);
        assert!(s.points.iter().all(|p| p[0] != 0.0 || p[1] != 0.0));
        assert!(!s.ring.as_ref().unwrap().contains(&ring_of_laser7()));
        // One full turn clockwise from straight behind: the azimuth measured from 180
        // degrees rises from 0 to just under 360.
        let from_behind: Vec<f64> =
            s.points.iter().map(|&p| (azimuth_deg(p) - 180.0).rem_euclid(360.0)).collect();
        assert!((from_behind[0] - 0.01).abs() < 1e-4, "{}", from_behind[0]);
        assert!(*from_behind.last().unwrap() > 359.9);
        assert!(from_behind.windows(2).all(|w| w[1] >= w[0] - 1e-6));
    }
}

#[test]
fn jitter_back_across_the_seam_does_not_cut_twice() {
    // Firing 90 sits at 180.00 degrees (the cut); firing 91 steps back to 179.99.
    let mut packets = spin(HDL, STRONGEST, 9000, 100, 70, |_, _, _| 1000);
    let block = &mut packets[91 / 12][(91 % 12) * BLOCK_LEN..];
    block[2..4].copy_from_slice(&17999u16.to_le_bytes());
    let rec = read(&capture(&packets).bytes).unwrap();
    assert_eq!((rec.scans.len(), rec.partial_rotations), (2, 2));
    assert_eq!(rec.scans[0].points.len(), 360 * 32);
    assert!((rec.scans[0].time_s.unwrap() - 1000.007).abs() < 1e-9);
}

fn ring_of_laser7() -> u16 {
    let el = VelodyneModel::Hdl32e.elevation_deg();
    el.iter().filter(|&&e| e < el[7]).count() as u16
}

#[test]
fn dual_return_keeps_both_returns_at_the_same_azimuth() {
    let dist = |f: usize, b: usize, ch: usize| match (f, ch) {
        (100, 4) => [3000, 4000][b],
        (101, 4) => [2000, 0][b], // one return only
        _ => 0,
    };
    let rec = read(&capture(&spin(HDL, DUAL, 9000, 100, 140, dist)).bytes).unwrap();
    assert_eq!(rec.scans.len(), 2);
    let s = &rec.scans[0];
    assert_eq!(s.points.len(), 3);
    let az = 190.0 + 4.0 * 1.152 / 46.08;
    assert_point(s.points[0], expected(6.0, -28.0, az));
    assert_point(s.points[1], expected(8.0, -28.0, az));
    assert_point(s.points[2], expected(4.0, -28.0, az + 1.0));
}

#[test]
fn foreign_packets_are_skipped_and_counted() {
    let packets = spin(HDL, STRONGEST, 9000, 100, 70, |_, _, ch| 1000 + ch as u16);
    let clean = read(&capture(&packets).bytes).unwrap();
    let mut w = PcapWriter::new(false, false, 1);
    let mut bad_flag = packets[0].clone();
    bad_flag[500] = 0xDD; // block 5's flag
    let mut unknown_product = packets[0].clone();
    unknown_product[PACKET_LEN - 1] = 0x28;
    let foreign: Vec<Vec<u8>> = vec![
        udp_frame(&[0u8; 512]),                        // position (GPS) packet
        ethernet(0x0800, &ipv4(6, &packets[0], 0)),    // TCP carrying a data payload
        udp_frame(b"not a lidar"),                     // other UDP traffic
        udp_frame(&bad_flag),                          // 1206 bytes, bad block flag
        udp_frame(&unknown_product),                   // unknown product id
        ethernet(0x0800, &ipv4(17, &packets[0], 0x2000)), // IP fragment (more fragments)
        ethernet(0x0806, &[0u8; 28]),                  // ARP
        udp_frame(&packets[0])[..600].to_vec(),        // cut by the snap length
    ];
    for (k, p) in packets.iter().enumerate() {
        w.record(1000, 1000 * k as u32, &udp_frame(p));
        if k % 9 == 0 {
            w.record(1000, 1000 * k as u32 + 1, &foreign[(k / 9) % foreign.len()]);
        }
    }
    let rec = read(&w.bytes).unwrap();
    assert_eq!(rec.foreign_packets, 8);
    assert_eq!(rec.data_packets, 70);
    assert_eq!(rec.scans, clean.scans);
}

#[test]
fn byte_orders_nanoseconds_and_link_types_decode_alike() {
    let packets = spin(VLP, STRONGEST, 20000, 100, 95, |f, _, ch| (500 + f + ch) as u16);
    let reference = read(&capture(&packets).bytes).unwrap();
    assert_eq!(reference.scans.len(), 2);
    let sll = |ip: &[u8]| {
        let mut f = vec![0, 0, 0, 1, 0, 6, 1, 2, 3, 4, 5, 6, 0, 0, 0x08, 0x00];
        f.extend_from_slice(ip);
        f
    };
    let vlan = |ip: &[u8]| {
        let mut body = vec![0x00, 0x05, 0x08, 0x00];
        body.extend_from_slice(ip);
        ethernet(0x8100, &body)
    };
    type Framing = Box<dyn Fn(&[u8]) -> Vec<u8>>;
    let variants: Vec<(bool, bool, u32, Framing)> = vec![
        (true, false, 1, Box::new(|ip: &[u8]| ethernet(0x0800, ip))),
        (false, true, 1, Box::new(|ip: &[u8]| ethernet(0x0800, ip))),
        (true, true, 1, Box::new(|ip: &[u8]| ethernet(0x0800, ip))),
        (false, false, 1, Box::new(vlan)),
        (true, false, 113, Box::new(sll)),
        (false, false, 101, Box::new(|ip: &[u8]| ip.to_vec())),
        (false, true, 228, Box::new(|ip: &[u8]| ip.to_vec())),
    ];
    for (be, nanos, link, frame) in variants {
        let mut w = PcapWriter::new(be, nanos, link);
        for (k, p) in packets.iter().enumerate() {
            w.record(1000, 1000 * k as u32, &frame(&ipv4(17, p, 0)));
        }
        let rec = read(&w.bytes).unwrap();
        assert_eq!(rec, reference, "big endian {be}, nanoseconds {nanos}, link {link}");
    }
}

#[test]
fn a_truncated_file_names_the_packet_and_its_offset() {
    let w = capture(&spin(HDL, STRONGEST, 9000, 100, 70, |_, _, _| 1000));
    let record = 16 + 42 + PACKET_LEN;
    // Cut inside packet 70's data, then inside its record header.
    for (cut, what) in [(10, "packet cut short"), (record - 5, "truncated record header")] {
        let e = read(&w.bytes[..w.bytes.len() - cut]).unwrap_err();
        assert!(e.is_input());
        let want = format!(".pcap: packet 70 (byte {}): {what}", 24 + 69 * record);
        assert!(e.to_string().contains(&want), "{e}");
    }
    let e = read(&w.bytes[..10]).unwrap_err();
    assert!(e.to_string().contains("truncated pcap header"), "{e}");
}

#[test]
fn no_complete_rotation_is_an_error() {
    let mut w = capture(&spin(HDL, STRONGEST, 9000, 100, 20, |_, _, _| 1000));
    w.record(2000, 0, &udp_frame(&[0u8; 512]));
    let f = write_file(&w.bytes);
    let e = read_pcap(f.path()).unwrap_err();
    assert!(e.is_input());
    let want = format!("{}: no complete rotation: 20 data packets, 1 foreign", f.path().display());
    assert_eq!(e.to_string(), want);
}

#[test]
fn mixed_product_ids_are_an_error_naming_the_packet() {
    let mut packets = spin(HDL, STRONGEST, 9000, 100, 70, |_, _, _| 1000);
    packets[40][PACKET_LEN - 1] = VLP;
    let e = read(&capture(&packets).bytes).unwrap_err();
    assert!(e.is_input());
    let s = e.to_string();
    let at = format!("packet 41 (byte {})", 24 + 40 * (16 + 42 + PACKET_LEN));
    assert!(s.contains(&at) && s.contains("VLP-16") && s.contains("HDL-32E"), "{s}");
}

#[test]
fn pcapng_and_other_files_are_rejected() {
    let e = read(&[0x0A, 0x0D, 0x0D, 0x0A, 0x1C, 0, 0, 0, 0x4D, 0x3C, 0x2B, 0x1A]).unwrap_err();
    assert!(e.is_input() && e.to_string().contains("pcapng"), "{e}");
    let e = read(b"# not a capture at all\n").unwrap_err();
    assert!(e.is_input() && e.to_string().contains("not a pcap"), "{e}");
    let e = read(&PcapWriter::new(false, false, 105).bytes).unwrap_err();
    assert!(e.is_input() && e.to_string().contains("link type 105"), "{e}");
}

/// An HDL-32E in a 24 m room, 1.7 m above its floor, turning from azimuth 90 degrees by
/// `step(s)` (0.01 degree) per firing at azimuth `s` from behind, firing every 46.08 us
/// from 1000 s; `stamp_us(k, us)` may move packet `k`'s pcap timestamp (`us` from 1000 s,
/// rounded to the microsecond). Returns the capture and each firing's azimuth from behind,
/// 0.01 degree, unwrapped (firing `n` is at 1000 s + n * 46.08 us).
fn spinning_room(packets: usize, step: impl Fn(f64) -> f64, stamp_us: impl Fn(usize, u64) -> u64) -> (PcapWriter, Vec<f64>) {
    let mut from_behind = vec![-9000.0f64];
    for _ in 1..packets * 12 {
        let s = *from_behind.last().unwrap();
        from_behind.push(s + step(s.rem_euclid(TURN)));
    }
    let el = VelodyneModel::Hdl32e.elevation_deg();
    let mut w = PcapWriter::new(false, false, 1);
    for k in 0..packets {
        let az: [u16; 12] = std::array::from_fn(|b| (from_behind[12 * k + b] + 18000.0).rem_euclid(TURN) as u16);
        let p = data_packet(HDL, STRONGEST, az, |b, ch| {
            let (e, a) = (el[ch].to_radians(), (az[b] as f64 / 100.0).to_radians());
            let d = [e.cos() * a.cos(), -e.cos() * a.sin(), e.sin()];
            let mut r = if d[2] < -1e-9 { -1.7 / d[2] } else { f64::INFINITY };
            for dc in &d[..2] {
                if dc.abs() > 1e-9 {
                    r = r.min(12.0 / dc.abs());
                }
            }
            if r < 100.0 { (r / DISTANCE_M).round() as u16 } else { 0 }
        });
        let us = stamp_us(k, (k as f64 * 12.0 * HDL32E_FIRING_US).round() as u64);
        w.record(1000 + (us / 1_000_000) as u32, (us % 1_000_000) as u32, &udp_frame(&p));
    }
    (w, from_behind)
}

/// [`spinning_room`] at 0.1 degree per firing over the first half of each turn (from
/// behind, 225 packets a turn) and 0.2 over the second.
fn two_speed_room(packets: usize, stamp_us: impl Fn(usize, u64) -> u64) -> (PcapWriter, Vec<f64>) {
    spinning_room(packets, |s| if s < 18000.0 { 10.0 } else { 20.0 }, stamp_us)
}

/// When the sensor pointed at `target` (0.01 degree from behind, unwrapped), s.
fn time_at_azimuth(from_behind: &[f64], target: f64) -> f64 {
    let n = from_behind.partition_point(|&s| s <= target) - 1;
    let f = (target - from_behind[n]) / (from_behind[n + 1] - from_behind[n]);
    1000.0 + (n as f64 + f) * HDL32E_FIRING_US * 1e-6
}

/// The recorded step from frame `k` to the next (the last frame: from the one before).
fn recorded_step(times: &[f64], k: usize) -> f64 {
    let k = k.min(times.len() - 2);
    times[k + 1] - times[k]
}

fn room_config(path: &Path, frames: usize) -> crate::config::Config {
    let mut cfg = crate::config::Config::default();
    cfg.scene.background = path.to_path_buf();
    cfg.render.backend = crate::config::BackendChoice::Raycast;
    cfg.frames = frames;
    cfg.humans.count = [6, 6];
    cfg
}

/// The column times of a capture whose sensor turns at two speeds are its own, to the
/// microsecond of its timestamps, in the recording and in the generated frames (what
/// `/sensor/column_time_s` holds); the uniform sweep is milliseconds off.
#[test]
fn column_times_follow_the_packets_of_an_uneven_turn() {
    let (w, from_behind) = two_speed_room(1100, |_, us| us);
    let f = write_file(&w.bytes);
    let target = crate::sensor::Sensor::hdl32e();
    let cols = target.columns;
    let rec = crate::input::Recording::open(f.path(), None, &target).unwrap();
    assert!(rec.len() >= 4 && rec.sweep_warning.is_none(), "{} frames, {:?}", rec.len(), rec.sweep_warning);
    for k in 0..rec.len() {
        let b = rec.column_offsets(k).unwrap();
        assert_eq!(b.len(), cols + 1);
        for (c, o) in b.iter().enumerate() {
            let want = time_at_azimuth(&from_behind, 36000.0 * (k as f64 + c as f64 / cols as f64));
            assert!((rec.times_s[k] + o - want).abs() < 2e-6, "frame {k} boundary {c}: {} vs {want}", rec.times_s[k] + o);
        }
    }
    let mut gen = crate::generator::Generator::new(room_config(f.path(), rec.len())).unwrap();
    let plan = gen.plan(0).unwrap();
    assert_eq!(plan.recording_start, Some(0));
    let mut out = crate::output::FrameOutput::default();
    for k in 0..rec.len() {
        let state = gen.frame(&plan, k, &mut out).unwrap();
        let (mut worst, mut off_uniform) = (0.0f64, 0.0f64);
        let step = recorded_step(&rec.times_s, k);
        for (c, t) in out.column_time_s.iter().enumerate() {
            let u = c as f64 + 0.5;
            let want = time_at_azimuth(&from_behind, 36000.0 * (k as f64 + u / cols as f64)) - rec.times_s[0];
            worst = worst.max((t - want).abs());
            off_uniform = off_uniform.max((t - (state.t_s + step * u / cols as f64)).abs());
        }
        assert!(worst < 2e-6, "frame {k}: column times {worst} s from the packets'");
        assert!(off_uniform > 5e-3, "frame {k}: the uniform sweep is {off_uniform} s off");
        assert!(out.column_time_s.windows(2).all(|w| w[1] > w[0]));
    }
}

/// People under a capture's own sweep whose speed changes every 3 degrees (0.05 and 0.4
/// degree per firing, so most people span a change): the default (two poses per person,
/// every vertex moved to its column's time) against posing the whole frame at each
/// column's table time, as on the synthetic hall.
#[test]
fn people_are_posed_at_the_captures_column_times() {
    let (w, _) = spinning_room(900, |s| if (s / 300.0) as u32 % 2 == 0 { 5.0 } else { 40.0 }, |_, us| us);
    let f = write_file(&w.bytes);
    let mut cfg = room_config(f.path(), 2);
    cfg.humans.count = [16, 16];
    let report = crate::commands::shutter::shutter_check(cfg, 2).unwrap();
    eprintln!("{report}");
    assert!(report.human_beams > 50, "{report}");
    assert!(report.agreeing as f64 >= 0.99 * report.human_beams as f64, "{report}");
    assert!(report.human_error_m.median <= 1e-3 && report.human_error_m.p99 <= 5e-3, "{report}");
    // The sensor stands still, so what is left is the people's own motion: 0.007 mm
    // median here; moving vertices by the sweep's mean rate instead of its table (the
    // uniform sweep's linearisation) leaves 0.125 mm.
    assert!(report.human_error_m.median <= 4e-5, "{report}");
}

/// A clock that steps back inside a turn or jumps ahead: those frames take the uniform
/// sweep over their recorded step (finite, strictly increasing), the others keep their
/// own, and one warning names how many fell back and why.
#[test]
fn capture_clocks_that_step_back_or_jump_fall_back_to_the_uniform_sweep() {
    // Packet 400 lies inside the second turn, 700 inside the third (225 packets a turn).
    let (w, _) = two_speed_room(1100, |k, us| match k {
        400 => us - 10_000,
        700.. => us + 500_000,
        _ => us,
    });
    let f = write_file(&w.bytes);
    let target = crate::sensor::Sensor::hdl32e();
    let rec = crate::input::Recording::open(f.path(), None, &target).unwrap();
    let own: Vec<bool> = (0..rec.len()).map(|k| rec.column_offsets(k).is_some()).collect();
    assert_eq!(own[..4], [true, false, false, true], "{own:?}");
    let warning = rec.sweep_warning.as_deref().unwrap();
    assert!(warning.starts_with(&format!("2 of {} frames take the uniform sweep", rec.len())), "{warning}");
    assert!(warning.contains("frame 1: its timestamps go back by 9."), "{warning}");
    let mut gen = crate::generator::Generator::new(room_config(f.path(), rec.len())).unwrap();
    let plan = gen.plan(0).unwrap();
    let mut out = crate::output::FrameOutput::default();
    for (k, own) in own.iter().enumerate() {
        let state = gen.frame(&plan, k, &mut out).unwrap();
        let times = &out.column_time_s;
        assert!(times.iter().all(|t| t.is_finite()) && times.windows(2).all(|w| w[1] > w[0]), "frame {k}");
        if !own {
            let step = recorded_step(&plan.times_s, k);
            for (c, t) in times.iter().enumerate() {
                assert!((t - state.t_s - step * (c as f64 + 0.5) / times.len() as f64).abs() < 1e-9, "frame {k} column {c}");
            }
        }
    }
}

#[test]
fn realism_refuses_a_capture_of_another_sensor_than_the_output() {
    // Two whole VLP-16 turns, measured on an HDL-32E output's grid: refused by name, while
    // the same capture on a VLP-16 grid is measured.
    let dist = |f: usize, _: usize, _: usize| 2000 + (f % 50) as u16;
    let f = write_file(&capture(&spin(VLP, STRONGEST, 9051, 20, 400, dist)).bytes);
    let grid = |s: crate::sensor::Sensor| crate::commands::realism::Grid { dirs: s.beam_dirs(), sensor: s };
    let err = crate::commands::realism::measure_recording(f.path(), &grid(crate::sensor::Sensor::hdl32e()), None, false).unwrap_err().to_string();
    assert!(err.contains("a capture of another sensor (VLP-16: 16 rows") && err.contains("hdl32e: 32 rows"), "{err}");
    let m = crate::commands::realism::measure_recording(f.path(), &grid(crate::sensor::Sensor::vlp16()), None, false).unwrap();
    assert!(m.frames >= 2 && m.beams() > m.holes());
}
