//! The raster backend's people proxies (`src/proxy.rs`) cover the meshes people are measured
//! with: every bundled person, 16 gait phases, six views (1.7 to 9 m, from above, level and
//! below): every ray that hits the full-detail mesh meets the proxy. (That is what the raster
//! backend needs: a beam the proxy covers is cast exactly against every person, so where
//! along the beam the proxy lies does not matter.) The same check with the offset shrunk must
//! fail, or it would prove nothing.

use crate::common;

use glam::{DVec3, Mat4, Vec3};
use pedscan::geometry::FrameGeometry;
use pedscan::human::{HumanModel, MODEL_TO_BODY};
use pedscan::human::proxy::ModelProxies;
use pedscan::backend::raster::people::PeopleRaster;
use pedscan::backend::raycast::{self, BeamCaster, Bvh};
use pedscan::backend::{BeamHits, NO_TRIANGLE};
use pedscan::sensor::Sensor;
use std::path::{Path, PathBuf};

fn bundled() -> Vec<PathBuf> {
    common::bundled_humans()
}

/// Rays from the origin over a window around a person `dist` metres away at height offset
/// `z` (the sensor looks at them from above, level or below): `n` x `2n` directions.
fn window(dist: f64, z: f64, height: f64, n: usize) -> Vec<DVec3> {
    let mut dirs = Vec::with_capacity(2 * n * n);
    let half_w = (0.7 / dist).atan();
    for i in 0..2 * n {
        let el_lo = ((z - 0.05) / dist).atan();
        let el_hi = ((z + height + 0.05) / dist).atan();
        let el = el_lo + (el_hi - el_lo) * (i as f64 + 0.5) / (2 * n) as f64;
        for j in 0..n {
            let az = -half_w + 2.0 * half_w * (j as f64 + 0.5) / n as f64;
            dirs.push(DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin()));
        }
    }
    dirs
}

/// Rays that hit the full mesh but miss the proxy, over every view
/// and phase of `model` with proxies built at `scale` times their offset.
fn uncovered(model: &HumanModel, scale: f32) -> (usize, usize) {
    let proxies = ModelProxies::build(model, 0.04, scale);
    let proxy = &proxies.lods[0];
    let full = &model.lods[0];
    let height = model.height_m as f64;
    let (mut bad, mut hits) = (0, 0);
    let mut joints = Vec::new();
    let mut placed = Vec::new();
    for phase in 0..16 {
        model.joint_matrices(phase as f32 / 16.0, &mut joints);
        for view in 0..6 {
            let yaw = std::f32::consts::TAU * (view as f32 + 0.3 * phase as f32) / 6.0;
            let (dist, z) = [(2.5, -1.2), (6.0, -0.3), (2.0, -0.2), (9.0, -1.8), (3.5, 0.4), (4.0, -0.9)][view];
            let transform = Mat4::from_translation(Vec3::new(dist as f32, 0.0, z as f32)) * Mat4::from_rotation_z(yaw) * MODEL_TO_BODY;
            let mut verts = vec![[0.0f32; 3]; full.positions.len()];
            model.skin_lod_into_slice(full, &joints, &transform, &mut placed, &mut verts);
            let mut body = FrameGeometry::default();
            body.push_mesh(&verts, &full.indices, 1, false);
            let mut pverts = vec![[0.0f32; 3]; proxy.positions.len()];
            model.skin_lod_into_slice(proxy, &joints, &transform, &mut placed, &mut pverts);
            let mut shell = FrameGeometry::default();
            shell.push_mesh(&pverts, &proxy.indices, 1, true);
            let dirs = window(dist, z, height, 24);
            let want = raycast::cast(&body, &Bvh::build(&body), &dirs, f64::MAX);
            let got = raycast::cast(&shell, &Bvh::build(&shell), &dirs, f64::MAX);
            for (w, g) in want.iter().zip(&got) {
                if w.is_hit() {
                    hits += 1;
                    if !g.is_hit() {
                        bad += 1;
                    }
                }
            }
        }
    }
    (bad, hits)
}

#[test]
fn proxies_cover_every_bundled_person_in_every_phase() {
    let files = bundled();
    assert_eq!(files.len(), 15);
    for f in &files {
        let model = HumanModel::load(f, true).unwrap();
        let (bad, hits) = uncovered(&model, 1.0);
        assert!(hits > 10_000, "{}: the views must see the person ({hits} hits)", model.name);
        assert_eq!(bad, 0, "{}: {bad} of {hits} rays hit the person but miss its proxy", model.name);
    }
}

#[test]
fn a_shrunk_proxy_offset_fails_the_coverage_check() {
    // The coarsest and a mid-size person: with a tenth of the offset, rays slip past.
    for name in ["h1200_w15", "h1700_w60"] {
        let f = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("data/humans/{name}.glb"));
        let model = HumanModel::load(&f, true).unwrap();
        let (bad, hits) = uncovered(&model, 0.1);
        assert!(bad > 0, "{name}: a tenth of the offset still covered all {hits} hits");
    }
}

/// The raster backend's proxy people (`raster::people`: the proxies drawn at beam resolution,
/// every covered beam cast exactly), which the backend uses on a GPU only, held on lavapipe:
/// six bundled people walking around the sensor at 2 to 10 m give the binned caster's hits
/// bit for bit, with zero validation errors.
#[test]
fn proxy_people_raster_equals_the_binned_caster() {
    let ctx = common::context();
    let sensor = Sensor::hdl32e();
    let (mut people, mut proxies) = (FrameGeometry::default(), FrameGeometry::default());
    let (mut joints, mut placed) = (Vec::new(), Vec::new());
    for (k, f) in bundled().iter().step_by(2).take(6).enumerate() {
        let model = HumanModel::load(f, true).unwrap();
        let proxy = &ModelProxies::build(&model, 0.04, 1.0).lods[0];
        model.joint_matrices(k as f32 / 6.0, &mut joints);
        let (az, dist) = (std::f32::consts::TAU * k as f32 / 6.0 + 0.4, 2.0 + 1.6 * k as f32);
        let at = Vec3::new(dist * az.cos(), dist * az.sin(), -1.7);
        let transform = Mat4::from_translation(at) * Mat4::from_rotation_z(1.3 * az) * MODEL_TO_BODY;
        for (lod, geom, double_sided) in [(&model.lods[0], &mut people, false), (proxy, &mut proxies, true)] {
            let mut verts = vec![[0.0f32; 3]; lod.positions.len()];
            model.skin_lod_into_slice(lod, &joints, &transform, &mut placed, &mut verts);
            geom.push_mesh(&verts, &lod.indices, k as u32 + 1, double_sided);
        }
    }
    let mut raster = PeopleRaster::new(&ctx, &sensor).unwrap();
    let mut got = BeamHits::default();
    raster.render(&proxies, &people, &mut got).unwrap();
    let mut caster = BeamCaster::new(&sensor.beam_dirs(), sensor.rows(), sensor.columns);
    let mut cast = Vec::new();
    caster.cast(&people, f64::MAX, &mut cast);
    let mut want = BeamHits::default();
    want.set_from(&cast);
    let hits = want.triangle.iter().filter(|&&t| t != NO_TRIANGLE).count();
    assert!(hits > 400, "the people must be seen ({hits} beams)");
    assert!(got == want, "{} of {hits} beams differ", (0..cast.len()).filter(|&b| got.triangle[b] != want.triangle[b]).count());
    let errors = ctx.validation_counter();
    drop(raster);
    drop(ctx);
    assert_eq!(errors.load(std::sync::atomic::Ordering::SeqCst), 0, "validation errors (see stderr)");
}
