//! GPU raster golden tests on lavapipe (or any Vulkan device) with the Khronos validation
//! layer ON: every test asserts zero validation errors after dropping renderer and context
//! (leaks are reported at vkDestroyDevice).
//!
//! Tolerances: range relative error <= 1e-4 per texel against the closed-form ray/box
//! distance along `Face::texel_dir(u, v)`; at most 0.5 % of a face's texels may differ
//! (texel centres lying on a box edge / silhouette, where the rasteriser's tie rule and the
//! f64 reference may disagree). On failure actual / expected PNGs are written to
//! `$TMPDIR/pedscan-gpu-raster/`.

use crate::common::{self, context, finish};

use glam::{DVec3, Vec3};
use pedscan::geometry::FrameGeometry;
use pedscan::gpu::Context;
use pedscan::backend::raster::projection::{CubeFaces, Face};
use pedscan::backend::raster::renderer::{FaceImage, Renderer};
use pedscan::sensor::Sensor;
use std::sync::atomic::Ordering;
use std::sync::Arc;

const REL_TOL: f64 = 1e-4;
const MAX_BAD_FRACTION: f64 = 0.005;


fn cube() -> CubeFaces {
    CubeFaces::new(&Sensor::hdl32e(), 1.0)
}


/// An axis-aligned box [lo, hi] as 12 triangles, wound so that normals point outward
/// (`outward`) or inward, in f32 for a `FrameGeometry`.
fn box_mesh(lo: DVec3, hi: DVec3, outward: bool) -> (Vec<[f32; 3]>, Vec<u32>) {
    let (pos, idx) = common::box_f64(lo, hi, outward);
    (pos.iter().map(|p| p.as_vec3().to_array()).collect(), idx)
}

/// A rectangle x = const facing the sensor (front-facing by the geometry convention).
fn quad_x(x: f64, y: (f64, f64), z: (f64, f64)) -> (Vec<[f32; 3]>, Vec<u32>) {
    let p = [[x, y.0, z.0], [x, y.1, z.0], [x, y.1, z.1], [x, y.0, z.1]]
        .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]);
    // Normal must point at the origin: dot((b - a) x (c - a), a) < 0.
    let [a, b, c] = [Vec3::from(p[0]), Vec3::from(p[1]), Vec3::from(p[2])];
    let idx = if (b - a).cross(c - a).dot(a) < 0.0 { vec![0, 1, 2, 0, 2, 3] } else { vec![0, 2, 1, 0, 3, 2] };
    (p.to_vec(), idx)
}

/// Slab test: (t_enter, t_exit) of the ray t * d with the box, if it hits for some t > 0.
fn ray_box(d: DVec3, lo: DVec3, hi: DVec3) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for i in 0..3 {
        if d[i] == 0.0 {
            if lo[i] > 0.0 || hi[i] < 0.0 {
                return None;
            }
            continue;
        }
        let (a, b) = (lo[i] / d[i], hi[i] / d[i]);
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    (t1 >= t0 && t1 > 0.0).then_some((t0, t1))
}

/// Compares a face against an expected range per texel (0 = nothing). Returns the number of
/// texels that differ; writes PNGs when more than the allowed fraction differ.
fn compare(name: &str, face: &Face, img: &FaceImage, expected: impl Fn(DVec3) -> f64) -> usize {
    assert!(img.rendered, "{name}: face {} not rendered", face.index);
    let mut bad = 0;
    let mut exp = vec![0f32; img.range_m.len()];
    for v in 0..img.height {
        for u in 0..img.width {
            let want = expected(face.texel_dir(u, v));
            exp[(v * img.width + u) as usize] = want as f32;
            let got = img.range_at(u, v) as f64;
            let ok = if want == 0.0 { got == 0.0 } else { ((got - want) / want).abs() <= REL_TOL };
            if !ok {
                bad += 1;
            }
        }
    }
    let allowed = (MAX_BAD_FRACTION * img.range_m.len() as f64) as usize;
    eprintln!("{name} face {}: {bad} of {} texels differ (allowed {allowed})", face.index, img.range_m.len());
    if bad > allowed {
        write_pngs(name, img, &exp);
    }
    assert!(bad <= allowed, "{name} face {}: {bad} texels differ (allowed {allowed})", face.index);
    bad
}

fn write_pngs(name: &str, img: &FaceImage, expected: &[f32]) {
    let dir = std::env::temp_dir().join("pedscan-gpu-raster");
    let _ = std::fs::create_dir_all(&dir);
    let max = img.range_m.iter().chain(expected).cloned().fold(1e-6f32, f32::max);
    let save = |tag: &str, data: &[f32]| {
        let pixels: Vec<u8> = data.iter().map(|r| (r / max * 255.0).round() as u8).collect();
        let path = dir.join(format!("{name}_face{}_{tag}.png", img.index));
        if let Some(buf) = image::GrayImage::from_raw(img.width, img.height, pixels) {
            let _ = buf.save(&path);
            eprintln!("wrote {}", path.display());
        }
    };
    save("actual", &img.range_m);
    save("expected", expected);
    let diff: Vec<f32> = img.range_m.iter().zip(expected).map(|(a, b)| (a - b).abs()).collect();
    save("diff", &diff);
}

