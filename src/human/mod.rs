//! Stage 4: people. Loads glTF 2.0 skinned humans with a walk animation, samples the walk at
//! a gait phase and skins the mesh (linear-blend skinning, 4 influences) on the CPU.
//!
//! Model frame: the glTF's own (y up, metres). A model is expected to face glTF +Z (the glTF
//! convention for an asset's front) with its feet on y = 0; [`MODEL_TO_BODY`] turns that into
//! pedscan's body frame (x forward, y left, z up, feet on z = 0) so a person with heading 0
//! walks along world +x.
//!
//! Gait: the phase advances by distance walked / stride length. The stride is the model's own,
//! the distance its animation covers in one cycle over a planted foot (`stride_length_m` in its
//! metadata), times a per-person factor the legs are re-solved for (two-bone IK,
//! [`GaitStyle::stride`]): the cycle is scaled to the walking speed. For models with the
//! bundled people's legs the stance foot is placed exactly about its heel and toe pivots and
//! pinned where the path turns ([`FootShift`]), so it stays planted at any speed and on
//! curves. A model without a recorded stride uses Alexander's relation between relative
//! stride and Froude number (see [`stride_length_m`]), and its feet slide where that differs.

pub(crate) mod checks;
pub mod proxy;

pub use checks::MAX_NODE_DEPTH;

use crate::error::{Error, Result};
use crate::geometry::{Adjacency, MeshLayout};
use glam::{Affine3A, Mat4, Quat, Vec3, Vec3A, Vec4};
use rayon::prelude::*;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Lists model files: a folder gives its `.glb` / `.gltf` files in name order.
pub fn model_files(paths: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| Error::io(p, e))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| matches!(f.extension().and_then(|e| e.to_str()), Some("glb") | Some("gltf")))
                .collect();
            found.sort();
            if found.is_empty() {
                return Err(Error::input(p.display(), "folder holds no .glb or .gltf human"));
            }
            files.extend(found);
        } else if p.is_file() {
            files.push(p.clone());
        } else {
            return Err(Error::input(p.display(), "human model file or folder does not exist"));
        }
    }
    Ok(files)
}

/// glTF model frame (y up, facing +Z) -> body frame (z up, facing +x):
/// a +90 deg turn about x (y up -> z up) followed by +90 deg about z (facing -y -> +x).
pub const MODEL_TO_BODY: Mat4 = Mat4::from_cols(
    Vec4::new(0.0, 1.0, 0.0, 0.0),
    Vec4::new(0.0, 0.0, 1.0, 0.0),
    Vec4::new(1.0, 0.0, 0.0, 0.0),
    Vec4::new(0.0, 0.0, 0.0, 1.0),
);

/// Standing heights of a person, metres (exclusive bounds): the rest mesh and the height
/// label of the metadata must lie between them.
pub const PERSON_HEIGHT_M: (f32, f32) = (0.1, 5.0);

/// Heaviest person a model's metadata may label, kg.
pub const MAX_WEIGHT_KG: f32 = 500.0;

/// Longest stride length a model's metadata may record, metres.
pub const MAX_STRIDE_M: f32 = 5.0;

/// Longest gait cycle a model's metadata may record, seconds.
pub const MAX_CYCLE_S: f32 = 10.0;

/// Largest recorded geometric error of a level of detail, metres.
pub const MAX_LOD_ERROR_M: f32 = 1.0;

/// Most nodes in a human glTF (a skeleton has tens to hundreds of bones).
pub const MAX_NODES: usize = 4096;

/// Most distinct key times of the walk animation (a cycle keyed at 1 kHz for 4 s has 4000).
pub const MAX_KEY_TIMES: usize = 4096;

/// Most triangles of one model, all its levels of detail together (each bundled model has
/// about 34,000); vertices may be three times as many.
pub const MAX_MODEL_TRIANGLES: usize = 2_000_000;

/// The mesh lies within this distance of the model's origin, and every joint, at rest and at
/// every key time of the walk, within this distance of the mesh's bounding box, metres.
pub const MAX_REACH_M: f32 = 10.0;

/// How people move (the paper's Table 5 ablations).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, serde::Serialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum MotionMode {
    /// Walk along the trajectory, gait phase tied to distance walked.
    Full,
    /// Follow the trajectory in a fixed pose.
    Sliding,
    /// Walk (gait advances) without moving.
    InPlace,
    /// Fixed pose, fixed place.
    Static,
}

impl MotionMode {
    /// Does this mode animate the gait (needs a skin and a walk animation)?
    pub fn animates(self) -> bool {
        matches!(self, MotionMode::Full | MotionMode::InPlace)
    }
    /// Does this mode move the person along the trajectory?
    pub fn moves(self) -> bool {
        matches!(self, MotionMode::Full | MotionMode::Sliding)
    }
}

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

