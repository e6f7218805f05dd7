//! Stage 1: sampling one sequence. From a seeded RNG, a configuration and the walkable area:
//! the sensor's trajectory, the people (model, trajectory, initial gait phase, stride) and the
//! frame times. Everything here is f64 in the world frame; nothing touches the GPU.

use crate::config::Config;
use crate::error::{Error, Result};
use crate::human::{stride_length_m, HumanModel, MotionMode};
use crate::scene::{Trajectory, WalkableGrid};
use glam::{DVec2, DVec3};
use rand::RngExt;

/// One person of a sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct HumanPlan {
    /// Index into the loaded models.
    pub model: usize,
    pub trajectory: Trajectory,
    /// Gait phase at t = 0, in [0, 1).
    pub phase0: f64,
    /// Stride length used to advance the gait, m.
    pub stride_m: f64,
    pub motion: MotionMode,
}

/// A person's state at one instant (world frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HumanAt {
    pub position_m: DVec3,
    pub heading_rad: f64,
    pub velocity_mps: DVec3,
    pub gait_phase: f64,
}

impl HumanPlan {
    /// State at time `t_s` according to the motion mode (the paper's Table 5 ablations).
    pub fn at(&self, t_s: f64) -> HumanAt {
        let tr = &self.trajectory;
        let moves = self.motion.moves();
        let tm = if moves { t_s } else { 0.0 };
        let phase = if self.motion.animates() {
            (self.phase0 + tr.distance(t_s) / self.stride_m).rem_euclid(1.0)
        } else {
            self.phase0
        };
        HumanAt {
            position_m: tr.position(tm),
            heading_rad: tr.heading_rad(tm),
            velocity_mps: if moves { tr.velocity(t_s) } else { DVec3::ZERO },
            gait_phase: phase,
        }
    }
}

/// Everything sampled for one sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct SequencePlan {
    pub sensor: Trajectory,
    pub humans: Vec<HumanPlan>,
    /// Frame times, seconds from the start of the sequence.
    pub times_s: Vec<f64>,
}

