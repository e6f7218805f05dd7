//! The returns of a recorded background that are not scored: the recording's own people,
//! who would otherwise be labeled background. A beam whose returned surface is such a return
//! gets `/label` [`crate::output::NOT_SCORED`] (the training loss and `evaluate` skip it); a
//! person composited in front of it keeps its label. Two sources, per window of recorded
//! frames:
//!
//! * **Labels** (`scene.ignore_labels`): the cells that points of the chosen SemanticKITTI
//!   classes project to ([`crate::input::labels`]), all of them by construction.
//! * **Motion** (`scene.ignore_moving`): the returns that the recording's other frames *see
//!   through*. A return of frame k at range r in cell b is the world point
//!   `p = world_from_sensor_k (dir_b r)`. Frame j (one of the recorded frames within
//!   [`SPAN_S`] before and after k, in the window or not; at most [`MAX_COMPARED`] of them,
//!   evenly spread) sees through p when, p lying at range `rho` from j's sensor in j's cell c
//!   (the background's own projection, [`Projector::project_points`]), c holds a return and
//!   every return of j within [`NEAR_M`] of c (the rows and columns that span at `rho`, at
//!   least [`MIN_NEAR_ROWS`] and [`MIN_NEAR_COLUMNS`] either side) lies beyond
//!   `rho + max(`[`MARGIN_M`]`, `[`MARGIN_SHARE`]` rho)`: j measured the space behind p
//!   empty, so whatever was at p was not there at j. p is not scored when at least
//!   [`MIN_SEEN_THROUGH`] frames see through it (every compared frame when fewer are
//!   compared). Something nearer than p in j (p hidden) or at p (p still there) says nothing
//!   against it. The neighbourhood's nearest return keeps the floor, walls at grazing angles
//!   and the edges of things from being seen through when p is rebuilt a little off (the
//!   cell's centre direction, a KITTI laser's offset from the rows' angles, the recording's
//!   rolling shutter, pose errors: all a few centimetres to decimetres, so the neighbourhood
//!   is metric), and the margin covers range noise.
//!
//!   What it finds: a person or thing that moved off a place the recording saw behind it
//!   within the sensor's range; not one that stands still over the span, nor the places of a
//!   walker that every other frame sees hidden behind the walker's own body (walking straight
//!   away near the recording's end, or straight towards the sensor near its start). It needs
//!   the poses (`--poses`, a bag's `/tf`; without, the sensor is taken as still). Returns
//!   that move with the sensor (the recording vehicle's own body) are not scored either.
//!   Measured on SemanticKITTI 07 and 00 (docs/inputs.md); it costs about 40 ms a frame of
//!   an HDL-64E grid (8 compared frames) on two cores.

use crate::error::Result;
use crate::input::labels::FrameLabels;
use crate::input::project::{Projector, NO_CELL};
use crate::input::{Recording, Scan};
use glam::{DMat4, DVec3};
use rayon::prelude::*;

/// The least margin, m, by which a compared frame's returns must lie beyond a return for
/// that frame to see through it.
pub const MARGIN_M: f64 = 0.3;
/// ... and the margin's share of the return's range from the compared frame's sensor.
pub const MARGIN_SHARE: f64 = 0.02;
/// The returns within this distance, m, of the cell (seen from the compared frame's sensor,
/// across and along its rows) must all lie beyond: the rows and columns either side it spans
/// at the return's range, at least [`MIN_NEAR_ROWS`] and [`MIN_NEAR_COLUMNS`], at most
/// [`MAX_NEAR_ROWS`] rows and 32 columns.
pub const NEAR_M: f64 = 0.2;
pub const MIN_NEAR_ROWS: usize = 1;
pub const MIN_NEAR_COLUMNS: usize = 2;
pub const MAX_NEAR_ROWS: usize = 4;
/// Frames that must see through a return for it not to be scored.
pub const MIN_SEEN_THROUGH: usize = 2;
/// The most other frames a frame is compared with (evenly spread over [`SPAN_S`]).
pub const MAX_COMPARED: usize = 8;
/// A frame is compared with the recorded frames at most this long before and after it, s
/// (within the window or not): a walker at 1.4 m/s is 2.2 m away by then.
pub const SPAN_S: f64 = 1.6;

/// What makes a recorded background's returns not scored.
#[derive(Clone, Debug, Default)]
pub struct NotScored {
    /// Returns the recording's other frames see through (`scene.ignore_moving`).
    pub moving: bool,
    /// Returns that points of the chosen classes project to (`scene.ignore_labels`).
    pub labels: Option<FrameLabels>,
}

impl NotScored {
    /// True when any source is on.
    pub fn is_on(&self) -> bool {
        self.moving || self.labels.is_some()
    }

