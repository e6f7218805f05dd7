//! Loading a glTF human: the file's checks, its skeleton, walk animation and levels of detail.

use super::*;
use super::gait::{global_rest, is_arm_name, is_leg_name, sample};
use crate::error::{Error, Result};
use glam::{Mat4, Quat, Vec3, Vec4};
use serde::Deserialize;
use std::path::Path;
use std::sync::Arc;

/// pedscan's metadata in a bundled model (`scenes[0].extras.pedscan`).
#[derive(Clone, Debug, Default, Deserialize)]
struct PedscanExtras {
    height_m: Option<f32>,
    weight_kg: Option<f32>,
    stride_length_m: Option<f32>,
    cycle_s: Option<f32>,
    #[serde(default)]
    lods: Vec<LodExtras>,
}

#[derive(Clone, Debug, Deserialize)]
struct LodExtras {
    mesh: usize,
    error_m: f32,
}

impl PedscanExtras {
    /// Checks every number of the metadata: finite and in the range of a person, each level of
    /// detail a distinct mesh of the `mesh_count`.
    fn check(&self, path: &Path, mesh_count: usize) -> Result<()> {
        let field = |key: &str, value: Option<f32>, (lo, hi): (f32, f32), unit: &str| match value {
            Some(v) if !(v.is_finite() && v > lo && v <= hi) => {
                Err(gltf_err(path, format!("scenes[0].extras.pedscan.{key} = {v} {unit} must be in ({lo}, {hi}]")))
            }
            _ => Ok(()),
        };
        field("height_m", self.height_m, PERSON_HEIGHT_M, "m")?;
        field("weight_kg", self.weight_kg, (0.0, MAX_WEIGHT_KG), "kg")?;
        field("stride_length_m", self.stride_length_m, (0.0, MAX_STRIDE_M), "m")?;
        field("cycle_s", self.cycle_s, (0.0, MAX_CYCLE_S), "s")?;
        let mut listed = vec![false; mesh_count];
        for (k, l) in self.lods.iter().enumerate() {
            if !(l.error_m >= 0.0 && l.error_m <= MAX_LOD_ERROR_M) {
                return Err(gltf_err(path, format!("scenes[0].extras.pedscan.lods[{k}].error_m = {} m must be in [0, {MAX_LOD_ERROR_M}]", l.error_m)));
            }
            match listed.get_mut(l.mesh) {
                None => return Err(gltf_err(path, format!("scenes[0].extras.pedscan.lods[{k}]: LOD mesh {} does not exist", l.mesh))),
                Some(seen) if *seen => {
                    return Err(gltf_err(path, format!("scenes[0].extras.pedscan.lods[{k}]: mesh {} is listed twice", l.mesh)))
                }
                Some(seen) => *seen = true,
            }
        }
        Ok(())
    }
}

#[derive(Clone, Debug, Deserialize)]
struct ExtrasRoot {
    pedscan: Option<PedscanExtras>,
}

fn gltf_err(path: &Path, msg: impl std::fmt::Display) -> Error {
    Error::input(path.display(), msg)
}