#[derive(Clone, Copy, Debug)]
struct NodeRest {
    parent: Option<usize>,
    translation: Vec3,
    rotation: Quat,
    scale: Vec3,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Property {
    Translation,
    Rotation,
    Scale,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Interp {
    Step,
    Linear,
    CubicSpline,
}

#[derive(Clone, Debug)]
struct Channel {
    node: usize,
    property: Property,
    interp: Interp,
    times: Vec<f32>,
    /// xyz(w) values; for CUBICSPLINE three per key (in-tangent, value, out-tangent).
    values: Vec<Vec4>,
    /// The value of the standing pose (see [`HumanModel::stand_pose`]), set once loaded.
    stand: Vec4,
    /// An arm bone's rotation: scaled by [`GaitStyle::arm_swing`] about `stand`.
    arm: bool,
}

/// Gait events of the bundled people's walk (`tools/humans/README.md`), in cycles after a
/// foot's heel strike (the left foot strikes at phase 0, the right at 0.5): the toes leave
/// the ground.
pub const TOE_OFF: f32 = 0.62;
/// The stance ankle passes under the hip.
pub const UNDER_HIP: f32 = 0.25;

/// How a person walks, beside the phase: 1 / 1 is the model's own walk.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaitStyle {
    /// 1 = walking, 0 = the standing pose (blended in between).
    pub walking: f32,
    /// The arms' swing about their standing pose: 1 = the animation's, 0 = none.
    pub arm_swing: f32,
    /// Stride over the model's own ([`HumanModel::stride_scale_range`]): the ankles' fore-and-aft
    /// travel relative to the hips is scaled by it and the legs re-solved (two-bone IK), so the
    /// walk covers this times the model's stride per cycle with the feet still planted.
    pub stride: f32,
    /// Per foot (left, right): where the path's turns put it beside the straight walk, body
    /// frame (see [`FootShift`]); zero on a straight path.
    pub feet: [FootShift; 2],
}

impl GaitStyle {
    /// The model's own walk.
    pub const WALK: GaitStyle = GaitStyle { walking: 1.0, arm_swing: 1.0, stride: 1.0, feet: [FootShift::ZERO; 2] };
}

/// A planar rigid move of one foot in the body frame (x forward, y left, yaw about z up),
/// applied after the walk has placed it: `p -> R(yaw) p + (forward, left)`. On a curved path a
/// planted foot has to move in the body frame, which turns under it; the sequence computes this
/// move so that the foot keeps the world place and heading it has mid-stance
/// (`crate::scene::sequence::HumanPlan::at`), and blends it over the swing.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FootShift {
    pub forward_m: f32,
    pub left_m: f32,
    pub yaw_rad: f32,
}

impl FootShift {
    pub const ZERO: FootShift = FootShift { forward_m: 0.0, left_m: 0.0, yaw_rad: 0.0 };
}

/// The nodes of one leg the stride scaling re-solves: hip (thigh bone), knee (shank bone),
/// ankle (foot bone); and where the foot pivots on the ground in the stance, model frame at
/// rest (the bundled people's walk, `tools/humans/README.md`): the heel contact point (the
/// rear-most point of the sole, under the ankle) during the heel rocker and the toe joint
/// (first metatarsophalangeal) during the forefoot rocker.
#[derive(Clone, Copy, Debug)]
struct Leg {
    thigh: usize,
    shank: usize,
    foot: usize,
    ankle: Vec3,
    heel: Vec3,
    mtp: Vec3,
    /// Forward (model z) translation of the flat foot from rest when its ankle passes under
    /// the hip (phase 0.25 after its heel strike).
    flat_under_hip: f32,
}

/// One level of detail: a compact skinned mesh (only the vertices its triangles use).
#[derive(Clone, Debug)]
pub struct Lod {
    /// Bind-pose positions, model frame.
    pub positions: Vec<Vec3>,
    pub joints: Vec<[u16; 4]>,
    pub weights: Vec<[f32; 4]>,
    pub indices: Vec<u32>,
    /// Recorded geometric error against LOD 0, metres (0 for LOD 0).
    pub error_m: f32,
    /// Triangle one-rings, for the exact refinement's neighbour search.
    pub adjacency: Arc<Adjacency>,
}

impl Lod {
    /// The layout of this mesh skinned into a frame (a person's level of detail or proxy).
    pub fn layout(&self, instance: u32, double_sided: bool, adjacency: Option<Arc<Adjacency>>) -> MeshLayout {
        MeshLayout { vertex_count: self.positions.len() as u32, triangle_count: self.triangle_count() as u32, instance, double_sided, adjacency }
    }
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }
}