    /// Per frame of the window `frames` of `rec`: its not-scored cells, ascending.
    pub fn window(&self, rec: &Recording, frames: std::ops::Range<usize>) -> Result<Vec<Vec<u32>>> {
        let mut cells = vec![Vec::new(); frames.len()];
        if self.moving {
            // The window and the recorded frames within SPAN_S before and after it.
            let t = &rec.times_s;
            let first = (0..frames.start).rev().take_while(|&j| within_span(t[frames.start] - t[j])).last().unwrap_or(frames.start);
            let end = (frames.end..rec.len()).take_while(|&j| within_span(t[j] - t[frames.end - 1])).last().map_or(frames.end, |j| j + 1);
            let ranges = rec.window_ranges(first..end)?;
            let poses: Vec<DMat4> = (first..end).map(|k| rec.pose(k)).collect();
            let span = Span { ranges: &ranges, poses: &poses, times_s: &t[first..end] };
            cells = moving_cells(&span, rec.beam_dirs(), rec.projector(), frames.start - first..frames.end - first);
        }
        if let Some(labels) = &self.labels {
            let labeled: Vec<Result<Vec<u32>>> = frames.clone().into_par_iter().map(|k| labels.cells(k, rec.projector())).collect();
            for (mine, theirs) in cells.iter_mut().zip(labeled) {
                mine.extend(theirs?);
                mine.sort_unstable();
                mine.dedup();
            }
        }
        Ok(cells)
    }
}

/// True when frames `dt_s` apart are compared: |dt| within [`SPAN_S`] (to the microsecond).
fn within_span(dt_s: f64) -> bool {
    dt_s.abs() <= SPAN_S + 1e-6
}

/// Recorded frames on the target grid with their poses and times (s), consecutive.
pub struct Span<'a> {
    /// Range images, row-major, 0 = no return.
    pub ranges: &'a [Vec<f32>],
    /// `world_from_sensor` per frame.
    pub poses: &'a [DMat4],
    pub times_s: &'a [f64],
}

/// The frames frame `k` is compared with: the others within [`SPAN_S`] of it, or
/// [`MAX_COMPARED`] of them evenly spread from the first to the last.
fn compared(k: usize, times_s: &[f64]) -> Vec<usize> {
    let others: Vec<usize> = (0..times_s.len()).filter(|&j| j != k && within_span(times_s[j] - times_s[k])).collect();
    if others.len() <= MAX_COMPARED {
        return others;
    }
    let last = others.len() - 1;
    (0..MAX_COMPARED).map(|i| others[(i * last + (MAX_COMPARED - 1) / 2) / (MAX_COMPARED - 1)]).collect()
}

/// A frame's nearest returns along its rows: level `l` holds, per cell, the nearest return
/// within `2^l` columns either side (columns wrap around; infinity where there is none), for
/// `l` up to [`COLUMN_LEVELS`] - 1.
struct RowMins {
    columns: usize,
    levels: Vec<Vec<f32>>,
}

/// Levels of [`RowMins`]: up to 2^5 = 32 columns either side ([`NEAR_M`] at 1.4 m on
/// 2,048 columns).
const COLUMN_LEVELS: usize = 6;

impl RowMins {
    /// Fills the levels from `range` (row-major, `columns` wide, 0 = no return).
    fn fill(&mut self, range: &[f32], columns: usize) {
        self.columns = columns;
        self.levels.resize_with(COLUMN_LEVELS, Vec::new);
        let (first, rest) = self.levels.split_at_mut(1);
        // Level 0: one column either side.
        let l0 = &mut first[0];
        l0.clear();
        l0.resize(range.len(), f32::INFINITY);
        let far = |r: f32| if r > 0.0 { r } else { f32::INFINITY };
        for (row, line) in range.chunks_exact(columns).enumerate() {
            for c in 0..columns {
                let m = far(line[(c + columns - 1) % columns]).min(far(line[c])).min(far(line[(c + 1) % columns]));
                l0[row * columns + c] = m;
            }
        }
        // Level l: level l - 1 at 2^(l-1) columns either side.
        let mut below: &Vec<f32> = l0;
        for (l, level) in rest.iter_mut().enumerate() {
            let shift = (1usize << l) % columns;
            level.clear();
            level.resize(range.len(), f32::INFINITY);
            for row in 0..range.len() / columns {
                let line = &below[row * columns..(row + 1) * columns];
                for c in 0..columns {
                    level[row * columns + c] = line[(c + columns - shift) % columns].min(line[(c + shift) % columns]);
                }
            }
            below = level;
        }
    }