impl HumanModel {
    /// Loads a glTF/GLB human. `needs_animation`: the motion mode animates the gait, so a skin
    /// and an animation are required.
    pub fn load(path: &Path, needs_animation: bool) -> Result<HumanModel> {
        let bytes = std::fs::read(path).map_err(|e| Error::input(path.display(), format!("cannot read: {e}")))?;
        let gltf = checks::parse(&bytes).map_err(|e| gltf_err(path, e))?;
        let base = path.parent().map(Path::to_path_buf);
        let buffers = gltf::import_buffers(&gltf.document, base.as_deref(), gltf.blob.clone())
            .map_err(|e| gltf_err(path, format!("cannot read buffers: {e}")))?;
        let doc = &gltf.document;
        let name = path.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();

        let extras: PedscanExtras = doc
            .scenes()
            .next()
            .and_then(|s| s.extras().as_ref().map(|raw| raw.get().to_string()))
            .map(|text| serde_json::from_str::<ExtrasRoot>(&text))
            .transpose()
            .map_err(|e| gltf_err(path, format!("scenes[0].extras.pedscan is malformed: {e}")))?
            .and_then(|r| r.pedscan)
            .unwrap_or_default();

        extras.check(path, doc.meshes().len())?;

        // Node hierarchy at rest: strict trees of bounded depth (transforms are composed
        // recursively), finite transforms.
        if doc.nodes().len() > MAX_NODES {
            return Err(gltf_err(path, format!("{} nodes is more than the supported {MAX_NODES}", doc.nodes().len())));
        }
        let parents = checks::node_parents(path, doc)?;
        let mut nodes = Vec::with_capacity(parents.len());
        let leg_nodes: Vec<bool> = doc.nodes().map(|n| n.name().is_some_and(is_leg_name)).collect();
        let node_named = |name: &str| doc.nodes().position(|n| n.name() == Some(name));
        // A leg's nodes: (thigh, shank, foot, toe).
        let leg = |side: &str| -> Option<[usize; 4]> {
            Some([
                node_named(&format!("upperleg01.{side}"))?,
                node_named(&format!("lowerleg01.{side}"))?,
                node_named(&format!("foot.{side}"))?,
                node_named(&format!("toe1-1.{side}"))?,
            ])
        };
        let arm_nodes: Vec<bool> = doc.nodes().map(|n| n.name().is_some_and(is_arm_name)).collect();
        for (n, parent) in doc.nodes().zip(parents) {
            let (t, r, s) = n.transform().decomposed();
            let rest = NodeRest { parent, translation: Vec3::from(t), rotation: Quat::from_array(r).normalize(), scale: Vec3::from(s) };
            if !(rest.translation.is_finite() && rest.rotation.is_finite() && rest.scale.is_finite()) {
                return Err(gltf_err(path, format!("node {} has a transform that is not finite", n.index())));
            }
            nodes.push(rest);
        }

        // Skin.
        let skin = doc.skins().next();
        let (joint_nodes, inverse_bind) = match &skin {
            Some(skin) => {
                let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
                let inverse_bind = read_inverse_bind(path, skin, &joints, &buffers)?;
                (joints, inverse_bind)
            }
            None => (Vec::new(), Vec::new()),
        };
        // A skeleton's node scaled to nothing collapses every joint under it onto one point
        // (legs of no length, which no walk can be solved for). A joint's own scale only
        // shrinks what it alone carries (an accessory hidden so), and is left to it.
        for &j in &joint_nodes {
            let mut n = nodes[j].parent;
            while let Some(k) = n {
                if nodes[k].scale.abs().min_element() < MIN_JOINT_SCALE {
                    return Err(gltf_err(path, format!("node {k} has the scale {}, which collapses joint node {j} under it", nodes[k].scale)));
                }
                n = nodes[k].parent;
            }
        }

        // Walk animation: the one named "walk", else the first.
        let anim = doc
            .animations()
            .find(|a| a.name().map(|n| n.eq_ignore_ascii_case("walk")).unwrap_or(false))
            .or_else(|| doc.animations().next());
        let channels = match &anim {
            Some(anim) => read_channels(path, anim, &buffers)?,
            None => Vec::new(),
        };
        let anim_duration = channels.iter().map(|c| *c.times.last().unwrap()).fold(0.0f32, f32::max);

        if needs_animation {
            if skin.is_none() {
                return Err(gltf_err(path, "has no skin; the motion mode animates the walk (use `static` or `sliding` for rigid models)"));
            }
            if channels.is_empty() || anim_duration <= 0.0 {
                return Err(gltf_err(path, "has no walk animation; the motion mode animates the walk (use `static` or `sliding`)"));
            }
        }

        // Levels of detail: listed in extras, else every skinned mesh node's mesh (first = LOD 0).
        let mut lod_meshes: Vec<(usize, f32)> = extras.lods.iter().map(|l| (l.mesh, l.error_m)).collect();
        if lod_meshes.is_empty() {
            let mesh = doc
                .nodes()
                .find(|n| n.mesh().is_some() && (n.skin().is_some() || skin.is_none()))
                .and_then(|n| n.mesh())
                .ok_or_else(|| gltf_err(path, "has no mesh"))?;
            lod_meshes.push((mesh.index(), 0.0));
        }
        lod_meshes.sort_by(|a, b| a.1.total_cmp(&b.1));
        let meshes: Vec<gltf::Mesh> = lod_meshes
            .iter()
            .map(|&(m, _)| doc.meshes().nth(m).ok_or_else(|| gltf_err(path, format!("LOD mesh {m} does not exist"))))
            .collect::<Result<_>>()?;
        // Every accessor is checked, and the levels' sizes summed, before any is read.
        let (mut vertices, mut triangles) = (0usize, 0usize);
        for mesh in &meshes {
            let (v, t) = check_mesh(path, mesh, &buffers, joint_nodes.len())?;
            (vertices, triangles) = (vertices + v, triangles + t);
        }
        if triangles > MAX_MODEL_TRIANGLES || vertices > 3 * MAX_MODEL_TRIANGLES {
            return Err(gltf_err(
                path,
                format!(
                    "its levels of detail hold {triangles} triangles ({vertices} vertices); at most {MAX_MODEL_TRIANGLES} triangles and {} vertices are supported",
                    3 * MAX_MODEL_TRIANGLES
                ),
            ));
        }
        let mut lods = Vec::new();
        for (mesh, (_, error_m)) in meshes.iter().zip(lod_meshes) {
            lods.push(read_lod(path, mesh, &buffers, error_m, joint_nodes.len())?);
        }
        // Meshes without a skin: put the mesh node's own transform into the vertices.
        if skin.is_none() {
            if let Some(node) = doc.nodes().find(|n| n.mesh().is_some()) {
                let m = global_rest(&nodes, node.index());
                for lod in &mut lods {
                    for p in &mut lod.positions {
                        *p = m.transform_point3(*p);
                    }
                }
            }
        }

        let (lo, hi) = lods[0].positions.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), p| (lo.min(p.y), hi.max(p.y)));
        let height_m = hi - lo;
        if !(height_m.is_finite() && height_m > PERSON_HEIGHT_M.0 && height_m < PERSON_HEIGHT_M.1) {
            return Err(gltf_err(path, format!("rest mesh height {height_m} m is not that of a person (0.1..5 m); is it in metres with y up?")));
        }
        if let Some(label) = extras.height_m {
            if !(label >= 0.8 * height_m && label <= 1.25 * height_m) {
                return Err(gltf_err(
                    path,
                    format!("scenes[0].extras.pedscan.height_m = {label} m disagrees with the rest mesh's height of {height_m} m (more than -20 %/+25 %)"),
                ));
            }
        }
        nodes.shrink_to_fit();

        let mut model = HumanModel {
            name,
            path: path.to_path_buf(),
            height_m,
            labelled_height_m: extras.height_m,
            weight_kg: extras.weight_kg,
            stride_length_m: extras.stride_length_m,
            cycle_s: extras.cycle_s.unwrap_or(anim_duration),
            lods,
            nodes,
            joint_nodes,
            inverse_bind,
            channels,
            legs: None,
            arms: None,
        };
        let arm = |side: &str| Some([node_named(&format!("upperarm01.{side}"))?, node_named(&format!("lowerarm01.{side}"))?, node_named(&format!("wrist.{side}"))?]);
        model.arms = arm("L").zip(arm("R")).map(|(l, r)| [l, r]);
        if let (Some(l), Some(r), Some(&root)) = (leg("L"), leg("R"), model.joint_nodes.first()) {
            model.legs = model.plant_legs([l, r]).map(|legs| (legs, root));
        }
        model.check_reach(path)?;
        model.stand_pose(&leg_nodes);
        for ch in &mut model.channels {
            ch.arm = ch.property == Property::Rotation && arm_nodes.get(ch.node).copied().unwrap_or(false);
        }
        Ok(model)
    }

    /// The standing pose a person stops in (speed 0), per animated channel: legs (nodes named
    /// like a leg, foot or toe bone), the root of the skeleton and anything translated take
    /// their rest transform (straight legs, soles on the ground: the glTF contract of the
    /// bundled people); every other rotation (spine, arms, head) the mean of its walk, which
    /// brings the arms down beside the body with the walk's elbow flexion. A model whose
    /// nodes have no such names averages every channel.
    fn stand_pose(&mut self, leg_nodes: &[bool]) {
        let root = self.joint_nodes.first().copied();
        for ch in &mut self.channels {
            let rest = &self.nodes[ch.node];
            let rest_value = match ch.property {
                Property::Translation => rest.translation.extend(0.0),
                Property::Rotation => Vec4::from(rest.rotation),
                Property::Scale => rest.scale.extend(0.0),
            };
            let at_rest = leg_nodes.get(ch.node).copied().unwrap_or(false) || Some(ch.node) == root || ch.property != Property::Rotation;
            ch.stand = if at_rest && leg_nodes.iter().any(|&l| l) {
                rest_value
            } else {
                // Mean over the cycle: quaternions aligned with the first sample, summed and
                // normalised; other values averaged.
                let end = ch.times.last().copied().unwrap_or(0.0);
                let n = 48;
                let samples: Vec<Vec4> = (0..n).map(|k| sample(ch, end * k as f32 / n as f32)).collect();
                if ch.property == Property::Rotation {
                    let first = samples[0];
                    let sum: Vec4 = samples.iter().map(|&q| if q.dot(first) < 0.0 { -q } else { q }).sum();
                    if sum.length() > 1e-6 { sum.normalize() } else { rest_value }
                } else {
                    samples.iter().copied().sum::<Vec4>() / n as f32
                }
            };
        }
    }

    /// Checks that the mesh lies within [`MAX_REACH_M`] of the model's origin (where the
    /// person stands) and, at rest and at every key time of the walk, that every joint lies
    /// within [`MAX_REACH_M`] of the mesh's bounding box and its joint matrix (pose times
    /// inverse bind matrix) keeps that box within [`MAX_REACH_M`] of itself (an affine map
    /// takes the box into the hull of its corners' images, and skinning blends those): a bone
    /// far away (a hostile or broken transform, keyframe or skin) would tear the person apart
    /// or lose its precision.
    fn check_reach(&self, path: &Path) -> Result<()> {
        let (lo, hi) = self.lods[0].positions.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        let off_box = |p: Vec3| p.distance(p.clamp(lo, hi));
        let origin = off_box(Vec3::ZERO);
        if !(origin <= MAX_REACH_M) {
            return Err(gltf_err(path, format!("the mesh lies {origin} m from the model's origin, more than {MAX_REACH_M} m")));
        }
        let corners: Vec<Vec3> = (0..8).map(|k| Vec3::select(glam::BVec3::new(k & 1 != 0, k & 2 != 0, k & 4 != 0), hi, lo)).collect();
        let check = |globals: &[Mat4], when: &str| {
            for (j, (g, inverse_bind)) in globals.iter().zip(&self.inverse_bind).enumerate() {
                let joint = off_box(g.w_axis.truncate());
                let skinned = corners.iter().map(|&c| off_box((*g * *inverse_bind).transform_point3(c))).fold(0.0f32, |a, b| a.max(b));
                let fault = if !(joint <= MAX_REACH_M) {
                    format!("lies {joint} m from the mesh")
                } else if !(skinned <= MAX_REACH_M) {
                    format!("with its inverse bind matrix moves the mesh up to {skinned} m off itself")
                } else {
                    continue;
                };
                return Err(gltf_err(
                    path,
                    format!("joint {j} (node {}) {fault} {when}; joints must stay within {MAX_REACH_M} m of the mesh", self.joint_nodes[j]),
                ));
            }
            Ok(())
        };
        let rest: Vec<Mat4> = self.joint_nodes.iter().map(|&n| global_rest(&self.nodes, n)).collect();
        check(&rest, "at rest")?;
        let mut times: Vec<f32> = self.channels.iter().flat_map(|c| c.times.iter().copied()).collect();
        times.sort_by(f32::total_cmp);
        times.dedup();
        if times.len() > MAX_KEY_TIMES {
            return Err(gltf_err(path, format!("the walk has {} key times, more than the supported {MAX_KEY_TIMES}", times.len())));
        }
        let mut globals = Vec::new();
        for t in times {
            self.joint_globals(t, GaitStyle::WALK, &mut globals);
            check(&globals, &format!("at t = {t} s of the walk"))?;
        }
        Ok(())
    }
}