#[test]
fn room_box_ranges_and_ids_match_closed_form() {
    let ctx = context();
    let faces = cube();
    let mut renderer = Renderer::new(&ctx, &faces).unwrap();
    let (lo, hi) = (DVec3::new(-6.0, -4.0, -1.5), DVec3::new(6.0, 4.0, 2.5));
    let mut geom = FrameGeometry::default();
    let (p, i) = box_mesh(lo, hi, false);
    geom.push_mesh(&p, &i, 3, true);
    let frame = renderer.render(&geom).unwrap().clone();
    assert_eq!(renderer.stats().faces_rendered, 4);
    for (face, img) in faces.faces.iter().zip(&frame.faces) {
        compare("room", face, img, |d| ray_box(d, lo, hi).map_or(0.0, |(_, t1)| t1 * d.length()));
        // Every texel hits the room; its triangle lies in the plane of the hit point.
        let mut bad_id = 0;
        for v in 0..img.height {
            for u in 0..img.width {
                let id = img.id_at(u, v);
                assert_ne!(id, 0, "room texel ({u}, {v}) of face {} has no id", face.index);
                assert_eq!(geom.mesh_of_triangle(id - 1).instance, 3);
                let d = face.texel_dir(u, v);
                let hit = d * ray_box(d, lo, hi).unwrap().1;
                let [a, b, c] = geom.triangle_f64(id - 1);
                let n = (b - a).cross(c - a).normalize();
                if n.dot(hit - a).abs() > 1e-3 {
                    bad_id += 1;
                }
            }
        }
        let allowed = (MAX_BAD_FRACTION * img.id.len() as f64) as usize;
        assert!(bad_id <= allowed, "face {}: {bad_id} ids on the wrong wall", face.index);
    }
    // Steady state: a second render of the same frame gives the same images.
    let again = renderer.render(&geom).unwrap();
    for (a, b) in again.faces.iter().zip(&frame.faces) {
        assert_eq!(a.range_m, b.range_m);
        assert_eq!(a.id, b.id);
    }
    finish(renderer, ctx);
}

#[test]
fn back_face_culling_keeps_the_near_side() {
    let ctx = context();
    let faces = cube();
    let mut renderer = Renderer::new(&ctx, &faces).unwrap();
    let (lo, hi) = (DVec3::new(3.0, -0.5, -0.6), DVec3::new(4.0, 0.5, 0.4));
    let near = |d: DVec3| ray_box(d, lo, hi).map_or(0.0, |(t0, _)| t0 * d.length());
    let far = |d: DVec3| ray_box(d, lo, hi).map_or(0.0, |(_, t1)| t1 * d.length());
    let f0 = &faces.faces[0];
    // (outward winding, double-sided, expected): outward + culling shows the near side
    // (the FrontFace convention); double-sided shows the near side by depth alone; inward
    // winding + culling shows the far side (proves culling is actually on).
    type Expected<'a> = &'a dyn Fn(DVec3) -> f64;
    let cases: [(&str, bool, bool, Expected); 3] = [
        ("outward_culled", true, false, &near),
        ("outward_double", true, true, &near),
        ("inward_culled", false, false, &far),
    ];
    for (name, outward, double_sided, expected) in cases {
        let mut geom = FrameGeometry::default();
        let (p, i) = box_mesh(lo, hi, outward);
        geom.push_mesh(&p, &i, 1, double_sided);
        let frame = renderer.render(&geom).unwrap();
        let rendered: Vec<bool> = frame.faces.iter().map(|f| f.rendered).collect();
        assert_eq!(rendered, [true, false, false, false], "{name}");
        let hits = frame.faces[0].range_m.iter().filter(|r| **r > 0.0).count();
        assert!(hits > 500, "{name}: only {hits} texels hit");
        compare(name, f0, &frame.faces[0], expected);
    }
    finish(renderer, ctx);
}

#[test]
fn nothing_visible_means_no_gpu_work() {
    let ctx = context();
    let faces = cube();
    let mut renderer = Renderer::new(&ctx, &faces).unwrap();
    let frame = renderer.render(&FrameGeometry::default()).unwrap();
    assert!(frame.faces.iter().all(|f| !f.rendered));
    assert!(!renderer.stats().submitted);
    let mut geom = FrameGeometry::default();
    // Straight above the band, and a speck inside the near plane.
    let (p, i) = box_mesh(DVec3::new(-0.5, -0.5, 10.0), DVec3::new(0.5, 0.5, 11.0), true);
    geom.push_mesh(&p, &i, 1, false);
    let (p, i) = box_mesh(DVec3::splat(-0.001), DVec3::splat(0.001), true);
    geom.push_mesh(&p, &i, 2, false);
    let frame = renderer.render(&geom).unwrap();
    assert!(frame.faces.iter().all(|f| !f.rendered));
    assert_eq!(renderer.stats(), Default::default());
    assert_eq!(renderer.render_count(), 0);
    finish(renderer, ctx);
}