/// A loaded human model: skeleton, walk animation, skinned levels of detail.
#[derive(Clone, Debug)]
pub struct HumanModel {
    /// File stem, e.g. `h1700_w60`.
    pub name: String,
    pub path: PathBuf,
    /// Standing height of the rest mesh (max y - min y of LOD 0), metres.
    pub height_m: f32,
    /// Height label from the model's metadata, if it has one.
    pub labelled_height_m: Option<f32>,
    /// Weight from the model's metadata, if it has any.
    pub weight_kg: Option<f32>,
    /// Stride length recorded in the model (distance of one animation cycle), if any.
    pub stride_length_m: Option<f32>,
    /// Duration of one gait cycle of the walk animation, seconds (0 without animation).
    pub cycle_s: f32,
    /// Levels of detail, LOD 0 first, coarser after, sorted by recorded error.
    pub lods: Vec<Lod>,
    nodes: Vec<NodeRest>,
    /// Node index of each skin joint; empty without a skin.
    joint_nodes: Vec<usize>,
    inverse_bind: Vec<Mat4>,
    channels: Vec<Channel>,
    /// Both legs and the node that carries the pelvis, when the skeleton names them like the
    /// bundled people's (`upperleg01`, `lowerleg01`, `foot`, `.L` / `.R`): the stride can be
    /// scaled. Otherwise the model walks its own stride.
    legs: Option<([Leg; 2], usize)>,
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
        };
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

    /// Nominal height: the metadata's label when present, else the measured rest height.
    pub fn nominal_height_m(&self) -> f32 {
        self.labelled_height_m.unwrap_or(self.height_m)
    }

    /// The coarsest LOD whose recorded error is at most `max_error_m` (LOD 0 if none is).
    pub fn lod_for_error(&self, max_error_m: f32) -> usize {
        let mut best = 0;
        for (i, l) in self.lods.iter().enumerate() {
            if l.error_m <= max_error_m {
                best = i;
            }
        }
        best
    }

    /// Joint matrices (model frame) of the walk sampled at `phase` in [0, 1).
    pub fn joint_matrices(&self, phase: f32, out: &mut Vec<Mat4>) {
        self.joint_matrices_styled(phase, GaitStyle::WALK, out);
    }

    /// Joint matrices of the walk at `phase` in `style`: the arm bones' rotations scaled
    /// about their standing pose by `arm_swing`, then everything blended with the standing
    /// pose by `walking` (1 = the walk, 0 = standing; rotations slerped, translations
    /// interpolated).
    pub fn joint_matrices_styled(&self, phase: f32, style: GaitStyle, out: &mut Vec<Mat4>) {
        self.joint_globals(phase.rem_euclid(1.0) * self.cycle_s, style, out);
        for (m, inverse_bind) in out.iter_mut().zip(&self.inverse_bind) {
            *m *= *inverse_bind;
        }
    }

    /// Global transforms (model frame) of the joints at time `t` (s) of the walk in `style`.
    fn joint_globals(&self, t: f32, style: GaitStyle, out: &mut Vec<Mat4>) {
        let walk = style.walking.clamp(0.0, 1.0);
        out.clear();
        if self.joint_nodes.is_empty() {
            return;
        }
        let mut local: Vec<(Vec3, Quat, Vec3)> =
            self.nodes.iter().map(|n| (n.translation, n.rotation, n.scale)).collect();
        for ch in &self.channels {
            let mut v = if walk > 0.0 { sample(ch, t) } else { ch.stand };
            if ch.arm && walk > 0.0 && style.arm_swing != 1.0 {
                // stand * (stand^-1 v)^a: the swing's angle scaled, its axis kept.
                let stand = Quat::from_vec4(ch.stand).normalize();
                let swing = (stand.inverse() * Quat::from_vec4(v).normalize()).normalize();
                v = Vec4::from(stand * Quat::from_scaled_axis(swing.to_scaled_axis() * style.arm_swing));
            }
            if walk > 0.0 && walk < 1.0 {
                v = if ch.property == Property::Rotation {
                    Vec4::from(Quat::from_vec4(ch.stand).normalize().slerp(Quat::from_vec4(v).normalize(), walk))
                } else {
                    ch.stand.lerp(v, walk)
                };
            }
            let l = &mut local[ch.node];
            match ch.property {
                Property::Translation => l.0 = v.truncate(),
                Property::Rotation => l.1 = Quat::from_vec4(v).normalize(),
                Property::Scale => l.2 = v.truncate(),
            }
        }
        let mut global: Vec<Option<Mat4>> = vec![None; self.nodes.len()];
        if let (Some((legs, root)), true) = (self.legs, walk > 0.0 && self.stride_length_m.is_some() && self.cycle_s > 0.0) {
            let phase = t / self.cycle_s;
            self.place_feet(&mut local, &mut global, legs, root, phase, 1.0 + walk * (style.stride - 1.0), walk, style.feet);
        }
        out.extend(self.joint_nodes.iter().map(|&node| global_of(&self.nodes, &local, &mut global, node)));
    }

    /// The stride scales a model's own stride takes without strain: its walk re-solved for
    /// 0.75 to 1.2 times the recorded stride.
    pub fn stride_scale_range(&self) -> (f32, f32) {
        if self.legs.is_some() && self.stride_length_m.is_some() {
            (0.75, 1.2)
        } else {
            (1.0, 1.0)
        }
    }

    /// The legs' rest pivots, as the builder of the bundled people takes them: the heel contact
    /// point is the rear-most vertex of the sole (the full mesh's lowest centimetre, more than
    /// 2 cm to the foot's side of the midline) under the ankle, the toe pivot the toe joint.
    /// The flat foot's forward translation under the hip follows the builder's placement too
    /// (both heels strike where the left one's ankle passes under the left hip a quarter of a
    /// stride later). None where a foot has no sole.
    fn plant_legs(&self, legs: [[usize; 4]; 2]) -> Option<[Leg; 2]> {
        let at = |n: usize| global_rest(&self.nodes, n).w_axis.truncate();
        let rest = &self.lods.first()?.positions;
        let mut out = Vec::with_capacity(2);
        for ([thigh, shank, foot, toe], side) in legs.into_iter().zip([1.0f32, -1.0]) {
            let ankle = at(foot);
            let back = rest.iter().filter(|p| p.y < 0.01 && side * p.x > 0.02).map(|p| p.z).fold(f32::INFINITY, f32::min);
            if !back.is_finite() {
                return None;
            }
            out.push(Leg { thigh, shank, foot, ankle, heel: Vec3::new(ankle.x, 0.0, back), mtp: at(toe), flat_under_hip: 0.0 });
        }
        let (hip_l, ankle_l, heel_l) = (at(out[0].thigh).z, out[0].ankle.z, out[0].heel.z);
        for leg in &mut out {
            leg.flat_under_hip = hip_l - ankle_l + heel_l - leg.heel.z;
        }
        Some([out[0], out[1]])
    }

    /// Global transform of node `i` at time `t` of the walk (the model's own walk, as
    /// [`HumanModel::joint_globals`] gives it in [`GaitStyle::WALK`]), from its chain alone.
    fn walk_global(&self, i: usize, t: f32) -> Mat4 {
        let n = &self.nodes[i];
        let (mut tr, mut rot, mut scale) = (n.translation, n.rotation, n.scale);
        for ch in self.channels.iter().filter(|c| c.node == i) {
            let v = sample(ch, t);
            match ch.property {
                Property::Translation => tr = v.truncate(),
                Property::Rotation => rot = Quat::from_vec4(v).normalize(),
                Property::Scale => scale = v.truncate(),
            }
        }
        let m = Mat4::from_scale_rotation_translation(scale, rot, tr);
        match n.parent {
            Some(p) => self.walk_global(p, t) * m,
            None => m,
        }
    }

    /// Places both feet of the pose `local` at `phase` and re-solves the legs, for `k` times
    /// the model's stride, `walk` of the way from the animation to the planted feet, each foot
    /// moved by `feet` (scaled by `walk`). Model frame: y up, the person faces +z.
    ///
    /// Over the stance a foot is placed as the builder placed it, but exactly rather than as
    /// the animation's keys interpolate it: rotated by its animated orientation (the heel and
    /// forefoot rockers) about its ground pivot (the heel contact point until the foot is flat,
    /// the toe joint after), the pivot moving backwards at `k` strides per cycle through the
    /// place where the flat foot has its ankle under the hip a quarter of a cycle after heel
    /// strike. Every point of the planted foot then moves at `k` times `stride / cycle`, which
    /// the phase (advanced per `k` strides) matches, so it stays where it is on the ground. Over
    /// the swing the foot follows the animation, moved fore or aft by `(k - 1) c(phase)`, `c`
    /// a cubic from where the stance leaves it to where the next one starts with the stance's
    /// slope at both ends (so at any `k` the foot leaves and meets the ground with no
    /// horizontal speed in the world, as the animation does at `k = 1`), and what the exact
    /// stance differed from the animation at toe-off fades out. The gait
    /// events are the bundled people's contract (`tools/humans/README.md`): left heel strike at
    /// phase 0, right at 0.5, toe-off 0.62 of the cycle after, foot flat from 0.10 to 0.31,
    /// ankle under the hip at 0.25.
    ///
    /// The pelvis moves up or down so that the more stretched leg is exactly as stretched as in
    /// the animation at this phase (a shorter stride stands taller), then each leg is a two-bone
    /// chain (hip -> knee -> ankle) bent in the plane of its animated knee.
    /// `cache` holds the globals of `local` (or `None`s) and is left consistent with the result.
    #[allow(clippy::too_many_arguments)]
    fn place_feet(
        &self,
        local: &mut [(Vec3, Quat, Vec3)],
        cache: &mut [Option<Mat4>],
        legs: [Leg; 2],
        root: usize,
        phase: f32,
        k: f32,
        walk: f32,
        feet: [FootShift; 2],
    ) {
        // Halfway through the flat foot: the pivot changes from the heel to the toe joint.
        const HEEL_TO_TOE: f32 = 0.205;
        let stride = self.stride_length_m.unwrap_or(0.0);
        // Over the swing the stance's line `c(u) = -stride (u - 0.25)` continues as a cubic
        // back to where the next stance starts, with the stance's slope at both ends: the foot
        // leaves and meets the ground at the speed the stance has (none, in the world).
        let swing_line = |u: f32| {
            let (back, front) = (-stride * (TOE_OFF - UNDER_HIP), stride * UNDER_HIP);
            let slope = -stride * (1.0 - TOE_OFF);
            let x = (u - TOE_OFF) / (1.0 - TOE_OFF);
            let (x2, x3) = (x * x, x * x * x);
            let c = (2.0 * x3 - 3.0 * x2 + 1.0) * back + (x3 - 2.0 * x2 + x) * slope + (3.0 * x2 - 2.0 * x3) * front + (x3 - x2) * slope;
            (k - 1.0) * c
        };
        // The ankle and orientation of the stance foot at its own phase u, placed exactly.
        let planted = |leg: &Leg, u: f32, rot: Quat| {
            let pivot = if u < HEEL_TO_TOE { leg.heel } else { leg.mtp };
            pivot + Vec3::Z * (leg.flat_under_hip - k * stride * (u - UNDER_HIP)) + rot * (leg.ankle - pivot)
        };
        let pos = |m: Mat4| m.w_axis.truncate();
        let nodes = &self.nodes;
        // Animated hips, knees, ankles and foot orientations; the targets.
        let anim: [(Vec3, Vec3, Vec3, Quat); 2] = legs.map(|l| {
            let f = global_of(nodes, local, cache, l.foot);
            (pos(global_of(nodes, local, cache, l.thigh)), pos(global_of(nodes, local, cache, l.shank)), pos(f), Quat::from_mat4(&f).normalize())
        });
        let stretch = anim.iter().map(|&(h, _, a, _)| (a - h).length()).fold(0.0f32, f32::max);
        let mut targets = [(Vec3::ZERO, Quat::IDENTITY); 2];
        for (i, (leg, &(_, _, ankle, rot))) in legs.iter().zip(&anim).enumerate() {
            let u = (phase - 0.5 * i as f32).rem_euclid(1.0);
            let moved = if u < TOE_OFF {
                planted(leg, u, rot) - ankle
            } else {
                // The animation at toe-off, where the exact stance handed over.
                let t_off = (phase + TOE_OFF - u).rem_euclid(1.0) * self.cycle_s;
                let off = self.walk_global(leg.foot, t_off);
                let handover = planted(leg, TOE_OFF, Quat::from_mat4(&off).normalize()) - pos(off) - Vec3::Z * swing_line(TOE_OFF);
                let fade = 1.0 - smoothstep((u - TOE_OFF) / (1.0 - TOE_OFF));
                Vec3::Z * swing_line(u) + handover * fade
            };
            // The turn's move, in the model frame (body x forward = model z, body y left =
            // model x, body yaw = model yaw about y).
            let f = feet[i];
            let turn = Quat::from_rotation_y(walk * f.yaw_rad);
            let target = ankle + walk * moved;
            targets[i] = (turn * target + walk * Vec3::new(f.left_m, 0.0, f.forward_m), turn * rot);
        }
        // Pelvis height: the highest at which no leg reaches further than `stretch`.
        let lift = anim
            .iter()
            .zip(&targets)
            .map(|(&(h, _, _, _), &(t, _))| {
                let flat = Vec3::new(t.x - h.x, 0.0, t.z - h.z).length_squared();
                (stretch * stretch - flat).max(0.0).sqrt() - (h.y - t.y)
            })
            .fold(f32::INFINITY, f32::min);
        if lift.is_finite() {
            local[root].0.y += lift;
            cache.fill(None);
        }
        for (leg, (&(_, knee0, _, _), &(target, foot_rot))) in legs.iter().zip(anim.iter().zip(&targets)) {
            let (hip_m, knee_m, ankle_m) =
                (global_of(nodes, local, cache, leg.thigh), global_of(nodes, local, cache, leg.shank), global_of(nodes, local, cache, leg.foot));
            let (hip, knee, ankle) = (pos(hip_m), pos(knee_m), pos(ankle_m));
            let (l1, l2) = ((knee - hip).length(), (ankle - knee).length());
            let to = target - hip;
            let d = to.length().clamp((l1 - l2).abs() + 1e-4, (l1 + l2) * 0.9999);
            let dir = to.normalize_or_zero();
            // The knee stays in the plane of the hip, the target and the animated knee.
            let pole = knee0 - hip - dir * (knee0 - hip).dot(dir);
            let side = pole.normalize_or_zero();
            let cos_a = ((l1 * l1 + d * d - l2 * l2) / (2.0 * l1 * d)).clamp(-1.0, 1.0);
            let new_knee = hip + l1 * (cos_a * dir + (1.0 - cos_a * cos_a).sqrt() * side);
            // Thigh: turn the hip->knee direction onto the new one.
            let turn1 = arc((knee - hip).normalize_or_zero(), (new_knee - hip).normalize_or_zero());
            self.set_global_rotation(local, cache, leg.thigh, turn1 * Quat::from_mat4(&hip_m).normalize());
            // Shank: with the thigh turned, turn the knee->ankle direction onto the target.
            let knee_m = global_of(nodes, local, cache, leg.shank);
            let (knee_now, ankle_now) = (pos(knee_m), pos(global_of(nodes, local, cache, leg.foot)));
            let turn2 = arc((ankle_now - knee_now).normalize_or_zero(), (target - knee_now).normalize_or_zero());
            self.set_global_rotation(local, cache, leg.shank, turn2 * Quat::from_mat4(&knee_m).normalize());
            // Foot: its animated orientation, turned with the path.
            self.set_global_rotation(local, cache, leg.foot, foot_rot);
        }
    }

    /// Sets node `i`'s local rotation so that its global rotation is `rotation` (its parent's
    /// global transform as `local` has it; scales are 1 in a walking skeleton); `cache` holds
    /// the globals of `local` before and after.
    fn set_global_rotation(&self, local: &mut [(Vec3, Quat, Vec3)], cache: &mut [Option<Mat4>], i: usize, rotation: Quat) {
        let parent = match self.nodes[i].parent {
            Some(p) => Quat::from_mat4(&global_of(&self.nodes, local, cache, p)).normalize(),
            None => Quat::IDENTITY,
        };
        local[i].1 = (parent.inverse() * rotation).normalize();
        cache.fill(None);
    }

    /// Skins LOD `lod` with `joints` and maps it through `transform` (model -> target frame),
    /// writing f32 positions into `out` (resized). Without a skin the bind pose is used.
    pub fn skin_into(&self, lod: usize, joints: &[Mat4], transform: &Mat4, out: &mut Vec<[f32; 3]>) {
        out.resize(self.lods[lod].positions.len(), [0.0; 3]);
        self.skin_into_slice(lod, joints, transform, &mut Vec::new(), out);
    }

    /// Like `skin_into`, into a slice of exactly the LOD's vertex count (e.g. the person's
    /// vertices in last frame's geometry); `placed` is scratch for the placed joint matrices.
    pub fn skin_into_slice(
        &self,
        lod: usize,
        joints: &[Mat4],
        transform: &Mat4,
        placed: &mut Vec<Affine3A>,
        out: &mut [[f32; 3]],
    ) {
        self.skin_lod_into_slice(&self.lods[lod], joints, transform, placed, out);
    }

    /// `skin_into_slice` for any mesh skinned to this model's skeleton (one of its LODs, or a
    /// proxy built from one: `crate::human::proxy`).
    pub fn skin_lod_into_slice(
        &self,
        l: &Lod,
        joints: &[Mat4],
        transform: &Mat4,
        placed: &mut Vec<Affine3A>,
        out: &mut [[f32; 3]],
    ) {
        assert_eq!(out.len(), l.positions.len(), "skinning into a slice of another size");
        if joints.is_empty() {
            out.par_iter_mut().zip(l.positions.par_iter()).for_each(|(o, p)| *o = transform.transform_point3(*p).into());
            return;
        }
        // The placement folded into each joint once (affine 3x4, SIMD), instead of once per
        // vertex: sum_k w_k (T J_k) p.
        placed.clear();
        placed.extend(joints.iter().map(|j| Affine3A::from_mat4(*transform * *j)));
        let placed = &placed[..];
        out.par_chunks_mut(2048).enumerate().for_each(|(c, chunk)| {
            let first = c * 2048;
            for (k, o) in chunk.iter_mut().enumerate() {
                *o = skin_vertex(l, placed, first + k).into();
            }
        });
    }
}

