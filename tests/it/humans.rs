//! The bundled humans as the runtime sees them: heights, recorded LOD error bounds, walking,
//! and what a model without skin or animation gets.

use crate::common;

use glam::{Mat4, Vec3};
use pedscan::human::HumanModel;
use std::path::{Path, PathBuf};

fn bundled() -> Vec<PathBuf> {
    common::bundled_humans()
}

/// Parses `h1700_w60` into (1.700 m, 60 kg).
fn label(name: &str) -> (f32, f32) {
    let (h, w) = name.trim_start_matches('h').split_once("_w").unwrap();
    (h.parse::<f32>().unwrap() / 1000.0, w.parse::<f32>().unwrap())
}

#[test]
fn all_fifteen_paper_variants_are_bundled_with_their_labels() {
    let files = bundled();
    assert_eq!(files.len(), 15, "{files:?}");
    for f in &files {
        let m = HumanModel::load(f, true).unwrap();
        let (h, w) = label(&m.name);
        assert_eq!(m.labelled_height_m, Some(h), "{}", m.name);
        assert_eq!(m.weight_kg, Some(w), "{}", m.name);
        // Measured standing height of the rest mesh within 1% of the label.
        let err = (m.height_m - h).abs() / h;
        assert!(err < 0.01, "{}: rest height {} m vs {} m ({:.3} %)", m.name, m.height_m, h, 100.0 * err);
        assert!(m.lods.len() >= 2, "{} has levels of detail", m.name);
        assert!(m.cycle_s > 0.5 && m.cycle_s < 2.0, "{} cycle {}", m.name, m.cycle_s);
        let stride = m.stride_length_m.unwrap();
        assert!(stride > 0.6 * h && stride < 1.0 * h, "{} stride {stride}", m.name);
    }
}

/// Posed LOD `lod` vertices of `m` at `phase` (None: rest pose without animation).
fn posed(m: &HumanModel, lod: usize, phase: Option<f32>) -> (Vec<Vec3>, Vec<u32>) {
    let mut joints = Vec::new();
    let mut out = Vec::new();
    match phase {
        Some(p) => m.joint_matrices(p, &mut joints),
        None => joints.clear(),
    }
    m.skin_into(lod, &joints, &Mat4::IDENTITY, &mut out);
    (out.into_iter().map(Vec3::from).collect(), m.lods[lod].indices.clone())
}

fn point_triangle_distance(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> f32 {
    // Ericson, Real-Time Collision Detection, 5.1.5 (closest point on triangle).
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return p.distance(a);
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return p.distance(b);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return p.distance(a + v * ab);
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return p.distance(c);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return p.distance(a + w * ac);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return p.distance(b + w * (c - b));
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    p.distance(a + ab * v + ac * w)
}

/// One-sided distance from every point of `from` to the surface (`verts`, `idx`), via a uniform
/// grid of triangles; returns the largest distance found, capped at `cap` (a point farther than
/// `cap` from every triangle reports `f32::INFINITY`).
fn one_sided(from: &[Vec3], verts: &[Vec3], idx: &[u32], cap: f32) -> f32 {
    let cell = cap.max(0.01);
    let key = |p: Vec3| ((p.x / cell).floor() as i32, (p.y / cell).floor() as i32, (p.z / cell).floor() as i32);
    let mut grid: std::collections::HashMap<(i32, i32, i32), Vec<usize>> = std::collections::HashMap::new();
    for (t, tri) in idx.chunks_exact(3).enumerate() {
        let [a, b, c] = [0, 1, 2].map(|k| verts[tri[k] as usize]);
        let lo = key(a.min(b).min(c));
        let hi = key(a.max(b).max(c));
        for x in lo.0..=hi.0 {
            for y in lo.1..=hi.1 {
                for z in lo.2..=hi.2 {
                    grid.entry((x, y, z)).or_default().push(t);
                }
            }
        }
    }
    let mut worst = 0.0f32;
    for p in from {
        let k = key(*p);
        let mut best = f32::INFINITY;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(ts) = grid.get(&(k.0 + dx, k.1 + dy, k.2 + dz)) {
                        for &t in ts {
                            let tri = &idx[3 * t..3 * t + 3];
                            let d = point_triangle_distance(*p, verts[tri[0] as usize], verts[tri[1] as usize], verts[tri[2] as usize]);
                            best = best.min(d);
                        }
                    }
                }
            }
        }
        worst = worst.max(if best <= cap { best } else { f32::INFINITY });
    }
    worst
}

