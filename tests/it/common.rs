//! Helpers shared by the integration tests.

use glam::DVec3;
use pedscan::gpu::{Context, ContextOptions, DeviceChoice};
use pedscan::backend::raster::renderer::Renderer;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::Ordering;
use std::sync::Arc;

/// A Vulkan context with the Khronos validation layer on (its absence is a failure, not a skip).
pub fn context() -> Arc<Context> {
    let ctx = Context::new(&ContextOptions { validation: true, device: DeviceChoice::Auto })
        .expect("Vulkan context with validation (install vulkan-validationlayers, mesa-vulkan-drivers)");
    assert!(ctx.validation_enabled());
    Arc::new(ctx)
}

/// Drops renderer and context, then asserts the validation layer reported no error at all
/// (leaks are reported when the device is destroyed).
pub fn finish(renderer: Renderer, ctx: Arc<Context>) {
    let errors = ctx.validation_counter();
    drop(renderer);
    assert_eq!(Arc::strong_count(&ctx), 1, "the context outlives everything else");
    drop(ctx);
    assert_eq!(errors.load(Ordering::SeqCst), 0, "validation errors (see stderr)");
}

/// An axis-aligned box [lo, hi] as 12 triangles (each side its own 4 vertices), wound so the
/// normals point outward (`outward`) or inward. f64 positions (world or sensor frame).
pub fn box_f64(lo: DVec3, hi: DVec3, outward: bool) -> (Vec<DVec3>, Vec<u32>) {
    let centre = 0.5 * (lo + hi);
    let mut pos = Vec::new();
    let mut idx = Vec::new();
    for axis in 0..3 {
        for side in [lo, hi] {
            let (a1, a2) = ((axis + 1) % 3, (axis + 2) % 3);
            let corner = |s1: bool, s2: bool| {
                let mut p = side;
                p[a1] = if s1 { hi[a1] } else { lo[a1] };
                p[a2] = if s2 { hi[a2] } else { lo[a2] };
                p
            };
            let quad = [corner(false, false), corner(true, false), corner(true, true), corner(false, true)];
            let n = (quad[1] - quad[0]).cross(quad[2] - quad[0]);
            let mut face_centre = centre;
            face_centre[axis] = side[axis];
            let out = n.dot(face_centre - centre) > 0.0;
            let base = pos.len() as u32;
            pos.extend_from_slice(&quad);
            let tris: [u32; 6] = if out == outward { [0, 1, 2, 0, 2, 3] } else { [0, 2, 1, 0, 3, 2] };
            idx.extend(tris.iter().map(|i| base + i));
        }
    }
    (pos, idx)
}

/// The bundled humans (`data/humans/*.glb`), in name order.
pub fn bundled_humans() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/humans");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "glb"))
        .collect();
    v.sort();
    v
}

/// Runs the built `pedscan` binary in `dir`, as a user would, with the Vulkan validation
/// layer on.
pub fn pedscan(args: &[&str], dir: &Path) -> Output {
    pedscan_with_env(args, dir, &[])
}

/// [`pedscan`] with extra environment variables for the run.
pub fn pedscan_with_env(args: &[&str], dir: &Path, envs: &[(&str, &str)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_pedscan"));
    c.args(args).current_dir(dir).envs(envs.iter().copied());
    // The one place the runs of the binary get validation (a missing layer fails the run):
    // every command that can open a Vulkan device takes `--validation`.
    if matches!(args.first(), Some(&"generate") | Some(&"crosscheck") | Some(&"sheet")) {
        c.arg("--validation");
    }
    c.output().expect("run pedscan")
}

/// Asserts that a run succeeded, showing its stderr when not.
pub fn ok(o: &Output) {
    assert!(o.status.success(), "pedscan failed ({:?}):\n{}", o.status.code(), String::from_utf8_lossy(&o.stderr));
}

/// Asserts that a run is refused as an input error (exit code 2) whose message names `needle`.
pub fn expect_input_error(args: &[&str], dir: &Path, needle: &str) {
    let o = pedscan(args, dir);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "exit code for {args:?}: {err}");
    assert!(err.contains(needle), "message for {args:?} should name `{needle}`: {err}");
}