/// Vertex `i` of `l` skinned with the placed joint matrices `placed` (linear blend); the bind
/// pose where `placed` is empty (a model without a skin).
#[inline(always)]
pub fn skin_vertex(l: &Lod, placed: &[Affine3A], i: usize) -> Vec3A {
    let p = Vec3A::from(l.positions[i]);
    if placed.is_empty() {
        return p;
    }
    let j = l.joints[i];
    let w = l.weights[i];
    let mut acc = Vec3A::ZERO;
    for k in 0..4 {
        if w[k] != 0.0 {
            acc += w[k] * placed[j[k] as usize].transform_point3a(p);
        }
    }
    acc
}

fn global_rest(nodes: &[NodeRest], i: usize) -> Mat4 {
    let n = &nodes[i];
    let m = Mat4::from_scale_rotation_translation(n.scale, n.rotation, n.translation);
    match n.parent {
        Some(p) => global_rest(nodes, p) * m,
        None => m,
    }
}

fn global_of(nodes: &[NodeRest], local: &[(Vec3, Quat, Vec3)], cache: &mut [Option<Mat4>], i: usize) -> Mat4 {
    if let Some(m) = cache[i] {
        return m;
    }
    let (t, r, s) = local[i];
    let m = Mat4::from_scale_rotation_translation(s, r, t);
    let g = match nodes[i].parent {
        Some(p) => global_of(nodes, local, cache, p) * m,
        None => m,
    };
    cache[i] = Some(g);
    g
}