#[test]
fn only_faces_that_see_an_object_are_rendered() {
    let ctx = context();
    let faces = cube();
    let mut renderer = Renderer::new(&ctx, &faces).unwrap();
    // In front of face 0 only.
    let mut geom = FrameGeometry::default();
    let (lo, hi) = (DVec3::new(5.0, -0.4, -0.8), DVec3::new(5.5, 0.4, 0.2));
    let (p, i) = box_mesh(lo, hi, true);
    geom.push_mesh(&p, &i, 1, false);
    let frame = renderer.render(&geom).unwrap();
    let rendered: Vec<bool> = frame.faces.iter().map(|f| f.rendered).collect();
    assert_eq!(rendered, [true, false, false, false]);
    assert_eq!(renderer.stats().draws, 1);
    compare("face0_only", &faces.faces[0], &renderer.frame().faces[0], |d| {
        ray_box(d, lo, hi).map_or(0.0, |(t0, _)| t0 * d.length())
    });
    // Straddling the seam between face 0 (+x) and face 1 (+y).
    let mut geom = FrameGeometry::default();
    let (lo, hi) = (DVec3::new(4.6, 4.6, -0.8), DVec3::new(5.4, 5.4, 0.2));
    let (p, i) = box_mesh(lo, hi, true);
    geom.push_mesh(&p, &i, 1, false);
    renderer.render(&geom).unwrap();
    let frame = renderer.frame();
    let rendered: Vec<bool> = frame.faces.iter().map(|f| f.rendered).collect();
    assert_eq!(rendered, [true, true, false, false]);
    assert_eq!(renderer.stats().draws, 2);
    for k in [0, 1] {
        compare("seam", &faces.faces[k], &frame.faces[k], |d| {
            ray_box(d, lo, hi).map_or(0.0, |(t0, _)| t0 * d.length())
        });
    }
    // Face 0 sees it at its left edge (u = 0 looks towards +y), face 1 at its right edge.
    let (f0, f1) = (&frame.faces[0], &frame.faces[1]);
    let row = faces.faces[0].texel(DVec3::new(5.0, 5.0, -0.3)).unwrap().1;
    assert!(f0.range_at(0, row) > 0.0 && f0.range_at(f0.width - 1, row) == 0.0);
    assert!(f1.range_at(f1.width - 1, row) > 0.0 && f1.range_at(0, row) == 0.0);
    finish(renderer, ctx);
}

#[test]
fn nearer_mesh_wins_the_id() {
    let ctx = context();
    let faces = cube();
    let mut renderer = Renderer::new(&ctx, &faces).unwrap();
    let mut geom = FrameGeometry::default();
    // Far, large quad first (instance 1), near small quad second (instance 2), overlapping.
    let (p, i) = quad_x(6.0, (-2.0, 2.0), (-2.0, 0.5));
    geom.push_mesh(&p, &i, 1, false);
    let (p, i) = quad_x(3.0, (-0.5, 0.5), (-0.5, 0.2));
    geom.push_mesh(&p, &i, 2, false);
    let frame = renderer.render(&geom).unwrap();
    let face = &faces.faces[0];
    let img = &frame.faces[0];
    let (mut near, mut far, mut bad) = (0, 0, 0);
    for v in 0..img.height {
        for u in 0..img.width {
            let d = face.texel_dir(u, v);
            let inside = |x: f64, y: (f64, f64), z: (f64, f64)| {
                let p = d * (x / d.x);
                p.y > y.0 && p.y < y.1 && p.z > z.0 && p.z < z.1
            };
            let id = img.id_at(u, v);
            let got = if id == 0 { 0 } else { geom.mesh_of_triangle(id - 1).instance };
            let want = if inside(3.0, (-0.5, 0.5), (-0.5, 0.2)) {
                near += 1;
                2
            } else if inside(6.0, (-2.0, 2.0), (-2.0, 0.5)) {
                far += 1;
                1
            } else {
                0
            };
            if got != want {
                bad += 1;
            }
        }
    }
    assert!(near > 500 && far > 500, "near {near} far {far}");
    let allowed = (MAX_BAD_FRACTION * img.id.len() as f64) as usize;
    assert!(bad <= allowed, "{bad} ids wrong (allowed {allowed})");
    finish(renderer, ctx);
}

/// An ellipsoid (a stand-in for a 25k-triangle human), outward-wound, as a UV sphere.
fn ellipsoid(centre: DVec3, radii: DVec3, rings: u32, segments: u32) -> (Vec<[f32; 3]>, Vec<u32>) {
    let mut pos = Vec::new();
    for r in 0..=rings {
        let theta = std::f64::consts::PI * r as f64 / rings as f64;
        for s in 0..segments {
            let phi = std::f64::consts::TAU * s as f64 / segments as f64;
            let unit = DVec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
            pos.push((centre + unit * radii).as_vec3().to_array());
        }
    }
    let mut idx = Vec::new();
    for r in 0..rings {
        for s in 0..segments {
            let (a, b) = (r * segments + s, r * segments + (s + 1) % segments);
            let (c, d) = (a + segments, b + segments);
            // Outward: seen from outside, counter-clockwise.
            idx.extend([a, c, b, b, c, d]);
        }
    }
    (pos, idx)
}