/// A skin's inverse bind matrices (identity where it has none), one per joint of `joints`,
/// each finite, affine and invertible.
fn read_inverse_bind(path: &Path, skin: &gltf::Skin, joints: &[usize], buffers: &[gltf::buffer::Data]) -> Result<Vec<Mat4>> {
    let Some(acc) = skin.inverse_bind_matrices() else {
        return Ok(vec![Mat4::IDENTITY; joints.len()]);
    };
    let what = format!("inverse bind matrices of skin {}", skin.index());
    let count = checks::accessor(path, &what, &acc, Some(&checks::MATRICES), buffers)?;
    if count != joints.len() {
        return Err(gltf_err(path, format!("skin {} has {count} inverse bind matrices for {} joints", skin.index(), joints.len())));
    }
    let matrices: Vec<Mat4> = skin
        .reader(|b| Some(&buffers[b.index()]))
        .read_inverse_bind_matrices()
        .ok_or_else(|| gltf_err(path, format!("{what} cannot be read")))?
        .map(|m| Mat4::from_cols_array_2d(&m))
        .collect();
    for (j, m) in matrices.iter().enumerate() {
        let fault = if !m.is_finite() {
            "is not finite"
        } else if !(m.determinant().abs() > 1e-12) {
            "is singular"
        } else if m.row(3).distance(Vec4::W) > 1e-5 {
            "is not affine (its last row is not 0 0 0 1)"
        } else {
            continue;
        };
        return Err(gltf_err(path, format!("inverse bind matrix {j} (joint node {}) of skin {} {fault}", joints[j], skin.index())));
    }
    Ok(matrices)
}

