//! Seconds spent per stage of a run (`generate --timings`).

/// Wall-clock seconds spent per stage of the frames generated so far. The writer runs on its
/// own thread, overlapping the next frame, so `write_s` is not part of the frame's critical
/// path unless it is the longer of the two.
#[derive(Clone, Copy, Debug, Default)]
pub struct StageTimes {
    pub frames: u64,
    /// Plan and sample sequences (walkable area, walks, tracks).
    pub plan_s: f64,
    /// Load a recorded frame, pose the background, skin and place the people.
    pub pose_s: f64,
    /// Ray caster with `debug.caster = "bvh"`: refit or build the trees (both layers).
    pub bvh_s: f64,
    /// Render (raster) or cast (ray caster) the background and resample it.
    pub background_s: f64,
    /// Render or cast the people and resample them.
    pub humans_s: f64,
    /// Composite, labels, instance ids, velocities.
    pub post_s: f64,
    /// Compress and write (HDF5, PNG), on the writer thread.
    pub write_s: f64,
}

impl std::fmt::Display for StageTimes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.frames.max(1) as f64;
        let main = self.plan_s + self.pose_s + self.bvh_s + self.background_s + self.humans_s + self.post_s;
        writeln!(f, "stage           ms/frame   share of frame thread")?;
        for (name, s) in [
            ("plan", self.plan_s),
            ("pose + skin", self.pose_s),
            ("bvh refit", self.bvh_s),
            ("background", self.background_s),
            ("people", self.humans_s),
            ("post", self.post_s),
        ] {
            // The BVH stage exists only with `debug.caster = "bvh"`.
            if name == "bvh refit" && s == 0.0 {
                continue;
            }
            writeln!(f, "{name:<14} {:>9.3}   {:>5.1} %", 1e3 * s / n, 100.0 * s / main.max(1e-12))?;
        }
        writeln!(f, "{:<14} {:>9.3}", "frame thread", 1e3 * main / n)?;
        write!(f, "{:<14} {:>9.3}   (writer thread, overlaps the next frame)", "write", 1e3 * self.write_s / n)
    }
}
