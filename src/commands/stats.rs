//! `pedscan stats DIR`: what a generated dataset holds, for deciding whether it suits a
//! training run: frames, people per frame (in the scene and seen), human beams per distance
//! bin (the paper's 0-4, 4-8, 8+ m), the class balance (the paper's per-frame class weight is
//! background beams / human beams) and the people's walking speeds; with a PNG of the
//! histograms.

use crate::error::{Error, Result};
use crate::plot::{Marker, Plot, Series, PALETTE};
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
    let mut files: Vec<PathBuf> = std::fs::read_dir(path)
        .map_err(|e| Error::input(path.display(), format!("cannot list: {e}")))?
        .filter_map(|d| d.ok().map(|d| d.path()))
        .filter(|p| p.is_file() && p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("seq_")) && p.extension().is_some_and(|e| e == "h5"))
        .collect();
    files.sort();
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
                if k > 0 && r > 0.0 {
                    humans += 1;
                    seen[(k as usize).min(n)] = true;
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

    /// The histograms as one picture: people per frame, human beams per distance bin, class
    /// weight, walking speed.
    pub fn plot(&self) -> image::RgbImage {
        let bars = |name: &str, colour: [u8; 3], counts: &[(f64, f64)]| Series { name: name.into(), points: counts.to_vec(), colour, line: true, marker: Marker::Circle };
        let frac = |c: u64| c as f64 / self.frames.max(1) as f64;
        let people = Plot {
            title: "people per frame".into(),
            x_label: "people".into(),
            y_label: "fraction of frames".into(),
            series: vec![
                bars("in the scene", PALETTE[0], &self.people_in_scene.iter().enumerate().map(|(k, &c)| (k as f64, frac(c))).collect::<Vec<_>>()),
                bars("seen (>= 1 beam)", PALETTE[1], &self.people_seen.iter().enumerate().map(|(k, &c)| (k as f64, frac(c))).collect::<Vec<_>>()),
            ],
            width: 640,
            height: 360,
            ..Plot::default()
        };
        let bins = Plot {
            title: "human beams by distance (0-4, 4-8, 8+ m)".into(),
            x_label: "bin lower edge, m".into(),
            y_label: "human beams per frame".into(),
            series: vec![bars(
                "human beams",
                PALETTE[2],
                &[0.0, 4.0, 8.0].iter().zip(self.human_beams_by_distance).map(|(&x, c)| (x, frac(c))).collect::<Vec<_>>(),
            )],
            width: 640,
            height: 360,
            ..Plot::default()
        };
        let mut weights = self.class_weight.clone();
        weights.sort_by(f64::total_cmp);
        let cdf: Vec<(f64, f64)> = weights.iter().enumerate().map(|(i, &w)| (w, (i + 1) as f64 / weights.len() as f64)).collect();
        let weight = Plot {
            title: "class weight per frame (background / human beams)".into(),
            x_label: "class weight".into(),
            y_label: "fraction of frames at or below".into(),
            log_x: true,
            series: vec![bars("frames with people", PALETTE[3], &cdf)],
            width: 640,
            height: 360,
            ..Plot::default()
        };
        let total: u64 = self.speed_histogram.iter().sum();
        let speed = Plot {
            title: "walking speed".into(),
            x_label: "m/s".into(),
            y_label: "fraction of person-frames".into(),
            series: vec![bars(
                "people",
                PALETTE[4],
                &self.speed_histogram.iter().enumerate().map(|(i, &c)| ((i as f64 + 0.5) * SPEED_BIN_MPS, c as f64 / total.max(1) as f64)).collect::<Vec<_>>(),
            )],
            width: 640,
            height: 360,
            ..Plot::default()
        };
        let tiles: Vec<image::RgbImage> = [people, bins, weight, speed].iter().map(Plot::render).collect();
        let (tw, th) = tiles[0].dimensions();
        let mut out = image::RgbImage::from_pixel(2 * tw, 2 * th, image::Rgb([255, 255, 255]));
        for (i, tile) in tiles.iter().enumerate() {
            image::imageops::overlay(&mut out, tile, (i as u32 % 2 * tw) as i64, (i as u32 / 2 * th) as i64);
        }
        out
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