/// Two-sided (Hausdorff-style, vertex-sampled) distance between each LOD and LOD 0, at rest and
/// at four gait phases, stays within the error the model records for that LOD (+0.1 mm for the
/// f32 skinning of a different vertex subset).
#[test]
fn recorded_lod_errors_bound_the_distance_to_the_full_mesh() {
    for f in bundled().iter().step_by(4) {
        let m = HumanModel::load(f, true).unwrap();
        for phase in [None, Some(0.0), Some(0.25), Some(0.5), Some(0.75)] {
            let (v0, i0) = posed(&m, 0, phase);
            for lod in 1..m.lods.len() {
                let bound = m.lods[lod].error_m + 1e-4;
                let (vk, ik) = posed(&m, lod, phase);
                let a = one_sided(&v0, &vk, &ik, bound);
                let b = one_sided(&vk, &v0, &i0, bound);
                assert!(
                    a <= bound && b <= bound,
                    "{} LOD {lod} at {phase:?}: distances {a} / {b} m exceed the recorded {} m",
                    m.name,
                    m.lods[lod].error_m
                );
            }
        }
    }
}

#[test]
fn the_walk_moves_the_legs_and_keeps_the_height() {
    let f = bundled().into_iter().find(|p| p.ends_with("h1700_w60.glb")).unwrap();
    let m = HumanModel::load(&f, true).unwrap();
    let (a, _) = posed(&m, 0, Some(0.0));
    let (b, _) = posed(&m, 0, Some(0.5));
    // Half a cycle apart the legs have swapped: many vertices move by decimetres.
    let moved = a.iter().zip(&b).filter(|(p, q)| p.distance(**q) > 0.1).count();
    assert!(moved > 1000, "only {moved} vertices moved > 10 cm between phase 0 and 0.5");
    for (name, v) in [("0.0", &a), ("0.5", &b)] {
        let lo = v.iter().map(|p| p.y).fold(f32::INFINITY, f32::min);
        let hi = v.iter().map(|p| p.y).fold(f32::NEG_INFINITY, f32::max);
        assert!(lo.abs() < 0.03, "feet near the floor at phase {name}: {lo}");
        assert!((hi - lo - 1.7).abs() < 0.1, "walking height at phase {name}: {}", hi - lo);
    }
}

/// Whole-body density (with the air in the lungs) the builder fits the bodies to, kg/m³
/// (tools/humans/README.md, "Body mass").
const BODY_DENSITY: f64 = 1010.0;

/// The mass a bundled body is built to: its weight label, except where that weight is below
/// the lowest plausible BMI for the age (tools/humans/README.md, "Unreachable weights"): the
/// −3 SD line of the WHO 2007 BMI-for-age reference (5–19 years), boys and girls averaged, at
/// the ages the builder gives 1.2 and 1.4 m: the 1.2 m child is built at BMI 12.0 (7 years;
/// 17.3 kg, not 15 kg), the 1.4 m child at BMI 12.6 (10 years; 24.7 kg, not 20 kg).
fn built_mass_kg(height_m: f64, weight_kg: f64) -> f64 {
    let floor_bmi = match (height_m * 1000.0).round() as u32 {
        1200 => 12.0,
        1400 => 12.6,
        _ => 0.0,
    };
    weight_kg.max(floor_bmi * height_m * height_m)
}

/// Volume enclosed by the full-detail mesh in the bind pose: sum of the signed tetrahedra
/// (origin, a, b, c) over the LOD 0 triangles.
fn closed_volume_m3(m: &HumanModel) -> f64 {
    let lod = &m.lods[0];
    let p = |i: u32| lod.positions[i as usize].as_dvec3();
    lod.indices.chunks_exact(3).map(|t| p(t[0]).dot(p(t[1]).cross(p(t[2]))) / 6.0).sum()
}

