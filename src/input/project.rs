//! Projection of a recorded frame onto the target sensor's beam grid: the range image of the
//! real background into which rendered people are composited.
//!
//! # Rule
//!
//! A point's **column** is the target's [`Sensor::column_of`] of its azimuth. Its **row** is
//! the target row nearest its elevation, accepted only within half the gap to the neighbouring
//! row on that side (above the top row and below the bottom row: half the gap to the next row
//! inwards; a one-row sensor accepts half a column pitch either side). A point outside every
//! row's band is counted in [`ProjectStats::outside_band`] and dropped; so is a point that is
//! not finite or sits at the origin. Each cell keeps the nearest return (smallest range; on a
//! tie the first point); every other point that reached the cell is counted in
//! [`ProjectStats::replaced`]. Cells no point reached stay `0.0`, a hole (no return), and are
//! kept as holes. So `kept + outside_band + replaced` is the number of points.
//!
//! **Rings.** When the scan knows each point's laser ring *and* the ring elevations (a raw
//! Velodyne capture), the row comes from the ring: ring `r` goes to the target row nearest
//! `ring_elevation_deg[r]` under the same half-gap rule, so a recorded HDL-32E frame lands row
//! for row on the `hdl32e` target even where a point's computed elevation is noisy (range
//! noise, the lasers' vertical offsets). A ring with no matching row (or no elevation) falls
//! back to the point's own elevation. When the scan has rings but no elevations (a PCD `ring`
//! field, the lasers of a KITTI scan's point order: [`super::kitti::lasers_of`]) and its ring
//! count (largest ring + 1) equals the target's row count and every ring's median elevation
//! lies within [`MAX_RING_ROW_OFFSET_DEG`] of that row's, ring `r` goes to row `rows - 1 - r`
//! (ring 0 is the lowest beam, the ROS convention); otherwise (another ring count, or the rings
//! of another sensor with as many rows) the rings are ignored and the elevations used. [`ProjectStats::ring_mapped`] says whether
//! rings chose the rows. A ring list whose length differs from the point list is ignored.
//!
//! # When the recording sensor differs from the target
//!
//! Nothing is interpolated; each return is moved to the nearest target beam or dropped:
//!
//! * **Rows.** Target rows that no source beam falls near stay holes; several source rings may
//!   land in one target row (the nearest return wins each cell); returns between two target
//!   rows go to the nearer within half a gap, and returns beyond the target's outermost rows
//!   (plus half a gap) are dropped.
//! * **Columns** are resampled by azimuth: each return goes to the target column containing its
//!   azimuth, nearest return per cell. A source denser in azimuth than the target fills every
//!   cell it covers (and loses the farther returns); a sparser one leaves holes between its
//!   firings.
//! * A **denser** source overall fills more cells, a **sparser** one leaves more holes; the
//!   holes are real no-return cells to the compositor.
//! * The recording's **rolling-shutter skew** (the sensor moving during the rotation) is not
//!   corrected: each point is used where the recording put it.
//!
//! Range limits of the target ([`Sensor::min_range_m`], [`Sensor::max_range_m`]) are not
//! applied here; the projected range is the point's distance from the sensor origin.

use super::Scan;
use crate::sensor::Sensor;

/// Counts of what one [`Projector::project`] call did with the scan's points.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ProjectStats {
    /// Points that hold a cell of the output (= cells with a return).
    pub kept: usize,
    /// Points outside every row's elevation band, or not finite, or at the origin.
    pub outside_band: usize,
    /// Points that reached an occupied cell and lost to a nearer (or equally near, earlier)
    /// return.
    pub replaced: usize,
    /// True when the scan's rings chose the rows (see the module docs).
    pub ring_mapped: bool,
}

