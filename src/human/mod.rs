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

pub mod carry;
pub(crate) mod checks;
pub mod clothes;
mod gait;
mod load;
pub mod proxy;
pub mod push;
mod sit;
mod skin;

pub use gait::{stride_length_m, FootShift, GaitStyle, LEG_LENGTH_FRACTION, TOE_OFF, UNDER_HIP};
pub use skin::skin_vertex;

pub use checks::MAX_NODE_DEPTH;

use crate::error::{Error, Result};
use crate::geometry::{Adjacency, MeshLayout};
use gait::Leg;
use glam::{Mat4, Quat, Vec3, Vec4};
use serde::Deserialize;
use std::path::PathBuf;
use std::sync::Arc;

/// Lists model files: a folder gives its `.glb` / `.gltf` files in name order.
pub fn model_files(paths: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for p in paths {
        if p.is_dir() {
            let found = crate::input::folder_files(p, |f| matches!(f.extension().and_then(|e| e.to_str()), Some("glb") | Some("gltf")))?;
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

/// Smallest scale along any axis of a skeleton joint's node or its ancestors at rest: below
/// it the joints under it collapse onto one point.
pub const MIN_JOINT_SCALE: f32 = 1e-3;

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
    /// Each arm's upper arm, forearm and wrist (left, right), when the skeleton names them like
    /// the bundled people's (`upperarm01`, `lowerarm01`, `wrist`, `.L` / `.R`): a seated
    /// person's hands go to the thighs ([`GaitStyle::seat_m`]).
    arms: Option<[[usize; 3]; 2]>,
}
impl HumanModel {
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
}

#[cfg(test)]
mod tests {
    use super::gait::sample;
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
            arms: None,
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
            arms: None,
        }
    }
}
