//! Hostile inputs to the model readers (sensor TOML, human and environment glTF): each is
//! refused as an input error naming the file (exit code 2, nothing written), in bounded time
//! and memory, instead of a panic, a runaway walk or a silently broken person. Every file is
//! a mutated copy of bundled data, written into a temporary folder.

use crate::common::{bounded, pedscan_bounded, REFUSED_RUN_DATA_BYTES};
use pedscan::human::HumanModel;
use pedscan::scene::Environment;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// A GLB split into its JSON and its binary chunk, to be mutated and written back.
struct Glb {
    json: Value,
    bin: Vec<u8>,
}

impl Glb {
    fn read(path: &Path) -> Glb {
        let b = std::fs::read(path).unwrap();
        let chunk = |at: usize| {
            let len = u32::from_le_bytes(b[at..at + 4].try_into().unwrap()) as usize;
            (&b[at + 8..at + 8 + len], at + 8 + len)
        };
        let (json, next) = chunk(12);
        let (bin, _) = chunk(next);
        Glb { json: serde_json::from_slice(json).unwrap(), bin: bin.to_vec() }
    }

    /// A bundled file (`data/...`).
    fn bundled(rel: &str) -> Glb {
        Glb::read(&Path::new(env!("CARGO_MANIFEST_DIR")).join("data").join(rel))
    }

    fn write(&self, path: &Path) {
        let mut json = serde_json::to_vec(&self.json).unwrap();
        json.resize(json.len().next_multiple_of(4), b' ');
        let mut bin = self.bin.clone();
        bin.resize(bin.len().next_multiple_of(4), 0);
        let mut out = Vec::new();
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&((12 + 8 + json.len() + 8 + bin.len()) as u32).to_le_bytes());
        for (data, kind) in [(&json, b"JSON"), (&bin, b"BIN\0")] {
            out.extend_from_slice(&(data.len() as u32).to_le_bytes());
            out.extend_from_slice(kind);
            out.extend_from_slice(data);
        }
        std::fs::write(path, out).unwrap();
    }

    /// Byte offset in the binary chunk of component `c` of element `e` of accessor `a`.
    fn at(&self, a: usize, e: usize, c: usize) -> usize {
        let acc = &self.json["accessors"][a];
        let view = &self.json["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
        let component = match acc["componentType"].as_u64().unwrap() {
            5120 | 5121 => 1,
            5122 | 5123 => 2,
            _ => 4,
        };
        let dims = match acc["type"].as_str().unwrap() {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            "MAT4" => 16,
            t => panic!("{t}"),
        };
        let stride = view["byteStride"].as_u64().map_or(component * dims, |s| s as usize);
        let offset = |v: &Value| v["byteOffset"].as_u64().unwrap_or(0) as usize;
        offset(view) + offset(acc) + e * stride + c * component
    }

    fn set_f32(&mut self, a: usize, e: usize, c: usize, v: f32) {
        let at = self.at(a, e, c);
        self.bin[at..at + 4].copy_from_slice(&v.to_le_bytes());
    }

    /// The output accessor of the first animation channel that animates `path`.
    fn animation_output(&self, path: &str) -> usize {
        let anim = &self.json["animations"][0];
        let ch = anim["channels"].as_array().unwrap().iter().find(|c| c["target"]["path"] == path).unwrap();
        anim["samplers"][ch["sampler"].as_u64().unwrap() as usize]["output"].as_u64().unwrap() as usize
    }
}

/// The bundled 1.70 m human: accessors 0..4 are POSITION, NORMAL, JOINTS_0 (u8) and WEIGHTS_0
/// (f32) shared by every level of detail, 4 the indices of LOD 0, 9 the inverse bind matrices.
const HUMAN: &str = "humans/h1700_w60.glb";
const POSITION: usize = 0;
const JOINTS: usize = 2;
const WEIGHTS: usize = 3;
const INVERSE_BIND: usize = 9;

/// Writes `glb` as `name` into `dir` and returns its path.
fn put(dir: &Path, name: &str, glb: &Glb) -> PathBuf {
    let p = dir.join(name);
    glb.write(&p);
    p
}