#[test]
fn ellipsoid_is_outward_and_renders_its_near_side() {
    let ctx = context();
    let faces = cube();
    let mut renderer = Renderer::new(&ctx, &faces).unwrap();
    let mut geom = FrameGeometry::default();
    let (p, i) = ellipsoid(DVec3::new(5.0, 0.0, -0.6), DVec3::new(0.25, 0.25, 0.25), 64, 128);
    geom.push_mesh(&p, &i, 1, false);
    let frame = renderer.render(&geom).unwrap();
    let img = &frame.faces[0];
    let nearest = img.range_m.iter().cloned().filter(|r| *r > 0.0).fold(f32::MAX, f32::min) as f64;
    let expect = DVec3::new(5.0, 0.0, -0.6).length() - 0.25;
    assert!((nearest - expect).abs() < 0.01, "nearest {nearest} expected {expect}");
    finish(renderer, ctx);
}

/// The canary's canary: an invalid call must be counted, or the zero counts above mean
/// nothing.
#[test]
fn validation_layer_counts_an_invalid_call() {
    let ctx = context();
    let errors = ctx.validation_counter();
    let info = ash::vk::BufferCreateInfo::default().size(0).usage(ash::vk::BufferUsageFlags::VERTEX_BUFFER);
    // SAFETY: deliberately invalid (size 0) to trigger VUID-VkBufferCreateInfo-size-00912;
    // lavapipe tolerates it, and any buffer created is destroyed right away.
    unsafe {
        if let Ok(b) = ctx.device().create_buffer(&info, None) {
            ctx.device().destroy_buffer(b, None);
        }
    }
    assert!(errors.load(Ordering::SeqCst) >= 1, "the validation layer did not report a size-0 buffer");
    drop(ctx);
}

// ------------------------------------------------------------------------------------------
// The cylindrical panorama (`render.projection = "cylinder"`)
// ------------------------------------------------------------------------------------------

use pedscan::config::Refine;
use pedscan::geometry::Adjacency;
use pedscan::backend::raster::projection::Panorama;
use pedscan::backend::raycast::{cast_frame, Hit};
use pedscan::backend::raster::resample::{resample, BeamLookup};
use pedscan::backend::{BeamHits, NO_TRIANGLE};

/// Beam level: exact refinement must reproduce the closed form on every beam.
const EXACT_ABS_TOL_M: f64 = 1e-5;
/// Texel level: the panorama's raw range is interpolated across each (possibly split)
/// triangle, exact only to second order in its angular size (refinement makes beams exact).
const PANORAMA_TEXEL_REL_TOL: f64 = 2e-3;

fn panorama_setup(ctx: &Arc<Context>, oversample: f64) -> (Sensor, Panorama, BeamLookup, Renderer) {
    let sensor = Sensor::hdl32e();
    let pano = Panorama::new(&sensor, oversample);
    let lookup = BeamLookup::new_panorama(&sensor, &pano);
    let renderer = Renderer::new_panorama(ctx, &pano).unwrap();
    (sensor, pano, lookup, renderer)
}

/// A front-facing grid of `nx` x `nz` cells on the plane x = `x` (sensor frame), with one-rings.
fn grid_x(x: f64, y: (f64, f64), z: (f64, f64), nx: u32, nz: u32) -> (Vec<[f32; 3]>, Vec<u32>) {
    let mut pos = Vec::new();
    for j in 0..=nz {
        for i in 0..=nx {
            let (fy, fz) = (i as f64 / nx as f64, j as f64 / nz as f64);
            pos.push([x as f32, (y.0 + fy * (y.1 - y.0)) as f32, (z.0 + fz * (z.1 - z.0)) as f32]);
        }
    }
    let mut idx = Vec::new();
    let at = |i: u32, j: u32| j * (nx + 1) + i;
    for j in 0..nz {
        for i in 0..nx {
            for tri in [[at(i, j), at(i + 1, j), at(i + 1, j + 1)], [at(i, j), at(i + 1, j + 1), at(i, j + 1)]] {
                let [a, b, c] = tri.map(|k| Vec3::from(pos[k as usize]));
                let front = (b - a).cross(c - a).dot(a) < 0.0;
                idx.extend(if front { tri } else { [tri[0], tri[2], tri[1]] });
            }
        }
    }
    (pos, idx)
}

/// Exact refinement against `expected` (range along the unit beam, None = no hit) on every
/// beam: returns (beams expected to hit, beams that differ in hit/miss, max |range error|).
fn beams_vs_closed_form(lookup: &BeamLookup, hits: &BeamHits, expected: impl Fn(DVec3) -> Option<f64>) -> (usize, usize, f64) {
    let (mut want_hits, mut differ, mut max_err) = (0, 0, 0f64);
    for (b, d) in lookup.dirs.iter().enumerate() {
        let got = (hits.triangle[b] != NO_TRIANGLE).then_some(hits.range_m[b] as f64);
        match (got, expected(*d)) {
            (Some(g), Some(w)) => {
                want_hits += 1;
                max_err = max_err.max((g - w).abs());
            }
            (None, None) => {}
            (_, w) => {
                want_hits += w.is_some() as usize;
                differ += 1;
            }
        }
    }
    (want_hits, differ, max_err)
}

