//! `pedscan stats DIR`: what a generated dataset holds, for deciding whether it suits a
//! training run: frames, people per frame (in the scene and seen), human beams per distance
//! bin (the paper's 0-4, 4-8, 8+ m), the class balance (the paper's per-frame class weight is
//! background beams / human beams) and the people's walking speeds; with a PNG of the
//! histograms.

use crate::error::{Error, Result};
use crate::plot::{Draw, Marker, Plot, Series, PALETTE};
use std::fmt;
use std::path::{Path, PathBuf};

/// The paper's distance bins, metres: [0, 4), [4, 8), [8, inf).
pub const DISTANCE_BINS_M: [f64; 2] = [4.0, 8.0];
/// Width of the speed histogram's bins, m/s.
pub const SPEED_BIN_MPS: f64 = 0.1;

/// Statistics of one or more sequence files.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Stats {
    pub files: usize,
    pub frames: usize,
    pub beams: u64,
    /// Beams with a return.
    pub returns: u64,
    pub human_beams: u64,
    /// Human beams in the paper's distance bins (0-4, 4-8, 8+ m).
    pub human_beams_by_distance: [u64; 3],
    /// Frames with k people in the sequence (index k).
    pub people_in_scene: Vec<u64>,
    /// Frames with k people hit by at least one beam (index k).
    pub people_seen: Vec<u64>,
    /// Per frame: background returns / human beams (the paper's class weight); frames
    /// without a human beam are left out.
    pub class_weight: Vec<f64>,
    /// People's walking speeds (one per person and frame), counts per `SPEED_BIN_MPS` bin.
    pub speed_histogram: Vec<u64>,
}

fn bump(hist: &mut Vec<u64>, i: usize) {
    if hist.len() <= i {
        hist.resize(i + 1, 0);
    }
    hist[i] += 1;
}

/// The sequence files of `path`: the file itself, or every `seq_*.h5` of a folder, sorted.
pub fn sequence_files(path: &Path) -> Result<Vec<PathBuf>> {
    if path.is_file() {
        return Ok(vec![path.to_path_buf()]);
    }
    if !path.is_dir() {
        return Err(Error::input(path.display(), "no such file or folder"));
    }
    let files = crate::input::folder_files(path, |p| {
        p.is_file() && p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("seq_")) && p.extension().is_some_and(|e| e == "h5")
    })?;
    if files.is_empty() {
        return Err(Error::input(path.display(), "no seq_*.h5 files: not a folder written by `pedscan generate`"));
    }
    Ok(files)
}

impl Stats {
    /// Adds one sequence file.
    pub fn add_file(&mut self, path: &Path) -> Result<()> {
        let shown = path.display();
        let bad = |m: String| Error::input(&shown, m);
        let file = hdf5::File::open(path).map_err(|e| bad(format!("not a readable HDF5 file ({e})")))?;
        let read_f32 = |name: &str| -> Result<(Vec<usize>, Vec<f32>)> {
            let ds = file.dataset(name).map_err(|_| bad(format!("no /{name}: not a pedscan sequence")))?;
            Ok((ds.shape(), ds.read_raw::<f32>().map_err(|e| bad(format!("/{name}: {e}")))?))
        };
        let (shape, range) = read_f32("range")?;
        let [t, h, w] = shape[..] else { return Err(bad(format!("/range has shape {shape:?}, expected [frames, rows, columns]"))) };
        let inst = file.dataset("instance").map_err(|_| bad("no /instance: not a pedscan sequence".into()))?;
        if inst.shape() != shape {
            return Err(bad(format!("/instance has shape {:?}, /range {shape:?}", inst.shape())));
        }
        let instance: Vec<u16> = inst.read_raw().map_err(|e| bad(format!("/instance: {e}")))?;
        let (vshape, velocity) = read_f32("humans/velocity_mps")?;
        let n = match vshape[..] {
            [vt, n, 3] if vt == t => n,
            _ => return Err(bad(format!("/humans/velocity_mps has shape {vshape:?}, expected [{t}, people, 3]"))),
        };
        let beams = h * w;
        self.files += 1;
        self.frames += t;
        let mut seen = vec![false; n + 1];
        for f in 0..t {
            let (r, k) = (&range[f * beams..(f + 1) * beams], &instance[f * beams..(f + 1) * beams]);
            seen.iter_mut().for_each(|s| *s = false);
            let (mut returns, mut humans) = (0u64, 0u64);
            for (&r, &k) in r.iter().zip(k) {
                if r > 0.0 {
                    returns += 1;
                }
                // Instances above the people's are movers (cars, cyclists).
                if k > 0 && k as usize <= n && r > 0.0 {
                    humans += 1;
                    seen[k as usize] = true;
                    let bin = DISTANCE_BINS_M.iter().take_while(|&&b| r as f64 >= b).count();
                    self.human_beams_by_distance[bin] += 1;
                }
            }
            self.beams += beams as u64;
            self.returns += returns;
            self.human_beams += humans;
            if humans > 0 {
                self.class_weight.push((returns - humans) as f64 / humans as f64);
            }
            bump(&mut self.people_in_scene, n);
            bump(&mut self.people_seen, seen[1..].iter().filter(|&&s| s).count());
            for p in 0..n {
                let v = &velocity[(f * n + p) * 3..(f * n + p) * 3 + 3];
                let speed = (v[0] as f64).hypot(v[1] as f64);
                if speed.is_finite() {
                    bump(&mut self.speed_histogram, (speed / SPEED_BIN_MPS) as usize);
                }
            }
        }
        Ok(())
    }

