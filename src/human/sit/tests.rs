use super::*;

fn bundled(name: &str) -> HumanModel {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/humans").join(name);
    HumanModel::load(&path, true).unwrap()
}

/// The nodes' global positions at the style (model frame: y up, +z forward, +x left).
fn joints_at(m: &HumanModel, style: GaitStyle) -> Vec<Vec3> {
    let mut g = Vec::new();
    m.joint_globals(0.3 * m.cycle_s, style, &mut g);
    g.iter().map(|j| j.w_axis.truncate()).collect()
}

fn skinned(m: &HumanModel, style: GaitStyle) -> Vec<Vec3> {
    let mut joints = Vec::new();
    m.joint_matrices_styled(0.3, style, &mut joints);
    let mut out = Vec::new();
    m.skin_into(0, &joints, &Mat4::IDENTITY, &mut out);
    out.into_iter().map(Vec3::from).collect()
}

/// On a bench (0.46 m) and a chair (0.47 m), and a child on a low seat: the hip joints the
/// flesh's height above the seat and over the person's origin, the thighs forward and within
/// 37 degrees of level, the knees ahead of the hips, the feet on the floor or hanging above it
/// (no vertex under it), the shins down, the elbows forward, the hands forward of the hips
/// over the thighs and above the seat, the
/// head lower than standing by about the thigh; nothing of the body below the seat's top
/// behind the knees (it sits on the seat, not in it); the walk's phase and style change
/// nothing.
#[test]
fn a_seated_person_sits_on_the_seat_with_the_feet_on_the_floor() {
    for (name, seat) in [("h1700_w60.glb", 0.46f32), ("h1800_w90.glb", 0.47), ("h1200_w20.glb", 0.32)] {
        let m = bundled(name);
        assert!(m.can_sit(), "{name}");
        let (legs, _) = m.legs.unwrap();
        let arms = m.arms.expect(name);
        let stand = GaitStyle { walking: 0.0, ..GaitStyle::WALK };
        let sit = GaitStyle { seat_m: seat, ..GaitStyle::WALK };
        let (s0, s1) = (joints_at(&m, stand), joints_at(&m, sit));
        let idx = |node: usize| m.joint_nodes.iter().position(|&n| n == node).unwrap();
        for (leg, side) in legs.iter().zip(["left", "right"]) {
            let (hip, knee, ankle) = (s1[idx(leg.thigh)], s1[idx(leg.shank)], s1[idx(leg.foot)]);
            let hip_stand = s0[idx(leg.thigh)].y;
            assert!((hip.y - (seat + HIP_OVER_SEAT * hip_stand)).abs() < 0.01, "{name} {side}: hip at {hip}");
            assert!(hip.z.abs() < 0.1, "{name} {side}: hip {hip} off the origin");
            let thigh = knee - hip;
            assert!(thigh.z > 0.8 * thigh.length(), "{name} {side}: thigh {thigh} not forward and within 37 degrees of level");
            let shin = ankle - knee;
            assert!(-shin.y > 0.8 * shin.length(), "{name} {side}: shin {shin} not down");
            assert!((ankle.y - s0[idx(leg.foot)].y).abs() < 0.02 || ankle.y > s0[idx(leg.foot)].y, "{name} {side}: ankle {ankle}");
        }
        let hip = s1[idx(legs[0].thigh)];
        for [upper, lower, wrist] in arms {
            let (shoulder, elbow, hand) = (s1[idx(upper)], s1[idx(lower)], s1[idx(wrist)]);
            assert!(elbow.z > shoulder.z && elbow.y > seat, "{name}: the elbow at {elbow}, the shoulder at {shoulder}");
            // The hands forward over the thighs, above the seat, beside the hips at most.
            assert!(hand.z > hip.z + 0.15 && hand.y > seat + 0.05 && hand.x.abs() < 0.3, "{name}: the hand at {hand}, the hip at {hip}");
        }
        let (stand_mesh, sit_mesh) = (skinned(&m, stand), skinned(&m, sit));
        let top = |v: &[Vec3]| v.iter().map(|p| p.y).fold(f32::MIN, f32::max);
        let low = sit_mesh.iter().map(|p| p.y).fold(f32::MAX, f32::min);
        assert!(low > -0.01, "{name}: a vertex {low} m under the floor");
        let thigh_len = (s0[idx(legs[0].shank)] - s0[idx(legs[0].thigh)]).length();
        let drop = top(&stand_mesh) - top(&sit_mesh);
        assert!((drop - thigh_len).abs() < 0.25 * thigh_len, "{name}: the head {drop} m lower, the thigh {thigh_len} m long");
        // A bench's seat, its front 0.15 m ahead of the hips and 0.4 m deep, as long as the
        // person is wide: nothing sinks into it, the hands neither.
        let hip_z = s1[idx(legs[0].thigh)].z;
        let inside = sit_mesh.iter().filter(|p| p.z < hip_z + 0.15 && p.z > hip_z - 0.25 && p.y < seat - 0.02).count();
        assert_eq!(inside, 0, "{name}: {inside} vertices inside the seat");
        // The walk's phase and the rest of the style do not move a seated person.
        let other = GaitStyle { walking: 1.0, arm_swing: 0.3, stride: 1.2, seat_m: seat, ..GaitStyle::WALK };
        let mut a = Vec::new();
        let mut b = Vec::new();
        m.joint_matrices_styled(0.1, sit, &mut a);
        m.joint_matrices_styled(0.7, other, &mut b);
        assert_eq!(a, b, "{name}");
    }
}