/// The channels of the walk animation `anim`, checked: accessors as their readers assume them,
/// one channel per node and property, input times finite and strictly increasing, every key
/// finite and every rotation key of a length (within 1e-3..1e3) that normalizes to a rotation.
fn read_channels(path: &Path, anim: &gltf::Animation, buffers: &[gltf::buffer::Data]) -> Result<Vec<Channel>> {
    let mut channels: Vec<Channel> = Vec::new();
    for (c, ch) in anim.channels().enumerate() {
        let (property, name) = match ch.target().property() {
            gltf::animation::Property::Translation => (Property::Translation, "translation"),
            gltf::animation::Property::Rotation => (Property::Rotation, "rotation"),
            gltf::animation::Property::Scale => (Property::Scale, "scale"),
            gltf::animation::Property::MorphTargetWeights => continue,
        };
        let node = ch.target().node().index();
        let what = format!("{name} channel {c} of animation {} on node {node}", anim.index());
        if channels.iter().any(|o| o.node == node && o.property == property) {
            return Err(gltf_err(path, format!("{what}: node {node} has a second {name} channel")));
        }
        let interp = match ch.sampler().interpolation() {
            gltf::animation::Interpolation::Step => Interp::Step,
            gltf::animation::Interpolation::Linear => Interp::Linear,
            gltf::animation::Interpolation::CubicSpline => Interp::CubicSpline,
        };
        let keys = if property == Property::Rotation { &checks::ROTATION_KEYS } else { &checks::VEC3_KEYS };
        checks::accessor(path, &format!("input times of {what}"), &ch.sampler().input(), Some(&checks::TIMES), buffers)?;
        checks::accessor(path, &format!("keys of {what}"), &ch.sampler().output(), Some(keys), buffers)?;
        let reader = ch.reader(|b| Some(&buffers[b.index()]));
        let times: Vec<f32> = reader
            .read_inputs()
            .ok_or_else(|| gltf_err(path, format!("{what} has no readable input times")))?
            .collect();
        let values: Vec<Vec4> = match reader.read_outputs() {
            Some(gltf::animation::util::ReadOutputs::Translations(it)) => it.map(|v| Vec3::from(v).extend(0.0)).collect(),
            Some(gltf::animation::util::ReadOutputs::Scales(it)) => it.map(|v| Vec3::from(v).extend(0.0)).collect(),
            Some(gltf::animation::util::ReadOutputs::Rotations(it)) => it.into_f32().map(Vec4::from).collect(),
            _ => return Err(gltf_err(path, format!("{what} has no readable keys"))),
        };
        let per_key = if interp == Interp::CubicSpline { 3 } else { 1 };
        if values.len() != times.len() * per_key {
            return Err(gltf_err(path, format!("{what} has {} input times but {} keys", times.len(), values.len())));
        }
        if times.windows(2).any(|w| !(w[1] > w[0])) || times.iter().any(|t| !t.is_finite()) {
            return Err(gltf_err(path, format!("{what}: input times are not finite and strictly increasing")));
        }
        for (k, v) in values.iter().enumerate() {
            // Cubic-spline tangents (all but every third value) need not be unit quaternions.
            let is_value = interp != Interp::CubicSpline || k % 3 == 1;
            if !v.is_finite() {
                return Err(gltf_err(path, format!("{what}: key {k} = {v} is not finite")));
            }
            // Rotations are normalized when sampled; one far from unit length is no rotation.
            if property == Property::Rotation && is_value && !(v.length() >= 1e-3 && v.length() <= 1e3) {
                return Err(gltf_err(path, format!("{what}: key {k} = {v} has length {}, too far from a unit quaternion", v.length())));
            }
        }
        channels.push(Channel { node, property, interp, times, values, stand: Vec4::ZERO, arm: false });
    }
    Ok(channels)
}

