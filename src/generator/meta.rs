//! A sequence's metadata: who walks in it, where its background and people come from.

use super::Generator;
use crate::output::{HumanMeta, MoverMeta, SequenceMeta};
use crate::scene::sequence::SequencePlan;
use std::path::Path;

impl Generator {
    /// Metadata of sequence `index`.
    pub fn meta(&self, index: usize, plan: &SequencePlan) -> SequenceMeta {
        let movers = plan.world.as_ref().map_or(&[][..], |w| &w.movers[..]);
        SequenceMeta {
            index,
            seed: self.cfg.seed,
            sensor: self.inputs.sensor.clone(),
            config_toml: self.recorded_config.clone(),
            rigid_velocity: self.cfg.output.velocity != crate::config::VelocityModel::Paper,
            frames: plan.times_s.len(),
            humans: plan
                .humans
                .iter()
                .enumerate()
                .map(|(i, h)| {
                    let m = &self.inputs.models[h.model];
                    let pushing = movers.iter().find(|m| m.pusher() == Some(i)).map(|m| m.kind.name().to_string());
                    HumanMeta { height_m: m.nominal_height_m(), weight_kg: m.weight_kg.unwrap_or(0.0), model: m.name.clone(), seat_m: (h.seat_m > 0.0).then_some(h.seat_m as f32), pushing }
                })
                .collect(),
            movers: movers
                .iter()
                .map(|m| MoverMeta { kind: m.kind.name().into(), length_m: (2.0 * m.half.x) as f32, width_m: (2.0 * m.half.y) as f32, pushed_by: m.pusher().map_or(0, |i| i as u32 + 1) })
                .collect(),
            outputs: self.outputs(),
            provenance: self.provenance(plan),
        }
    }

    /// Where the background and the people of a plan come from (see [`SequenceMeta`]).
    pub fn provenance(&self, plan: &SequencePlan) -> Vec<(String, String)> {
        let name = |p: &Path| p.file_name().map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned());
        let bg = &self.cfg.scene.background;
        let backend = if self.backend.choice() == crate::config::BackendChoice::Raycast { "raycast" } else { "raster" };
        let mut v = vec![("backend".to_string(), backend.to_string()), (
            "background".to_string(),
            match (&self.inputs.recording, &self.inputs.environment) {
                _ if plan.world.is_some() => format!("world {}", name(bg)),
                (Some(_), _) => format!("recording {}", name(bg)),
                (None, Some(_)) => format!("environment {}", name(bg)),
                _ => "none".into(),
            },
        )];
        if let Some(w) = &plan.world {
            v.push(("world".into(), w.summary()));
        }
        if let (Some(rec), Some(s)) = (&self.inputs.recording, plan.recording_start) {
            v.push(("recording_first_frame".into(), s.to_string()));
            v.push(("recording_frames".into(), rec.len().to_string()));
            v.push(("recording".into(), rec.description.clone()));
        }
        if !self.cfg.scene.poses.as_os_str().is_empty() {
            v.push(("poses".into(), name(&self.cfg.scene.poses)));
        }
        v.push(("floor_z_m".into(), format!("{:.4}", plan.floor_z_m)));
        if !self.cfg.humans.tracks.as_os_str().is_empty() {
            v.push(("tracks".into(), name(&self.cfg.humans.tracks)));
            let mut ids = Vec::new();
            for h in &plan.humans {
                if let crate::scene::sequence::HumanPath::Track(t) = &h.trajectory {
                    ids.push(t.track.id.to_string());
                    if ids.len() == 1 {
                        v.push(("tracks_window_start_s".into(), format!("{}", t.t0_s)));
                    }
                }
            }
            v.push(("track_ids".into(), ids.join(",")));
        }
        v
    }
}