/// 0 below 0, 1 above 1, smooth (zero slope at both ends) in between.
fn smoothstep(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// Samples a channel at time `t` (clamped to its key range), glTF interpolation rules.
fn sample(ch: &Channel, t: f32) -> Vec4 {
    let times = &ch.times;
    let n = times.len();
    let value = |k: usize| if ch.interp == Interp::CubicSpline { ch.values[3 * k + 1] } else { ch.values[k] };
    if n == 1 || t <= times[0] {
        return value(0);
    }
    if t >= times[n - 1] {
        return value(n - 1);
    }
    let k = times.partition_point(|&x| x <= t) - 1;
    let (t0, t1) = (times[k], times[k + 1]);
    let dt = t1 - t0;
    let u = (t - t0) / dt;
    match ch.interp {
        Interp::Step => value(k),
        Interp::Linear => {
            if ch.property == Property::Rotation {
                let a = Quat::from_vec4(value(k)).normalize();
                let b = Quat::from_vec4(value(k + 1)).normalize();
                Vec4::from(a.slerp(b, u))
            } else {
                value(k).lerp(value(k + 1), u)
            }
        }
        Interp::CubicSpline => {
            let p0 = ch.values[3 * k + 1];
            let m0 = ch.values[3 * k + 2] * dt;
            let p1 = ch.values[3 * (k + 1) + 1];
            let m1 = ch.values[3 * (k + 1)] * dt;
            let (u2, u3) = (u * u, u * u * u);
            let v = (2.0 * u3 - 3.0 * u2 + 1.0) * p0
                + (u3 - 2.0 * u2 + u) * m0
                + (-2.0 * u3 + 3.0 * u2) * p1
                + (u3 - u2) * m1;
            if ch.property == Property::Rotation {
                Vec4::from(Quat::from_vec4(v).normalize())
            } else {
                v
            }
        }
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

/// Hip (leg) height as a fraction of stature (Winter, Biomechanics and Motor Control of Human
/// Movement, anthropometric segment lengths: greater trochanter at 0.530 H).
pub const LEG_LENGTH_FRACTION: f64 = 0.530;

impl HumanModel {
    /// The stride the gait phase advances by (distance per cycle): the model's recorded stride
    /// (feet planted at every speed), else Alexander's for its height at `speed_mps`.
    pub fn gait_stride_m(&self, speed_mps: f64) -> f64 {
        match self.stride_length_m {
            Some(s) => s as f64,
            None => stride_length_m(self.height_m as f64, speed_mps.max(0.1)),
        }
    }
}

/// The rotation taking unit `from` onto unit `to`; none where either is zero (a degenerate
/// chain keeps its pose rather than turning into NaN). Small turns are kept:
/// `Quat::from_rotation_arc` returns the identity below ~7e-4 rad (cos within 2 ulp of 1),
/// which froze the re-solved legs for a few frames around each instant where the stride
/// scaling moves a foot by less than a few tenths of a millimetre (the stance foot then slid
/// at (k - 1) / k of the walking speed).
fn arc(from: Vec3, to: Vec3) -> Quat {
    if from == Vec3::ZERO || to == Vec3::ZERO {
        return Quat::IDENTITY;
    }
    // (from x to, 1 + from . to), normalised: the rotation by the angle between them about
    // their normal, exact down to zero; only near-opposite vectors need the general form.
    let w = 1.0 + from.dot(to);
    if w < 1e-4 {
        return Quat::from_rotation_arc(from, to);
    }
    let c = from.cross(to);
    Quat::from_xyzw(c.x, c.y, c.z, w).normalize()
}

/// Whether a node name names a leg bone (the standing pose keeps those at rest): `leg`,
/// `thigh`, `shin`, `calf`, `knee`, `foot`, `ankle`, `toe`, any case.
fn is_leg_name(name: &str) -> bool {
    let n = name.to_ascii_lowercase();
    ["leg", "thigh", "shin", "calf", "knee", "foot", "ankle", "toe"].iter().any(|k| n.contains(k))
}

/// Whether a node name names an arm bone (its swing scales with the person's arm swing):
/// `arm`, `shoulder`, `clavicle`, `elbow`, `hand`, `wrist`, any case (not `armature`, the
/// usual name of an exported skeleton's root).
fn is_arm_name(name: &str) -> bool {
    let n = name.to_ascii_lowercase().replace("armature", "");
    ["arm", "shoulder", "clavicle", "elbow", "hand", "wrist"].iter().any(|k| n.contains(k))
}

/// Stride length (heel strike to heel strike of the same foot) of a person of `height_m`
/// walking at `speed_mps`, from Alexander's relation between relative stride length and the
/// Froude number (R. McN. Alexander, "Estimates of speeds of dinosaurs", Nature 261:129-130,
/// 1976): `stride / h = 2.3 * (v^2 / (g h))^0.3`, with h the leg length. At 1.3 m/s a 1.70 m
/// person strides 1.26 m, a 1.20 m child 0.99 m. Speeds near 0 give a floor of 0.2 h.
pub fn stride_length_m(height_m: f64, speed_mps: f64) -> f64 {
    let h = LEG_LENGTH_FRACTION * height_m;
    let froude = speed_mps * speed_mps / (9.81 * h);
    (2.3 * h * froude.powf(0.3)).max(0.2 * h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn model_to_body_turns_gltf_front_up_left_into_x_z_y() {
        let f = MODEL_TO_BODY.transform_vector3(Vec3::Z);
        let u = MODEL_TO_BODY.transform_vector3(Vec3::Y);
        let l = MODEL_TO_BODY.transform_vector3(Vec3::X);
        assert_eq!(f, Vec3::X);
        assert_eq!(u, Vec3::Z);
        assert_eq!(l, Vec3::Y);
        assert!((MODEL_TO_BODY.determinant() - 1.0).abs() < 1e-6, "a rotation, not a mirror");
    }

    #[test]
    fn stride_grows_with_speed_and_height() {
        let adult = stride_length_m(1.7, 1.3);
        assert!((adult - 1.2617).abs() < 1e-3, "{adult}");
        assert!((stride_length_m(1.2, 1.3) - 0.9887).abs() < 1e-3);
        assert!(stride_length_m(1.7, 1.6) > adult);
        assert!(stride_length_m(1.2, 1.3) < adult);
        assert!(stride_length_m(1.7, 0.0) > 0.0);
    }

    /// Two bones along +y: the root at the origin, the child 1 m up; a vertex at y = 1.5 half
    /// bound to each. Rotating the child by 90 deg about z moves its half by hand-computable
    /// amounts.
    #[test]
    fn two_bone_linear_blend_skinning_matches_hand_computation() {
        let nodes = vec![
            NodeRest { parent: None, translation: Vec3::ZERO, rotation: Quat::IDENTITY, scale: Vec3::ONE },
            NodeRest { parent: Some(0), translation: Vec3::Y, rotation: Quat::IDENTITY, scale: Vec3::ONE },
        ];
        let model = HumanModel {
            name: "t".into(),
            path: PathBuf::new(),
            height_m: 2.0,
            labelled_height_m: None,
            weight_kg: None,
            stride_length_m: None,
            cycle_s: 1.0,
            lods: vec![Lod {
                positions: vec![Vec3::new(0.0, 1.5, 0.0), Vec3::new(0.0, 0.5, 0.0), Vec3::new(0.0, 2.0, 0.0)],
                joints: vec![[0, 1, 0, 0], [0, 0, 0, 0], [1, 0, 0, 0]],
                weights: vec![[0.5, 0.5, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]],
                indices: vec![0, 1, 2],
                error_m: 0.0,
                adjacency: Arc::new(Adjacency::build(&[0, 1, 2])),
            }],
            nodes,
            joint_nodes: vec![0, 1],
            inverse_bind: vec![Mat4::IDENTITY, Mat4::from_translation(-Vec3::Y)],
            channels: vec![Channel {
                node: 1,
                property: Property::Rotation,
                interp: Interp::Linear,
                times: vec![0.0, 1.0],
                values: vec![
                    Vec4::from(Quat::from_rotation_z(std::f32::consts::FRAC_PI_2)),
                    Vec4::from(Quat::from_rotation_z(std::f32::consts::FRAC_PI_2)),
                ],
                stand: Vec4::from(Quat::IDENTITY),
                arm: false,
            }],
            legs: None,
        };
        let mut joints = Vec::new();
        model.joint_matrices(0.25, &mut joints);
        let mut out = Vec::new();
        model.skin_into(0, &joints, &Mat4::IDENTITY, &mut out);
        // Child rotated 90 deg about z at (0,1,0): (0,1.5,0) -> (-0.5,1,0) for the child;
        // blended half/half with the unmoved root: (-0.25, 1.25, 0).
        let close = |a: [f32; 3], b: [f32; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6);
        assert!(close(out[0], [-0.25, 1.25, 0.0]), "{:?}", out[0]);
        assert!(close(out[1], [0.0, 0.5, 0.0]), "{:?}", out[1]);
        assert!(close(out[2], [-1.0, 1.0, 0.0]), "{:?}", out[2]);
    }

    #[test]
    fn linear_rotation_sampling_slerps_and_clamps() {
        let ch = Channel {
            node: 0,
            property: Property::Rotation,
            interp: Interp::Linear,
            times: vec![0.0, 2.0],
            values: vec![Vec4::from(Quat::IDENTITY), Vec4::from(Quat::from_rotation_x(1.0))],
            stand: Vec4::from(Quat::IDENTITY),
            arm: false,
        };
        let q = Quat::from_vec4(sample(&ch, 1.0));
        assert!(q.angle_between(Quat::from_rotation_x(0.5)) < 1e-5);
        assert_eq!(sample(&ch, -1.0), Vec4::from(Quat::IDENTITY));
        let end = Quat::from_vec4(sample(&ch, 5.0));
        assert!(end.angle_between(Quat::from_rotation_x(1.0)) < 1e-6);
    }
}

/// Small hand-built models for tests elsewhere in the crate.
#[cfg(test)]
pub(crate) mod tests_support {
    use super::*;

    /// A rigid 0.4 x 0.3 x 1.7 m box "person" (glTF frame: y up, facing +Z), one joint, no
    /// animation.
    pub fn tiny_model() -> HumanModel {
        let (x, y, z) = (0.2f32, 1.7f32, 0.15f32);
        let positions = vec![
            Vec3::new(-x, 0.0, -z),
            Vec3::new(x, 0.0, -z),
            Vec3::new(x, y, -z),
            Vec3::new(-x, y, -z),
            Vec3::new(-x, 0.0, z),
            Vec3::new(x, 0.0, z),
            Vec3::new(x, y, z),
            Vec3::new(-x, y, z),
        ];
        let indices = vec![0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4, 1, 2, 6, 1, 6, 5, 2, 3, 7, 2, 7, 6, 3, 0, 4, 3, 4, 7];
        HumanModel {
            name: "box".into(),
            path: PathBuf::from("box.glb"),
            height_m: 1.7,
            labelled_height_m: Some(1.7),
            weight_kg: Some(60.0),
            stride_length_m: None,
            cycle_s: 1.0,
            lods: vec![Lod {
                joints: vec![[0; 4]; 8],
                weights: vec![[1.0, 0.0, 0.0, 0.0]; 8],
                positions,
                adjacency: Arc::new(Adjacency::build(&indices)),
                indices,
                error_m: 0.0,
            }],
            nodes: vec![NodeRest { parent: None, translation: Vec3::ZERO, rotation: Quat::IDENTITY, scale: Vec3::ONE }],
            joint_nodes: vec![0],
            inverse_bind: vec![Mat4::IDENTITY],
            channels: Vec::new(),
            legs: None,
        }
    }
}
