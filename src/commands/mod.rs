//! The commands beside `generate`'s pipeline, one file each: `run` (the `generate` job over
//! every sequence), `crosscheck` (a backend against the ray-cast reference), `bench` (time
//! against error, in child processes), `sheet` (a contact sheet of the people), `shutter-check` (the rolling shutter against
//! posing per column), `realism` (a recording against a pedscan output).

pub mod bench;
pub mod bench_worlds;
pub mod crosscheck;
pub mod project;
pub mod realism;
pub mod run;
pub mod sheet;
pub mod shutter;
pub mod stats;