/// A model whose skeleton does not name its legs, or its arms, cannot sit, nor one with a
/// backpack (it would go through the seat's back): asked to, it stands; one with a bag sits.
#[test]
fn a_model_that_cannot_sit_stands_where_asked_to() {
    let body = bundled("h1700_w60.glb");
    let mut no_legs = body.clone();
    no_legs.legs = None;
    let mut no_arms = body.clone();
    no_arms.arms = None;
    let packed = body.carrying(crate::human::carry::Carried::Backpack);
    assert!(body.can_sit() && body.carrying(crate::human::carry::Carried::Bag).can_sit());
    for m in [no_legs, no_arms, packed] {
        assert!(!m.can_sit(), "{}", m.name);
        let mut a = Vec::new();
        let mut b = Vec::new();
        m.joint_matrices_styled(0.2, GaitStyle { walking: 0.0, ..GaitStyle::WALK }, &mut a);
        m.joint_matrices_styled(0.2, GaitStyle { seat_m: 0.45, ..GaitStyle::WALK }, &mut b);
        assert_eq!(a, b, "{}", m.name);
        m.joint_matrices_styled(0.2, GaitStyle::WALK, &mut b);
        assert_ne!(a, b, "{}: the walk is the standing pose", m.name);
    }
}

/// Where the room ahead of the seat is short (a café table's foot before its chair), the
/// feet stay within it, toes included: the ankles drawn back under the knees, the thighs
/// still forward, the hips where they were; with room to spare, the toes reach past it, so
/// the room is what holds them back.
#[test]
fn a_seated_persons_feet_stay_within_the_room_ahead() {
    for (name, room) in [("h1700_w60.glb", 0.45f32), ("h1800_w90.glb", 0.42), ("h1800_w90.glb", 0.55)] {
        let m = bundled(name);
        let (legs, _) = m.legs.unwrap();
        let idx = |node: usize| m.joint_nodes.iter().position(|&n| n == node).unwrap();
        let free = GaitStyle { seat_m: 0.47, ..GaitStyle::WALK };
        let short = GaitStyle { feet_room_m: room, ..free };
        let feet_reach = |style| skinned(&m, style).iter().filter(|p| p.y < 0.2).map(|p| p.z).fold(f32::MIN, f32::max);
        assert!(feet_reach(free) > room + 0.02, "{name}: the toes reach {} m with room to spare", feet_reach(free));
        assert!(feet_reach(short) <= room + 0.01, "{name}: the toes reach {} m, the room {room} m", feet_reach(short));
        let (a, b) = (joints_at(&m, free), joints_at(&m, short));
        for leg in &legs {
            let (hip, knee, ankle) = (b[idx(leg.thigh)], b[idx(leg.shank)], b[idx(leg.foot)]);
            assert!((hip - a[idx(leg.thigh)]).length() < 1e-5, "{name}: the hips moved");
            assert!((knee - hip).z > 0.8 * (knee - hip).length(), "{name}: the thigh {} not forward", knee - hip);
            assert!(ankle.z < a[idx(leg.foot)].z && ankle.z >= hip.z - 1e-4, "{name}: the ankle at {ankle}, the hip at {hip}");
            assert!(-(ankle - knee).y > 0.8 * (ankle - knee).length(), "{name}: the shin {} not down", ankle - knee);
        }
    }
}
