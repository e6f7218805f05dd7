//! `velocity = "limb"`: the velocity of the surface point each human beam hits, against finite
//! differences of the posed meshes themselves (the generator's own posing at neighbouring
//! instants, the sensor held at the frame's pose), and what it says about a walk.

use glam::DVec3;
use pedscan::backend::NO_TRIANGLE;
use pedscan::config::{BackendChoice, Config, VelocityModel};
use pedscan::generator::Generator;
use pedscan::output::FrameOutput;

#[test]
fn limb_velocity_is_the_motion_of_the_hit_point_on_the_posed_mesh() {
    let mut cfg = Config::default();
    // The posed meshes at one instant, as the test poses them (no rolling shutter).
    cfg.sensor_model = pedscan::config::SensorModelConfig::off();
    cfg.render.backend = BackendChoice::Raycast;
    cfg.humans.count = [12, 12];
    cfg.output.velocity = VelocityModel::Limb;
    let mut gen = Generator::new(cfg).expect("generator");
    let plan = gen.plan(0).expect("plan");
    let dt = 1e-3;
    let (mut checked, mut worst, mut fast, mut slow) = (0usize, 0.0f64, 0usize, 0usize);
    for k in [4, 20] {
        let state = gen.frame_state(&plan, k);
        gen.pose_frame(&plan, &state).unwrap();
        gen.render_posed().unwrap();
        gen.point_velocities(&plan, &state);
        let hits = gen.human_hits().clone();
        let limb = gen.point_velocity().to_vec();
        let people = gen.posed().people.clone();
        // The same people posed at t -+ dt with the sensor where it is at t.
        let mut at = |sign: f64| {
            let mut p = plan.clone();
            p.times_s[k] += sign * dt;
            let mut st = gen.frame_state(&p, k);
            st.world_from_sensor = state.world_from_sensor;
            gen.pose_frame(&p, &st).unwrap();
            gen.posed().people.clone()
        };
        let (before, after) = (at(-1.0), at(1.0));
        assert_eq!(before.meshes.len(), people.meshes.len(), "the same people at the same levels of detail");
        let dirs = gen.beam_dirs().to_vec();
        for (b, &t) in hits.triangle.iter().enumerate() {
            if t == NO_TRIANGLE {
                continue;
            }
            let corners = |g: &pedscan::geometry::FrameGeometry| g.triangle_f64(t);
            // Barycentric coordinates of the hit in the triangle at t.
            let [a, bb, c] = corners(&people);
            let p = dirs[b] * hits.range_m[b] as f64;
            let n = (bb - a).cross(c - a);
            let area = n.length_squared();
            let l1 = (p - a).cross(c - a).dot(n) / area;
            let l2 = (bb - a).cross(p - a).dot(n) / area;
            let l = [1.0 - l1 - l2, l1, l2];
            let point = |g: &pedscan::geometry::FrameGeometry| {
                let v = corners(g);
                l[0] * v[0] + l[1] * v[1] + l[2] * v[2]
            };
            let fd = (point(&after) - point(&before)) / (2.0 * dt);
            let err = (limb[b] - fd).length();
            worst = worst.max(err);
            // f32 sensor-frame positions (~1e-6 m at 10 m) over 2 ms: ~1e-3 m/s.
            assert!(err < 0.01 + 0.01 * fd.length(), "beam {b}: limb {:?} vs posed meshes {fd:?}", limb[b]);
            let v_h = state.human_velocity_mps[people.mesh_of_triangle(t).instance as usize - 1];
            let rel = (state.world_from_sensor.inverse().transform_vector3(v_h) - limb[b]).length();
            fast += (rel > 1.0) as usize;
            slow += (rel < 0.3) as usize;
            checked += 1;
        }
    }
    eprintln!("{checked} human beams, worst {worst:.2e} m/s, {fast} beams > 1 m/s off the pelvis velocity, {slow} within 0.3");
    assert!(checked > 200, "{checked} human beams");
    // A walk is not a rigid body: swinging limbs move well away from the pelvis velocity; the
    // trunk moves with it, up to its bob (5 cm at ~1.8 Hz: ~0.3 m/s).
    assert!(fast > checked / 20 && slow > checked / 4, "fast {fast}, slow {slow} of {checked}");

    // Through the post-pass: a human beam's velocity is the point's, minus the sensor's own
    // motion (as `rigid`).
    let state = gen.frame_state(&plan, 4);
    let mut out = FrameOutput::default();
    gen.frame(&plan, 4, &mut out).unwrap();
    let w = DVec3::new(0.0, 0.0, state.sensor_yaw_rate_rps);
    let v_s = state.world_from_sensor.inverse().transform_vector3(state.sensor_velocity_mps);
    let mut humans = 0;
    for b in 0..out.range.len() {
        if out.label[b] == 1 {
            let p = DVec3::from(out.xyz[b].map(f64::from));
            let want = gen.point_velocity()[b] - v_s - w.cross(p);
            let got = DVec3::from(out.velocity[b].map(f64::from));
            assert!((got - want).length() < 1e-4, "beam {b}: {got:?} vs {want:?}");
            humans += 1;
        }
    }
    assert!(humans > 50);
}
