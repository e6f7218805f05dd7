//! The integration tests, one crate (one link of the library, one binary to run): each
//! module was a test binary of its own. `cargo test --test it <module>::` runs one of them.

mod common;

mod beam_caster;
mod beam_exact;
mod crosscheck;
mod docs;
mod exports;
mod fuzz_corpus;
mod gait;
mod generate;
mod gpu_raster;
mod hostile_inputs;
mod hostile_models;
mod humans;
mod layering;
mod layout;
mod limb;
mod not_scored;
mod output;
mod plots;
mod production;
mod project;
mod proxy;
mod real_inputs;
mod realism;
mod sensor_model;
mod stability;
mod worlds;