/// Texel level: every texel of the panorama against the closed form along its centre
/// direction; returns the number of texels whose hit/miss or range (relative
/// `PANORAMA_TEXEL_REL_TOL`) differ. Catches a triangle smeared across the image or lost.
fn panorama_texels_vs(name: &str, pano: &Panorama, img: &FaceImage, expected: impl Fn(DVec3) -> f64) -> usize {
    assert!(img.rendered, "{name}: panorama not rendered");
    assert_eq!((img.width, img.height), (pano.width, pano.height));
    let mut bad = 0;
    let mut exp = vec![0f32; img.range_m.len()];
    for v in 0..img.height {
        for u in 0..img.width {
            let want = expected(pano.texel_dir(u, v));
            exp[(v * img.width + u) as usize] = want as f32;
            let got = img.range_at(u, v) as f64;
            let ok = if want == 0.0 { got == 0.0 } else { ((got - want) / want).abs() <= PANORAMA_TEXEL_REL_TOL };
            bad += !ok as usize;
        }
    }
    let allowed = (MAX_BAD_FRACTION * img.range_m.len() as f64) as usize;
    eprintln!("{name}: {bad} of {} panorama texels differ (allowed {allowed})", img.range_m.len());
    if bad > allowed {
        write_pngs(name, img, &exp);
    }
    assert!(bad <= allowed, "{name}: {bad} texels differ (allowed {allowed})");
    bad
}

/// Ray / rectangle on the plane x = `x`: range along the unit direction `d`.
fn ray_rect_x(d: DVec3, x: f64, y: (f64, f64), z: (f64, f64)) -> Option<f64> {
    let d = d.normalize();
    let t = x / d.x;
    let p = d * t;
    (t > 0.0 && p.y > y.0 && p.y < y.1 && p.z > z.0 && p.z < z.1).then_some(t)
}

#[test]
fn panorama_quad_straddling_the_wrap_behind_the_sensor_is_hit_on_both_sides() {
    let ctx = context();
    let (sensor, pano, lookup, mut renderer) = panorama_setup(&ctx, 2.0);
    let (x, y, z) = (-4.0, (-1.0, 1.0), (-1.2, 0.4));
    // Coarse (2 large triangles: the CPU list, split and drawn on both sides of the wrap) and
    // fine (5 cm cells: drawn directly, twice, once per side).
    for (name, nx, nz, direct) in [("wrap_quad_coarse", 1, 1, false), ("wrap_quad_fine", 40, 32, true)] {
        let (p, i) = grid_x(x, y, z, nx, nz);
        let mut geom = FrameGeometry::default();
        geom.push_mesh_with_adjacency(&p, &i, 1, false, Some(Arc::new(Adjacency::build(&i))));
        let frame = renderer.render(&geom).unwrap().clone();
        let stats = renderer.stats();
        eprintln!("{name}: {stats:?}");
        if direct {
            assert_eq!((stats.panorama.direct_meshes, stats.draws), (1, 2), "{name}: one mesh, drawn on both sides");
        } else {
            assert_eq!(stats.panorama.soup_meshes, 1, "{name}");
            assert!(stats.panorama.wrap_triangles > 0, "{name}: pieces across the wrap");
        }
        panorama_texels_vs(name, &pano, &frame.faces[0], |d| ray_rect_x(d, x, y, z).unwrap_or(0.0));
        // Both edge columns of the image are covered.
        let img = &frame.faces[0];
        let row = pano.texel(DVec3::new(-1.0, 0.0, -0.1)).1;
        assert!(img.range_at(0, row) > 0.0 && img.range_at(pano.width - 1, row) > 0.0, "{name}");
        let mut hits = BeamHits::default();
        resample(&lookup, &frame, &geom, Refine::Exact, &mut hits);
        let (want, differ, err) = beams_vs_closed_form(&lookup, &hits, |d| ray_rect_x(d, x, y, z));
        eprintln!("{name}: {want} beams should hit, {differ} differ, max error {err:.2e} m");
        assert!(want > 500, "{name}: {want}");
        assert_eq!(differ, 0, "{name}: every beam that should hit does, and no other");
        assert!(err <= EXACT_ABS_TOL_M, "{name}: max range error {err} m");
        // Columns 0 and W-1 (the wrap) both see it.
        let w = sensor.columns;
        let on = |c: usize| (0..sensor.rows()).any(|r| hits.triangle[r * w + c] != NO_TRIANGLE);
        assert!(on(0) && on(w - 1), "{name}: beams on both sides of the wrap");
    }
    finish(renderer, ctx);
}

