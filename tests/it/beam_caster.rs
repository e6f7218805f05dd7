//! The generation ray caster (triangles binned into beams) against the BVH ray caster on the
//! real workload: the bundled people walking in the bundled hall, posed frame by frame, for
//! the HDL-32E, a VLP-16 and a 2048-column grid. Every beam must agree bit for bit (range and
//! triangle); the two share only the ray/triangle test.

use pedscan::config::{BackendChoice, Config};
use pedscan::generator::Generator;
use pedscan::backend::raycast::{cast, BeamCaster, Bvh};

fn compare(sensor: &str, humans: usize, sequences: usize, frames: &[usize]) {
    let mut cfg = Config::default();
    cfg.render.backend = BackendChoice::Raycast;
    cfg.humans.count = [humans, humans];
    cfg.sensor = sensor.to_string();
    let mut gen = Generator::new(cfg).expect("generator");
    let mut caster = BeamCaster::new(gen.beam_dirs(), gen.sensor().rows(), gen.sensor().columns);
    let mut got = Vec::new();
    let (mut human_hits, mut checked) = (0, 0);
    for index in 0..sequences {
        let plan = gen.plan(index).expect("plan");
        for &k in frames {
            let state = gen.frame_state(&plan, k);
            gen.pose_frame(&plan, &state).expect("pose");
            let posed = gen.posed();
            for (layer, geom) in [("background", posed.background), ("people", posed.people)] {
                if geom.meshes.is_empty() {
                    continue;
                }
                caster.cast(geom, f64::MAX, &mut got);
                let reference = cast(geom, &Bvh::build(geom), gen.beam_dirs(), f64::MAX);
                for (b, (g, r)) in got.iter().zip(&reference).enumerate() {
                    assert!(
                        g.triangle == r.triangle && g.range_m.to_bits() == r.range_m.to_bits(),
                        "{sensor} sequence {index} frame {k} {layer} beam {b}: {g:?} vs {r:?}"
                    );
                }
                if layer == "people" {
                    human_hits += reference.iter().filter(|h| h.is_hit()).count();
                }
                checked += 1;
            }
        }
    }
    assert!(checked >= 2 * sequences, "{sensor}: {checked} layers checked");
    assert!(human_hits > 100, "{sensor}: only {human_hits} beams hit people; the test must see people");
}

#[test]
fn beam_caster_equals_the_bvh_on_walking_people_in_the_hall() {
    let dir = tempfile::tempdir().unwrap();
    compare("hdl32e", 30, 2, &[0, 17, 31]);
    compare("vlp16", 12, 1, &[5]);
    let wide = dir.path().join("wide.toml");
    let elev: Vec<String> = (0..24).map(|i| format!("{:.3}", 12.0 - 1.37 * i as f64)).collect();
    std::fs::write(&wide, format!("elevation_deg = [{}]\ncolumns = 2048\n", elev.join(", "))).unwrap();
    compare(wide.to_str().unwrap(), 12, 1, &[3]);
}

#[test]
fn beam_caster_equals_the_bvh_for_a_person_brushing_the_sensor_and_far_away() {
    // One posed person moved so that its surface passes 0.3 m from the sensor (it then covers
    // a large part of the grid, around the z axis too), and the same person 80 m behind.
    let mut cfg = Config::default();
    cfg.render.backend = BackendChoice::Raycast;
    cfg.humans.count = [1, 1];
    cfg.scene.background = std::path::PathBuf::new();
    let mut gen = Generator::new(cfg).expect("generator");
    let plan = gen.plan(0).expect("plan");
    let state = gen.frame_state(&plan, 0);
    gen.pose_frame(&plan, &state).expect("pose");
    let person = gen.posed().people.clone();
    assert_eq!(person.meshes.len(), 1, "the person must be drawn");
    let indices: Vec<u32> = person.indices.clone();
    let centre = glam::Vec3::from(person.meshes[0].centre);
    let mut caster = BeamCaster::new(gen.beam_dirs(), gen.sensor().rows(), gen.sensor().columns);
    let mut got = Vec::new();
    for (name, offset) in [
        ("0.3 m ahead", -centre + glam::Vec3::new(0.55, 0.0, 0.0)),
        ("straddling the axis", -centre + glam::Vec3::new(0.0, 0.0, -0.2)),
        ("80 m behind, on the column-0 edge", -centre + glam::Vec3::new(-80.0, 0.01, 0.1)),
    ] {
        let moved: Vec<[f32; 3]> = person.positions.iter().map(|p| (glam::Vec3::from(*p) + offset).to_array()).collect();
        let mut geom = pedscan::geometry::FrameGeometry::default();
        geom.push_mesh(&moved, &indices, 1, false);
        caster.cast(&geom, f64::MAX, &mut got);
        let reference = cast(&geom, &Bvh::build(&geom), gen.beam_dirs(), f64::MAX);
        let hits = reference.iter().filter(|h| h.is_hit()).count();
        assert!(hits > 0, "{name}: the person must be hit");
        for (b, (g, r)) in got.iter().zip(&reference).enumerate() {
            assert!(g.triangle == r.triangle && g.range_m.to_bits() == r.range_m.to_bits(), "{name} beam {b}: {g:?} vs {r:?}");
        }
    }
}
