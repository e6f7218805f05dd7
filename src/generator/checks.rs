//! What the checks read of a frame: `crosscheck` (each layer through several backends),
//! `shutter-check` (the rolling shutter against posing every column), `bench` (the people at
//! full detail) and the tests.

use super::Generator;
use crate::backend::{Backend, BeamHits, Layer, LayerKind};
use crate::error::Result;
use crate::geometry::FrameGeometry;
use crate::pose::{FrameState, PoseStage};
use crate::scene::sequence::SequencePlan;
use glam::DVec3;

/// One beam of [`Generator::reference_rolling_hits`]: (beam, nearest person's (range,
/// instance), environment's range or 0).
pub type ReferenceHit = (usize, Option<(f64, u16)>, f64);

/// One posed frame as the backends see it (see [`Generator::posed`]).
pub struct Posed<'a> {
    pub background: &'a FrameGeometry,
    pub people: &'a FrameGeometry,
    /// The people's proxies, one mesh per person (empty unless the backend draws proxies).
    pub proxies: &'a FrameGeometry,
}

fn layer_of(s: &PoseStage, kind: LayerKind) -> Layer<'_> {
    match kind {
        LayerKind::Background => Layer::Background(&s.background),
        LayerKind::People => Layer::People { people: &s.humans, proxies: &s.proxies },
    }
}

impl Generator {
    /// The frame [`Generator::pose_frame`] posed last.
    pub fn posed(&self) -> Posed<'_> {
        Posed { background: &self.posed.background, people: &self.posed.humans, proxies: &self.posed.proxies }
    }

    /// The point velocities [`Generator::point_velocities`] computed last (per beam).
    pub fn point_velocity(&self) -> &[DVec3] {
        &self.scratch.point_velocity
    }

    /// The people layer's hits of the frame [`Generator::render_posed`] cast last.
    pub fn human_hits(&self) -> &BeamHits {
        &self.scratch.human_hits
    }

    /// [`Generator::pose_frame`] with every person at full detail (the reference of `bench`).
    pub fn pose_frame_full_detail(&mut self, plan: &SequencePlan, state: &FrameState) -> Result<()> {
        self.pose_frame_at(plan, state, 0.0, self.rolls())
    }

    /// The rolling shutter's reference for frame `k` of a plan: for each of `columns`, the
    /// whole frame posed at that column's time (every vertex at one instant) and the column's
    /// beams cast exactly (watertight f64, nearest hit) through the people and the
    /// environment. Returns, per beam of those columns, `(beam, people, background)`: the
    /// nearest person's (range, instance) and the environment's range (0 = none). Slow by
    /// design: a pose per column.
    pub fn reference_rolling_hits(
        &mut self,
        plan: &SequencePlan,
        k: usize,
        columns: impl Iterator<Item = usize>,
    ) -> Result<Vec<ReferenceHit>> {
        let sweep = self.inputs.pose(None).sweep(plan, k, plan.times_s[k], true);
        let w = self.inputs.sensor.columns;
        let mut out = Vec::new();
        let mut people = crate::backend::raster::clusters::MeshClusters::default();
        let mut background = crate::backend::raster::clusters::MeshClusters::default();
        let mut scratch = Vec::new();
        for c in columns {
            let state = self.frame_state_at(plan, k, sweep.column_time(c));
            self.pose_frame_at(plan, &state, self.cfg.render.lod_max_error_mrad, false)?;
            let s = &self.posed;
            people.reset(&s.humans);
            background.reset(&s.background);
            for row in 0..self.inputs.sensor.rows() {
                let b = row * w + c;
                let dir = self.inputs.dirs[b];
                let h = people.cast(&s.humans, dir, &mut scratch).map(|(r, t)| (r, s.humans.mesh_of_triangle(t).instance as u16));
                let bg = background.cast(&s.background, dir, &mut scratch).map_or(0.0, |(r, _)| r);
                out.push((b, h, bg));
            }
        }
        Ok(out)
    }

    /// The people and background layers' hits of the frame cast last (see
    /// [`Generator::render_posed`]): per beam, the nearest person's (range, instance) and the
    /// background's range (0 = none).
    pub fn layer_hits(&self, b: usize) -> (Option<(f64, u16)>, f64) {
        let s = &self.scratch;
        let t = s.human_hits.triangle[b];
        let h = (t != crate::backend::NO_TRIANGLE).then(|| (s.human_hits.range_m[b] as f64, self.posed.humans.mesh_of_triangle(t).instance as u16));
        (h, s.bg_hits.range_m[b] as f64)
    }

    /// One layer of the posed frame through the generator's backend, into `hits`.
    pub fn cast_layer(&mut self, kind: LayerKind, hits: &mut BeamHits) -> Result<()> {
        self.backend.cast(layer_of(&self.posed, kind), hits)
    }

    /// One layer of the posed frame through another backend (`crosscheck` holds several).
    pub fn cast_with(&self, backend: &mut dyn Backend, kind: LayerKind, hits: &mut BeamHits) -> Result<()> {
        backend.cast(layer_of(&self.posed, kind), hits)
    }
}