/// Writes `glb` as `name`, loads it with `load` and returns the error message, which must be
/// an input error naming the file and `needle`, given before the load allocates 64 MiB (the
/// hostile files here peak at 7.8 MB, the size of the model they mutate; a hostile count must
/// be refused before it is believed).
fn refused<T>(
    dir: &Path,
    name: &str,
    glb: &Glb,
    needle: &str,
    load: impl FnOnce(&Path) -> pedscan::error::Result<T> + Send + 'static,
) -> String {
    let p = put(dir, name, glb);
    let e = bounded(name, 64 << 20, move || load(&p).err()).unwrap_or_else(|| panic!("{name} was accepted"));
    let msg = e.to_string();
    assert!(e.is_input(), "{name}: {msg}");
    assert!(msg.contains(name) && msg.contains(needle), "{name}: the message should name `{needle}`: {msg}");
    msg
}

/// [`refused`] for a human model (loaded for a motion that animates the walk).
fn human_refused(dir: &Path, name: &str, glb: &Glb, needle: &str) -> String {
    refused(dir, name, glb, needle, |p| HumanModel::load(p, true))
}

/// [`refused`] for an environment.
fn environment_refused(dir: &Path, name: &str, glb: &Glb, needle: &str) -> String {
    refused(dir, name, glb, needle, Environment::load)
}

/// Runs `pedscan generate` into `o` with `args` and asserts that it is refused as an input
/// error (exit code 2) naming `file` and `needle`, with nothing written.
fn generate_refused(dir: &Path, args: &[&str], file: &str, needle: &str) {
    let mut all = vec!["generate", "--out", "o", "--frames", "2", "--humans", "1..1", "--backend", "raycast"];
    all.extend_from_slice(args);
    let o = pedscan_bounded(&all, dir, REFUSED_RUN_DATA_BYTES);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "exit code for {args:?}: {err}");
    assert!(err.contains(file) && err.contains(needle), "message for {args:?} should name {file} and `{needle}`: {err}");
    let left: Vec<_> = std::fs::read_dir(dir.join("o")).map(|d| d.filter_map(|e| e.ok()).map(|e| e.path()).collect()).unwrap_or_default();
    assert!(left.is_empty(), "{args:?} left files behind: {left:?}");
}

fn bundled_human_path() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data").join(HUMAN).display().to_string()
}

#[test]
fn sensor_with_a_nan_among_unsorted_elevations_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let mut elevations: Vec<String> = (0..32).map(|k| format!("{:.1}", ((k * 13) % 32) as f64 - 22.0)).collect();
    elevations[9] = "nan".into();
    std::fs::write(dir.join("nan_sensor.toml"), format!("elevation_deg = [{}]\ncolumns = 512\n", elevations.join(", "))).unwrap();
    generate_refused(dir, &["--sensor", "nan_sensor.toml", "--models", &bundled_human_path()], "nan_sensor.toml", "elevation_deg[9]");
    std::fs::write(dir.join("inf_rate.toml"), "elevation_deg = [2.0, -2.0]\ncolumns = 512\nrate_hz = inf\n").unwrap();
    generate_refused(dir, &["--sensor", "inf_rate.toml", "--models", &bundled_human_path()], "inf_rate.toml", "rate_hz");
}

