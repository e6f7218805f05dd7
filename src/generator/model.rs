//! The sensor model's stage: the surfaces of the composited frame handed to
//! [`crate::sensor_model`], and its result written into the frame.

use super::Generator;
use crate::output::FrameOutput;
use crate::pose::FrameState;
use crate::sensor_model::surfaces::{EnvWorld, SceneSurfaces};
use crate::sensor_model::SequenceDraws;
use rayon::prelude::*;

impl Generator {
    /// The sensor model's draws for sequence `index` with `people` people, drawn unless held.
    pub(super) fn draws_for(&mut self, index: usize, people: usize) {
        let key = (index, people);
        if self.scratch.draws_for != Some(key) {
            let m = &self.cfg.sensor_model;
            self.scratch.draws = SequenceDraws::draw(m, self.cfg.seed, index, self.inputs.sensor.rows(), people);
            self.scratch.draws_for = Some(key);
        }
    }

    /// The clean surface per beam of the composited `out` (its reflectance and incidence),
    /// then the sensor model: `out`'s range, label and instance become the returned ones,
    /// `/clean/*` keeps the others, and `/intensity` is filled.
    pub(super) fn apply_sensor_model(&mut self, state: &FrameState, out: &mut FrameOutput) {
        // A caller that never said which sequence this is gets sequence 0's draws.
        let index = self.scratch.draws_for.map_or(0, |k| k.0);
        self.draws_for(index, state.humans.len());
        let (s, p) = (&mut self.scratch, &self.posed);
        let scene = SceneSurfaces {
            humans: &p.humans,
            human_hits: &s.human_hits,
            background: &p.background,
            bg_hits: &s.bg_hits,
            recorded: p.recorded.as_deref(),
            recorded_intensity: &p.recorded_intensity,
            intensity_scale: self.inputs.intensity_scale,
            columns: self.inputs.sensor.columns,
            layout: &p.layout,
            regions: &self.inputs.regions,
            reflectance: &s.draws.reflectance,
            dirs: &self.inputs.dirs,
            env_meshes: &self.inputs.env_meshes,
            env_world: match &self.inputs.environment {
                Some(env) if !p.column_pose.is_empty() => {
                    Some(EnvWorld { positions: p.env_positions(env), meshes: &self.inputs.env_meshes, column_pose: &p.column_pose })
                }
                _ => None,
            },
        };
        let n = self.inputs.dirs.len();
        // In parallel: each beam's surface (its triangle's normal, region, reflectance) is
        // ~1 ms a frame on one core.
        (0..n).into_par_iter().with_min_len(1024).map(|b| scene.clean(b, out.range[b], out.instance[b])).collect_into_vec(&mut s.clean);
        let frame = crate::sensor_model::FrameIn {
            cfg: &self.cfg.sensor_model,
            dirs: &self.inputs.dirs,
            columns: self.inputs.sensor.columns,
            elevation_rad: &self.inputs.elevation_rad,
            azimuth_rad: &self.inputs.azimuth_rad,
            min_range_m: self.inputs.sensor.min_range_m,
            max_range_m: self.inputs.sensor.max_range_m,
            clean: &s.clean,
            draws: &s.draws,
            intensity_scale: self.inputs.intensity_scale,
            recorded_intensity: (p.recorded.is_some() && p.recorded_intensity.len() == n).then_some(p.recorded_intensity.as_slice()),
            seed: self.cfg.seed,
            sequence: s.draws_for.map_or(0, |k| k.0),
            frame: state.frame,
        };
        let mut beams = std::mem::take(&mut s.beams_out);
        crate::sensor_model::apply(&frame, &scene, &mut beams);
        if self.cfg.sensor_model.enabled {
            out.clean_range.clone_from(&out.range);
            out.clean_label.clone_from(&out.label);
            out.clean_instance.clone_from(&out.instance);
        } else {
            out.clean_range.clear();
            out.clean_label.clear();
            out.clean_instance.clear();
        }
        out.intensity.clear();
        out.intensity.extend(beams.iter().map(|b| b.intensity));
        for (b, o) in beams.iter().enumerate() {
            out.range[b] = o.range_m;
            out.instance[b] = o.instance;
            out.label[b] = (o.instance > 0) as u8;
        }
        s.beams_out = beams;
    }
}