#[test]
fn every_body_weighs_its_label_at_body_density() {
    let mut failures = Vec::new();
    for f in bundled() {
        let m = HumanModel::load(&f, true).unwrap();
        let (h, w) = label(&m.name);
        let target = built_mass_kg(f64::from(h), f64::from(w));
        let mass = closed_volume_m3(&m) * BODY_DENSITY;
        let err = (mass - target) / target;
        if err.abs() > 0.05 {
            failures.push(format!("{}: {mass:.1} kg from the volume, built for {target:.1} kg ({:+.1} %)", m.name, 100.0 * err));
        }
    }
    assert!(failures.is_empty(), "mass from volume x {BODY_DENSITY} kg/m³ not within 5 %:\n{}", failures.join("\n"));
}

/// A minimal glTF: one 1.7 m tall box, no skin, no animation.
fn write_rigid_box(path: &Path) {
    write_rigid_box_under_chain(path, 0);
}

/// The box (node 0) under a chain of `depth` empty parents (node k + 1 holds node k).
fn write_rigid_box_under_chain(path: &Path, depth: usize) {
    let (x, y, z) = (0.2f32, 1.7f32, 0.15f32);
    let pos: Vec<[f32; 3]> = vec![[-x, 0.0, -z], [x, 0.0, -z], [x, y, -z], [-x, y, -z], [-x, 0.0, z], [x, 0.0, z], [x, y, z], [-x, y, z]];
    let idx: Vec<u16> = vec![0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4, 1, 2, 6, 1, 6, 5, 2, 3, 7, 2, 7, 6, 3, 0, 4, 3, 4, 7];
    let mut bin: Vec<u8> = pos.iter().flatten().flat_map(|f| f.to_le_bytes()).collect();
    let pos_len = bin.len();
    bin.extend(idx.iter().flat_map(|i| i.to_le_bytes()));
    let nodes: Vec<String> = std::iter::once(r#"{"mesh":0}"#.to_string())
        .chain((0..depth).map(|k| format!(r#"{{"children":[{k}]}}"#)))
        .collect();
    let nodes = nodes.join(",");
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[{depth}]}}],"nodes":[{nodes}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":8,"type":"VEC3","min":[-0.2,0,-0.15],"max":[0.2,1.7,0.15]}},
                     {{"bufferView":1,"componentType":5123,"count":36,"type":"SCALAR"}}],
        "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":{pos_len}}},{{"buffer":0,"byteOffset":{pos_len},"byteLength":72}}],
        "buffers":[{{"byteLength":{}}}]}}"#,
        bin.len()
    );
    let mut js = json.into_bytes();
    while js.len() % 4 != 0 {
        js.push(b' ');
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((12 + 8 + js.len() + 8 + bin.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(js.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&js);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    std::fs::write(path, out).unwrap();
}

#[test]
fn a_model_without_skin_or_animation_is_refused_only_when_the_motion_needs_them() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("rigid.glb");
    write_rigid_box(&p);
    let e = HumanModel::load(&p, true).unwrap_err();
    assert!(e.is_input(), "{e}");
    assert!(e.to_string().contains("rigid.glb") && e.to_string().contains("skin"), "{e}");
    let m = HumanModel::load(&p, false).unwrap();
    assert!((m.height_m - 1.7).abs() < 1e-6);
    let (v, _) = posed(&m, 0, Some(0.3));
    assert_eq!(v.len(), 8, "the rigid mesh is used as is");
}


#[test]
fn a_hostile_node_hierarchy_is_an_input_error_not_a_crash() {
    let dir = tempfile::tempdir().unwrap();
    let ok = dir.path().join("shallow.glb");
    write_rigid_box_under_chain(&ok, 20);
    let m = HumanModel::load(&ok, false).unwrap();
    assert!((m.height_m - 1.7).abs() < 1e-6, "parents without transforms keep the box");
    let deep = dir.path().join("deep.glb");
    write_rigid_box_under_chain(&deep, pedscan::human::MAX_NODE_DEPTH + 100);
    let e = HumanModel::load(&deep, false).unwrap_err();
    assert!(e.is_input() && e.to_string().contains("deep.glb"), "{e}");
}

/// `humans.carrying`: that share of the people carry a backpack, a bag or two (the model named
/// NAME+KIND in the HDF5), every kind drawn, the same bytes at 1 and 2 threads; a share
/// outside 0..1 or NaN is refused naming the key, nothing written.
#[test]
fn people_carry_backpacks_and_bags_where_asked() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("c.toml"), "sensor = \"vlp16\"\n[humans]\ncount = [10, 10]\ncarrying = 0.5\n").unwrap();
    let args = |out: &'static str| ["generate", "--config", "c.toml", "--backend", "raycast", "--sequences", "3", "--frames", "2", "--outputs", "range,label,instance", "--out", out];
    common::ok(&common::pedscan_with_env(&args("a"), dir, &[("RAYON_NUM_THREADS", "1")]));
    common::ok(&common::pedscan_with_env(&args("b"), dir, &[("RAYON_NUM_THREADS", "2")]));
    let mut kinds = std::collections::BTreeMap::new();
    for seq in 0..3 {
        let f = format!("seq_{seq:06}.h5");
        assert!(std::fs::read(dir.join("a").join(&f)).unwrap() == std::fs::read(dir.join("b").join(&f)).unwrap(), "{f} differs between 1 and 2 threads");
        let h = hdf5::File::open(dir.join("a").join(&f)).unwrap();
        let models: Vec<hdf5::types::VarLenUnicode> = h.dataset("humans/model").unwrap().read_raw().unwrap();
        assert_eq!(models.len(), 10);
        for m in &models {
            let kind = m.as_str().split_once('+').map_or("none", |(_, k)| k).to_string();
            *kinds.entry(kind).or_insert(0usize) += 1;
        }
    }
    let none = kinds.get("none").copied().unwrap_or(0);
    // 30 people, each carrying with probability 0.5: 15 expected, 5..25 is beyond 3.6 sigma.
    assert!((5..=25).contains(&none), "{kinds:?}");
    assert_eq!(kinds.keys().filter(|k| ["backpack", "bag", "bags"].contains(&k.as_str())).count(), 3, "{kinds:?}");
    assert_eq!(kinds.len(), 4, "{kinds:?}");
    refuses_shares_outside_0_1(dir, "humans", "carrying");
}