#[test]
fn float_vec3_indices_are_refused_for_a_human_and_an_environment() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // Indices naming the positions (FLOAT VEC3): gltf's index reader hit `unreachable!`.
    let mut human = Glb::bundled(HUMAN);
    human.json["meshes"][0]["primitives"][0]["indices"] = json!(POSITION);
    put(dir, "vec3_indices_human.glb", &human);
    generate_refused(dir, &["--models", "vec3_indices_human.glb"], "vec3_indices_human.glb", "indices");
    let mut hall = Glb::bundled("scene/hall.glb");
    hall.json["meshes"][2]["primitives"][0]["indices"] = hall.json["meshes"][2]["primitives"][0]["attributes"]["POSITION"].clone();
    put(dir, "vec3_indices_hall.glb", &hall);
    generate_refused(
        dir,
        &["--models", &bundled_human_path(), "--background", "vec3_indices_hall.glb"],
        "vec3_indices_hall.glb",
        "indices",
    );
    // The other attributes gltf reads by type: JOINTS_0 as FLOAT, WEIGHTS_0 as a signed
    // type, POSITION as bytes, inverse bind matrices as VEC4, an animation's times as VEC3.
    let mut joints = Glb::bundled(HUMAN);
    joints.json["meshes"][0]["primitives"][0]["attributes"]["JOINTS_0"] = json!(WEIGHTS);
    human_refused(dir, "float_joints.glb", &joints, "JOINTS_0");
    let mut weights = Glb::bundled(HUMAN);
    weights.json["accessors"][WEIGHTS]["componentType"] = json!(5122);
    human_refused(dir, "short_weights.glb", &weights, "WEIGHTS_0");
    let mut positions = Glb::bundled(HUMAN);
    positions.json["accessors"][POSITION]["componentType"] = json!(5121);
    human_refused(dir, "byte_positions.glb", &positions, "POSITION");
    let mut ibm = Glb::bundled(HUMAN);
    ibm.json["accessors"][INVERSE_BIND]["type"] = json!("VEC4");
    human_refused(dir, "vec4_inverse_bind.glb", &ibm, "inverse bind matrices");
    let mut times = Glb::bundled(HUMAN);
    let input = times.json["animations"][0]["samplers"][0]["input"].as_u64().unwrap() as usize;
    times.json["accessors"][input]["type"] = json!("VEC3");
    times.json["accessors"][input]["count"] = json!(16);
    human_refused(dir, "vec3_times.glb", &times, "input times");
    // Empty and sparse accessors are refused too (an empty one underflowed in gltf).
    let mut empty = Glb::bundled(HUMAN);
    empty.json["accessors"][POSITION]["count"] = json!(0);
    human_refused(dir, "empty_positions.glb", &empty, "POSITION");
    let mut sparse = Glb::bundled("scene/hall.glb");
    sparse.json["accessors"][0]["sparse"] =
        json!({"count": 1, "indices": {"bufferView": 1, "componentType": 5125}, "values": {"bufferView": 0}});
    environment_refused(dir, "sparse_hall.glb", &sparse, "sparse");
}

#[test]
fn environment_node_cycles_and_runaway_instancing_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // Node 0 its own child: walked a million times, copying the floor each time (15 s, 11 GB).
    let mut cyclic = Glb::bundled("scene/hall.glb");
    cyclic.json["nodes"][0]["children"] = json!([0]);
    put(dir, "cyclic_hall.glb", &cyclic);
    generate_refused(dir, &["--models", &bundled_human_path(), "--background", "cyclic_hall.glb"], "cyclic_hall.glb", "node 0");
    // A longer cycle below a root.
    let mut longer = Glb::bundled("scene/hall.glb");
    longer.json["nodes"][0]["children"] = json!([1]);
    longer.json["nodes"][1]["children"] = json!([2]);
    longer.json["nodes"][2]["children"] = json!([0]);
    environment_refused(dir, "cycle3_hall.glb", &longer, "ancestor");
    // One node the child of two: the spec's strict trees forbid it, and chains of them
    // multiply the walk.
    let mut shared = Glb::bundled("scene/hall.glb");
    shared.json["nodes"][0]["children"] = json!([2]);
    shared.json["nodes"][1]["children"] = json!([2]);
    let roots: Vec<Value> = shared.json["scenes"][0]["nodes"].as_array().unwrap().iter().filter(|n| **n != json!(2)).cloned().collect();
    shared.json["scenes"][0]["nodes"] = Value::Array(roots);
    environment_refused(dir, "shared_hall.glb", &shared, "node 2");
    // Nodes each instancing a mesh of 1000 wall primitives, together just over the documented
    // cap of triangles: refused before any is copied.
    let mut many = Glb::bundled("scene/hall.glb");
    let wall = many.json["meshes"][2]["primitives"][0].clone();
    let per_node = 1000 * many.json["accessors"][wall["indices"].as_u64().unwrap() as usize]["count"].as_u64().unwrap() as usize / 3;
    many.json["meshes"][2]["primitives"] = Value::Array(vec![wall; 1000]);
    let first = many.json["nodes"].as_array().unwrap().len();
    let mut roots = Vec::new();
    for k in 0..pedscan::scene::MAX_ENVIRONMENT_TRIANGLES / per_node + 1 {
        many.json["nodes"].as_array_mut().unwrap().push(json!({"mesh": 2, "translation": [k as f64, 0.0, 0.0]}));
        roots.push(json!(first + k));
    }
    many.json["scenes"][0]["nodes"] = Value::Array(roots);
    let msg = environment_refused(dir, "instanced_hall.glb", &many, "triangles");
    assert!(msg.contains(&pedscan::scene::MAX_ENVIRONMENT_TRIANGLES.to_string()), "{msg}");
    // The bundled hall itself still loads.
    Environment::load(&put(dir, "hall.glb", &Glb::bundled("scene/hall.glb"))).unwrap();
}

