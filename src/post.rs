//! Stage 7: the CPU post-pass of one frame. Composites people over the background by per-beam
//! minimum range, applies the sensor's range limits, and derives labels, instances, xyz and
//! velocities on the beam grid (sensor frame).
//!
//! Velocity of the surface point relative to the sensor, in the sensor frame, m/s:
//! - `paper` (Kim et al. 2020, eq. 1): human beam `R^T (V_h - V_s)`, background `-R^T V_s`,
//!   with R the sensor's world rotation and V_h, V_s world velocities from the trajectories;
//! - `rigid`: the same minus `w x p`, the apparent motion caused by the sensor's yaw rate w
//!   for a point p in the sensor frame (the person's own turning is not included);
//! - `limb`: as `rigid`, with a human beam's `V_h` replaced by the world velocity of the
//!   surface point it hits (`PostParams::point_velocity_mps`, from the posed mesh's motion:
//!   [`crate::generator::Generator::point_velocities`]).

use crate::config::VelocityModel;
use crate::geometry::FrameGeometry;
use crate::output::{FrameOutput, OutputSet, NOT_SCORED};
use crate::backend::{BeamHits, NO_TRIANGLE};
use glam::{DMat3, DVec3};
use rayon::prelude::*;

/// The sensor's motion while one column is fired (world frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColumnMotion {
    /// Rotation part of `world_from_sensor`.
    pub rot: DMat3,
    /// Sensor velocity, m/s.
    pub velocity_mps: DVec3,
    /// Yaw rate about world z, rad/s.
    pub yaw_rate_rps: f64,
}

/// What the post-pass needs besides the two hit grids.
pub struct PostParams<'a> {
    pub dirs: &'a [DVec3],
    pub columns: usize,
    pub min_range_m: f64,
    pub max_range_m: f64,
    pub keep_holes: bool,
    pub velocity_model: VelocityModel,
    pub outputs: OutputSet,
    /// The sensor's motion per column (rolling shutter: one entry per column), or one entry
    /// for every column.
    pub column_motion: &'a [ColumnMotion],
    /// World velocity of each person (index = instance - 1), at the time its columns were
    /// fired.
    pub human_velocity_mps: &'a [DVec3],
    /// `limb` only: per beam, the world velocity of the surface point the human hit names,
    /// rotated into the sensor frame (`R^T V`); empty otherwise.
    pub point_velocity_mps: &'a [DVec3],
}

/// The nearer of person and background per beam: range, label, instance (and the
/// background's own range), within the sensor's range limits.
pub fn select(p: &PostParams, human: &BeamHits, human_geom: &FrameGeometry, background: &[f32], out: &mut FrameOutput) {
    let n = p.dirs.len();
    out.range.resize(n, 0.0);
    out.label.resize(n, 0);
    out.instance.resize(n, 0);
    out.background_range.clear();
    let in_limits = |r: f64| r >= p.min_range_m && r <= p.max_range_m;
    if p.outputs.background {
        out.background_range.extend(background.iter().map(|&r| if r > 0.0 && in_limits(r as f64) { r } else { 0.0 }));
    }
    out.range.par_iter_mut().zip(out.label.par_iter_mut()).zip(out.instance.par_iter_mut()).enumerate().with_min_len(1024).for_each(
        |(b, ((range, label), instance))| {
            let bg = background[b] as f64;
            let h = human.range_m[b] as f64;
            let ht = human.triangle[b];
            let human_first = ht != NO_TRIANGLE && h > 0.0 && if bg > 0.0 { h < bg } else { !p.keep_holes };
            let (r, inst) = if human_first {
                (h, human_geom.mesh_of_triangle(ht).instance)
            } else if bg > 0.0 {
                (bg, 0)
            } else {
                (0.0, 0)
            };
            let returned = r > 0.0 && in_limits(r);
            let (r, inst) = if returned { (r, inst) } else { (0.0, 0) };
            *range = r as f32;
            *label = (inst > 0) as u8;
            *instance = inst as u16;
        },
    );
}