/// How far, degrees, a ring's median elevation may lie from the row it would fill for rings
/// without elevations to choose the rows (see the module docs). KITTI's HDL-64E lasers, seen
/// from the origin of their points, lie up to 1.05 deg above the `hdl64e` rows (the lasers'
/// offset above that origin; SemanticKITTI 07, odometry 01-03, 06, 09, 10); another sensor's
/// 64 rows lie far further from them (`os1-64`: +21 deg against +2 at the top).
pub const MAX_RING_ROW_OFFSET_DEG: f64 = 3.0;

/// Points per ring whose median elevation is held against the ring's row.
const RING_SAMPLES: usize = 256;

/// The cell of a point [`Projector::project_points`] drops (outside every band, not finite,
/// at the origin).
pub const NO_CELL: u32 = u32::MAX;

/// Projects recorded scans onto one target beam grid; the row bands are computed once.
#[derive(Clone, Debug)]
pub struct Projector {
    target: Sensor,
    /// Band edges in degrees, descending, `rows + 1` of them: row `r` takes elevations in
    /// `(edges_deg[r + 1], edges_deg[r]]`.
    edges_deg: Vec<f64>,
    /// `tan` of the same edges (compared with `z / hypot(x, y)`, no `atan` per point).
    edges_tan: Vec<f64>,
}

/// How rows are chosen for one scan.
enum RowSource<'a> {
    Elevation,
    RingElevation(&'a [u16], &'a [f64]),
    RingFlip(&'a [u16]),
}

impl Projector {
    /// Prepares the row bands of `target` (which must have strictly descending elevations, as
    /// a validated [`Sensor`] has).
    pub fn new(target: &Sensor) -> Projector {
        let e = &target.elevation_deg;
        let n = e.len();
        let mut edges_deg = Vec::with_capacity(n + 1);
        if n == 1 {
            let half = 180.0 / target.columns.max(1) as f64;
            edges_deg.extend([e[0] + half, e[0] - half]);
        } else if n > 1 {
            edges_deg.push(e[0] + (e[0] - e[1]) / 2.0);
            edges_deg.extend(e.windows(2).map(|w| (w[0] + w[1]) / 2.0));
            edges_deg.push(e[n - 1] - (e[n - 2] - e[n - 1]) / 2.0);
        }
        // Keep the edges inside (-90, 90) so that tan stays monotonic.
        for v in &mut edges_deg {
            *v = v.clamp(-89.999, 89.999);
        }
        let edges_tan = edges_deg.iter().map(|d| d.to_radians().tan()).collect();
        Projector { target: target.clone(), edges_deg, edges_tan }
    }

    /// The target sensor.
    pub fn target(&self) -> &Sensor {
        &self.target
    }

    /// Projects `scan` into `range_out`, resized to `rows * columns` (row-major,
    /// `row * columns + col`), metres, `0.0` = no return. See the module docs for the rule.
    pub fn project(&self, scan: &Scan, range_out: &mut Vec<f32>) -> ProjectStats {
        self.project_with_intensity(scan, range_out, &mut Vec::new())
    }

    /// [`Projector::project`], and the intensity of the return each cell keeps into
    /// `intensity_out` (same shape; left empty when the scan has no intensity).
    pub fn project_with_intensity(&self, scan: &Scan, range_out: &mut Vec<f32>, intensity_out: &mut Vec<f32>) -> ProjectStats {
        self.project_into(scan, range_out, intensity_out, None)
    }

    /// [`Projector::project_with_intensity`], and each point's cell into `cells_out` (one per
    /// point of the scan, in its order): the cell `row * columns + col` the rule sends it to,
    /// also when a nearer return keeps that cell, or [`NO_CELL`] for a point outside every
    /// band, not finite or at the origin.
    pub fn project_points(&self, scan: &Scan, range_out: &mut Vec<f32>, intensity_out: &mut Vec<f32>, cells_out: &mut Vec<u32>) -> ProjectStats {
        cells_out.clear();
        cells_out.resize(scan.points.len(), NO_CELL);
        self.project_into(scan, range_out, intensity_out, Some(cells_out))
    }