/// Checks every accessor of the triangle primitives of `mesh` before any is read (where
/// `joint_count` > 0 the model has a skin, and each primitive needs JOINTS_0 and WEIGHTS_0);
/// returns the vertices and triangles reading it will hold.
fn check_mesh(path: &Path, mesh: &gltf::Mesh, buffers: &[gltf::buffer::Data], joint_count: usize) -> Result<(usize, usize)> {
    let (mut vertices, mut triangles) = (0, 0);
    for prim in mesh.primitives() {
        match checks::primitive(path, mesh, &prim, buffers, joint_count > 0)? {
            Some((n, corners)) => (vertices, triangles) = (vertices + n, triangles + corners / 3),
            None if prim.mode() == gltf::mesh::Mode::Triangles => {
                return Err(gltf_err(path, format!("POSITION of mesh {} primitive {} is missing", mesh.index(), prim.index())))
            }
            None => {}
        }
    }
    Ok((vertices, triangles))
}

/// Reads one level of detail from `mesh`, whose accessors [`check_mesh`] has checked.
fn read_lod(path: &Path, mesh: &gltf::Mesh, buffers: &[gltf::buffer::Data], error_m: f32, joint_count: usize) -> Result<Lod> {
    let mut positions = Vec::new();
    let mut joints = Vec::new();
    let mut weights = Vec::new();
    let mut indices = Vec::new();
    for prim in mesh.primitives() {
        if prim.mode() != gltf::mesh::Mode::Triangles {
            continue;
        }
        let at = format!("mesh {} primitive {}", mesh.index(), prim.index());
        let reader = prim.reader(|b| Some(&buffers[b.index()]));
        let base = positions.len() as u32;
        let pos: Vec<Vec3> = reader
            .read_positions()
            .ok_or_else(|| gltf_err(path, format!("POSITION of {at} cannot be read")))?
            .map(Vec3::from)
            .collect();
        let n = pos.len();
        positions.extend(pos);
        if joint_count > 0 {
            let (Some(j), Some(w)) = (reader.read_joints(0), reader.read_weights(0)) else {
                return Err(gltf_err(path, format!("JOINTS_0 or WEIGHTS_0 of {at} cannot be read")));
            };
            for (v, (jj, ww)) in j.into_u16().zip(w.into_f32()).enumerate() {
                if let Some(&bad) = jj.iter().find(|&&ji| ji as usize >= joint_count) {
                    return Err(gltf_err(path, format!("JOINTS_0 of {at}: vertex {v} names joint {bad} of a skin with {joint_count} joints")));
                }
                let sum: f32 = ww.iter().sum();
                if ww.iter().any(|x| !(x.is_finite() && *x >= 0.0)) || !(sum > 0.0 && sum.is_finite()) {
                    return Err(gltf_err(
                        path,
                        format!("WEIGHTS_0 of {at}: vertex {v} has skin weights {ww:?}; they must be finite, non-negative and not all zero"),
                    ));
                }
                joints.push(jj);
                weights.push(ww.map(|x| x / sum));
            }
        } else {
            joints.extend(std::iter::repeat([0u16; 4]).take(n));
            weights.extend(std::iter::repeat([0.0f32; 4]).take(n));
        }
        match reader.read_indices() {
            Some(idx) => {
                for i in idx.into_u32() {
                    if i as usize >= n {
                        return Err(gltf_err(path, format!("indices of {at}: index {i} points past the {n} vertices")));
                    }
                    indices.push(base + i);
                }
            }
            None => indices.extend(base..base + n as u32),
        }
    }
    if indices.len() < 3 || indices.len() % 3 != 0 {
        return Err(gltf_err(path, format!("mesh {} has no triangles", mesh.index())));
    }
    if positions.iter().any(|p| !p.is_finite()) {
        return Err(gltf_err(path, "a vertex position is not finite"));
    }
    let indices = spatially_ordered(&positions, &indices);
    // Compact: keep only the vertices this LOD's triangles use, in first-use order.
    let mut remap = vec![u32::MAX; positions.len()];
    let mut lod = Lod {
        positions: Vec::new(),
        joints: Vec::new(),
        weights: Vec::new(),
        indices: Vec::with_capacity(indices.len()),
        error_m,
        adjacency: Arc::default(),
    };
    for i in indices {
        let r = &mut remap[i as usize];
        if *r == u32::MAX {
            *r = lod.positions.len() as u32;
            lod.positions.push(positions[i as usize]);
            lod.joints.push(joints[i as usize]);
            lod.weights.push(weights[i as usize]);
        }
        lod.indices.push(*r);
    }
    lod.adjacency = Arc::new(Adjacency::build(&lod.indices));
    Ok(lod)
}