#[test]
fn panorama_room_box_around_the_sensor_every_beam_exact() {
    let ctx = context();
    for oversample in [1.0, 2.0] {
        let (_, pano, lookup, mut renderer) = panorama_setup(&ctx, oversample);
        let (lo, hi) = (DVec3::new(-6.0, -4.0, -1.5), DVec3::new(6.0, 4.0, 2.5));
        let mut geom = FrameGeometry::default();
        let (p, i) = box_mesh(lo, hi, false);
        geom.push_mesh_with_adjacency(&p, &i, 3, true, Some(Arc::new(Adjacency::build(&i))));
        let frame = renderer.render(&geom).unwrap().clone();
        let stats = renderer.stats();
        eprintln!("room x{oversample}: {stats:?}");
        // Floor and ceiling wind around the vertical axis: split, the parts out of the band
        // culled, nothing dropped.
        assert_eq!(stats.panorama.soup_meshes, 1);
        assert_eq!(stats.panorama.dropped_at_axis, 0);
        assert!(stats.panorama.culled > 0);
        let name = format!("room_x{oversample}");
        panorama_texels_vs(&name, &pano, &frame.faces[0], |d| ray_box(d, lo, hi).map_or(0.0, |(_, t1)| t1 * d.length()));
        let img = &frame.faces[0];
        assert!(img.id.iter().all(|&id| id != 0), "{name}: every texel sees the room");
        // Every texel's triangle lies in the plane of its hit point.
        let mut bad_id = 0;
        for v in 0..img.height {
            for u in 0..img.width {
                let id = img.id_at(u, v);
                let d = pano.texel_dir(u, v);
                let hit = d * ray_box(d, lo, hi).unwrap().1;
                let [a, b, c] = geom.triangle_f64(id - 1);
                let n = (b - a).cross(c - a).normalize();
                bad_id += (n.dot(hit - a).abs() > 1e-3) as usize;
            }
        }
        let allowed = (MAX_BAD_FRACTION * img.id.len() as f64) as usize;
        assert!(bad_id <= allowed, "{name}: {bad_id} ids on the wrong wall");
        let mut hits = BeamHits::default();
        resample(&lookup, &frame, &geom, Refine::Exact, &mut hits);
        let (want, differ, err) = beams_vs_closed_form(&lookup, &hits, |d| ray_box(d, lo, hi).map(|(_, t1)| t1));
        eprintln!("{name}: {want} beams, {differ} differ, max error {err:.2e} m");
        assert_eq!((want, differ), (lookup.dirs.len(), 0));
        assert!(err <= EXACT_ABS_TOL_M, "{name}: {err}");
    }
    assert_eq!(Arc::strong_count(&ctx), 1);
    let errors = ctx.validation_counter();
    drop(ctx);
    assert_eq!(errors.load(Ordering::SeqCst), 0);
}

#[test]
fn panorama_large_walls_close_by_are_split_and_exact() {
    let ctx = context();
    let (_, pano, lookup, mut renderer) = panorama_setup(&ctx, 2.0);
    // Two triangles each: 60 m walls 0.6 m to the left and 0.5 m behind the sensor (this one
    // across the wrap), 4 m tall; and a 60 m x 60 m floor 0.8 m below, around the axis.
    let walls: [(&str, Vec<[f64; 3]>); 3] = [
        ("left", vec![[-30.0, 0.6, -1.0], [30.0, 0.6, -1.0], [30.0, 0.6, 3.0], [-30.0, 0.6, 3.0]]),
        ("behind", vec![[-0.5, 30.0, -1.0], [-0.5, -30.0, -1.0], [-0.5, -30.0, 3.0], [-0.5, 30.0, 3.0]]),
        ("floor", vec![[-30.0, -30.0, -0.8], [30.0, -30.0, -0.8], [30.0, 30.0, -0.8], [-30.0, 30.0, -0.8]]),
    ];
    for (name, q) in walls {
        let p: Vec<[f32; 3]> = q.iter().map(|v| v.map(|c| c as f32)).collect();
        let i = vec![0, 1, 2, 0, 2, 3];
        let mut geom = FrameGeometry::default();
        geom.push_mesh_with_adjacency(&p, &i, 0, true, Some(Arc::new(Adjacency::build(&i))));
        let tris = [[0usize, 1, 2], [0, 2, 3]].map(|t| t.map(|k| DVec3::from(q[k])));
        let expected = |d: DVec3| -> Option<f64> {
            tris.iter().filter_map(|t| pedscan::backend::raycast::intersect_triangle(d.normalize(), t, false)).reduce(f64::min)
        };
        let frame = renderer.render(&geom).unwrap().clone();
        let stats = renderer.stats();
        eprintln!("{name}: {stats:?}");
        assert!(stats.panorama.splits > 50, "{name}: the wall is split");
        assert_eq!(stats.panorama.dropped_at_axis, 0, "{name}");
        panorama_texels_vs(name, &pano, &frame.faces[0], |d| expected(d).unwrap_or(0.0));
        let mut hits = BeamHits::default();
        resample(&lookup, &frame, &geom, Refine::Exact, &mut hits);
        let (want, differ, err) = beams_vs_closed_form(&lookup, &hits, expected);
        eprintln!("{name}: {want} beams should hit, {differ} differ, max error {err:.2e} m");
        assert!(want > 1000, "{name}");
        assert_eq!(differ, 0, "{name}");
        assert!(err <= EXACT_ABS_TOL_M, "{name}: {err}");
    }
    finish(renderer, ctx);
}

