//! The exact beam raster (`raster::beam_exact`) against the binned ray caster, on lavapipe
//! with the validation layer on: the bundled hall and the bundled people walking in it, and
//! random large and awkward triangles. Every beam must agree on hit or miss, and on the
//! range to 1e-6 relative (1e-4 m at 100 m; the two may pick different triangles only where
//! triangles meet at the beam). Zero validation errors.

use crate::common::context;
use pedscan::backend::raster::beam_exact::{self, BeamExact};
use pedscan::backend::raycast::{BeamCaster, Hit};
use pedscan::backend::{self, BeamHits, Gpu, Layer, NO_TRIANGLE};
use pedscan::config::{BackendChoice, Config};
use pedscan::generator::Generator;
use pedscan::geometry::FrameGeometry;
use pedscan::sensor::Sensor;
use std::sync::atomic::Ordering;
use std::sync::Arc;

/// Compares one layer beam by beam; returns (beams hit, beams whose triangle differs).
fn compare(what: &str, got: &BeamHits, reference: &[Hit], geom: &FrameGeometry) -> (usize, usize) {
    let (mut hits, mut other_triangle) = (0, 0);
    for (b, r) in reference.iter().enumerate() {
        let g = (got.triangle[b], got.range_m[b] as f64);
        assert_eq!(g.0 != NO_TRIANGLE, r.is_hit(), "{what} beam {b}: {g:?} vs {r:?}");
        if !r.is_hit() {
            continue;
        }
        hits += 1;
        let tol = 1e-6 * r.range_m + 1e-6;
        assert!((g.1 - r.range_m as f32 as f64).abs() <= tol, "{what} beam {b}: range {} vs {}", g.1, r.range_m);
        if g.0 != r.triangle {
            other_triangle += 1;
            // A different triangle only where the two meet: the same mesh (instance).
            assert_eq!(geom.mesh_of_triangle(g.0).instance, r.instance(geom), "{what} beam {b}: another instance");
        }
    }
    (hits, other_triangle)
}

fn finish(raster: BeamExact, ctx: Arc<pedscan::gpu::Context>) {
    let errors = ctx.validation_counter();
    drop(raster);
    assert_eq!(Arc::strong_count(&ctx), 1);
    drop(ctx);
    assert_eq!(errors.load(Ordering::SeqCst), 0, "validation errors (see stderr)");
}

#[test]
fn beam_raster_equals_the_ray_caster_on_the_hall_and_walking_people() {
    let ctx = context();
    let mut cfg = Config::default();
    cfg.render.backend = BackendChoice::Raycast;
    cfg.humans.count = [20, 20];
    let mut gen = Generator::new(cfg).expect("generator");
    let mut caster = BeamCaster::new(gen.beam_dirs(), gen.sensor().rows(), gen.sensor().columns);
    let mut raster = BeamExact::new(&ctx, gen.sensor(), beam_exact::HOST_BEAMS).unwrap();
    let (mut reference, mut got) = (Vec::new(), BeamHits::default());
    let (mut hits, mut differ, mut layers, mut fallback) = ([0usize; 2], 0, 0, 0);
    for index in 0..2 {
        let plan = gen.plan(index).expect("plan");
        for k in [0, 13, 31] {
            let state = gen.frame_state(&plan, k);
            gen.pose_frame(&plan, &state).expect("pose");
            let posed = gen.posed();
            for (l, (layer, geom)) in [("background", posed.background), ("people", posed.people)].into_iter().enumerate() {
                caster.cast(geom, f64::MAX, &mut reference);
                raster.cast(geom, &mut got).unwrap();
                let (h, d) = compare(&format!("sequence {index} frame {k} {layer}"), &got, &reference, geom);
                hits[l] += h;
                differ += d;
                layers += 1;
                fallback += raster.stats().fallback_beams;
                // The tiles keep the drawn texels near the covered ones: a few per beam.
                if l == 0 {
                    assert!(raster.stats().texels < 10 * 32_768, "{:?}", raster.stats());
                }
            }
        }
    }
    eprintln!("hits {hits:?}, other triangle on {differ} beams, {fallback} fallback beams, {layers} layers");
    assert!(hits[0] > 6 * 30_000, "the hall surrounds the sensor: {hits:?}");
    assert!(hits[1] > 500, "the people must be seen: {hits:?}");
    finish(raster, ctx);
}