    /// The one projection loop behind every entry point; `cells_out`, when given, already
    /// holds [`NO_CELL`] per point.
    fn project_into(&self, scan: &Scan, range_out: &mut Vec<f32>, intensity_out: &mut Vec<f32>, mut cells_out: Option<&mut Vec<u32>>) -> ProjectStats {
        let rows = self.target.rows();
        let cols = self.target.columns;
        range_out.clear();
        range_out.resize(rows * cols, 0.0);
        let intensity = scan.intensity.as_deref().filter(|i| i.len() == scan.points.len());
        intensity_out.clear();
        if intensity.is_some() {
            intensity_out.resize(rows * cols, 0.0);
        }
        let source = self.row_source(scan);
        let mut stats = ProjectStats {
            ring_mapped: !matches!(source, RowSource::Elevation),
            ..ProjectStats::default()
        };
        for (i, p) in scan.points.iter().enumerate() {
            let (x, y, z) = (p[0] as f64, p[1] as f64, p[2] as f64);
            let range = (x * x + y * y + z * z).sqrt();
            let r32 = range as f32;
            if !(r32.is_finite() && r32 > 0.0) {
                stats.outside_band += 1;
                continue;
            }
            let row = match source {
                RowSource::Elevation => self.row_of_point(x, y, z),
                RowSource::RingElevation(ring, elev) => elev
                    .get(ring[i] as usize)
                    .and_then(|&e| self.row_of_elevation_deg(e))
                    .or_else(|| self.row_of_point(x, y, z)),
                RowSource::RingFlip(ring) => Some(rows - 1 - ring[i] as usize),
            };
            let Some(row) = row else {
                stats.outside_band += 1;
                continue;
            };
            let c = row * cols + self.target.column_of(x, y);
            if let Some(cells) = cells_out.as_deref_mut() {
                cells[i] = u32::try_from(c).expect("a validated sensor has at most 4096 x 65536 cells");
            }
            let cell = &mut range_out[c];
            let nearer = *cell == 0.0 || r32 < *cell;
            if *cell == 0.0 {
                stats.kept += 1;
            } else {
                stats.replaced += 1;
            }
            if nearer {
                *cell = r32;
                if let Some(src) = intensity {
                    intensity_out[c] = src[i];
                }
            }
        }
        stats
    }

    fn row_source<'a>(&self, scan: &'a Scan) -> RowSource<'a> {
        let Some(ring) = scan.ring.as_deref() else {
            return RowSource::Elevation;
        };
        if ring.len() != scan.points.len() {
            return RowSource::Elevation;
        }
        if let Some(elev) = scan.ring_elevation_deg.as_deref() {
            return RowSource::RingElevation(ring, elev);
        }
        let ring_count = ring.iter().map(|&r| r as usize + 1).max().unwrap_or(0);
        if ring_count == self.target.rows() && self.rings_near_their_rows(&scan.points, ring) {
            RowSource::RingFlip(ring)
        } else {
            RowSource::Elevation
        }
    }

    /// True when every ring's median elevation (over at most about [`RING_SAMPLES`] of its
    /// points, evenly spread) lies within [`MAX_RING_ROW_OFFSET_DEG`] of the row `rows - 1 - r`
    /// that ring `r` would fill.
    fn rings_near_their_rows(&self, points: &[[f32; 3]], ring: &[u16]) -> bool {
        let rows = self.target.rows();
        let mut count = vec![0usize; rows];
        for &r in ring {
            count[r as usize] += 1;
        }
        let stride: Vec<usize> = count.iter().map(|&n| n.div_ceil(RING_SAMPLES).max(1)).collect();
        let mut seen = vec![0usize; rows];
        let mut elevation: Vec<Vec<f64>> = count.iter().map(|&n| Vec::with_capacity(n.min(RING_SAMPLES))).collect();
        for (p, &r) in points.iter().zip(ring) {
            let r = r as usize;
            if seen[r] % stride[r] == 0 {
                elevation[r].push((p[2] as f64).atan2((p[0] as f64).hypot(p[1] as f64)).to_degrees());
            }
            seen[r] += 1;
        }
        elevation.iter_mut().enumerate().filter(|(_, e)| !e.is_empty()).all(|(r, e)| {
            let mid = e.len() / 2;
            let median = *e.select_nth_unstable_by(mid, f64::total_cmp).1;
            (median - self.target.elevation_deg[rows - 1 - r]).abs() <= MAX_RING_ROW_OFFSET_DEG
        })
    }

    /// Row whose band holds elevation `e` (degrees), if any.
    fn row_of_elevation_deg(&self, e: f64) -> Option<usize> {
        band(&self.edges_deg, e)
    }

    /// Row whose band holds the elevation of direction (x, y, z), if any.
    fn row_of_point(&self, x: f64, y: f64, z: f64) -> Option<usize> {
        band(&self.edges_tan, z / x.hypot(y))
    }
}