/// `humans.sitting`: in the street, that share of the people sit on its benches (the XML's
/// `seated_m`, at a bench's height), are seen (human beams) and still; the same bytes at 1
/// and 2 threads; a share outside 0..1 or NaN is refused naming the key, nothing written.
#[test]
fn people_sit_on_the_streets_benches_where_asked() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("c.toml"), "sensor = \"vlp16\"\n[humans]\ncount = [8, 8]\nsitting = 0.5\nspawn_radius_m = 30.0\n[scene]\nbackground = \"street\"\nmarkets = 1.0\nsensor_height_m = 1.73\n").unwrap();
    let args = |out: &'static str| ["generate", "--config", "c.toml", "--backend", "raycast", "--sequences", "2", "--frames", "2", "--out", out];
    common::ok(&common::pedscan_with_env(&args("a"), dir, &[("RAYON_NUM_THREADS", "1")]));
    common::ok(&common::pedscan_with_env(&args("b"), dir, &[("RAYON_NUM_THREADS", "2")]));
    let (mut seated, mut seen) = (0, 0);
    for seq in 0..2 {
        for ext in ["h5", "xml"] {
            let f = format!("seq_{seq:06}.{ext}");
            assert!(std::fs::read(dir.join("a").join(&f)).unwrap() == std::fs::read(dir.join("b").join(&f)).unwrap(), "{f} differs between 1 and 2 threads");
        }
        let xml = std::fs::read_to_string(dir.join("a").join(format!("seq_{seq:06}.xml"))).unwrap();
        let people: Vec<&str> = xml.lines().filter(|l| l.trim_start().starts_with("<human ") && l.contains("model=")).collect();
        assert_eq!(people.len(), 8, "{xml}");
        for (k, line) in people.iter().enumerate() {
            let Some(s) = line.split("seated_m=\"").nth(1) else { continue };
            let seat: f64 = s.split('"').next().unwrap().parse().unwrap();
            assert!([0.45, 0.46, 0.47].iter().any(|h| (seat - h).abs() < 1e-9), "{line}");
            seated += 1;
            // In the last frame: still, and seen where anything of it is.
            let id = format!("<human id=\"{}\" ", k + 1);
            let last = xml.lines().filter(|l| l.trim_start().starts_with(&id) && l.contains("speed_mps")).last().unwrap();
            assert!(last.contains("speed_mps=\"0.000\""), "{last}");
            seen += usize::from(!last.contains("beams=\"0\""));
        }
    }
    // 16 people, each drawn to sit with probability 0.5 (a bench is seldom taken): 3..13.
    assert!((3..=13).contains(&seated), "{seated} of 16 seated");
    assert!(seen > 0, "no seated person seen");
    refuses_shares_outside_0_1(dir, "humans", "sitting");
}