    /// Statistics over the sequence files of `path` (a file or an output folder).
    pub fn of(path: &Path) -> Result<Stats> {
        let mut s = Stats::default();
        for f in sequence_files(path)? {
            s.add_file(&f)?;
        }
        Ok(s)
    }

    /// The histograms as one picture, as bars: people per frame (in the scene and seen), human
    /// beams per distance bin, walking speed; and the class weight's distribution (its
    /// cumulative fraction of frames, on a log axis).
    pub fn plot(&self) -> image::RgbImage {
        let bars = |name: &str, colour: [u8; 3], width: f64, points: Vec<(f64, f64)>| Series { name: name.into(), points, colour, draw: Draw::Bars { width } };
        let frac = |c: u64| c as f64 / self.frames.max(1) as f64;
        // Side by side: "in the scene" left of each count, "seen" right of it.
        let per_frame = |h: &[u64], dx: f64| h.iter().enumerate().map(|(k, &c)| (k as f64 + dx, frac(c))).collect();
        let tile = |title: &str, x_label: &str, y_label: &str, series: Vec<Series>| Plot {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series,
            width: 640,
            height: 360,
            ..Plot::default()
        };
        let people = tile(
            "people per frame",
            "people",
            "fraction of frames",
            vec![bars("in the scene", PALETTE[0], 0.4, per_frame(&self.people_in_scene, -0.2)), bars("seen (>= 1 beam)", PALETTE[1], 0.4, per_frame(&self.people_seen, 0.2))],
        );
        // Bars over 0-4, 4-8 and 8-12 m, the last standing for 8 m and beyond.
        let distance: Vec<(f64, f64)> = [2.0, 6.0, 10.0].iter().zip(self.human_beams_by_distance).map(|(&x, c)| (x, frac(c))).collect();
        let bins = tile("human beams by distance (0-4, 4-8, 8+ m)", "distance, m (the last bar: 8 m and beyond)", "human beams per frame", vec![bars("human beams", PALETTE[2], 3.6, distance)]);
        let mut weights = self.class_weight.clone();
        weights.sort_by(f64::total_cmp);
        let cdf: Vec<(f64, f64)> = weights.iter().enumerate().map(|(i, &w)| (w, (i + 1) as f64 / weights.len() as f64)).collect();
        let mut weight = tile(
            "class weight per frame (background / human beams)",
            "class weight",
            "fraction of frames at or below",
            vec![Series { name: "frames with people".into(), points: cdf, colour: PALETTE[3], draw: Draw::Line(Marker::Circle) }],
        );
        weight.log_x = true;
        let total = self.speed_histogram.iter().sum::<u64>().max(1) as f64;
        let speeds = self.speed_histogram.iter().enumerate().map(|(i, &c)| ((i as f64 + 0.5) * SPEED_BIN_MPS, c as f64 / total)).collect();
        let speed = tile("walking speed", "m/s", "fraction of person-frames", vec![bars("people", PALETTE[4], 0.9 * SPEED_BIN_MPS, speeds)]);
        crate::plot::render_grid(&[people, bins, weight, speed], 2)
    }
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    crate::commands::crosscheck::quantile_sorted(&s, 0.5)
}