#[test]
fn skin_accessors_that_do_not_fit_or_disagree_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // A count of 2^32 - 1 made gltf's reader give up silently: every vertex unweighted,
    // skinned onto the origin (145 s for 2 frames, no person in them).
    let mut huge = Glb::bundled(HUMAN);
    huge.json["accessors"][JOINTS]["count"] = json!(4294967295u64);
    put(dir, "huge_joints.glb", &huge);
    generate_refused(dir, &["--models", "huge_joints.glb"], "huge_joints.glb", "JOINTS_0");
    // WEIGHTS_0 on the (shorter) view of the joints.
    let mut view = Glb::bundled(HUMAN);
    view.json["accessors"][WEIGHTS]["bufferView"] = view.json["accessors"][JOINTS]["bufferView"].clone();
    put(dir, "weights_view.glb", &view);
    generate_refused(dir, &["--models", "weights_view.glb"], "weights_view.glb", "WEIGHTS_0");
    // A count that fits its view but differs from POSITION's.
    let mut fewer = Glb::bundled(HUMAN);
    fewer.json["accessors"][WEIGHTS]["count"] = json!(100);
    human_refused(dir, "fewer_weights.glb", &fewer, "POSITION");
    // An offset past the end of the buffer.
    let mut offset = Glb::bundled(HUMAN);
    offset.json["accessors"][JOINTS]["byteOffset"] = json!(1u64 << 40);
    human_refused(dir, "far_offset.glb", &offset, "JOINTS_0");
    // A joint index past the skin's 137 joints.
    let mut joint = Glb::bundled(HUMAN);
    let at = joint.at(JOINTS, 5, 0);
    joint.bin[at] = 200;
    human_refused(dir, "joint_200.glb", &joint, "joint");
    // Weights: NaN, negative, all zero.
    for (name, values) in
        [("nan_weight.glb", [f32::NAN, 0.5, 0.0, 0.0]), ("negative_weight.glb", [1.5, -0.5, 0.0, 0.0]), ("zero_weights.glb", [0.0; 4])]
    {
        let mut w = Glb::bundled(HUMAN);
        for (c, v) in values.into_iter().enumerate() {
            w.set_f32(WEIGHTS, 7, c, v);
        }
        human_refused(dir, name, &w, "weight");
    }
    // A skinned mesh without weights (its vertices would all collapse onto the origin).
    let mut bare = Glb::bundled(HUMAN);
    for m in bare.json["meshes"].as_array_mut().unwrap() {
        m["primitives"][0]["attributes"].as_object_mut().unwrap().remove("WEIGHTS_0");
    }
    human_refused(dir, "no_weights.glb", &bare, "WEIGHTS_0");
}