/// Index `r` with `edges[r + 1] < v <= edges[r]` for descending `edges`; `None` outside (and
/// for NaN).
fn band(edges: &[f64], v: f64) -> Option<usize> {
    let k = edges.partition_point(|&b| b >= v);
    (k >= 1 && k < edges.len()).then(|| k - 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    /// A range that differs from cell to cell (2 m to 50 m).
    fn range_of(row: usize, col: usize) -> f64 {
        2.0 + ((row * 31 + col * 17) % 97) as f64 * 0.5
    }

    fn point(d: DVec3, range: f64) -> [f32; 3] {
        let p = d * range;
        [p.x as f32, p.y as f32, p.z as f32]
    }

    /// Direction at azimuth of column `col` of `s` and elevation `el_deg`.
    fn dir(s: &Sensor, col: usize, el_deg: f64) -> DVec3 {
        let az = s.azimuth_rad(col);
        let el = el_deg.to_radians();
        DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
    }

    /// A perturbation of up to +-0.9 deg, beyond the +-0.667 deg half-gap of the hdl32e.
    fn wobble(row: usize, col: usize) -> f64 {
        0.9 * ((row * 7 + col * 13) as f64 * 0.61).sin()
    }

    fn assert_reproduces(s: &Sensor, out: &[f32]) {
        assert_eq!(out.len(), s.rows() * s.columns);
        for r in 0..s.rows() {
            for c in 0..s.columns {
                let want = range_of(r, c);
                let got = out[r * s.columns + c] as f64;
                assert!((got - want).abs() <= 1e-5 * want, "row {r} col {c}: {got} vs {want}");
            }
        }
    }

    /// The stats of a scan that fills every cell of `s` once.
    fn whole_grid(s: &Sensor, ring_mapped: bool) -> ProjectStats {
        ProjectStats { kept: s.rows() * s.columns, outside_band: 0, replaced: 0, ring_mapped }
    }

    #[test]
    fn own_beam_grid_is_reproduced_cell_for_cell() {
        let s = Sensor::hdl32e();
        let mut scan = Scan::default();
        for r in 0..s.rows() {
            for c in 0..s.columns {
                scan.points.push(point(s.beam_dir(r, c), range_of(r, c)));
            }
        }
        let proj = Projector::new(&s);
        let mut out = vec![1.0; 3]; // resized and cleared
        let st = proj.project(&scan, &mut out);
        assert_eq!(
            st,
            whole_grid(&s, false)
        );
        assert_reproduces(&s, &out);
        // The same buffer again: same answer.
        assert_eq!(proj.project(&scan, &mut out), st);
        assert_reproduces(&s, &out);
    }

    /// Ring id of an HDL-32E laser for target row `row`: the sensor interleaves its lasers
    /// (id 0 = -30.67, id 1 = -9.33, id 2 = -29.33, ...).
    fn hdl32e_ring_of_row(row: usize) -> u16 {
        if row >= 16 {
            (2 * (31 - row)) as u16
        } else {
            (2 * (15 - row) + 1) as u16
        }
    }

    #[test]
    fn rings_with_elevations_map_row_to_row_despite_noisy_elevations() {
        let s = Sensor::hdl32e();
        let mut elev = vec![0.0; 33];
        for r in 0..32 {
            elev[hdl32e_ring_of_row(r) as usize] = s.elevation_deg[r];
        }
        elev[32] = 60.0; // a ring no target row matches
        let mut scan = Scan { ring: Some(Vec::new()), ..Scan::default() };
        for r in 0..s.rows() {
            for c in 0..s.columns {
                scan.points
                    .push(point(dir(&s, c, s.elevation_deg[r] + wobble(r, c)), range_of(r, c)));
                scan.ring.as_mut().unwrap().push(hdl32e_ring_of_row(r));
            }
        }
        let proj = Projector::new(&s);
        let mut out = Vec::new();

        // Without rings the wobble moves some returns to the neighbouring row.
        let plain = Scan { ring: None, ..scan.clone() };
        let st = proj.project(&plain, &mut out);
        assert!(!st.ring_mapped && st.replaced > 0);

        scan.ring_elevation_deg = Some(elev);
        // A point of the unmatched ring falls back to its own elevation (row 5), in a column
        // the grid leaves empty once the row-5 point there is removed.
        let (fr, fc) = (5, 700);
        scan.points.remove(fr * s.columns + fc);
        scan.ring.as_mut().unwrap().remove(fr * s.columns + fc);
        scan.points.push(point(s.beam_dir(fr, fc), range_of(fr, fc)));
        scan.ring.as_mut().unwrap().push(32);
        let st = proj.project(&scan, &mut out);
        assert_eq!(
            st,
            whole_grid(&s, true)
        );
        assert_reproduces(&s, &out);
    }

    #[test]
    fn pcd_rings_without_elevations_flip_to_rows() {
        let s = Sensor::hdl32e();
        let mut scan = Scan { ring: Some(Vec::new()), ..Scan::default() };
        for r in 0..s.rows() {
            for c in 0..s.columns {
                scan.points
                    .push(point(dir(&s, c, s.elevation_deg[r] + wobble(r, c)), range_of(r, c)));
                scan.ring.as_mut().unwrap().push((31 - r) as u16); // ring 0 = lowest
            }
        }
        let proj = Projector::new(&s);
        let mut out = Vec::new();
        let st = proj.project(&scan, &mut out);
        assert_eq!(
            st,
            whole_grid(&s, true)
        );
        assert_reproduces(&s, &out);

        // 16 rings onto 32 rows: the rings are ignored, the elevations used.
        let mut scan = Scan { ring: Some(Vec::new()), ..Scan::default() };
        for r in 0..s.rows() {
            scan.points.push(point(s.beam_dir(r, 3), 10.0));
            scan.ring.as_mut().unwrap().push((r % 16) as u16);
        }
        let st = proj.project(&scan, &mut out);
        assert!(!st.ring_mapped);
        assert_eq!(st.kept, 32);
        for r in 0..s.rows() {
            assert!((out[r * s.columns + 3] - 10.0).abs() < 1e-5);
        }
    }

    #[test]
    fn nearest_return_wins() {
        let s = Sensor::hdl32e();
        let proj = Projector::new(&s);
        let mut out = Vec::new();
        let d = s.beam_dir(10, 400);
        // Directions a little off the beam centre, still in the same cell.
        let d2 = dir(&s, 400, s.elevation_deg[10] + 0.2);
        let mut intensity = Vec::new();
        for ranges in [[10.0, 5.0, 7.0], [5.0, 10.0, 7.0], [7.0, 10.0, 5.0]] {
            let scan = Scan {
                points: vec![point(d, ranges[0]), point(d2, ranges[1]), point(d, ranges[2])],
                // Each return's intensity is its range: the kept one must say 5.
                intensity: Some(ranges.iter().map(|r| *r as f32).collect()),
                ..Scan::default()
            };
            let st = proj.project_with_intensity(&scan, &mut out, &mut intensity);
            assert_eq!((st.kept, st.replaced, st.outside_band), (1, 2, 0));
            assert!((out[10 * s.columns + 400] - 5.0).abs() < 1e-6);
            assert_eq!(out.iter().filter(|v| **v != 0.0).count(), 1);
            assert_eq!(intensity[10 * s.columns + 400], 5.0, "the nearest return's intensity");
            assert_eq!(intensity.iter().filter(|v| **v != 0.0).count(), 1);
        }
        // A tie keeps the first; it is still counted as replaced.
        let scan = Scan { points: vec![point(d, 5.0), point(d2, 5.0)], ..Scan::default() };
        let st = proj.project(&scan, &mut out);
        assert_eq!((st.kept, st.replaced), (1, 1));
    }

    #[test]
    fn points_outside_the_band_are_counted() {
        let s = Sensor::hdl32e(); // rows 10.67 .. -30.67, half gap about 0.667
        let proj = Projector::new(&s);
        let mut out = Vec::new();
        let c = 100;
        let scan = Scan {
            points: vec![
                point(dir(&s, c, 11.5), 10.0),                     // above the top band
                point(dir(&s, c, 11.2), 10.0),                     // inside the top band: row 0
                point(dir(&s, c, -31.2), 10.0),                    // inside the bottom band: row 31
                point(dir(&s, c, -31.5), 10.0),                    // below
                point(dir(&s, c, 45.0), 10.0),                     // far above
                [0.0, 0.0, 5.0],                                   // straight up
                [f32::NAN, 1.0, 1.0],                              // not finite
                [0.0, 0.0, 0.0],                                   // the origin
                point(dir(&s, c, s.elevation_deg[3] + 0.6), 10.0), // between rows 2 and 3: row 3
            ],
            ..Scan::default()
        };
        let st = proj.project(&scan, &mut out);
        assert_eq!(st, ProjectStats { kept: 3, outside_band: 6, replaced: 0, ring_mapped: false });
        for r in [0, 31, 3] {
            assert!((out[r * s.columns + c] - 10.0).abs() < 1e-5, "row {r}");
        }
        assert_eq!(out.iter().filter(|v| **v != 0.0).count(), 3);
    }

    /// Brute force: nearest target row by |difference|, accepted within half the gap on that
    /// side (the inward gap beyond the outermost rows).
    fn oracle_row(t: &Sensor, e: f64) -> Option<usize> {
        let el = &t.elevation_deg;
        let (r, _) = el
            .iter()
            .enumerate()
            .min_by(|a, b| (a.1 - e).abs().partial_cmp(&(b.1 - e).abs()).unwrap())
            .unwrap();
        let n = el.len();
        let half = if e >= el[r] {
            if r > 0 {
                (el[r - 1] - el[r]) / 2.0
            } else {
                (el[0] - el[1]) / 2.0
            }
        } else if r + 1 < n {
            (el[r] - el[r + 1]) / 2.0
        } else {
            (el[n - 2] - el[n - 1]) / 2.0
        };
        ((e - el[r]).abs() <= half).then_some(r)
    }

    #[test]
    fn a_vlp16_scan_lands_in_the_nearest_hdl32e_rows() {
        let src = Sensor::vlp16();
        let t = Sensor::hdl32e();
        let mut scan = Scan::default();
        let mut want = vec![0.0f64; t.rows() * t.columns];
        let mut outside = 0;
        for r in 0..src.rows() {
            for c in 0..src.columns {
                let range = range_of(r, c);
                let d = src.beam_dir(r, c);
                scan.points.push(point(d, range));
                match oracle_row(&t, src.elevation_deg[r]) {
                    None => outside += 1,
                    Some(tr) => {
                        let cell = &mut want[tr * t.columns + t.column_of(d.x, d.y)];
                        if *cell == 0.0 || range < *cell {
                            *cell = range;
                        }
                    }
                }
            }
        }
        // +15 and +13 deg are above the hdl32e's top band (10.67 + 0.67); the others land.
        assert_eq!(outside, 2 * src.columns);
        let proj = Projector::new(&t);
        let mut out = Vec::new();
        let st = proj.project(&scan, &mut out);
        assert_eq!(st.outside_band, outside);
        assert_eq!(st.kept + st.replaced + st.outside_band, scan.points.len());
        assert_eq!(st.kept, 14 * t.columns);
        for (i, (g, w)) in out.iter().zip(&want).enumerate() {
            assert!((*g as f64 - w).abs() <= 1e-5 * w.max(1.0), "cell {i}: {g} vs {w}");
        }
        // E.g. -15 deg lands in row 19 (-14.67), +11 deg in row 0 (+10.67); rows between them
        // that no vlp16 beam is near stay holes.
        assert_eq!(oracle_row(&t, -15.0), Some(19));
        assert!(out[19 * t.columns..20 * t.columns].iter().all(|v| *v > 0.0));
        assert!(out[..t.columns].iter().all(|v| *v > 0.0));
        let filled_rows = (0..t.rows()).filter(|r| out[r * t.columns] > 0.0).count();
        assert_eq!(filled_rows, 14);
    }

    /// `project_points` against `project_with_intensity` on `scan`: the same images and stats,
    /// every point's cell the one the images say it reached.
    fn assert_cells_agree(proj: &Projector, scan: &Scan) -> Vec<u32> {
        let (mut range, mut intensity, mut cells) = (Vec::new(), Vec::new(), vec![7; 3]);
        let st = proj.project_points(scan, &mut range, &mut intensity, &mut cells);
        let (mut want_range, mut want_intensity) = (Vec::new(), Vec::new());
        assert_eq!(proj.project_with_intensity(scan, &mut want_range, &mut want_intensity), st);
        assert_eq!((range == want_range, intensity == want_intensity), (true, true));
        assert_eq!(cells.len(), scan.points.len());
        assert_eq!(cells.iter().filter(|&&c| c == NO_CELL).count(), st.outside_band);
        // Each point's cell holds a return at most as far as the point; each return is a point
        // sent to its cell; as many distinct cells as kept returns.
        let ranges: Vec<f32> = scan.points.iter().map(|p| (p.map(f64::from).iter().map(|v| v * v).sum::<f64>()).sqrt() as f32).collect();
        for (i, &c) in cells.iter().enumerate().filter(|(_, &c)| c != NO_CELL) {
            let kept = range[c as usize];
            assert!(kept > 0.0 && kept <= ranges[i], "point {i} in cell {c}: {kept} vs {}", ranges[i]);
        }
        let mut filled: Vec<u32> = cells.iter().copied().filter(|&c| c != NO_CELL).collect();
        filled.sort_unstable();
        filled.dedup();
        assert_eq!(filled.len(), st.kept);
        assert!(filled.iter().all(|&c| cells.iter().zip(&ranges).any(|(&pc, &r)| pc == c && r == range[c as usize])));
        cells
    }

    #[test]
    fn each_points_cell_is_the_cell_it_reached() {
        let t = Sensor::hdl32e();
        let proj = Projector::new(&t);
        // A vlp16 grid onto the hdl32e (outside points, replaced ones), and a nearer copy of
        // every 5th return of one row, and points that are dropped.
        let src = Sensor::vlp16();
        let mut scan = Scan::default();
        for r in 0..src.rows() {
            for c in (0..src.columns).step_by(3) {
                scan.points.push(point(src.beam_dir(r, c), range_of(r, c)));
                if r == 9 && c % 5 == 0 {
                    scan.points.push(point(src.beam_dir(r, c), 1.0));
                }
            }
        }
        scan.points.extend([[f32::NAN, 1.0, 1.0], [0.0; 3], [0.0, 0.0, 5.0]]);
        scan.intensity = Some((0..scan.points.len()).map(|i| i as f32).collect());
        let cells = assert_cells_agree(&proj, &scan);
        assert_eq!(cells[cells.len() - 3..], [NO_CELL; 3]);
        // A point and its nearer copy share the cell.
        let row9 = 9 * src.columns.div_ceil(3);
        assert_eq!(cells[row9], cells[row9 + 1]);
        // Rings choose the rows: the cells follow them.
        let mut ringed = Scan::default();
        for r in 0..t.rows() {
            for c in (0..t.columns).step_by(5) {
                ringed.points.push(point(dir(&t, c, t.elevation_deg[r] + wobble(r, c)), range_of(r, c)));
            }
        }
        ringed.ring = Some((0..ringed.points.len()).map(|i| (31 - i / t.columns.div_ceil(5)) as u16).collect());
        let cells = assert_cells_agree(&proj, &ringed);
        assert!(cells.iter().enumerate().all(|(i, &c)| c as usize / t.columns == i / t.columns.div_ceil(5)));
    }

    #[test]
    fn rings_of_another_sensor_with_as_many_rows_are_not_laid_row_for_row() {
        // KITTI-like: 64 lasers at the hdl64e's angles, seen 20 cm above the origin, ring 0 the
        // lowest; their own elevations stray by up to 2 deg at 6 m.
        let t = Sensor::preset("hdl64e").unwrap();
        let mut scan = Scan { ring: Some(Vec::new()), ..Scan::default() };
        for r in 0..t.rows() {
            for c in (0..t.columns).step_by(7) {
                let d = t.beam_dir(r, c) * (6.0 + (c % 50) as f64);
                scan.points.push([d.x as f32, d.y as f32, (d.z + 0.2) as f32]);
                scan.ring.as_mut().unwrap().push((t.rows() - 1 - r) as u16);
            }
        }
        let mut out = Vec::new();
        let st = Projector::new(&t).project(&scan, &mut out);
        assert!(st.ring_mapped);
        assert!((0..t.rows()).all(|r| out[r * t.columns..(r + 1) * t.columns].iter().filter(|v| **v > 0.0).count() == t.columns.div_ceil(7)));
        // The same 64 rings onto the os1-64 (+21 to -21 deg): by elevation.
        assert!(!Projector::new(&Sensor::preset("os1-64").unwrap()).project(&scan, &mut out).ring_mapped);
    }

    #[test]
    fn band_edges() {
        let p = Projector::new(&Sensor::vlp16());
        assert_eq!(p.row_of_elevation_deg(15.0), Some(0));
        assert_eq!(p.row_of_elevation_deg(15.99), Some(0));
        assert_eq!(p.row_of_elevation_deg(16.01), None);
        assert_eq!(p.row_of_elevation_deg(-15.99), Some(15));
        assert_eq!(p.row_of_elevation_deg(-16.01), None);
        assert_eq!(p.row_of_elevation_deg(0.9), Some(7));
        assert_eq!(p.row_of_elevation_deg(1.1), Some(7));
        assert_eq!(p.row_of_elevation_deg(f64::NAN), None);
        // A one-row sensor: half a column pitch either side.
        let mut one = Sensor::vlp16();
        one.elevation_deg = vec![0.0];
        one.columns = 360;
        let p = Projector::new(&one);
        assert_eq!(p.row_of_elevation_deg(0.4), Some(0));
        assert_eq!(p.row_of_elevation_deg(-0.6), None);
    }
}