/// The triangles of `indices` reordered along a Morton curve of their bind-pose centroids, so
/// that runs of consecutive triangles are compact in space: the exact casts bound runs of 32
/// (`crate::backend::raster::clusters::MeshClusters`), and compact runs keep those boxes tight. Each triangle
/// keeps its vertex order (winding); only the order of the triangles changes.
fn spatially_ordered(positions: &[Vec3], indices: &[u32]) -> Vec<u32> {
    let centroid = |t: &[u32]| (positions[t[0] as usize] + positions[t[1] as usize] + positions[t[2] as usize]) / 3.0;
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for t in indices.chunks_exact(3) {
        let c = centroid(t);
        lo = lo.min(c);
        hi = hi.max(c);
    }
    let scale = 1023.0 / (hi - lo).max_element().max(1e-9);
    // Spreads the low 10 bits of `v` to every third bit.
    let spread = |v: u32| {
        let mut x = v & 0x3ff;
        x = (x | (x << 16)) & 0x030000ff;
        x = (x | (x << 8)) & 0x0300f00f;
        x = (x | (x << 4)) & 0x030c30c3;
        (x | (x << 2)) & 0x09249249
    };
    let mut keyed: Vec<(u32, u32)> = indices
        .chunks_exact(3)
        .enumerate()
        .map(|(k, t)| {
            let q = ((centroid(t) - lo) * scale).round();
            (spread(q.x as u32) | (spread(q.y as u32) << 1) | (spread(q.z as u32) << 2), k as u32)
        })
        .collect();
    keyed.sort_unstable();
    keyed.iter().flat_map(|&(_, k)| indices[3 * k as usize..3 * k as usize + 3].iter().copied()).collect()
}
