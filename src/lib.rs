//! pedscan: automatically labeled LiDAR sequences of walking people.
//!
//! One module (a folder where it has parts) per stage, listed here in the data flow of a
//! frame:
//!
//! 1. `config` (TOML + flags, checked once) and `sensor` (the beam model);
//! 2. `input`: recorded backgrounds, sensor poses and pedestrian tracks;
//! 3. `scene`: the environment and its walkable area, and each sequence's plan (sensor
//!    path, people, walks);
//! 4. `human`: glTF people, gait and skinning, and their conservative proxies;
//! 5. `pose`: a frame's sensor and people at its time, the environment and the people in
//!    view placed (and under the rolling shutter warped) into `geometry`, the posed
//!    triangles of a frame in the sensor frame;
//! 6. `backend`: the nearest surface per beam, by Vulkan raster (`backend::raster`, on `gpu`)
//!    or the CPU ray caster (`raycast`), both behind one trait;
//! 7. `post`: composite people over the background, labels, instances, velocities;
//!    `sensor_model`: what a real sensor returns of it (surfaces, footprints, dropout, noise);
//! 8. `output`: HDF5, XML, PNG, PLY, SemanticKITTI, ROS 2 bags, and the sequence's writer.
//!
//! `generator` loads a run's inputs once and runs the stages for every frame; `commands` holds `generate`'s job and the
//! tools beside it (crosscheck, bench, contact sheet); `plot` draws the bench's figures;
//! `debug` holds the test hooks of a run (`debug.kill`).
//!
//! Dependencies go one way: no module uses another that uses it back, directly or through
//! others, at any level of the module tree (`tests/it/layering.rs` checks it).

pub mod config;
pub mod sensor;
pub mod input;
pub mod scene;
pub mod human;
pub mod pose;
pub mod geometry;
pub mod backend;
pub mod gpu;
pub mod post;
pub mod sensor_model;
pub mod realism;
pub mod output;
pub mod generator;
pub mod commands;
pub mod plot;
pub mod error;
pub mod debug;

pub use error::{Error, Result};

/// The crate version, recorded in every output file.
pub fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}