#[test]
fn panorama_nothing_visible_means_no_gpu_work() {
    let ctx = context();
    let (_, _, _, mut renderer) = panorama_setup(&ctx, 2.0);
    let frame = renderer.render(&FrameGeometry::default()).unwrap();
    assert!(!frame.faces[0].rendered);
    assert!(!renderer.stats().submitted);
    let mut geom = FrameGeometry::default();
    // Straight above the band, straight below it, and a speck inside the near limit.
    let (p, i) = box_mesh(DVec3::new(-0.5, -0.5, 10.0), DVec3::new(0.5, 0.5, 11.0), true);
    geom.push_mesh(&p, &i, 1, false);
    let (p, i) = box_mesh(DVec3::new(-0.5, -0.5, -11.0), DVec3::new(0.5, 0.5, -10.0), true);
    geom.push_mesh(&p, &i, 2, false);
    let (p, i) = box_mesh(DVec3::splat(-0.001), DVec3::splat(0.001), true);
    geom.push_mesh(&p, &i, 3, false);
    let frame = renderer.render(&geom).unwrap();
    assert!(!frame.faces[0].rendered);
    assert_eq!(renderer.stats(), Default::default());
    assert_eq!(renderer.render_count(), 0);
    finish(renderer, ctx);
}

/// People posed around the sensor: in front, behind across the wrap, on a cube seam, far, and
/// one within a metre (its bounding sphere around the vertical axis: the CPU list). The
/// panorama with exact refinement against the ray-cast reference, with the tolerances the
/// cube path is held to (`pedscan crosscheck` acceptance: >= 99.5 % of human beams agree,
/// p99 range error <= 1 mm); the cube path on the same scene for comparison.
#[test]
fn panorama_matches_the_ray_cast_reference_on_posed_people() {
    use pedscan::human::{HumanModel, MODEL_TO_BODY};
    let ctx = context();
    let models: Vec<HumanModel> = ["h1700_w60", "h1200_w20", "h1800_w90", "h1600_w50"]
        .iter()
        .map(|n| HumanModel::load(&pedscan::config::data_dir().join("humans").join(format!("{n}.glb")), true).unwrap())
        .collect();
    // (x, y, heading, phase) on a floor 0.8 m below the sensor.
    let people = [(5.0, 0.3, 1.0, 0.1), (-4.0, 0.05, 2.0, 0.4), (3.5, 3.6, -0.5, 0.7), (12.0, -7.0, 0.3, 0.2), (0.2, 0.8, 1.5, 0.9), (-2.5, -1.5, -2.0, 0.6)];
    let mut geom = FrameGeometry::default();
    let (mut joints, mut skinned) = (Vec::new(), Vec::new());
    for (k, &(x, y, heading, phase)) in people.iter().enumerate() {
        let m = &models[k % models.len()];
        let body = glam::DMat4::from_translation(DVec3::new(x, y, -0.8)) * glam::DMat4::from_rotation_z(heading);
        m.joint_matrices(phase as f32, &mut joints);
        let t = (body * MODEL_TO_BODY.as_dmat4()).as_mat4();
        m.skin_into(0, &joints, &t, &mut skinned);
        geom.push_mesh_with_adjacency(&skinned, &m.lods[0].indices, k as u32 + 1, false, Some(m.lods[0].adjacency.clone()));
    }
    let sensor = Sensor::hdl32e();
    let reference = cast_frame(&geom, &sensor.beam_dirs(), 1e3);
    let agreement = |hits: &BeamHits, reference: &[Hit]| {
        let (mut both, mut union, mut errors, mut mixups) = (0, 0, Vec::new(), 0);
        for (b, r) in reference.iter().enumerate() {
            let rh = hits.triangle[b] != NO_TRIANGLE;
            if rh || r.is_hit() {
                union += 1;
            }
            if rh && r.is_hit() {
                both += 1;
                errors.push((hits.range_m[b] as f64 - r.range_m).abs());
                mixups += (geom.mesh_of_triangle(hits.triangle[b]).instance != r.instance(&geom)) as usize;
            }
        }
        errors.sort_by(f64::total_cmp);
        let p99 = errors[((errors.len() - 1) as f64 * 0.99).round() as usize];
        (both as f64 / union as f64, p99, union, mixups)
    };
    let mut rows = Vec::new();
    for (name, cylinder) in [("cube", false), ("cylinder", true)] {
        let (lookup, mut renderer) = if cylinder {
            let pano = Panorama::new(&sensor, 2.0);
            (BeamLookup::new_panorama(&sensor, &pano), Renderer::new_panorama(&ctx, &pano).unwrap())
        } else {
            let cube = CubeFaces::new(&sensor, 2.0);
            (BeamLookup::new(&sensor, &cube), Renderer::new(&ctx, &cube).unwrap())
        };
        renderer.render(&geom).unwrap();
        let stats = renderer.stats();
        let mut hits = BeamHits::default();
        resample(&lookup, renderer.frame(), &geom, Refine::Exact, &mut hits);
        let (a, p99, union, mixups) = agreement(&hits, &reference);
        eprintln!("{name}: agreement {:.4} % of {union} beams, p99 {:.2e} m, {mixups} instance mix-ups, {stats:?}", 100.0 * a, p99);
        if cylinder {
            assert_eq!(stats.panorama.soup_meshes, 1, "the person within a metre goes through the CPU list");
            assert_eq!(stats.panorama.direct_meshes, 5);
        }
        rows.push((a, p99, mixups));
        let errors = ctx.validation_counter();
        drop(renderer);
        assert_eq!(errors.load(Ordering::SeqCst), 0);
    }
    let (a, p99, mixups) = rows[1];
    assert_eq!(a, 1.0, "cylinder agreement {a}");
    assert!(p99 <= 1e-3, "cylinder p99 {p99} m");
    assert_eq!(mixups, 0);
    assert_eq!(Arc::strong_count(&ctx), 1);
    let errors = ctx.validation_counter();
    drop(ctx);
    assert_eq!(errors.load(Ordering::SeqCst), 0);
}