impl fmt::Display for Stats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let per_frame = |c: u64| c as f64 / self.frames.max(1) as f64;
        let mean_k = |h: &[u64]| h.iter().enumerate().map(|(k, &c)| k as f64 * c as f64).sum::<f64>() / self.frames.max(1) as f64;
        writeln!(f, "files:        {}", self.files)?;
        writeln!(f, "frames:       {}", self.frames)?;
        writeln!(f, "people:       {:.1} per frame in the scene, {:.1} seen", mean_k(&self.people_in_scene), mean_k(&self.people_seen))?;
        writeln!(
            f,
            "returns:      {:.1} % of {} beams",
            100.0 * self.returns as f64 / self.beams.max(1) as f64,
            self.beams
        )?;
        writeln!(
            f,
            "human beams:  {:.1} per frame ({:.2} % of returns); 0-4 m {:.1}, 4-8 m {:.1}, 8+ m {:.1} per frame",
            per_frame(self.human_beams),
            100.0 * self.human_beams as f64 / self.returns.max(1) as f64,
            per_frame(self.human_beams_by_distance[0]),
            per_frame(self.human_beams_by_distance[1]),
            per_frame(self.human_beams_by_distance[2])
        )?;
        writeln!(
            f,
            "class weight: median {:.1} (background / human beams, {} frames with people)",
            median(&self.class_weight),
            self.class_weight.len()
        )?;
        let total: u64 = self.speed_histogram.iter().sum();
        // The centre of the bin where the cumulative count reaches fraction p.
        let q = |p: f64| {
            let mut acc = 0;
            for (i, &c) in self.speed_histogram.iter().enumerate() {
                acc += c;
                if acc as f64 >= p * total as f64 {
                    return (i as f64 + 0.5) * SPEED_BIN_MPS;
                }
            }
            f64::NAN
        };
        write!(f, "speed:        median {:.2} m/s, 5-95 % {:.2}-{:.2} m/s over {total} person-frames", q(0.5), q(0.05), q(0.95))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plot::tests::{bars, ink};

    #[test]
    fn the_picture_draws_the_histograms_as_bars_with_text() {
        let s = Stats {
            files: 1,
            frames: 10,
            human_beams_by_distance: [300, 200, 100],
            people_in_scene: vec![0, 0, 10],
            people_seen: vec![0, 4, 6],
            class_weight: vec![20.0, 40.0, 80.0],
            speed_histogram: vec![0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 5, 10, 20, 10],
            ..Stats::default()
        };
        let img = s.plot();
        assert_eq!(img.dimensions(), (1280, 720));
        let tile = |k: u32| image::imageops::crop_imm(&img, k % 2 * 640, k / 2 * 360, 640, 360).to_image();
        // Human beams by distance (top right): three bars, as tall as 300, 200 and 100.
        let distance: Vec<(u32, u32)> = bars(&tile(1), PALETTE[2]).into_iter().filter(|b| b.1 > 20).collect();
        assert_eq!(distance.len(), 3, "{distance:?}");
        for (b, c) in distance.iter().zip([3.0, 2.0, 1.0]) {
            assert!((b.1 as f64 - c * distance[2].1 as f64).abs() <= 2.0, "{distance:?}");
        }
        // Walking speed (bottom right): bars of 5, 10, 20 and 10 person-frames.
        let speed: Vec<(u32, u32)> = bars(&tile(3), PALETTE[4]).into_iter().filter(|b| b.1 > 15).collect();
        assert_eq!(speed.len(), 4, "{speed:?}");
        for (b, c) in speed.iter().zip([1.0, 2.0, 4.0, 2.0]) {
            assert!((b.1 as f64 - c * speed[0].1 as f64).abs() <= 2.0, "{speed:?}");
        }
        // People per frame (top left): 2 in the scene in every frame, seen 1 or 2, side by side.
        let scene: Vec<(u32, u32)> = bars(&tile(0), PALETTE[0]).into_iter().filter(|b| b.1 > 20).collect();
        let seen: Vec<(u32, u32)> = bars(&tile(0), PALETTE[1]).into_iter().filter(|b| b.1 > 20).collect();
        assert_eq!((scene.len(), seen.len()), (1, 2), "{scene:?} {seen:?}");
        assert!(seen[1].0 > scene[0].0 && seen[0].0 < scene[0].0, "{scene:?} {seen:?}");
        // Every tile has its title drawn, over its middle.
        for k in 0..4 {
            assert!(ink(&tile(k), (150, 490), (0, 28)) > 100, "tile {k} has no title");
        }
    }
}