/// The beams of `cells` (a recorded background's not-scored returns) whose returned surface
/// is that background's (a return, no person) get [`NOT_SCORED`]; `/clean/label` the same on
/// the clean range and instance. A person in front keeps its label; a beam without a return
/// stays 0.
pub fn mark_not_scored(cells: &[u32], out: &mut FrameOutput) {
    for &c in cells {
        let c = c as usize;
        if out.range.get(c).is_some_and(|&r| r > 0.0) && out.instance[c] == 0 {
            out.label[c] = NOT_SCORED;
        }
        if out.clean_range.get(c).is_some_and(|&r| r > 0.0) && out.clean_instance[c] == 0 {
            out.clean_label[c] = NOT_SCORED;
        }
    }
}

/// xyz and velocity per beam from the frame's final range and instance. A human beam's `limb`
/// velocity is the hit point's own when `human` names a triangle of that person on the beam,
/// else the person's.
pub fn derive(p: &PostParams, human: &BeamHits, human_geom: &FrameGeometry, out: &mut FrameOutput) {
    let n = p.dirs.len();
    let w_cols = p.columns;
    out.xyz.resize(if p.outputs.xyz { n } else { 0 }, [0.0; 3]);
    out.velocity.resize(if p.outputs.velocity { n } else { 0 }, [0.0; 3]);
    assert!(
        p.velocity_model != VelocityModel::Limb || !p.outputs.velocity || p.point_velocity_mps.len() == n,
        "limb velocities need one point velocity per beam"
    );
    assert!(p.column_motion.len() == 1 || p.column_motion.len() == w_cols, "one column motion, or one per column");
    // Per column: R^T, the sensor's velocity in its own frame and its yaw rate vector.
    let motion: Vec<(DMat3, DVec3, DVec3)> = p
        .column_motion
        .iter()
        .map(|m| {
            let r_t = m.rot.transpose();
            (r_t, r_t * m.velocity_mps, DVec3::new(0.0, 0.0, m.yaw_rate_rps))
        })
        .collect();
    let (range, instance) = (&out.range, &out.instance);
    let xyz_on = p.outputs.xyz;
    if xyz_on {
        out.xyz.par_iter_mut().enumerate().with_min_len(1024).for_each(|(b, x)| {
            *x = (p.dirs[b] * range[b] as f64).as_vec3().into();
        });
    }
    if p.outputs.velocity {
        out.velocity.par_iter_mut().enumerate().with_min_len(1024).for_each(|(b, v)| {
            let r = range[b] as f64;
            if r <= 0.0 {
                *v = [0.0; 3];
                return;
            }
            let (r_t, v_s, w) = motion[if motion.len() == 1 { 0 } else { b % w_cols }];
            let inst = instance[b];
            let point = p.dirs[b] * r;
            let ht = human.triangle[b];
            let own_point = ht != NO_TRIANGLE && human_geom.mesh_of_triangle(ht).instance == inst as u32;
            let mut vel = match (inst > 0, p.velocity_model) {
                (false, _) => -v_s,
                (true, VelocityModel::Limb) if own_point => p.point_velocity_mps[b] - v_s,
                (true, _) => r_t * p.human_velocity_mps[inst as usize - 1] - v_s,
            };
            if p.velocity_model != VelocityModel::Paper {
                vel -= w.cross(point);
            }
            *v = vel.as_vec3().into();
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`select`], then [`derive`], as the generator runs them (without the sensor model).
    fn composite(p: &PostParams, human: &BeamHits, human_geom: &FrameGeometry, background: &[f32], out: &mut FrameOutput) {
        select(p, human, human_geom, background, out);
        derive(p, human, human_geom, out);
    }

    const MOTION: [ColumnMotion; 1] = [ColumnMotion {
        rot: DMat3::from_cols(DVec3::new(0.0, 1.0, 0.0), DVec3::new(-1.0, 0.0, 0.0), DVec3::Z),
        velocity_mps: DVec3::new(0.0, 1.0, 0.0),
        yaw_rate_rps: 0.5,
    }];

    fn params<'a>(dirs: &'a [DVec3], hv: &'a [DVec3], keep_holes: bool, model: VelocityModel) -> PostParams<'a> {
        PostParams {
            dirs,
            columns: dirs.len(),
            min_range_m: 0.5,
            max_range_m: 100.0,
            keep_holes,
            velocity_model: model,
            outputs: OutputSet::default(),
            column_motion: &MOTION,
            human_velocity_mps: hv,
            point_velocity_mps: &[],
        }
    }

    #[test]
    fn nearer_wins_holes_are_filled_or_kept_and_velocities_follow_eq1() {
        let mut geom = FrameGeometry::default();
        geom.push_mesh(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &[0, 1, 2], 1, false);
        let dirs = vec![DVec3::X; 5];
        let hv = [DVec3::new(2.0, 0.0, 0.0)];
        // beams: human nearer, human farther, human over a hole, nothing, human too near.
        let human = BeamHits { range_m: vec![3.0, 9.0, 4.0, 0.0, 0.2], triangle: vec![0, 0, 0, NO_TRIANGLE, 0] };
        let bg = vec![5.0, 6.0, 0.0, 0.0, 7.0];
        let mut out = FrameOutput::default();
        composite(&params(&dirs, &hv, false, VelocityModel::Paper), &human, &geom, &bg, &mut out);
        assert_eq!(out.range, vec![3.0, 6.0, 4.0, 0.0, 0.0]);
        assert_eq!(out.label, vec![1, 0, 1, 0, 0]);
        assert_eq!(out.instance, vec![1, 0, 1, 0, 0]);
        assert_eq!(out.background_range, vec![5.0, 6.0, 0.0, 0.0, 7.0]);
        // Sensor yawed +90 deg moving along world +y = its own +x at 1 m/s.
        let v_s = DVec3::new(1.0, 0.0, 0.0);
        let v_h = DVec3::new(0.0, -2.0, 0.0); // world +x seen from the yawed sensor
        let close = |a: [f32; 3], b: DVec3| (DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64) - b).length() < 1e-6;
        assert!(close(out.velocity[0], v_h - v_s), "{:?}", out.velocity[0]);
        assert!(close(out.velocity[1], -v_s), "{:?}", out.velocity[1]);
        assert!(close(out.velocity[3], DVec3::ZERO));
        assert_eq!(out.xyz[0], [3.0, 0.0, 0.0]);

        composite(&params(&dirs, &hv, true, VelocityModel::Rigid), &human, &geom, &bg, &mut out);
        assert_eq!(out.range, vec![3.0, 6.0, 0.0, 0.0, 0.0], "keep_holes keeps the hole");
        // Rigid: minus w x p with w = 0.5 z and p = (6, 0, 0) -> -(0, 3, 0).
        assert!(close(out.velocity[1], -v_s - DVec3::new(0.0, 3.0, 0.0)), "{:?}", out.velocity[1]);

        // Limb: the hit point's own velocity (sensor frame) instead of the person's, and the
        // rigid term: beam 0 hits the person at p = (3, 0, 0), w x p = (0, 1.5, 0).
        let point = vec![DVec3::new(0.5, 0.25, -1.0), DVec3::ZERO, DVec3::new(7.0, 0.0, 0.0), DVec3::ZERO, DVec3::ZERO];
        let limb = PostParams { point_velocity_mps: &point, ..params(&dirs, &hv, false, VelocityModel::Limb) };
        composite(&limb, &human, &geom, &bg, &mut out);
        assert!(close(out.velocity[0], point[0] - v_s - DVec3::new(0.0, 1.5, 0.0)), "{:?}", out.velocity[0]);
        assert!(close(out.velocity[1], -v_s - DVec3::new(0.0, 3.0, 0.0)), "background as rigid: {:?}", out.velocity[1]);
        assert!(close(out.velocity[2], point[2] - v_s - DVec3::new(0.0, 2.0, 0.0)), "{:?}", out.velocity[2]);
    }

    #[test]
    fn select_keeps_the_range_limits_and_gives_ties_and_empty_hits_to_the_background() {
        let mut geom = FrameGeometry::default();
        geom.push_mesh(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &[0, 1, 2], 1, false);
        let dirs = vec![DVec3::X; 4];
        let hv = [DVec3::ZERO];
        // beams: a person exactly at the wall's range (a tie: the background, which is strictly
        // nearer-wins), a hit that names a triangle at range 0 (no hit), a person in front of a
        // wall beyond the sensor's 100 m, and a wall nearer than its 0.5 m.
        let human = BeamHits { range_m: vec![5.0, 0.0, 3.0, 0.0], triangle: vec![0, 0, 0, NO_TRIANGLE] };
        let bg = vec![5.0, 4.0, 150.0, 0.3];
        let mut out = FrameOutput::default();
        composite(&params(&dirs, &hv, false, VelocityModel::Paper), &human, &geom, &bg, &mut out);
        assert_eq!(out.range, vec![5.0, 4.0, 3.0, 0.0]);
        assert_eq!(out.label, vec![0, 0, 1, 0]);
        assert_eq!(out.instance, vec![0, 0, 1, 0]);
        // The background's own range obeys the same limits.
        assert_eq!(out.background_range, vec![5.0, 4.0, 0.0, 0.0]);
    }

    #[test]
    fn not_scored_cells_mark_the_backgrounds_returns_only() {
        // Beams: the background returned, a person in front of it (in the clean frame the
        // background: the person is the sensor model's mixed return), no return, a background
        // return not in the cells.
        let mut out = FrameOutput {
            range: vec![5.0, 3.0, 0.0, 6.0],
            label: vec![0, 1, 0, 0],
            instance: vec![0, 2, 0, 0],
            clean_range: vec![5.0, 5.0, 0.0, 6.0],
            clean_label: vec![0, 0, 0, 0],
            clean_instance: vec![0, 0, 0, 0],
            ..Default::default()
        };
        mark_not_scored(&[0, 1, 2], &mut out);
        assert_eq!(out.label, vec![NOT_SCORED, 1, 0, 0]);
        assert_eq!(out.clean_label, vec![NOT_SCORED, NOT_SCORED, 0, 0]);
        // Without the sensor model (no clean frame) too.
        let mut out = FrameOutput { range: vec![5.0, 3.0], label: vec![0, 1], instance: vec![0, 1], ..Default::default() };
        mark_not_scored(&[0, 1], &mut out);
        assert_eq!(out.label, vec![NOT_SCORED, 1]);
    }

    #[test]
    fn the_rolling_shutters_motion_is_taken_per_column_of_the_row_major_grid() {
        // 2 rows x 3 columns, a wall everywhere, the sensor at a different speed per column.
        let dirs = vec![DVec3::X; 6];
        let motion: Vec<ColumnMotion> = (1..=3)
            .map(|c| ColumnMotion { rot: DMat3::IDENTITY, velocity_mps: DVec3::new(c as f64, 0.0, 0.0), yaw_rate_rps: 0.0 })
            .collect();
        let p = PostParams { columns: 3, column_motion: &motion, ..params(&dirs, &[], false, VelocityModel::Paper) };
        let human = BeamHits { range_m: vec![0.0; 6], triangle: vec![NO_TRIANGLE; 6] };
        let mut out = FrameOutput::default();
        composite(&p, &human, &FrameGeometry::default(), &[5.0; 6], &mut out);
        let vx: Vec<f32> = out.velocity.iter().map(|v| v[0]).collect();
        assert_eq!(vx, vec![-1.0, -2.0, -3.0, -1.0, -2.0, -3.0]);
    }

    #[test]
    fn limb_takes_the_hit_points_velocity_only_for_the_person_the_beam_is_labelled() {
        // Person 1 owns triangle 0, person 2 triangle 1. Beam 0's nearest triangle is person 1's
        // while its label says person 2 (as the sensor model's mixed returns can label it): its
        // velocity is person 2's, not the point's. Beam 1 hits person 2's own triangle.
        let mut geom = FrameGeometry::default();
        let tri = [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        geom.push_mesh(&tri, &[0, 1, 2], 1, false);
        geom.push_mesh(&tri, &[0, 1, 2], 2, false);
        let dirs = vec![DVec3::X; 2];
        let hv = [DVec3::new(0.0, 1.0, 0.0), DVec3::new(0.0, 2.0, 0.0)];
        let point = vec![DVec3::new(9.0, 0.0, 0.0), DVec3::new(7.0, 0.0, 0.0)];
        let still = [ColumnMotion { rot: DMat3::IDENTITY, velocity_mps: DVec3::ZERO, yaw_rate_rps: 0.0 }];
        let p = PostParams {
            point_velocity_mps: &point,
            column_motion: &still,
            ..params(&dirs, &hv, false, VelocityModel::Limb)
        };
        let human = BeamHits { range_m: vec![4.0, 4.0], triangle: vec![0, 1] };
        let mut out = FrameOutput { range: vec![4.0, 4.0], label: vec![1, 1], instance: vec![2, 2], ..Default::default() };
        derive(&p, &human, &geom, &mut out);
        assert_eq!(out.velocity, vec![[0.0, 2.0, 0.0], [7.0, 0.0, 0.0]]);
    }
}