/// Samples the sensor trajectory and the people of one sequence.
/// `grid` is the environment's walkable area (None: an empty, unbounded floor).
pub fn sample_plan(
    rng: &mut impl rand::Rng,
    cfg: &Config,
    rate_hz: f64,
    grid: Option<&WalkableGrid>,
    models: &[HumanModel],
) -> Result<SequencePlan> {
    let times_s: Vec<f64> = (0..cfg.frames).map(|k| k as f64 / rate_hz).collect();
    let uniform = |rng: &mut dyn FnMut() -> f64, r: [f64; 2]| r[0] + (r[1] - r[0]) * rng();
    let mut u01 = || rng.random::<f64>();

    // The sensor: a free start, an arc that stays clear of obstacles for the whole window.
    let sc = &cfg.scene;
    let mut sensor = None;
    for _ in 0..2000 {
        let start = match grid {
            Some(g) => {
                let x = g.origin.x + u01() * g.nx as f64 * g.cell_m;
                let y = g.origin.y + u01() * g.ny as f64 * g.cell_m;
                let p = DVec2::new(x, y);
                if g.clearance(p) < sc.sensor_clearance_m {
                    continue;
                }
                p
            }
            None => DVec2::ZERO,
        };
        let tr = Trajectory {
            start_m: start,
            z_m: sc.sensor_height_m,
            heading0_rad: (u01() * 2.0 - 1.0) * std::f64::consts::PI,
            speed_mps: uniform(&mut u01, sc.sensor_speed_mps),
            yaw_rate_rps: uniform(&mut u01, sc.sensor_yaw_rate_rps),
        };
        let clear = grid.map_or(true, |g| times_s.iter().all(|&t| g.clearance(tr.position(t).truncate()) >= sc.sensor_clearance_m));
        if clear {
            sensor = Some(tr);
            break;
        }
    }
    let sensor = sensor.ok_or_else(|| {
        Error::input(
            "scene.environment",
            "no room for the sensor's trajectory (tried 2000 starts); lower scene.sensor_speed_mps or scene.sensor_clearance_m",
        )
    })?;

    // The people.
    let hc = &cfg.humans;
    let [lo, hi] = hc.count;
    let count = lo + (u01() * (hi - lo + 1) as f64).floor().min((hi - lo) as f64) as usize;
    let mut humans: Vec<HumanPlan> = Vec::with_capacity(count);
    let s0 = sensor.start_m;
    for k in 0..count {
        let model = ((u01() * models.len() as f64) as usize).min(models.len() - 1);
        let height = models[model].height_m as f64;
        let mut placed = None;
        for _ in 0..2000 {
            let r = hc.spawn_radius_m * u01().sqrt();
            let a = u01() * std::f64::consts::TAU;
            let start = s0 + r * DVec2::new(a.cos(), a.sin());
            let speed = uniform(&mut u01, hc.speed_mps);
            let tr = Trajectory {
                start_m: start,
                z_m: 0.0,
                heading0_rad: (u01() * 2.0 - 1.0) * std::f64::consts::PI,
                speed_mps: speed,
                yaw_rate_rps: uniform(&mut u01, hc.yaw_rate_rps),
            };
            let plan = HumanPlan {
                model,
                trajectory: tr,
                phase0: u01(),
                stride_m: stride_length_m(height, speed.max(0.1)),
                motion: hc.motion,
            };
            let ok = times_s.iter().all(|&t| {
                let p = plan.at(t).position_m.truncate();
                let free = grid.map_or(true, |g| g.clearance(p) >= hc.clearance_m);
                let off_sensor = p.distance(sensor.position(t).truncate()) >= hc.min_separation_m;
                let apart = humans.iter().all(|h| h.at(t).position_m.truncate().distance(p) >= hc.min_separation_m);
                free && off_sensor && apart
            });
            if ok {
                placed = Some(plan);
                break;
            }
        }
        match placed {
            Some(p) => humans.push(p),
            None => {
                return Err(Error::input(
                    "humans",
                    format!(
                        "could place only {k} of {count} people without collisions (2000 tries each); \
                         lower humans.count, humans.min_separation_m or raise humans.spawn_radius_m"
                    ),
                ))
            }
        }
    }
    Ok(SequencePlan { sensor, humans, times_s })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn plan(motion: MotionMode) -> HumanPlan {
        HumanPlan {
            model: 0,
            trajectory: Trajectory { start_m: DVec2::new(1.0, 2.0), z_m: 0.0, heading0_rad: 0.3, speed_mps: 1.2, yaw_rate_rps: 0.1 },
            phase0: 0.25,
            stride_m: 1.2,
            motion,
        }
    }

    #[test]
    fn gait_phase_advances_by_distance_over_stride() {
        let p = plan(MotionMode::Full);
        // 1.2 m/s for 0.5 s = 0.6 m = half a 1.2 m stride.
        assert!((p.at(0.5).gait_phase - 0.75).abs() < 1e-12);
        assert!((p.at(1.0).gait_phase - 0.25).abs() < 1e-12, "wraps after a whole stride");
        assert!((p.at(0.0).gait_phase - 0.25).abs() < 1e-12);
    }

    #[test]
    fn motion_modes_follow_the_papers_ablations() {
        let t = 0.7;
        let full = plan(MotionMode::Full).at(t);
        let sliding = plan(MotionMode::Sliding).at(t);
        let in_place = plan(MotionMode::InPlace).at(t);
        let fixed = plan(MotionMode::Static).at(t);
        let start = plan(MotionMode::Full).at(0.0);
        assert_eq!(sliding.position_m, full.position_m);
        assert_eq!(sliding.gait_phase, 0.25);
        assert_eq!(in_place.position_m, start.position_m);
        assert_eq!(in_place.velocity_mps, DVec3::ZERO);
        assert_eq!(in_place.gait_phase, full.gait_phase);
        assert_eq!(fixed.position_m, start.position_m);
        assert_eq!(fixed.gait_phase, 0.25);
        assert_eq!(fixed.velocity_mps, DVec3::ZERO);
    }

    #[test]
    fn sampling_is_reproducible_and_respects_counts() {
        let mut cfg = Config::default();
        cfg.humans.count = [3, 5];
        let model = crate::human::tests_support::tiny_model();
        let a = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(7), &cfg, 10.0, None, std::slice::from_ref(&model)).unwrap();
        let b = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(7), &cfg, 10.0, None, std::slice::from_ref(&model)).unwrap();
        assert_eq!(a, b);
        assert!((3..=5).contains(&a.humans.len()));
        assert_eq!(a.times_s.len(), 32);
        for t in &a.times_s {
            for (i, h) in a.humans.iter().enumerate() {
                let p = h.at(*t).position_m.truncate();
                assert!(p.distance(a.sensor.position(*t).truncate()) >= cfg.humans.min_separation_m);
                for g in &a.humans[i + 1..] {
                    assert!(g.at(*t).position_m.truncate().distance(p) >= cfg.humans.min_separation_m);
                }
            }
        }
    }
}
