//! pedscan: automatically labeled LiDAR sequences of walking people.
//!
//! Modules follow the data flow of one frame: `sensor` (beam model) -> `scene` (humans,
//! trajectories, sensor poses, background) -> `human` (glTF, skinning, gait) -> `geometry`
//! (posed triangles in the sensor frame) -> `projection` + `raster` on `gpu` (Vulkan) ->
//! `resample` (beam grid) -> `post` (composite, labels, velocity) -> `output` (HDF5, XML, PNG).
//! `raycast` is the independent CPU reference over the same triangles.

pub mod background;
pub mod bench;
pub mod config;
pub mod crosscheck;
pub mod error;
pub mod geometry;
pub mod gpu;
pub mod human;
pub mod output;
pub mod panorama;
pub mod people;
pub mod pipeline;
pub mod planner;
pub mod plot;
pub mod post;
pub mod projection;
pub mod proxy;
pub mod raster;
pub mod raycast;
pub mod resample;
pub mod run;
pub mod scene;
pub mod sensor;
pub mod sheet;
pub mod sequence;
pub mod tracks;

pub use error::{Error, Result};

/// The crate version, recorded in every output file.
pub fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}
