use super::*;

fn bundled(name: &str) -> HumanModel {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/humans").join(name);
    HumanModel::load(&path, true).unwrap()
}

/// LOD 0 of `m` skinned at `phase` of its walk (`walking` 1) or standing (0).
fn posed(m: &HumanModel, phase: f32, walking: f32) -> Vec<Vec3> {
    let mut joints = Vec::new();
    m.joint_matrices_styled(phase, GaitStyle { walking, ..GaitStyle::WALK }, &mut joints);
    let mut out = Vec::new();
    m.skin_into(0, &joints, &Mat4::IDENTITY, &mut out);
    out.into_iter().map(Vec3::from).collect()
}

fn bounds(p: &[Vec3]) -> (Vec3, Vec3) {
    p.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), q| (lo.min(*q), hi.max(*q)))
}

/// Standing, a backpack lies against the back (behind the torso's rearmost point over its
/// height, within 2 cm of it) below the shoulders, and bags hang below the hands beside the
/// legs, clear of the ground; walking, each thing keeps its shape (a rigid box: every
/// corner-to-corner distance within 2 mm of standing's) and its place on the body (its
/// distance to the nearest body point skinned as it is within 1 cm), on a child's body and an adult's;
/// every level of detail carries the same box, and the body's own vertices do not move.
#[test]
fn carried_things_hang_where_they_are_held_and_move_with_the_body() {
    for name in ["h1700_w60.glb", "h1200_w20.glb"] {
        let m = bundled(name);
        let h = m.height_m;
        let n = m.lods[0].positions.len();
        let body = posed(&m, 0.0, 0.0);
        for kind in CARRIED {
            let c = m.carrying(kind);
            assert_eq!(c.name, format!("{}+{}", m.name, kind.name()));
            let boxes = if kind == Carried::Bags { 2 } else { 1 };
            for (a, b) in c.lods.iter().zip(&m.lods) {
                assert_eq!(a.positions.len(), b.positions.len() + 8 * boxes);
                assert_eq!(a.indices.len(), b.indices.len() + 36 * boxes);
                assert_eq!(&a.positions[..b.positions.len()], &b.positions[..]);
                // The one-rings as built for the whole mesh.
                let whole = Adjacency::build(&a.indices);
                assert!((0..(a.indices.len() / 3) as u32).all(|t| a.adjacency.of(t) == whole.of(t)), "{name} {kind:?}: one-rings");
                assert!(!a.adjacency.of((a.indices.len() / 3 - 1) as u32).is_empty());
            }
            let stand = posed(&c, 0.0, 0.0);
            assert_eq!(&stand[..n], &body[..], "{name} {kind:?}: the body itself");
            for k in 0..boxes {
                let corners = &stand[n + 8 * k..n + 8 * (k + 1)];
                let (lo, hi) = bounds(corners);
                if kind == Carried::Backpack {
                    let back = body.iter().filter(|p| p.y >= lo.y && p.y <= hi.y && p.x.abs() <= hi.x).map(|p| p.z).fold(f32::INFINITY, f32::min);
                    assert!(hi.z < back && hi.z > back - 0.02, "{name}: the pack's front {} m, the back {back} m", hi.z);
                    assert!(hi.y < 0.82 * h && lo.y > 0.45 * h, "{name}: the pack spans {}..{} m of {h}", lo.y, hi.y);
                } else {
                    // Hanging from a hand (the body within 13 cm above its top's middle),
                    // beside the leg (none of the body inside it), clear of the ground.
                    let top = Vec3::new((lo.x + hi.x) / 2.0, hi.y, (lo.z + hi.z) / 2.0);
                    let hand = body.iter().copied().filter(|p| p.y > hi.y).min_by(|a, b| a.distance(top).total_cmp(&b.distance(top))).unwrap();
                    assert!(hand.distance(top) < 0.13, "{name}: the bag's top {top}, the body nearest above it {hand}");
                    let inside = body.iter().filter(|p| p.cmpgt(lo).all() && p.cmplt(hi).all()).count();
                    assert_eq!(inside, 0, "{name}: the body inside the bag");
                    let side = if k == 0 { -1.0 } else { 1.0 };
                    assert!(top.x * side > 0.1 * h / 1.7, "{name}: the bag at x {}", top.x);
                    assert!(hi.y < 0.5 * h && hi.y > 0.3 * h && lo.y > 0.1, "{name}: the bag spans {}..{} m", lo.y, hi.y);
                }
            }
            let held_by = |p: &[Vec3], k: usize| {
                let at = p[n + 8 * k..n + 8 * (k + 1)].iter().copied().sum::<Vec3>() / 8.0;
                // The body's vertex nearest to it skinned as it is.
                let l = &c.lods[0];
                let same = |i: usize| l.joints[i] == l.joints[n + 8 * k] && l.weights[i] == l.weights[n + 8 * k];
                let near = (0..n).filter(|&i| same(i)).min_by(|&a, &b| stand[a].distance(stand[n + 8 * k]).total_cmp(&stand[b].distance(stand[n + 8 * k]))).unwrap();
                (at, near)
            };
            for phase in [0.0, 0.13, 0.25, 0.38, 0.5, 0.63, 0.75, 0.88] {
                let walk = posed(&c, phase, 1.0);
                for k in 0..boxes {
                    for i in 0..8 {
                        for j in 0..8 {
                            let (a, b) = (n + 8 * k + i, n + 8 * k + j);
                            let d = walk[a].distance(walk[b]) - stand[a].distance(stand[b]);
                            assert!(d.abs() < 2e-3, "{name} {kind:?} phase {phase}: corners {i}-{j} stretched by {d} m");
                        }
                    }
                    let (at_s, near) = held_by(&stand, k);
                    let (at_w, _) = held_by(&walk, k);
                    let d = at_w.distance(walk[near]) - at_s.distance(stand[near]);
                    assert!(d.abs() < 0.01, "{name} {kind:?} phase {phase}: moved {d} m against the body");
                    assert!(bounds(&walk[n + 8 * k..n + 8 * (k + 1)]).0.y > 0.05, "{name} {kind:?} phase {phase}: on the ground");
                }
            }
        }
    }
}

/// `equip` keeps the models alone at 0, else appends a variant per kind in order.
#[test]
fn equip_appends_a_variant_per_kind_in_order() {
    let m = bundled("h1700_w60.glb");
    let tiny = crate::human::tests_support::tiny_model();
    assert_eq!(equip(vec![m.clone(), tiny.clone()], 0.0).len(), 2);
    let names: Vec<String> = equip(vec![m, tiny], 0.4).into_iter().map(|m| m.name).collect();
    assert_eq!(names, ["h1700_w60", "box", "h1700_w60+backpack", "box+backpack", "h1700_w60+bag", "box+bag", "h1700_w60+bags", "box+bags"]);
}
