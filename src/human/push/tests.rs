use super::*;

fn bundled(name: &str) -> HumanModel {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/humans").join(name);
    HumanModel::load(&path, true).unwrap()
}

/// The joints' global positions at `phase` in the style (model frame: y up, +z forward, +x
/// left).
fn joints_at(m: &HumanModel, phase: f32, style: GaitStyle) -> Vec<Vec3> {
    let mut g = Vec::new();
    m.joint_globals(phase * m.cycle_s, style, &mut g);
    g.iter().map(|j| j.w_axis.truncate()).collect()
}

/// Adults push, children and people with a bag in a hand do not; the handle is ahead of the
/// body a little above the hips (0.55-0.66 of the height: 1.02 m for 1.7 m), the hands about a
/// shoulder width apart.
#[test]
fn adults_hold_a_handle_ahead_at_the_waist() {
    for name in ["h1700_w60.glb", "h1800_w90.glb", "h1600_w50.glb"] {
        let m = bundled(name);
        assert!(m.can_push(), "{name}");
        let h = m.push_handle().expect(name);
        let tall = m.nominal_height_m();
        assert!(h.forward_m > 0.2 && h.forward_m < 0.55, "{name}: {h:?}");
        assert!(h.height_m > 0.55 * tall && h.height_m < 0.66 * tall, "{name}: {h:?}");
        assert!(h.half_width_m > 0.08 && h.half_width_m < 0.3, "{name}: {h:?}");
    }
    let child = bundled("h1200_w20.glb");
    assert!(!child.can_push() && child.push_handle().is_none());
    let mut bag = bundled("h1700_w60.glb");
    bag.name.push_str("+bag");
    assert!(!bag.can_push() && bag.push_handle().is_none());
    let mut backpack = bundled("h1700_w60.glb");
    backpack.name.push_str("+backpack");
    assert!(backpack.can_push());
}

/// Walking and pushing, the hands stay on the handle over the whole cycle (within the torso's
/// sway) where the walk's own hands swing far; the legs walk as they do without pushing; a
/// seated person who is asked to push sits; a model that cannot push walks as it does.
#[test]
fn the_hands_stay_on_the_handle_while_the_legs_walk() {
    let m = bundled("h1700_w60.glb");
    let arms = m.arms.unwrap();
    let (legs, _) = m.legs.unwrap();
    let idx = |node: usize| m.joint_nodes.iter().position(|&n| n == node).unwrap();
    let h = m.push_handle().unwrap();
    let walk = GaitStyle::WALK;
    let push = GaitStyle { pushing: true, ..walk };
    let (mut push_z, mut walk_z) = ((f32::INFINITY, f32::NEG_INFINITY), (f32::INFINITY, f32::NEG_INFINITY));
    for k in 0..20 {
        let phase = k as f32 / 20.0;
        let (p, w) = (joints_at(&m, phase, push), joints_at(&m, phase, walk));
        for [_, _, wrist] in arms {
            let (a, b) = (p[idx(wrist)], w[idx(wrist)]);
            assert!((a.z - h.forward_m).abs() < 0.08 && (a.y - h.height_m).abs() < 0.08, "phase {phase}: the hand at {a}, the handle {h:?}");
            push_z = (push_z.0.min(a.z), push_z.1.max(a.z));
            walk_z = (walk_z.0.min(b.z), walk_z.1.max(b.z));
        }
        for leg in legs {
            for node in [leg.thigh, leg.shank, leg.foot] {
                assert!(p[idx(node)].distance(w[idx(node)]) < 1e-5, "phase {phase}: a leg moved");
            }
        }
    }
    assert!(push_z.1 - push_z.0 < 0.12 && walk_z.1 - walk_z.0 > 0.2, "the hands' travel fore and aft: pushing {push_z:?}, walking {walk_z:?}");
    let seat = GaitStyle { seat_m: 0.46, ..walk };
    assert_eq!(joints_at(&m, 0.3, GaitStyle { pushing: true, ..seat }), joints_at(&m, 0.3, seat));
    let child = bundled("h1200_w20.glb");
    assert_eq!(joints_at(&child, 0.3, push), joints_at(&child, 0.3, walk));
}