#[test]
fn implausible_extras_and_broken_skeletons_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // A negative height label was written to the output as the person's height.
    let mut negative = Glb::bundled(HUMAN);
    negative.json["scenes"][0]["extras"]["pedscan"]["height_m"] = json!(-1.7);
    put(dir, "negative_height.glb", &negative);
    generate_refused(dir, &["--models", "negative_height.glb"], "negative_height.glb", "height_m");
    // Every number of the metadata: zero, absurd, infinite (1e39 is inf as f32), negative.
    for (key, value, name) in [
        ("height_m", json!(0.0), "zero_height.glb"),
        ("height_m", json!(1e39), "inf_height.glb"),
        ("height_m", json!(1e6), "tall.glb"),
        ("height_m", json!(2.5), "mislabelled.glb"),
        ("weight_kg", json!(-60.0), "negative_weight_kg.glb"),
        ("weight_kg", json!(1e39), "inf_weight_kg.glb"),
        ("stride_length_m", json!(0.0), "zero_stride.glb"),
        ("stride_length_m", json!(400.0), "long_stride.glb"),
        ("cycle_s", json!(1e39), "inf_cycle.glb"),
        ("cycle_s", json!(-1.0), "negative_cycle.glb"),
    ] {
        let mut g = Glb::bundled(HUMAN);
        g.json["scenes"][0]["extras"]["pedscan"][key] = value;
        human_refused(dir, name, &g, key);
    }
    let mut lod = Glb::bundled(HUMAN);
    lod.json["scenes"][0]["extras"]["pedscan"]["lods"][2]["error_m"] = json!(-0.02);
    human_refused(dir, "negative_lod_error.glb", &lod, "error_m");
    let mut repeated = Glb::bundled(HUMAN);
    let lods: Vec<Value> = (0..10_000).map(|k| json!({"mesh": 1, "error_m": 0.01 + k as f64 * 1e-6})).collect();
    repeated.json["scenes"][0]["extras"]["pedscan"]["lods"] = Value::Array(lods);
    human_refused(dir, "repeated_lods.glb", &repeated, "mesh 1");
    // NaN keyframes: rotation (distorted people), translation, and a NaN time.
    let mut rot = Glb::bundled(HUMAN);
    let out = rot.animation_output("rotation");
    rot.set_f32(out, 3, 1, f32::NAN);
    human_refused(dir, "nan_rotation.glb", &rot, "rotation");
    for c in 0..4 {
        rot.set_f32(out, 3, c, 0.0);
    }
    human_refused(dir, "zero_rotation.glb", &rot, "too far from a unit quaternion");
    let mut tr = Glb::bundled(HUMAN);
    let out = tr.animation_output("translation");
    tr.set_f32(out, 0, 2, f32::INFINITY);
    human_refused(dir, "inf_translation.glb", &tr, "translation");
    // A translation keyframe throwing the root 2 km away.
    let mut far_key = Glb::bundled(HUMAN);
    let out = far_key.animation_output("translation");
    far_key.set_f32(out, 4, 0, 2000.0);
    human_refused(dir, "far_keyframe.glb", &far_key, "joint");
    // A bone 2e9 m away at rest.
    let mut far = Glb::bundled(HUMAN);
    far.json["nodes"][5]["translation"] = json!([2e9, 0.0, 0.0]);
    human_refused(dir, "far_bone.glb", &far, "node 5");
    // Inverse bind matrices: NaN, singular.
    let mut nan_ibm = Glb::bundled(HUMAN);
    nan_ibm.set_f32(INVERSE_BIND, 3, 5, f32::NAN);
    human_refused(dir, "nan_inverse_bind.glb", &nan_ibm, "inverse bind matrix 3");
    let mut singular = Glb::bundled(HUMAN);
    for c in 0..16 {
        singular.set_f32(INVERSE_BIND, 4, c, 0.0);
    }
    human_refused(dir, "singular_inverse_bind.glb", &singular, "inverse bind matrix 4");
    let mut far_bind = Glb::bundled(HUMAN);
    far_bind.set_f32(INVERSE_BIND, 6, 12, 2e9);
    human_refused(dir, "far_inverse_bind.glb", &far_bind, "joint 6 (node 6) with its inverse bind matrix");
    // A skeleton node scaled to nothing (the root, or one leg joint): its joints collapse.
    let mut flat = Glb::bundled(HUMAN);
    flat.json["nodes"][0]["scale"] = json!([0.0, 0.0, 0.0]);
    human_refused(dir, "zero_scale_root.glb", &flat, "node 0 has the scale");
    let mut leg = Glb::bundled(HUMAN);
    let thigh = leg.json["nodes"].as_array().unwrap().iter().position(|n| n["name"] == "upperleg01.L").unwrap();
    leg.json["nodes"][thigh]["scale"] = json!([1.0, 0.0, 1.0]);
    human_refused(dir, "zero_scale_leg.glb", &leg, &format!("node {thigh} has the scale"));
    // Node cycle in a human: named.
    let mut cyclic = Glb::bundled(HUMAN);
    cyclic.json["nodes"][3]["children"] = json!([0]);
    human_refused(dir, "cyclic_human.glb", &cyclic, "ancestor");
    // The unmodified copy loads: the mutations, not the copying, are refused.
    let good = HumanModel::load(&put(dir, "h1700_w60.glb", &Glb::bundled(HUMAN)), true).unwrap();
    assert_eq!(good.labelled_height_m, Some(1.7));
}
