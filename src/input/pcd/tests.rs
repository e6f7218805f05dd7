//! Tests of the PCD reader: every header field, ASCII / binary / compressed bodies, and the
//! malformed files it must refuse with a message naming the file.

use super::*;
use std::path::PathBuf;

#[allow(clippy::too_many_arguments)]
fn header(
    fields: &str,
    size: &str,
    ty: &str,
    count: &str,
    w: usize,
    h: usize,
    vp: &str,
    data: &str,
) -> String {
    format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {ty}\nCOUNT {count}\nWIDTH {w}\nHEIGHT {h}\nVIEWPOINT {vp}\nPOINTS {}\nDATA {data}\n",
        w * h
    )
}

const ID: &str = "0 0 0 1 0 0 0";

fn write(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.path().join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// LZF made of literal runs only (valid LZF, no compression).
fn lzf_literals(data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    for chunk in data.chunks(32) {
        out.push((chunk.len() - 1) as u8);
        out.extend_from_slice(chunk);
    }
    out
}

fn compressed_file(head: &str, lzf: &[u8], uncompressed: usize) -> Vec<u8> {
    let mut b = head.as_bytes().to_vec();
    b.extend_from_slice(&(lzf.len() as u32).to_le_bytes());
    b.extend_from_slice(&(uncompressed as u32).to_le_bytes());
    b.extend_from_slice(lzf);
    b
}

fn err(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> String {
    let e = read_pcd(&write(dir, name, bytes)).unwrap_err();
    assert!(e.is_input(), "{e}");
    e.to_string()
}

fn sample() -> Vec<[f32; 3]> {
    (0..50)
        .map(|i| [i as f32 * 0.5 + 1.0, -(i as f32) * 0.25, (i as f32 * 0.1).sin()])
        .collect()
}

#[test]
fn ascii_with_comments_nan_and_zero() {
    let d = tempfile::tempdir().unwrap();
    let mut s = header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", 5, 1, ID, "ascii");
    s.push_str("1 2 3 10\nnan nan nan 0\n\n0 0 0 5\n-1.5 2.5e1 -3 7\n4 5 6 1\n");
    let scan = read_pcd(&write(&d, "a.pcd", s.as_bytes())).unwrap();
    assert_eq!(scan.points, vec![[1.0, 2.0, 3.0], [-1.5, 25.0, -3.0], [4.0, 5.0, 6.0]]);
    assert!(scan.ring.is_none() && scan.ring_elevation_deg.is_none());
    // The kept points' intensities.
    assert_eq!(scan.intensity, Some(vec![10.0, 7.0, 1.0]));
}

#[test]
fn binary_f32_and_f64() {
    let d = tempfile::tempdir().unwrap();
    let pts = sample();
    let mut b =
        header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", pts.len(), 1, ID, "binary")
            .into_bytes();
    for p in &pts {
        for v in p {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&7.0f32.to_le_bytes());
    }
    let scan = read_pcd(&write(&d, "b.pcd", &b)).unwrap();
    assert_eq!(scan.points, pts);
    assert_eq!(scan.intensity, Some(vec![7.0; pts.len()]));

    // Doubles, with the fields in another order.
    let mut b =
        header("intensity z y x", "4 8 8 8", "F F F F", "1 1 1 1", pts.len(), 1, ID, "binary")
            .into_bytes();
    for p in &pts {
        b.extend_from_slice(&1.0f32.to_le_bytes());
        for v in [p[2], p[1], p[0]] {
            b.extend_from_slice(&(v as f64).to_le_bytes());
        }
    }
    assert_eq!(read_pcd(&write(&d, "b64.pcd", &b)).unwrap().points, pts);

    // An integer intensity (Ouster-style U2) and an unsupported one (COUNT 2: passed over).
    let mut b = header("x y z intensity", "4 4 4 2", "F F F U", "1 1 1 1", pts.len(), 1, ID, "binary").into_bytes();
    for (i, p) in pts.iter().enumerate() {
        for v in p {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&(100 + i as u16).to_le_bytes());
    }
    let want: Vec<f32> = (0..pts.len()).map(|i| 100.0 + i as f32).collect();
    assert_eq!(read_pcd(&write(&d, "u2.pcd", &b)).unwrap().intensity, Some(want));
    let mut b = header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 2", pts.len(), 1, ID, "binary").into_bytes();
    for p in &pts {
        for v in p {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&[0u8; 8]);
    }
    let scan = read_pcd(&write(&d, "i2.pcd", &b)).unwrap();
    assert_eq!((scan.points.len(), scan.intensity), (pts.len(), None));
}

#[test]
fn binary_compressed_with_literal_runs() {
    let d = tempfile::tempdir().unwrap();
    let pts = sample();
    let n = pts.len();
    // Column-wise: all x, all y, all z, all intensity.
    let mut raw = Vec::new();
    for a in 0..3 {
        for p in &pts {
            raw.extend_from_slice(&p[a].to_le_bytes());
        }
    }
    for i in 0..n {
        raw.extend_from_slice(&(i as f32).to_le_bytes());
    }
    let head = header(
        "x y z intensity",
        "4 4 4 4",
        "F F F F",
        "1 1 1 1",
        n,
        1,
        ID,
        "binary_compressed",
    );
    let b = compressed_file(&head, &lzf_literals(&raw), raw.len());
    let scan = read_pcd(&write(&d, "c.pcd", &b)).unwrap();
    assert_eq!(scan.points, pts);
    assert_eq!(scan.intensity, Some((0..n).map(|i| i as f32).collect()));
}

#[test]
fn binary_compressed_with_a_back_reference() {
    let d = tempfile::tempdir().unwrap();
    // 3 points, z = 2.0 everywhere: the z column is one literal float then a
    // back-reference 4 bytes back, 8 bytes long (overlapping copy).
    let xs = [1.0f32, 2.0, 3.0];
    let ys = [-1.0f32, -2.0, -3.0];
    let mut lit = Vec::new();
    for v in xs.iter().chain(&ys).chain(&[2.0f32]) {
        lit.extend_from_slice(&v.to_le_bytes());
    }
    let mut lzf = lzf_literals(&lit); // 28 bytes: one run
                                      // ctrl: length field 6 (6 + 2 = 8 bytes), distance high bits 0; then low byte 3 (4 back).
    lzf.extend_from_slice(&[6 << 5, 3]);
    let head = header("x y z", "4 4 4", "F F F", "1 1 1", 3, 1, ID, "binary_compressed");
    let b = compressed_file(&head, &lzf, 36);
    let scan = read_pcd(&write(&d, "br.pcd", &b)).unwrap();
    assert_eq!(scan.points, vec![[1.0, -1.0, 2.0], [2.0, -2.0, 2.0], [3.0, -3.0, 2.0]]);
}

#[test]
fn lzf_back_references_short_and_long() {
    let mut out = Vec::new();
    // "abc", then 6 bytes from 3 back.
    lzf_decompress(&[2, b'a', b'b', b'c', 4 << 5, 2], 9, &mut out).unwrap();
    assert_eq!(out, b"abcabcabc");
    // "a", then the long form: 7 + 11 + 2 = 20 bytes from 1 back.
    lzf_decompress(&[0, b'a', 7 << 5, 11, 0], 21, &mut out).unwrap();
    assert_eq!(out, vec![b'a'; 21]);
    // A distance beyond what is decompressed, and data ending inside a reference.
    assert!(lzf_decompress(&[0, b'a', 1 << 5, 5], 4, &mut out).is_err());
    assert!(lzf_decompress(&[0, b'a', 7 << 5], 4, &mut out).is_err());
    // A literal run past the end of the input.
    assert!(lzf_decompress(&[5, b'a'], 6, &mut out).is_err());
}

#[test]
fn ring_field_binary_and_ascii() {
    let d = tempfile::tempdir().unwrap();
    let mut b = header(
        "x y z intensity ring time",
        "4 4 4 4 2 4",
        "F F F F U F",
        "1 1 1 1 1 1",
        3,
        1,
        ID,
        "binary",
    )
    .into_bytes();
    for (i, p) in [[1.0f32, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [0.0, 2.0, 0.5]].iter().enumerate()
    {
        for v in p {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&9.0f32.to_le_bytes());
        b.extend_from_slice(&(30 - i as u16).to_le_bytes());
        b.extend_from_slice(&0.01f32.to_le_bytes());
    }
    let scan = read_pcd(&write(&d, "r.pcd", &b)).unwrap();
    assert_eq!(scan.points, vec![[1.0, 0.0, 0.0], [0.0, 2.0, 0.5]]);
    assert_eq!(scan.ring, Some(vec![30, 28]));
    assert!(scan.ring_elevation_deg.is_none());

    let mut s = header("x y z ring", "4 4 4 1", "F F F I", "1 1 1 1", 2, 1, ID, "ascii");
    s.push_str("1 2 3 5\n4 5 6 0\n");
    assert_eq!(read_pcd(&write(&d, "ra.pcd", s.as_bytes())).unwrap().ring, Some(vec![5, 0]));

    // A negative ring of a kept point, and a float ring.
    let mut s = header("x y z ring", "4 4 4 1", "F F F I", "1 1 1 1", 1, 1, ID, "ascii");
    s.push_str("1 2 3 -1\n");
    let m = err(&d, "neg.pcd", s.as_bytes());
    assert!(m.contains("neg.pcd:12") && m.contains("ring"), "{m}");
    let s = header("x y z ring", "4 4 4 4", "F F F F", "1 1 1 1", 0, 1, ID, "ascii");
    let m = err(&d, "fr.pcd", s.as_bytes());
    assert!(m.contains("fr.pcd") && m.contains("ring"), "{m}");
}

#[test]
fn extra_fields_padding_and_count_are_skipped() {
    let d = tempfile::tempdir().unwrap();
    let pts = sample();
    // normal: 3 floats; _: 3 padding bytes; rgb: a packed u32; x y z between them.
    let head = header(
        "normal x _ y rgb z",
        "4 4 1 4 4 4",
        "F F U F U F",
        "3 1 3 1 1 1",
        pts.len(),
        1,
        ID,
        "binary",
    );
    let mut b = head.into_bytes();
    for p in &pts {
        for v in [0.1f32, 0.2, 0.3, p[0]] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&[0xAA; 3]);
        b.extend_from_slice(&p[1].to_le_bytes());
        b.extend_from_slice(&0xFF00FFu32.to_le_bytes());
        b.extend_from_slice(&p[2].to_le_bytes());
    }
    assert_eq!(read_pcd(&write(&d, "e.pcd", &b)).unwrap().points, pts);

    // The same layout compressed (columns of width SIZE x COUNT).
    let n = pts.len();
    let mut raw = Vec::new();
    for _ in 0..n {
        for v in [0.1f32, 0.2, 0.3] {
            raw.extend_from_slice(&v.to_le_bytes());
        }
    }
    for p in &pts {
        raw.extend_from_slice(&p[0].to_le_bytes());
    }
    raw.extend(vec![0xAAu8; 3 * n]);
    for p in &pts {
        raw.extend_from_slice(&p[1].to_le_bytes());
    }
    raw.extend(vec![0u8; 4 * n]);
    for p in &pts {
        raw.extend_from_slice(&p[2].to_le_bytes());
    }
    let head = header(
        "normal x _ y rgb z",
        "4 4 1 4 4 4",
        "F F U F U F",
        "3 1 3 1 1 1",
        n,
        1,
        ID,
        "binary_compressed",
    );
    let b = compressed_file(&head, &lzf_literals(&raw), raw.len());
    assert_eq!(read_pcd(&write(&d, "ec.pcd", &b)).unwrap().points, pts);

    // ascii: COUNT 3 takes three values.
    let mut s = header("normal x y z", "4 4 4 4", "F F F F", "3 1 1 1", 1, 1, ID, "ascii");
    s.push_str("0.1 0.2 0.3 1 2 3\n");
    assert_eq!(
        read_pcd(&write(&d, "ea.pcd", s.as_bytes())).unwrap().points,
        vec![[1.0, 2.0, 3.0]]
    );
}

#[test]
fn organised_cloud_holes_are_dropped() {
    let d = tempfile::tempdir().unwrap();
    let mut b = header("x y z", "4 4 4", "F F F", "1 1 1", 2, 2, ID, "binary").into_bytes();
    for p in [[1.0f32, 1.0, 1.0], [f32::NAN; 3], [2.0, 2.0, 2.0], [0.0; 3]] {
        for v in p {
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    assert_eq!(read_pcd(&write(&d, "o.pcd", &b)).unwrap().points, vec![[1.0; 3], [2.0; 3]]);
}

#[test]
fn viewpoint_maps_points_into_the_sensor_frame() {
    let d = tempfile::tempdir().unwrap();
    // Sensor at (1, 2, 3), yawed +90 deg: sensor x = world y.
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let vp = format!("1 2 3 {h} 0 0 {h}");
    let sensor_pts = [[5.0f64, 0.0, 0.0], [0.0, 2.0, -1.0], [1.0, 1.0, 1.0]];
    let q = DQuat::from_xyzw(0.0, 0.0, h, h);
    let t = DVec3::new(1.0, 2.0, 3.0);
    let mut s = header("x y z", "8 8 8", "F F F", "1 1 1", 3, 1, &vp, "ascii");
    for p in sensor_pts {
        let w = q * DVec3::from(p) + t;
        s.push_str(&format!("{} {} {}\n", w.x, w.y, w.z));
    }
    // The first point lies 5 m ahead of the sensor, i.e. at world (1, 7, 3).
    let first = s.lines().nth(11).unwrap();
    let w: Vec<f64> = first.split_whitespace().map(|v| v.parse().unwrap()).collect();
    assert!(
        (w[0] - 1.0).abs() < 1e-12 && (w[1] - 7.0).abs() < 1e-12 && (w[2] - 3.0).abs() < 1e-12,
        "{first}"
    );
    let scan = read_pcd(&write(&d, "v.pcd", s.as_bytes())).unwrap();
    for (a, e) in scan.points.iter().zip(sensor_pts) {
        for k in 0..3 {
            assert!((a[k] as f64 - e[k]).abs() < 1e-5, "{a:?} vs {e:?}");
        }
    }
    // A quaternion far from unit norm.
    let s = header("x y z", "4 4 4", "F F F", "1 1 1", 0, 1, "0 0 0 2 0 0 0", "ascii");
    let m = err(&d, "vq.pcd", s.as_bytes());
    assert!(m.contains("vq.pcd:9") && m.contains("norm"), "{m}");
}

#[test]
fn header_errors_name_file_and_line() {
    let d = tempfile::tempdir().unwrap();
    // Missing key.
    let s =
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nHEIGHT 1\nPOINTS 0\nDATA ascii\n";
    let m = err(&d, "m.pcd", s.as_bytes());
    assert!(m.contains("m.pcd") && m.contains("WIDTH"), "{m}");
    // Unknown key.
    let s = "VERSION 0.7\nFIELDS x y z\nCOLOR red\nDATA ascii\n";
    let m = err(&d, "u.pcd", s.as_bytes());
    assert!(m.contains("u.pcd:3") && m.contains("COLOR"), "{m}");
    // No DATA line.
    let m = err(&d, "nd.pcd", b"VERSION 0.7\nFIELDS x y z\n");
    assert!(m.contains("nd.pcd") && m.contains("DATA"), "{m}");
    // Unsupported version and data kind.
    let m = err(&d, "v.pcd", b"VERSION 0.5\n");
    assert!(m.contains("v.pcd:1") && m.contains("0.5"), "{m}");
    let s = header("x y z", "4 4 4", "F F F", "1 1 1", 0, 1, ID, "binary_lz4");
    let m = err(&d, "dk.pcd", s.as_bytes());
    assert!(m.contains("dk.pcd:11") && m.contains("binary_lz4"), "{m}");
    // Unsupported TYPE / SIZE for x y z.
    let s = header("x y z", "4 4 4", "F U F", "1 1 1", 0, 1, ID, "binary");
    let m = err(&d, "t.pcd", s.as_bytes());
    assert!(m.contains("t.pcd") && m.contains("field y has TYPE U"), "{m}");
    let s = header("x y z", "4 4 2", "F F F", "1 1 1", 0, 1, ID, "binary");
    let m = err(&d, "s.pcd", s.as_bytes());
    assert!(m.contains("field z has TYPE F SIZE 2"), "{m}");
    // Missing z, and list lengths.
    let s = header("x y intensity", "4 4 4", "F F F", "1 1 1", 0, 1, ID, "binary");
    assert!(err(&d, "nz.pcd", s.as_bytes()).contains("no z"));
    let s = header("x y z", "4 4", "F F F", "1 1 1", 0, 1, ID, "binary");
    let m = err(&d, "sl.pcd", s.as_bytes());
    assert!(m.contains("sl.pcd:4") && m.contains("SIZE has 2 entries"), "{m}");
    // POINTS != WIDTH * HEIGHT.
    let s = header("x y z", "4 4 4", "F F F", "1 1 1", 10, 1, ID, "binary")
        .replace("POINTS 10", "POINTS 12");
    let m = err(&d, "p.pcd", s.as_bytes());
    assert!(
        m.contains("p.pcd:10") && m.contains("POINTS 12 is not WIDTH 10 x HEIGHT 1"),
        "{m}"
    );
    // A repeated key.
    let s = header("x y z", "4 4 4", "F F F", "1 1 1", 0, 1, ID, "binary")
        .replace("HEIGHT 1\n", "HEIGHT 1\nHEIGHT 1\n");
    let m = err(&d, "r.pcd", s.as_bytes());
    assert!(m.contains("r.pcd:9") && m.contains("twice"), "{m}");
}

#[test]
fn lying_headers_are_errors() {
    let d = tempfile::tempdir().unwrap();
    // binary: 10 points promised, 3 given.
    let mut b = header("x y z", "4 4 4", "F F F", "1 1 1", 10, 1, ID, "binary").into_bytes();
    b.extend_from_slice(&[0x3f; 36]);
    let m = err(&d, "lb.pcd", &b);
    assert!(
        m.contains("lb.pcd") && m.contains("lying header") && m.contains("120 bytes"),
        "{m}"
    );
    // ascii: 3 lines promised, 2 given.
    let mut s = header("x y z", "4 4 4", "F F F", "1 1 1", 3, 1, ID, "ascii");
    s.push_str("1 2 3\n4 5 6\n");
    let m = err(&d, "la.pcd", s.as_bytes());
    assert!(m.contains("la.pcd") && m.contains("only 2 data lines"), "{m}");
    // ascii: one line too many.
    let mut s = header("x y z", "4 4 4", "F F F", "1 1 1", 1, 1, ID, "ascii");
    s.push_str("1 2 3\n4 5 6\n");
    let m = err(&d, "lm.pcd", s.as_bytes());
    assert!(m.contains("lm.pcd:13") && m.contains("more data lines"), "{m}");
    // compressed: uncompressed size disagrees with POINTS.
    let head = header("x y z", "4 4 4", "F F F", "1 1 1", 2, 1, ID, "binary_compressed");
    let raw = [0u8; 12];
    let m = err(&d, "lc.pcd", &compressed_file(&head, &lzf_literals(&raw), raw.len()));
    assert!(m.contains("lc.pcd") && m.contains("lying header"), "{m}");
    // compressed: fewer bytes than the compressed size says.
    let mut b = compressed_file(&head, &lzf_literals(&[0u8; 24]), 24);
    b.truncate(b.len() - 5);
    let m = err(&d, "lt.pcd", &b);
    assert!(m.contains("lying header") && m.contains("compressed size"), "{m}");
    // compressed: LZF that decompresses to fewer bytes than declared.
    let m = err(&d, "lz.pcd", &compressed_file(&head, &lzf_literals(&[1u8; 20]), 24));
    assert!(
        m.contains("lz.pcd")
            && m.contains("LZF")
            && m.contains("20 bytes, not the declared 24"),
        "{m}"
    );
    // ... or more.
    let m = err(&d, "lz2.pcd", &compressed_file(&head, &lzf_literals(&[1u8; 30]), 24));
    assert!(m.contains("LZF") && m.contains("past the declared 24"), "{m}");
}

#[test]
fn a_body_longer_than_the_header_says_is_an_error() {
    let d = tempfile::tempdir().unwrap();
    let pts = sample();
    let body: Vec<u8> = pts.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    // binary: POINTS half the records that follow.
    let mut b = header("x y z", "4 4 4", "F F F", "1 1 1", pts.len() / 2, 1, ID, "binary").into_bytes();
    b.extend_from_slice(&body);
    let m = err(&d, "half.pcd", &b);
    assert!(m.contains("half.pcd") && m.contains("POINTS 25 x 12-byte records is 300 bytes of data but 600 follow"), "{m}");
    // binary header over an ascii body: named as such.
    let mut b = header("x y z", "4 4 4", "F F F", "1 1 1", 2, 1, ID, "binary").into_bytes();
    b.extend_from_slice(b"1 2 3\n4 5 6\n");
    let m = err(&d, "text.pcd", &b);
    assert!(m.contains("text.pcd") && m.contains("(the data is text: DATA ascii?)"), "{m}");
    // compressed: bytes after the compressed data.
    let head = header("x y z", "4 4 4", "F F F", "1 1 1", 2, 1, ID, "binary_compressed");
    let mut b = compressed_file(&head, &lzf_literals(&[0u8; 24]), 24);
    b.extend_from_slice(&[0u8; 7]);
    let m = err(&d, "tail.pcd", &b);
    assert!(m.contains("compressed size is 25 bytes but 32 bytes follow"), "{m}");
}

#[test]
fn a_byte_order_mark_before_the_header_is_skipped() {
    let d = tempfile::tempdir().unwrap();
    let mut s = String::from("\u{feff}");
    s.push_str(&header("x y z", "4 4 4", "F F F", "1 1 1", 1, 1, ID, "ascii"));
    s.push_str("1 2 3\n");
    assert_eq!(read_pcd(&write(&d, "bom.pcd", s.as_bytes())).unwrap().points, vec![[1.0, 2.0, 3.0]]);
}

#[test]
fn ascii_line_errors() {
    let d = tempfile::tempdir().unwrap();
    let mut s = header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", 2, 1, ID, "ascii");
    s.push_str("1 2 3 4\n1 2 3\n");
    let m = err(&d, "w.pcd", s.as_bytes());
    assert!(
        m.contains("w.pcd:13") && m.contains("expected 4 values") && m.contains("found 3"),
        "{m}"
    );
    let mut s = header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", 2, 1, ID, "ascii");
    s.push_str("1 2 3 4\n1 2 3 4 5\n");
    assert!(err(&d, "w2.pcd", s.as_bytes()).contains("found 5"));
    let mut s = header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", 2, 1, ID, "ascii");
    s.push_str("1 2 3 4\n1 two 3 4\n");
    let m = err(&d, "n.pcd", s.as_bytes());
    assert!(m.contains("n.pcd:13") && m.contains("`two` is not a number"), "{m}");
}