/// `generate` refuses `[table] key` at 1.5, -0.1 and NaN (exit 2, naming `table.key`) and
/// writes nothing.
fn refuses_shares_outside_0_1(dir: &std::path::Path, table: &str, key: &str) {
    for bad in ["1.5", "-0.1", "nan"] {
        std::fs::write(dir.join("bad.toml"), format!("[{table}]\n{key} = {bad}\n")).unwrap();
        common::expect_input_error(&["generate", "--config", "bad.toml", "--out", "x"], dir, &format!("{table}.{key}"));
        assert!(!dir.join("x").exists(), "nothing written");
    }
}

/// `pedscan sheet --pushing --seated M` on lavapipe under the validation layer (no error): a
/// row per phase, then the pushing row and the seated row. The adult's pushing row differs
/// from its walk at the same phase (the arms held forward), the child's is its walk to the
/// pixel (a child cannot push); seated differs from walking for both. A seat that is no seat's
/// height is refused naming the flag, exit 2, nothing written.
#[test]
fn the_contact_sheet_draws_the_pushing_and_seated_rows() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let humans = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/humans");
    let (adult, child) = (humans.join("h1700_w60.glb"), humans.join("h1200_w20.glb"));
    let (adult, child) = (adult.to_str().unwrap(), child.to_str().unwrap());
    let args = ["sheet", "--models", adult, "--models", child, "--phases", "0,0.5", "--pushing", "--seated", "0.45", "--out", "s.png"];
    common::ok(&common::pedscan(&args, dir));
    let img = image::open(dir.join("s.png")).unwrap().to_rgb8();
    // 150 columns a model; a 14-pixel caption, then 241 rows a row of the sheet.
    let (cw, ch, top) = (150u32, 241u32, 14u32);
    assert_eq!(img.dimensions(), (2 * cw, top + 4 * ch));
    let cell = |model: u32, row: u32| -> Vec<[u8; 3]> {
        (0..ch).flat_map(|y| (0..cw).map(move |x| (x, y))).map(|(x, y)| img.get_pixel(model * cw + x, top + row * ch + y).0).collect()
    };
    let differ = |a: &[[u8; 3]], b: &[[u8; 3]]| a.iter().zip(b).filter(|(p, q)| p != q).count();
    for model in 0..2 {
        let seen = cell(model, 0).iter().filter(|p| **p != [235, 235, 235] && **p != [255, 255, 255]).count();
        assert!(seen > 1000, "model {model}: {seen} pixels of the person");
        assert!(differ(&cell(model, 0), &cell(model, 3)) > 500, "model {model}: seated as walking");
    }
    assert!(differ(&cell(0, 0), &cell(0, 2)) > 100, "the adult pushes as it walks");
    assert_eq!(differ(&cell(1, 0), &cell(1, 2)), 0, "the child pushes");
    let bad = common::pedscan(&["sheet", "--models", adult, "--seated", "3", "--out", "bad.png"], dir);
    assert_eq!(bad.status.code(), Some(2), "{}", String::from_utf8_lossy(&bad.stderr));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--seated"));
    assert!(!dir.join("bad.png").exists());
}