/// SplitMix64.
struct Rng(u64);
impl Rng {
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        lo + (hi - lo) * (((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64)
    }
}

#[test]
fn beam_raster_equals_the_ray_caster_on_large_awkward_and_wrapping_triangles() {
    let ctx = context();
    let sensor = Sensor::hdl32e();
    let mut geom = FrameGeometry::default();
    let mut rng = Rng(5);
    // Random large triangles, single- and double-sided, many across the azimuth wrap (-x)
    // or around the z axis; a floor and a ceiling through which the axis passes; a wall on
    // the wrap; a sliver; a triangle with a vertex at the origin; a NaN vertex.
    for (k, cull) in [(0u32, true), (1, false)] {
        let mut v = Vec::new();
        for _ in 0..3 * 200 {
            v.push([rng.range(-20.0, 20.0) as f32, rng.range(-20.0, 20.0) as f32, rng.range(-8.0, 8.0) as f32]);
        }
        geom.push_mesh(&v, &(0..600).collect::<Vec<u32>>(), k, !cull);
    }
    let quads: [[[f32; 3]; 4]; 3] = [
        [[-30.0, -30.0, -1.8], [30.0, -30.0, -1.8], [30.0, 30.0, -1.8], [-30.0, 30.0, -1.8]],
        [[-30.0, -30.0, 3.0], [-30.0, 30.0, 3.0], [30.0, 30.0, 3.0], [30.0, -30.0, 3.0]],
        [[-5.0, 2.0, -3.0], [-5.0, -2.0, -3.0], [-5.0, -2.0, 2.0], [-5.0, 2.0, 2.0]],
    ];
    for q in quads {
        geom.push_mesh(&q, &[0, 1, 2, 0, 2, 3], 2, false);
    }
    let odd: Vec<[f32; 3]> = vec![
        [6.0, 0.0, -1.0],
        [6.0, 1e-4, 2.0],
        [6.0, 2e-4, -1.0], // sliver
        [0.0, 0.0, 0.0],
        [5.0, 1.0, -1.0],
        [5.0, -1.0, 1.0], // vertex at the origin
        [f32::NAN, 1.0, 0.0],
        [3.0, 0.0, 0.0],
        [3.0, 1.0, 1.0], // NaN
    ];
    geom.push_mesh(&odd, &(0..9).collect::<Vec<u32>>(), 3, true);
    let dirs = sensor.beam_dirs();
    let mut caster = BeamCaster::new(&dirs, sensor.rows(), sensor.columns);
    let (mut reference, mut got) = (Vec::new(), BeamHits::default());
    caster.cast(&geom, f64::MAX, &mut reference);
    // Every share of the work (`render.host_cast_beams`): the device draws every triangle, the
    // default split, the host casts them all and nothing is drawn.
    let mut drawn = Vec::new();
    for host_beams in [0, beam_exact::HOST_BEAMS, i64::MAX as u64] {
        let mut raster = BeamExact::new(&ctx, &sensor, host_beams).unwrap();
        raster.cast(&geom, &mut got).unwrap();
        let (hits, differ) = compare(&format!("awkward, host_cast_beams {host_beams}"), &got, &reference, &geom);
        eprintln!("host_cast_beams {host_beams}: {hits} hits, other triangle on {differ}, {:?}", raster.stats());
        assert!(hits > 30_000, "{hits}");
        drawn.push(raster.stats().instances);
    }
    assert!(drawn[0] > drawn[1] && drawn[1] > 0 && drawn[2] == 0, "instances drawn per share: {drawn:?}");
    let mut raster = BeamExact::new(&ctx, &sensor, beam_exact::HOST_BEAMS).unwrap();
    raster.cast(&geom, &mut got).unwrap();
    // Again, reusing every buffer: the same.
    let first = got.clone();
    raster.cast(&geom, &mut got).unwrap();
    assert_eq!(got, first);
    // Nothing to draw: all beams miss, no GPU work needed.
    raster.cast(&FrameGeometry::default(), &mut got).unwrap();
    assert!(got.triangle.iter().all(|&t| t == NO_TRIANGLE) && got.triangle.len() == dirs.len());
    finish(raster, ctx);
}

/// The raster backend on lavapipe casts a frame's two layers overlapped (`cast_frame`: the
/// background drawn on the device while the host bins the people): the same hits as casting
/// them one at a time, the people bit for bit the binned caster's, the background as
/// `compare` holds it. Zero validation errors.
#[test]
fn raster_frames_overlap_their_layers_with_the_same_hits() {
    let mut cfg = Config::default();
    cfg.render.backend = BackendChoice::Raycast;
    cfg.humans.count = [12, 12];
    let mut gen = Generator::new(cfg.clone()).expect("generator");
    cfg.render.backend = BackendChoice::Raster;
    let mut gpu = Gpu::new("auto", true);
    let mut raster = backend::create(&cfg, gen.sensor(), gen.models(), &mut gpu).unwrap();
    drop(gpu);
    assert!(raster.proxies().is_none(), "lavapipe bins the people: no proxies to pose");
    let mut caster = BeamCaster::new(gen.beam_dirs(), gen.sensor().rows(), gen.sensor().columns);
    let plan = gen.plan(0).expect("plan");
    let (mut reference, mut want, mut seen) = (Vec::new(), BeamHits::default(), 0);
    for k in [0, 17, 31] {
        let state = gen.frame_state(&plan, k);
        gen.pose_frame(&plan, &state).expect("pose");
        let posed = gen.posed();
        let people = Layer::People { people: posed.people, proxies: posed.proxies };
        let (mut bg, mut humans) = (BeamHits::default(), BeamHits::default());
        raster.cast_frame(Layer::Background(posed.background), people, &mut bg, &mut humans).unwrap();
        let (mut bg1, mut humans1) = (BeamHits::default(), BeamHits::default());
        raster.cast(Layer::Background(posed.background), &mut bg1).unwrap();
        raster.cast(people, &mut humans1).unwrap();
        assert!(bg == bg1 && humans == humans1, "frame {k}: overlapped and one at a time differ");
        caster.cast(posed.people, f64::MAX, &mut reference);
        want.set_from(&reference);
        assert!(humans == want, "frame {k}: people differ from the binned caster");
        seen += want.triangle.iter().filter(|&&t| t != NO_TRIANGLE).count();
        caster.cast(posed.background, f64::MAX, &mut reference);
        compare(&format!("frame {k} background"), &bg, &reference, posed.background);
    }
    assert!(seen > 500, "the people must be seen ({seen} beams)");
    backend::finish(raster).expect("no validation errors");
}