    /// The nearest return within `rows` rows and at least `columns` columns (rounded up to a
    /// power of two, at most 2^([`COLUMN_LEVELS`] - 1)) either side of `cell`; infinity where there is none.
    fn nearest(&self, cell: usize, rows: usize, columns: usize) -> f32 {
        let level = &self.levels[(columns.max(1).next_power_of_two().trailing_zeros() as usize).min(COLUMN_LEVELS - 1)];
        let (row, c) = (cell / self.columns, cell % self.columns);
        let last = level.len() / self.columns - 1;
        (row.saturating_sub(rows)..=(row + rows).min(last)).map(|r| level[r * self.columns + c]).fold(f32::INFINITY, f32::min)
    }
}

/// Per frame of `targets` (indices into `span`, on the grid of `projector` whose beam
/// directions are `dirs`): the cells whose return the span's other frames see through (see the
/// module docs), ascending.
pub fn moving_cells(span: &Span, dirs: &[DVec3], projector: &Projector, targets: std::ops::Range<usize>) -> Vec<Vec<u32>> {
    let (ranges, poses) = (span.ranges, span.poses);
    let sensor = projector.target();
    let columns = sensor.columns;
    // The grid's pitch, radians: a column, and a row on average.
    let column_rad = std::f64::consts::TAU / columns as f64;
    let e = &sensor.elevation_deg;
    let row_rad = if e.len() > 1 { (e[0] - e[e.len() - 1]).to_radians() / (e.len() - 1) as f64 } else { column_rad };
    // Each compared frame's row minima are built where they are used (a frame's take 24
    // bytes a cell: a span's would not fit in memory).
    targets
        .into_par_iter()
        .map_init(|| RowMins { columns, levels: Vec::new() }, |mins, k| {
            let returned: Vec<usize> = (0..ranges[k].len()).filter(|&b| ranges[k][b] > 0.0).collect();
            let mut seen_through = vec![0u16; returned.len()];
            let others = compared(k, span.times_s);
            let (mut scan, mut image, mut cells) = (Scan::default(), Vec::new(), Vec::new());
            for &j in &others {
                let j_from_k = poses[j].inverse() * poses[k];
                scan.points.clear();
                scan.points.extend(returned.iter().map(|&b| j_from_k.transform_point3(dirs[b] * ranges[k][b] as f64).as_vec3().to_array()));
                projector.project_points(&scan, &mut image, &mut Vec::new(), &mut cells);
                mins.fill(&ranges[j], columns);
                for (i, &c) in cells.iter().enumerate() {
                    if c == NO_CELL || ranges[j][c as usize] <= 0.0 {
                        continue;
                    }
                    let rho = DVec3::from(scan.points[i].map(f64::from)).length();
                    let rows = ((NEAR_M / (rho * row_rad)).ceil() as usize).clamp(MIN_NEAR_ROWS, MAX_NEAR_ROWS);
                    let cols = ((NEAR_M / (rho * column_rad)).ceil() as usize).max(MIN_NEAR_COLUMNS);
                    if mins.nearest(c as usize, rows, cols) as f64 > rho + MARGIN_M.max(MARGIN_SHARE * rho) {
                        seen_through[i] += 1;
                    }
                }
            }
            let need = MIN_SEEN_THROUGH.min(others.len()).max(1);
            returned.iter().zip(&seen_through).filter(|(_, &n)| n as usize >= need).map(|(&b, _)| b as u32).collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::Sensor;

    #[test]
    fn compared_frames_are_the_others_near_in_time_or_spread_over_them() {
        let at = |n: usize| (0..n).map(|k| k as f64 * 0.1).collect::<Vec<f64>>();
        assert_eq!(compared(0, &at(1)), Vec::<usize>::new());
        assert_eq!(compared(2, &at(5)), vec![0, 1, 3, 4]);
        // 10 Hz: frames 1 to 16 after frame 0, 8 of them; frame 20 sees 4 to 36.
        let c = compared(0, &at(64));
        assert_eq!(c.len(), MAX_COMPARED);
        assert_eq!((c[0], c[MAX_COMPARED - 1]), (1, 16));
        assert!(c.windows(2).all(|w| w[0] < w[1]), "{c:?}");
        let c = compared(20, &at(64));
        assert_eq!((c.len(), c[0], c[MAX_COMPARED - 1]), (MAX_COMPARED, 4, 36));
        assert!(!c.contains(&20));
    }

    #[test]
    fn the_nearest_return_around_a_cell_wraps_the_columns_and_skips_holes() {
        // 3 rows x 16 columns.
        let mut r = vec![0.0f32; 48];
        r[0] = 5.0; // row 0, column 0
        r[9] = 9.0; // row 0, column 9
        r[32 + 5] = 7.0; // row 2, column 5
        let mut m = RowMins { columns: 16, levels: Vec::new() };
        m.fill(&r, 16);
        // One column either side at least (level 0), one row.
        assert_eq!(m.nearest(10, 1, 1), 9.0);
        assert_eq!(m.nearest(15, 0, 1), 5.0, "across the wrap");
        assert_eq!(m.nearest(16 + 3, 1, 1), f32::INFINITY, "nothing within a column");
        // Two columns either side reach column 5 from 3, in row 2 (rows 0 to 2 from row 1).
        assert_eq!(m.nearest(16 + 3, 1, 2), 7.0);
        assert_eq!(m.nearest(16 + 3, 0, 2), f32::INFINITY);
        // Three columns round up to four: column 3 reaches 0 (5 beats 7 and 9 is too far).
        assert_eq!(m.nearest(3, 2, 3), 5.0);
        // Eight columns either side of column 12 reach 9 and, across the wrap, 0 and 5.
        assert_eq!(m.nearest(12, 0, 8), 5.0);
        assert_eq!(m.nearest(32 + 12, 2, 8), 5.0);
        // A grid without returns.
        m.fill(&[0.0; 48], 16);
        assert_eq!(m.nearest(20, 2, 100), f32::INFINITY);
    }

    /// A room's walls 12 m away as the HDL-32E sees them from `o` (world = sensor axes), with a
    /// box of 0.6 x 0.6 x 1.8 m at `thing` when given; ranges on the grid.
    fn room(o: DVec3, thing: Option<DVec3>) -> Vec<f32> {
        let s = Sensor::hdl32e();
        s.beam_dirs()
            .iter()
            .map(|d| {
                let mut best = f64::INFINITY;
                for (axis, wall) in [(0, 12.0), (0, -12.0), (1, 12.0), (1, -12.0), (2, -1.7)] {
                    let t = (wall - o[axis]) / d[axis];
                    if t > 0.0 {
                        best = best.min(t);
                    }
                }
                if let Some(c) = thing {
                    // Slab test against the box.
                    let (lo, hi) = (c - DVec3::new(0.3, 0.3, 0.0), c + DVec3::new(0.3, 0.3, 1.8));
                    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
                    for a in 0..3 {
                        let (u, v) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
                        t0 = t0.max(u.min(v));
                        t1 = t1.min(u.max(v));
                    }
                    if t0 <= t1 {
                        best = best.min(t0);
                    }
                }
                best as f32
            })
            .collect()
    }

    #[test]
    fn a_box_that_moves_is_seen_through_and_the_still_room_is_not() {
        // The sensor moves 0.2 m a frame along x; a box stands still at (4, -3) and another
        // walks 0.6 m a frame along y past (5, 2); floor at -1.7 m.
        let s = Sensor::hdl32e();
        let proj = Projector::new(&s);
        let dirs = s.beam_dirs();
        let n = 6;
        let origin = |k: usize| DVec3::new(0.2 * k as f64, 0.0, 0.0);
        let walker = |k: usize| DVec3::new(5.0, 0.6 * k as f64 - 1.0, -1.7);
        let still = DVec3::new(4.0, -3.0, -1.7);
        let hit = |o: DVec3, d: DVec3, r: f32, at: DVec3| {
            let p = o + d * r as f64;
            (p.x - at.x).abs() <= 0.31 && (p.y - at.y).abs() <= 0.31 && p.z >= at.z - 0.01
        };
        let mut ranges = Vec::new();
        for k in 0..n {
            // The two boxes: the nearer surface per beam.
            let a = room(origin(k), Some(walker(k)));
            let b = room(origin(k), Some(still));
            ranges.push(a.iter().zip(&b).map(|(x, y)| x.min(*y)).collect::<Vec<f32>>());
        }
        let poses: Vec<DMat4> = (0..n).map(|k| DMat4::from_translation(origin(k))).collect();
        let times: Vec<f64> = (0..n).map(|k| k as f64 * 0.1).collect();
        let cells = moving_cells(&Span { ranges: &ranges, poses: &poses, times_s: &times }, &dirs, &proj, 0..n);
        for k in 0..n {
            let (mut walker_beams, mut flagged_walker, mut flagged_other) = (0, 0, 0);
            for (b, &r) in ranges[k].iter().enumerate() {
                let flagged = cells[k].binary_search(&(b as u32)).is_ok();
                if r > 0.0 && hit(origin(k), dirs[b], r, walker(k)) {
                    walker_beams += 1;
                    flagged_walker += flagged as usize;
                } else {
                    flagged_other += flagged as usize;
                    assert!(!flagged || !hit(origin(k), dirs[b], r, still), "frame {k}: the still box's beam {b} is flagged");
                }
            }
            assert!(walker_beams > 100, "frame {k}: {walker_beams}");
            // All but the feet, where the floor just behind lies within the margin and the
            // rows around.
            assert!(flagged_walker * 10 >= walker_beams * 8, "frame {k}: {flagged_walker} of {walker_beams} walker beams");
            assert_eq!(flagged_other, 0, "frame {k}: still surfaces flagged");
        }
    }
}