#[test]
fn panorama_back_face_culling_keeps_the_near_side() {
    let ctx = context();
    let (_, pano, _, mut renderer) = panorama_setup(&ctx, 2.0);
    let (lo, hi) = (DVec3::new(3.0, -0.5, -0.6), DVec3::new(4.0, 0.5, 0.4));
    let near = |d: DVec3| ray_box(d, lo, hi).map_or(0.0, |(t0, _)| t0 * d.length());
    let far = |d: DVec3| ray_box(d, lo, hi).map_or(0.0, |(_, t1)| t1 * d.length());
    type Expected<'a> = &'a dyn Fn(DVec3) -> f64;
    // As for the cube: outward + culling shows the near side, inward + culling the far side
    // (culling is on and keeps the sensor's counter-clockwise), double-sided the near side.
    let cases: [(&str, bool, bool, Expected); 3] =
        [("pano_outward_culled", true, false, &near), ("pano_outward_double", true, true, &near), ("pano_inward_culled", false, false, &far)];
    for (name, outward, double_sided, expected) in cases {
        // Fine enough to be drawn directly (5 cm cells) and as 12 triangles (the CPU list).
        for direct in [false, true] {
            let mut geom = FrameGeometry::default();
            let (p, i) = box_mesh(lo, hi, outward);
            if direct {
                // Subdivide every box face 4 x 4 times (midpoints keep the winding).
                let (mut p, mut i) = (p, i);
                for _ in 0..4 {
                    let mut ni = Vec::new();
                    for t in i.chunks_exact(3) {
                        let [a, b, c] = [t[0], t[1], t[2]].map(|k| Vec3::from(p[k as usize]));
                        let base = p.len() as u32;
                        p.extend([(a + b) / 2.0, (b + c) / 2.0, (c + a) / 2.0].map(|v| v.to_array()));
                        let (ab, bc, ca) = (base, base + 1, base + 2);
                        ni.extend([t[0], ab, ca, ab, t[1], bc, ca, bc, t[2], ab, bc, ca]);
                    }
                    i = ni;
                }
                geom.push_mesh(&p, &i, 1, double_sided);
            } else {
                geom.push_mesh(&p, &i, 1, double_sided);
            }
            let frame = renderer.render(&geom).unwrap().clone();
            let stats = renderer.stats();
            assert_eq!(stats.panorama.direct_meshes == 1, direct, "{name}: {stats:?}");
            panorama_texels_vs(name, &pano, &frame.faces[0], expected);
        }
    }
    finish(renderer, ctx);
}

/// `bench`'s triangle-rate probe draws and casts the same patches: both paths see them, on
/// about as many beams (texel centres are the beams), more for more patches; no validation
/// error.
#[test]
fn triangle_rate_probe_draws_and_casts_the_same_patches() {
    let ctx = context();
    let errors = ctx.validation_counter();
    let rows = pedscan::commands::bench::triangle_rates(&ctx, &[300, 3000], 1).unwrap();
    for r in &rows {
        eprintln!("{r:?}");
        assert!(r.raster_ms > 0.0 && r.raycast_ms > 0.0);
        let ratio = r.raster_texels as f64 / r.raycast_beams as f64;
        assert!(r.raycast_beams > 0 && (0.8..1.25).contains(&ratio), "{r:?}");
    }
    assert!(rows[1].raycast_beams > 2 * rows[0].raycast_beams, "{rows:?}");
    drop(ctx);
    assert_eq!(errors.load(std::sync::atomic::Ordering::SeqCst), 0, "validation errors (see stderr)");
}

/// `bench`'s table of where the raster background's work runs: the fixed cost (hall only) of
/// the ray caster and of the raster backend at three shares, then whole frames; the share
/// decides what the device draws (all, some, nothing). Validation on: the bench fails on
/// any message.
#[test]
fn host_share_bench_draws_all_some_and_nothing() {
    let mut base = pedscan::config::Config::default();
    base.humans.count = [3, 3];
    base.debug.validation = true;
    let (device, rows) = pedscan::commands::bench::host_share_costs(&base, 2, 1).unwrap();
    assert!(!device.is_empty());
    assert_eq!(rows.len(), 8, "{rows:?}");
    assert!(rows.iter().all(|r| r.ms > 0.0), "{rows:?}");
    let drawn: Vec<f64> = rows.iter().filter_map(|r| r.raster.map(|d| d.rectangles)).collect();
    assert!(drawn.len() == 3 && drawn[0] > drawn[1] && drawn[1] > 0.0 && drawn[2] == 0.0, "rectangles per share: {drawn:?}");
    let table = pedscan::commands::bench::shares_markdown(&device, &rows, 2, 1);
    assert_eq!(table.matches("| environment only").count() + table.matches("| whole frame").count(), 8, "{table}");
}
