//! Casting a whole beam grid by binning triangles into beams: the fast ray caster for
//! generation, with the BVH caster ([`super::cast`]) and brute force as its referees.
//!
//! Every beam of a spinning sensor starts at the origin, so a triangle can only be hit by the
//! beams whose direction lies inside its central projection onto the unit sphere. Instead of
//! building (or refitting) a BVH over the posed triangles and tracing every beam through it,
//! [`BeamCaster::cast`] walks the triangles once, bounds each one's projection in beam-grid
//! coordinates (columns from the azimuth, rows from the sine of the elevation), and runs the
//! same watertight f64 ray/triangle test ([`crate::backend::triangle::intersect_pre`]) for the beams inside that
//! bound only. A posed person is ~27k triangles a third of a beam spacing wide at 10 m, so
//! almost every triangle is dropped after a few f32 comparisons, and the BVH refit of a frame
//! (O(triangles), with the triangles copied into slots) is not needed at all.
//!
//! **Exactness.** The bound is conservative, so each beam is tested against every triangle it
//! can hit; with the same intersection function and the same tie rule (smaller range, then
//! smaller triangle index) the result equals [`super::cast_brute_force`] bit for bit, for any
//! thread count. Why the bound holds:
//! * The projection of a triangle is a spherical triangle whose sides are great-circle arcs.
//! * Azimuth: if the triangle's xy-projection does not contain the z axis, the azimuths of its
//!   points fill the shortest arc that holds the three vertex azimuths (less than 180 degrees).
//!   Vertex azimuths come from a polynomial `atan` whose error, sampled densely (5e7 points),
//!   stays below 1.17e-5 rad (a unit test checks 6e5 of them); the bound is widened by
//!   4e-5 rad plus the f32 rounding of the column coordinate.
//! * Elevation: `sin(el) = z` of the unit direction is linear on the sphere, so without a pole
//!   inside, its extremes lie on the sides. On an arc of angle `theta` between unit vectors A
//!   and B, every point is `w1 A + w2 B` with `w1 + w2 <= 1 / cos(theta / 2)`, so `z` exceeds
//!   `max(zA, zB)` only by that factor (when positive); the same holds below. The factor comes
//!   from the triangle's longest chord.
//! * A triangle whose azimuth arc is wider than a quarter turn (it surrounds or nearly touches
//!   the z axis), or with a vertex on the axis, is tested against every beam; one with a
//!   longest chord over ~87 degrees (chord^2 >= 1.9) against every row of its columns.
//!   Non-finite vertices never hit (as in the reference) and are skipped.
//! * Preconditions (checked in [`BeamCaster::new`]): at least 8 columns on the sensor's
//!   uniform azimuth grid, rows of constant elevation in strictly descending order. The row-gap
//!   shortcut needs two neighbouring column cells to span well under half a turn.

use crate::backend::triangle::{better, intersect_pre, Hit, RayPre};
use crate::geometry::FrameGeometry;
use glam::DVec3;
use rayon::prelude::*;
use crate::sensor::atan2_fast;
use std::f32::consts::PI as PI32;

/// Triangles per parallel job.
const JOB_TRIANGLES: usize = 4096;
/// Vertices per parallel job of the projection pass.
const JOB_VERTICES: usize = 4096;
/// Jobs wanted per cast (row bands split meshes of few triangles).
const MIN_JOBS: usize = 16;
/// Bound on the error of [`atan2_fast`] in radians (sampled maximum 1.17e-5) with margin.
const AZIMUTH_MARGIN_RAD: f32 = 4e-5;
/// Margin on `sin(elevation)` for the f32 normalisation of the vertices.
const SIN_MARGIN: f32 = 4e-6;

/// A triangle's conservative bound in the beam grid ([`BeamCaster::bounds`]): columns
/// `c0..=c1` (they may run past the last column or below 0: wrap them with
/// `rem_euclid(columns)`; at most one turn), rows `r0..r1` (end exclusive).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridBound {
    pub triangle: u32,
    pub c0: i64,
    pub c1: i64,
    pub r0: u32,
    pub r1: u32,
}

/// A beam grid (rows of constant elevation, columns of the sensor's azimuth convention) and
/// the per-frame buffers of the binned cast (reused: no allocation in steady state).
pub struct BeamCaster {
    rows: usize,
    columns: usize,
    /// Per beam (row-major): the watertight ray constants of its direction.
    pre: Vec<Option<RayPre>>,
    /// `sin(elevation)` per row, descending with the row index.
    row_sin: Vec<f32>,
    /// Per vertex: the column cell `floor(u)` as `2 floor(u) + e`, where `e = 1` when `u` is
    /// within the azimuth margin of a cell edge (`NO_CELL`: no azimuth); and the row gap (the
    /// number of rows above the vertex) when the vertex is farther than the gap table's
    /// margin from both rows around it, else `i32::MIN` (see `gap_table`).
    cell: Vec<[i32; 2]>,
    /// Per vertex: column coordinate `u` and `sin(elevation)` (meaningful where the vertex
    /// is finite and off the z axis).
    us: Vec<[f32; 2]>,
    /// Row gap per bin of `sin(elevation)` over [-1, 1] (`GAP_BINS` bins): the gap that holds
    /// the whole bin widened by the bulge margin, or `i32::MIN`. Arcs bulge away from zero
    /// elevation, so the gap above the top row is used only if that row is at or above zero,
    /// and the gap below the bottom row only if that row is at or below zero.
    gap_table: Vec<i32>,
    /// Per triangle job: the hits it found (beam, range, triangle).
    jobs: Vec<Vec<(u32, f64, u32)>>,
    /// Per triangle job of [`BeamCaster::bounds`]: the bounds it found.
    bound_jobs: Vec<Vec<GridBound>>,
    /// The jobs: (mesh, first triangle, end triangle, first row, end row).
    spans: Vec<(usize, usize, usize, usize, usize)>,
    /// Per beam: its direction in f32, for the conservative pre-test.
    dir32: Vec<[f32; 3]>,
    /// Per row and block of `BLOCK` columns: a unit axis (f32) and a radius bounding
    /// `|d - axis|` for the block's beams `d` (rounding included).
    blocks: Vec<[f32; 4]>,
    /// Per beam: the best range and triangle so far.
    best_t: Vec<f64>,
    best_tri: Vec<u32>,
}

impl BeamCaster {
    /// A caster for the beams `dirs` (row-major, `rows x columns`) of a sensor whose column
    /// `c` has azimuth `pi * (1 - 2 (c + 0.5) / columns)` and whose rows have strictly
    /// descending elevations (see [`crate::sensor::Sensor`]).
    pub fn new(dirs: &[DVec3], rows: usize, columns: usize) -> BeamCaster {
        assert_eq!(dirs.len(), rows * columns, "beam grid size");
        // The bounds below rely on this grid layout (a sensor's `beam_dirs`).
        assert!(columns >= 8, "the beam caster needs at least 8 columns, got {columns}");
        for r in 0..rows {
            let z = dirs[r * columns].z;
            assert!(r == 0 || z < dirs[(r - 1) * columns].z, "rows must descend strictly in elevation (row {r})");
            for c in 0..columns {
                let d = dirs[r * columns + c];
                let az = std::f64::consts::PI * (1.0 - 2.0 * (c as f64 + 0.5) / columns as f64);
                let dz = (d.z - z).abs();
                let daz = crate::geometry::wrap_pi(d.y.atan2(d.x) - az);
                assert!(dz <= 1e-12 && daz.abs() <= 1e-9, "beam ({r}, {c}) is off the sensor's grid");
            }
        }
        let row_sin: Vec<f32> = (0..rows).map(|r| dirs[r * columns].z as f32).collect();
        let gap_table = gap_table(&row_sin, columns);
        BeamCaster {
            rows,
            columns,
            pre: dirs.iter().map(|&d| RayPre::new(d)).collect(),
            row_sin,
            cell: Vec::new(),
            us: Vec::new(),
            gap_table,
            jobs: Vec::new(),
            bound_jobs: Vec::new(),
            spans: Vec::new(),
            dir32: dirs.iter().map(|d| d.as_vec3().to_array()).collect(),
            blocks: beam_blocks(dirs, rows, columns),
            best_t: Vec::new(),
            best_tri: Vec::new(),
        }
    }

    /// Number of beams.
    pub fn len(&self) -> usize {
        self.rows * self.columns
    }

    /// True for an empty grid.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The first hit of every beam within `max_range_m` over all meshes of `geom` (sensor
    /// frame), written to `out` (row-major); equal bit for bit to `cast_brute_force`.
    pub fn cast(&mut self, geom: &FrameGeometry, max_range_m: f64, out: &mut Vec<Hit>) {
        let n = self.len();
        self.best_t.clear();
        self.best_t.resize(n, max_range_m);
        self.best_tri.clear();
        self.best_tri.resize(n, u32::MAX);
        out.clear();
        if !(max_range_m > 0.0) || geom.meshes.is_empty() {
            out.resize(n, Hit::NONE);
            return;
        }
        self.project(geom);
        let margin_u = azimuth_margin_columns(self.columns);
        // Triangle jobs: (mesh, first triangle, end, row band), so each job has one cull
        // flag. Few triangles (a room of large walls) are split by rows instead, so that
        // every core gets work.
        let chunks: usize = geom.meshes.iter().map(|m| (m.triangle_count as usize).div_ceil(JOB_TRIANGLES)).sum();
        let bands = (MIN_JOBS / chunks.max(1)).clamp(1, self.rows.max(1));
        let mut spans = std::mem::take(&mut self.spans);
        spans.clear();
        for (k, m) in geom.meshes.iter().enumerate() {
            let end = m.first_triangle as usize + m.triangle_count as usize;
            let mut s = m.first_triangle as usize;
            while s < end {
                let e = (s + JOB_TRIANGLES).min(end);
                for b in 0..bands {
                    spans.push((k, s, e, b * self.rows / bands, (b + 1) * self.rows / bands));
                }
                s = e;
            }
        }
        let mut jobs = std::mem::take(&mut self.jobs);
        if jobs.len() < spans.len() {
            jobs.resize_with(spans.len(), Vec::new);
        }
        let grid = self.grid(margin_u, max_range_m);
        jobs[..spans.len()].par_iter_mut().zip(spans.par_iter()).for_each(|(hits, &(k, s, e, r0, r1))| {
            hits.clear();
            let cull = !geom.meshes[k].double_sided;
            for t in s..e {
                if grid.quick_skip(geom, t) {
                    continue;
                }
                grid.triangle(geom, t as u32, cull, (r0, r1), hits);
            }
        });
        for hits in &jobs[..spans.len()] {
            for &(b, t, tri) in hits {
                let b = b as usize;
                if better(t, tri, self.best_t[b], self.best_tri[b]) {
                    self.best_t[b] = t;
                    self.best_tri[b] = tri;
                }
            }
        }
        out.extend(self.best_t.iter().zip(&self.best_tri).map(|(&t, &tri)| Hit::from_best(t, tri)));
        self.spans = spans;
        self.jobs = jobs;
    }

    /// The projection pass: per vertex its column cell, row gap, `u` and `sin(elevation)`
    /// (`cell`, `us`).
    fn project(&mut self, geom: &FrameGeometry) {
        let w = self.columns as f32;
        let col_per_rad = w / (2.0 * PI32);
        let margin_u = azimuth_margin_columns(self.columns);
        self.cell.resize(geom.positions.len(), [0; 2]);
        self.us.resize(geom.positions.len(), [0.0; 2]);
        let gaps = &self.gap_table;
        self.cell
            .par_chunks_mut(JOB_VERTICES)
            .zip(self.us.par_chunks_mut(JOB_VERTICES))
            .zip(geom.positions.par_chunks(JOB_VERTICES))
            .for_each(|((cell, us), pos)| {
                // Four vertices at a time in SIMD lanes, the rest one by one.
                let n4 = pos.len() / 4 * 4;
                for ((k, us), p) in cell[..n4].chunks_exact_mut(4).zip(us[..n4].chunks_exact_mut(4)).zip(pos[..n4].chunks_exact(4)) {
                    vertex_cells_x4(p, w, col_per_rad, margin_u, gaps, k, us);
                }
                for ((k, us), p) in cell[n4..].iter_mut().zip(us[n4..].iter_mut()).zip(&pos[n4..]) {
                    (*k, *us) = vertex_cells(*p, w, col_per_rad, margin_u, gaps);
                }
            });
    }

    /// Every triangle of `geom` (sensor frame) that some beam may hit, with its conservative
    /// bound in the grid (the bound [`BeamCaster::cast`] tests), in triangle order, into
    /// `out`. A beam outside its triangle's bound cannot hit it; a triangle not listed is hit
    /// by no beam. The raster backend draws these bounds and tests the beams on the device.
    pub fn bounds(&mut self, geom: &FrameGeometry, out: &mut Vec<GridBound>) {
        out.clear();
        if geom.meshes.is_empty() {
            return;
        }
        self.project(geom);
        let margin_u = azimuth_margin_columns(self.columns);
        // Jobs of JOB_TRIANGLES triangles of one mesh, each into its own reused list.
        let mut spans = std::mem::take(&mut self.spans);
        spans.clear();
        for (k, m) in geom.meshes.iter().enumerate() {
            let end = m.first_triangle as usize + m.triangle_count as usize;
            spans.extend((m.first_triangle as usize..end).step_by(JOB_TRIANGLES).map(|s| (k, s, (s + JOB_TRIANGLES).min(end), 0, 0)));
        }
        let mut parts = std::mem::take(&mut self.bound_jobs);
        if parts.len() < spans.len() {
            parts.resize_with(spans.len(), Vec::new);
        }
        let grid = self.grid(margin_u, f64::MAX);
        parts[..spans.len()].par_iter_mut().zip(spans.par_iter()).for_each(|(v, &(_, s, e, _, _))| {
            v.clear();
            for t in s..e {
                if grid.quick_skip(geom, t) {
                    continue;
                }
                if let Some((c0, c1, r0, r1)) = grid.bound(geom, t as u32) {
                    v.push(GridBound { triangle: t as u32, c0, c1, r0: r0 as u32, r1: r1 as u32 });
                }
            }
        });
        for p in &parts[..spans.len()] {
            out.extend_from_slice(p);
        }
        self.bound_jobs = parts;
        self.spans = spans;
    }

    /// The hits (beam, range, triangle) of the beams inside each of `bounds`, from the
    /// [`BeamCaster::bounds`] of the same `geom` just before (its projection pass is reused),
    /// into `hits`: what [`BeamCaster::cast`] finds for those triangles.
    pub fn cast_bounds(&self, geom: &FrameGeometry, bounds: &[GridBound], hits: &mut Vec<(u32, f64, u32)>) {
        hits.clear();
        let grid = self.grid(azimuth_margin_columns(self.columns), f64::MAX);
        let mut mesh = 0;
        for g in bounds {
            while geom.meshes[mesh].first_triangle + geom.meshes[mesh].triangle_count <= g.triangle {
                mesh += 1;
            }
            grid.triangle(geom, g.triangle, !geom.meshes[mesh].double_sided, (0, self.rows), hits);
        }
    }

    /// The watertight ray constants of beam `b` (`None`: a degenerate direction).
    pub(crate) fn ray_pre(&self, b: usize) -> Option<&RayPre> {
        self.pre[b].as_ref()
    }

    /// Beam `b`'s direction in f32, as the conservative pre-test uses it.
    pub fn dir32(&self, b: usize) -> [f32; 3] {
        self.dir32[b]
    }

    /// Rows and columns of the grid.
    pub fn shape(&self) -> (usize, usize) {
        (self.rows, self.columns)
    }

    fn grid(&self, margin_u: f32, max_range_m: f64) -> Grid<'_> {
        Grid {
            rows: self.rows,
            columns: self.columns,
            row_sin: &self.row_sin,
            pre: &self.pre,
            dir32: &self.dir32,
            blocks: &self.blocks,
            blocks_per_row: self.columns.div_ceil(BLOCK),
            cell: &self.cell,
            us: &self.us,
            margin_u,
            max_range_m,
        }
    }
}

/// Column code of a vertex without an azimuth: odd (never "clear of the cell edges") and
/// below every real code.
const NO_CELL: i32 = i32::MIN + 1;

/// Columns per block of the wide-span pre-test.
const BLOCK: usize = 8;

/// The blocks of a beam grid (see `BeamCaster::blocks`).
fn beam_blocks(dirs: &[DVec3], rows: usize, columns: usize) -> Vec<[f32; 4]> {
    let mut v = Vec::new();
    for r in 0..rows {
        for first in (0..columns).step_by(BLOCK) {
            let beams = &dirs[r * columns + first..r * columns + (first + BLOCK).min(columns)];
            let axis = beams.iter().copied().sum::<DVec3>().normalize();
            let axis32 = axis.as_vec3();
            // Measured from the f32 axis to the f32 directions the pre-test uses, widened for
            // the f32 dot products.
            let radius = beams.iter().map(|d| (d.as_vec3() - axis32).as_dvec3().length()).fold(0.0f64, f64::max);
            v.push([axis32.x, axis32.y, axis32.z, (radius * (1.0 + 1e-5) + 1e-6) as f32]);
        }
    }
    v
}

/// Bins of the row-gap table.
const GAP_BINS: usize = 8192;

/// The row-gap table of a grid (see `BeamCaster::gap_table`).
fn gap_table(row_sin: &[f32], columns: usize) -> Vec<i32> {
    let rows = row_sin.len();
    // Largest angle between two vertices in one bounded gap and within two column cells,
    // and the furthest a side between them can bulge in sin(elevation): |z| (1/cos(t/2) - 1).
    let el: Vec<f64> = row_sin.iter().map(|&s| (s as f64).clamp(-1.0, 1.0).asin()).collect();
    let gap_el = el.windows(2).map(|w| w[0] - w[1]).fold(0.0f64, f64::max);
    // Vertices in neighbouring cells are at most 2 cells (plus the margin) apart in azimuth.
    let cells = 2.0 + 2.0 * azimuth_margin_columns(columns) as f64;
    let theta = gap_el + cells * std::f64::consts::TAU / columns as f64;
    let margin = (1.0 / (0.5 * theta).cos() - 1.0) * 1.01 + 2.0 * SIN_MARGIN as f64 + 1e-6;
    let bin = 2.0 / GAP_BINS as f64;
    (0..GAP_BINS)
        .map(|k| {
            let lo = -1.0 + k as f64 * bin - margin;
            let hi = -1.0 + (k + 1) as f64 * bin + margin;
            // Rows strictly above the widened bin, and rows at or above its bottom.
            let above = row_sin.iter().filter(|&&s| s as f64 > hi).count();
            let reach = row_sin.iter().filter(|&&s| s as f64 >= lo).count();
            let usable = match above {
                0 => rows > 0 && row_sin[0] >= 0.0,
                g if g == rows => row_sin[rows - 1] <= 0.0,
                _ => true,
            };
            if above == reach && usable {
                above as i32
            } else {
                i32::MIN
            }
        })
        .collect()
}

/// `floor(x)` as an integer without a libm call (|x| < 2^31; NaN gives 0).
#[inline(always)]
fn floor_i(x: f32) -> i32 {
    let i = x as i32;
    if (i as f32) > x {
        i - 1
    } else {
        i
    }
}

/// `ceil(x)` as an integer (see `floor_i`).
#[inline(always)]
fn ceil_i(x: f32) -> i32 {
    let i = x as i32;
    if (i as f32) < x {
        i + 1
    } else {
        i
    }
}

/// Margin on column coordinates: the azimuth error bound plus the f32 rounding of `u`.
fn azimuth_margin_columns(columns: usize) -> f32 {
    let w = columns as f32;
    AZIMUTH_MARGIN_RAD * w / (2.0 * PI32) + 2.0 * w * f32::EPSILON * 4.0
}

/// The column cell and row gap of a vertex (see `BeamCaster::cell`) and its `u` and
/// `sin(elevation)`, without branches; `NO_CELL` / `i32::MIN` where the vertex is non-finite,
/// at the origin or on the z axis.
#[inline(always)]
fn vertex_cells(p: [f32; 3], w: f32, col_per_rad: f32, margin_u: f32, gaps: &[i32]) -> ([i32; 2], [f32; 2]) {
    let [x, y, z] = p;
    let rxy2 = x * x + y * y;
    let r2 = rxy2 + z * z;
    // False for NaN and infinities too.
    let valid = r2 > 1e-30 && r2 < 1e30 && rxy2 > 1e-12 * r2;
    let u = 0.5 * w - 0.5 - atan2_fast(y, x) * col_per_rad;
    let lo = floor_i(u - margin_u);
    let near_edge = (lo != floor_i(u + margin_u)) as i32;
    let col = if valid { 2 * floor_i(u) + near_edge } else { NO_CELL };
    let s = z / r2.sqrt();
    let bin = floor_i((s + 1.0) * (0.5 * GAP_BINS as f32)).clamp(0, GAP_BINS as i32 - 1);
    let gap = if valid { gaps[bin as usize] } else { i32::MIN };
    ([col, gap], [u, s])
}

/// `vertex_cells` for four vertices in SIMD lanes (same bounds; the lanes may round
/// differently from the scalar form, which is harmless: both are conservative).
#[inline(always)]
fn vertex_cells_x4(
    p: &[[f32; 3]],
    w: f32,
    col_per_rad: f32,
    margin_u: f32,
    gaps: &[i32],
    cell: &mut [[i32; 2]],
    us: &mut [[f32; 2]],
) {
    use glam::Vec4;
    let x = Vec4::new(p[0][0], p[1][0], p[2][0], p[3][0]);
    let y = Vec4::new(p[0][1], p[1][1], p[2][1], p[3][1]);
    let z = Vec4::new(p[0][2], p[1][2], p[2][2], p[3][2]);
    let rxy2 = x * x + y * y;
    let r2 = rxy2 + z * z;
    let valid = (r2.cmpgt(Vec4::splat(1e-30)) & r2.cmplt(Vec4::splat(1e30)) & rxy2.cmpgt(r2 * 1e-12)).bitmask();
    // atan2 as in `atan2_fast`.
    let (ax, ay) = (x.abs(), y.abs());
    let a = ax.min(ay) / ax.max(ay);
    let s2 = a * a;
    let mut r = ((((0.020_835_1 * s2 - 0.085_133) * s2 + 0.180_141) * s2 - 0.330_299_5) * s2 + 0.999_866) * a;
    r = Vec4::select(ay.cmpgt(ax), Vec4::splat(0.5 * PI32) - r, r);
    r = Vec4::select(x.cmplt(Vec4::ZERO), Vec4::splat(PI32) - r, r);
    r = Vec4::select(y.cmplt(Vec4::ZERO), -r, r);
    let u = Vec4::splat(0.5 * w - 0.5) - r * col_per_rad;
    let lo = (u - Vec4::splat(margin_u)).floor().to_array();
    let hi = (u + Vec4::splat(margin_u)).floor().to_array();
    let fl = u.floor().to_array();
    let s = z / r2.sqrt();
    let bin = ((s + 1.0) * (0.5 * GAP_BINS as f32)).floor().to_array();
    let (u, s) = (u.to_array(), s.to_array());
    for k in 0..4 {
        let ok = valid & (1 << k) != 0;
        let near_edge = (lo[k] != hi[k]) as i32;
        let b = (bin[k] as i32).clamp(0, GAP_BINS as i32 - 1);
        cell[k] = if ok { [2 * fl[k] as i32 + near_edge, gaps[b as usize]] } else { [NO_CELL, i32::MIN] };
        us[k] = [u[k], s[k]];
    }
}

/// The grid as seen by one triangle job.
struct Grid<'a> {
    rows: usize,
    columns: usize,
    row_sin: &'a [f32],
    pre: &'a [Option<RayPre>],
    dir32: &'a [[f32; 3]],
    blocks: &'a [[f32; 4]],
    blocks_per_row: usize,
    cell: &'a [[i32; 2]],
    us: &'a [[f32; 2]],
    margin_u: f32,
    max_range_m: f64,
}

impl Grid<'_> {
    /// True when triangle `t` is certainly hit by no beam, from its vertices' cells alone: all
    /// three azimuths inside one column cell, clear of its edges (an odd code marks a vertex
    /// near a cell edge, or without azimuth); or all three in one row gap, in two neighbouring
    /// column cells (so the sides cannot bulge by more than the gap margin). Evaluated without
    /// short circuits: one well-predicted branch per triangle.
    #[inline(always)]
    fn quick_skip(&self, geom: &FrameGeometry, t: usize) -> bool {
        let cell = self.cell;
        let i = &geom.indices[3 * t..3 * t + 3];
        let (k0, k1, k2) = (cell[i[0] as usize], cell[i[1] as usize], cell[i[2] as usize]);
        let same_col = (k0[0] & 1 == 0) & (k0[0] == k1[0]) & (k0[0] == k2[0]);
        let same_gap = (k0[1] != i32::MIN) & (k0[1] == k1[1]) & (k0[1] == k2[1]);
        let lo = k0[0].min(k1[0]).min(k2[0]);
        let hi = k0[0].max(k1[0]).max(k2[0]);
        let neighbours = (lo != NO_CELL) & ((hi >> 1) - (lo >> 1) <= 1);
        same_col | (same_gap & neighbours)
    }

    /// The conservative bound of triangle `t` in the grid: columns `c0..=c1` (to be wrapped
    /// with `rem_euclid(columns)`), rows `r0..r1`; `None` when no beam can hit it (or a vertex
    /// is not finite: such a triangle never hits).
    #[inline(always)]
    fn bound(&self, geom: &FrameGeometry, t: u32) -> Option<(i64, i64, usize, usize)> {
        let i = &geom.indices[3 * t as usize..3 * t as usize + 3];
        let w = self.columns as f32;
        let pos = &geom.positions;
        let p = [0, 1, 2].map(|k| pos[i[k] as usize]);
        // Non-finite vertices never hit.
        if !p.iter().all(|v| v.iter().all(|c| c.is_finite())) {
            return None;
        }
        // (u, sin el), u = NaN where the azimuth is undefined.
        let [a, b, c] = [0, 1, 2].map(|k| {
            let v = i[k] as usize;
            let us = self.us[v];
            [us[1], if self.cell[v][0] == NO_CELL { f32::NAN } else { us[0] }]
        });
        // Columns: the shortest arc holding the three azimuths. `surround`: the triangle
        // surrounds or touches the z axis (a pole may lie inside its projection).
        let surround;
        let (c0, c1) = if a[1].is_nan() || b[1].is_nan() || c[1].is_nan() {
            surround = true;
            (0, self.columns as i64 - 1)
        } else {
            let (mut u0, mut u1, mut u2) = (a[1], b[1], c[1]);
            let mut lo = u0.min(u1).min(u2);
            let mut hi = u0.max(u1).max(u2);
            if hi - lo > 0.5 * w {
                // Across the column-0 edge: move the low side up by a turn.
                let half = 0.5 * w - 0.5;
                for u in [&mut u0, &mut u1, &mut u2] {
                    if *u < half {
                        *u += w;
                    }
                }
                lo = u0.min(u1).min(u2);
                hi = u0.max(u1).max(u2);
            }
            surround = hi - lo > 0.25 * w;
            if surround {
                (0, self.columns as i64 - 1)
            } else {
                let c0 = ceil_i(lo - self.margin_u);
                let c1 = floor_i(hi + self.margin_u);
                if c0 > c1 {
                    return None;
                }
                (c0 as i64, c1 as i64)
            }
        };
        // Rows: sin(elevation) over the sides, stretched by the longest chord.
        let c2 = if surround {
            4.0
        } else {
            let [ua, ub, uc] = p.map(|v| glam::Vec3::from(v).normalize());
            ua.distance_squared(ub).max(ub.distance_squared(uc)).max(uc.distance_squared(ua))
        };
        let (r0, r1) = if c2 >= 1.9 {
            (0, self.rows)
        } else {
            // 1 / cos(theta / 2) with cos(theta / 2) = sqrt(1 - c^2 / 4), rounded up.
            let k = (1.0 / (1.0 - 0.25 * c2).sqrt()) * (1.0 + 4.0 * f32::EPSILON);
            let zmax = a[0].max(b[0]).max(c[0]);
            let zmin = a[0].min(b[0]).min(c[0]);
            let hi = if zmax > 0.0 { zmax * k } else { zmax } + SIN_MARGIN;
            let lo = if zmin < 0.0 { zmin * k } else { zmin } - SIN_MARGIN;
            // Rows are sorted by descending sin: the first row at or below `hi` ...
            let r0 = self.row_sin.partition_point(|&s| s > hi);
            // ... to the last row at or above `lo`.
            let r1 = self.row_sin.partition_point(|&s| s >= lo);
            (r0, r1)
        };
        (r0 < r1).then_some((c0, c1, r0, r1))
    }

    /// Bounds triangle `t` in the grid and tests the beams inside the bound.
    #[inline(always)]
    fn triangle(
        &self,
        geom: &FrameGeometry,
        t: u32,
        cull: bool,
        band: (usize, usize),
        hits: &mut Vec<(u32, f64, u32)>,
    ) {
        let Some((c0, c1, r0, r1)) = self.bound(geom, t) else { return };
        let i = &geom.indices[3 * t as usize..3 * t as usize + 3];
        let pos = &geom.positions;
        let (r0, r1) = (r0.max(band.0), r1.min(band.1));
        if r0 >= r1 {
            return;
        }
        let tri = [
            DVec3::from(pos[i[0] as usize].map(f64::from)),
            DVec3::from(pos[i[1] as usize].map(f64::from)),
            DVec3::from(pos[i[2] as usize].map(f64::from)),
        ];
        // Edge planes through the origin: a beam strictly outside one of them and strictly
        // inside another is outside the triangle. The tolerance is far above the rounding of
        // these f32 products; where the exact test's own rounding is larger (a plane through
        // two nearly parallel vertices), the other two planes nearly coincide with opposite
        // normals, so a beam the exact test hits sets neither flag from them, and one plane
        // alone never drops a beam.
        let edge = |p: DVec3, q: DVec3| {
            let n = p.cross(q).as_vec3();
            (n, 1e-6 * (n.x.abs() + n.y.abs() + n.z.abs()) + 1e-30)
        };
        let planes = [edge(tri[0], tri[1]), edge(tri[1], tri[2]), edge(tri[2], tri[0])];
        let n = self.columns as i64;
        // Wide spans go block by block (BLOCK columns of a row): a block whose beams are all
        // strictly outside one edge plane and strictly inside another is skipped whole.
        // |n . d - n . axis| <= |n| |d - axis| <= |n| radius for every beam d of the block.
        let blocked = c1 - c0 >= 2 * BLOCK as i64;
        let norms = planes.map(|(nrm, _)| nrm.length() * (1.0 + 1e-6));
        for r in r0..r1 {
            let row = r * self.columns;
            let mut c = c0;
            while c <= c1 {
                let cw = c.rem_euclid(n);
                let block = cw as usize / BLOCK;
                let end = c + ((block * BLOCK + BLOCK - 1).min(self.columns - 1) as i64 - cw);
                let end = if blocked { end.min(c1) } else { c1 };
                if blocked {
                    let [ax, ay, az, radius] = self.blocks[r * self.blocks_per_row + block];
                    let axis = glam::Vec3::new(ax, ay, az);
                    let mut out = false;
                    let mut inside = false;
                    for ((nrm, tol), len) in planes.iter().zip(norms) {
                        let e = nrm.dot(axis);
                        let spread = len * radius;
                        out |= e + spread < -tol;
                        inside |= e - spread > *tol;
                    }
                    if out && inside {
                        c = end + 1;
                        continue;
                    }
                }
                for c in c..=end {
                    let b = row + c.rem_euclid(n) as usize;
                    let d = glam::Vec3::from(self.dir32[b]);
                    let mut out = false;
                    let mut inside = false;
                    for (nrm, tol) in &planes {
                        let e = nrm.dot(d);
                        out |= e < -tol;
                        inside |= e > *tol;
                    }
                    if out && inside {
                        continue;
                    }
                    let Some(pre) = &self.pre[b] else { continue };
                    if let Some(range) = intersect_pre(pre, &tri, cull) {
                        if range <= self.max_range_m {
                            hits.push((b as u32, range, t));
                        }
                    }
                }
                c = end + 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::FrameGeometry;
    use crate::backend::raycast::cast_brute_force;
    use crate::sensor::Sensor;

    #[test]
    fn atan2_fast_error_is_below_its_bound() {
        let mut worst = 0.0f64;
        let n = 200_000;
        for k in 0..n {
            let a = -std::f64::consts::PI + 2.0 * std::f64::consts::PI * (k as f64 + 0.37) / n as f64;
            for r in [1e-3f64, 1.0, 37.0] {
                let (y, x) = ((r * a.sin()) as f32, (r * a.cos()) as f32);
                let exact = (y as f64).atan2(x as f64);
                let mut d = (atan2_fast(y, x) as f64 - exact).abs();
                d = d.min((d - 2.0 * std::f64::consts::PI).abs());
                worst = worst.max(d);
            }
        }
        // A denser sweep's maximum is 1.17e-5; the margin is built on that.
        assert!(worst < 1.2e-5, "atan2_fast error {worst:e}");
        assert!(worst > 1e-7, "the test must measure the polynomial's error ({worst:e})");
        assert!((AZIMUTH_MARGIN_RAD as f64) > 3.0 * worst);
    }

    use crate::backend::raycast::test_support::Rng;

    fn f32v(v: DVec3) -> [f32; 3] {
        [v.x as f32, v.y as f32, v.z as f32]
    }

    /// A closed, outward-facing UV sphere (front faces counter-clockwise from outside).
    fn sphere(centre: DVec3, radius: f64, rings: usize, segments: usize) -> (Vec<[f32; 3]>, Vec<u32>) {
        let mut v = vec![f32v(centre + DVec3::Z * radius)];
        for i in 1..rings {
            let th = std::f64::consts::PI * i as f64 / rings as f64;
            for j in 0..segments {
                let ph = 2.0 * std::f64::consts::PI * j as f64 / segments as f64;
                v.push(f32v(centre + radius * DVec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos())));
            }
        }
        v.push(f32v(centre - DVec3::Z * radius));
        let s = segments as u32;
        let ring = |i: u32, j: u32| 1 + (i - 1) * s + j % s;
        let mut idx = Vec::new();
        for j in 0..s {
            idx.extend([0, ring(1, j), ring(1, j + 1)]);
        }
        for i in 1..rings as u32 - 1 {
            for j in 0..s {
                idx.extend([ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)]);
                idx.extend([ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)]);
            }
        }
        let last = v.len() as u32 - 1;
        for j in 0..s {
            idx.extend([last, ring(rings as u32 - 1, j + 1), ring(rings as u32 - 1, j)]);
        }
        (v, idx)
    }

    fn check_equal(sensor: &Sensor, geom: &FrameGeometry, max_range: f64) -> usize {
        let dirs = sensor.beam_dirs();
        let reference = cast_brute_force(geom, &dirs, max_range, |_| true);
        let mut caster = BeamCaster::new(&dirs, sensor.rows(), sensor.columns);
        let mut got = Vec::new();
        caster.cast(geom, max_range, &mut got);
        let mut hits = 0;
        for (b, (g, r)) in got.iter().zip(&reference).enumerate() {
            assert_eq!(g.triangle, r.triangle, "beam {b} (row {}, col {})", b / sensor.columns, b % sensor.columns);
            assert_eq!(g.range_m.to_bits(), r.range_m.to_bits(), "beam {b}");
            hits += r.is_hit() as usize;
        }
        // Casting again reuses the buffers and gives the same.
        let mut again = Vec::new();
        caster.cast(geom, max_range, &mut again);
        assert_eq!(again, got);
        check_bounds(&mut caster, sensor, geom);
        hits
    }

    /// Every beam that hits a triangle at all (not only the nearest hit) lies in the bound
    /// `BeamCaster::bounds` lists for that triangle; the list is in triangle order.
    fn check_bounds(caster: &mut BeamCaster, sensor: &Sensor, geom: &FrameGeometry) {
        let dirs = sensor.beam_dirs();
        let mut bounds = Vec::new();
        caster.bounds(geom, &mut bounds);
        assert!(bounds.windows(2).all(|w| w[0].triangle < w[1].triangle), "bounds in triangle order");
        let n = sensor.columns as i64;
        let mut checked = 0;
        for m in &geom.meshes {
            for t in m.first_triangle..m.first_triangle + m.triangle_count {
                let tri = geom.triangle_f64(t);
                let bound = bounds.iter().find(|g| g.triangle == t);
                for (b, d) in dirs.iter().enumerate() {
                    if crate::backend::triangle::intersect_triangle(*d, &tri, !m.double_sided).is_none() {
                        continue;
                    }
                    checked += 1;
                    let (row, col) = ((b / sensor.columns) as u32, (b % sensor.columns) as i64);
                    let g = bound.unwrap_or_else(|| panic!("triangle {t} is hit by beam {b} but has no bound"));
                    let inside = g.r0 <= row && row < g.r1 && (col - g.c0).rem_euclid(n) <= g.c1 - g.c0;
                    assert!(inside, "beam {b} (row {row}, col {col}) hits triangle {t} outside its bound {g:?}");
                }
            }
        }
        assert!(checked > 0 || geom.meshes.is_empty() || bounds.is_empty());
    }

    fn small_sensor(columns: usize) -> Sensor {
        Sensor { columns, ..Sensor::hdl32e() }
    }

    #[test]
    fn closed_spheres_all_around_equal_brute_force() {
        // Spheres near and far, across the column-0 edge (behind the sensor, -x), above and
        // below the beam band, one straddling the z axis above the sensor.
        let mut geom = FrameGeometry::default();
        let mut rng = Rng(7);
        for k in 0..24 {
            let az = rng.range(-3.2, 3.2);
            let d = rng.range(0.6, 30.0);
            let centre = DVec3::new(d * az.cos(), d * az.sin(), rng.range(-6.0, 3.0));
            let (v, i) = sphere(centre, rng.range(0.05, 1.5), 12, 24);
            geom.push_mesh(&v, &i, k + 1, k % 5 == 0);
        }
        let behind = sphere(DVec3::new(-4.0, 0.0, -0.5), 0.7, 10, 20);
        geom.push_mesh(&behind.0, &behind.1, 30, false);
        let above = sphere(DVec3::new(0.05, -0.02, 2.5), 0.6, 10, 20);
        geom.push_mesh(&above.0, &above.1, 31, true);
        let hits = check_equal(&small_sensor(512), &geom, 100.0);
        assert!(hits > 1000, "{hits} hits: the scene must cover many beams");
    }

    #[test]
    fn large_and_awkward_triangles_equal_brute_force() {
        let mut geom = FrameGeometry::default();
        let mut rng = Rng(11);
        // Random large triangles (up to tens of metres, many crossing the wrap or the axis).
        let mut v = Vec::new();
        let mut i = Vec::new();
        for _ in 0..300 {
            let base = v.len() as u32;
            for _ in 0..3 {
                v.push([rng.range(-20.0, 20.0) as f32, rng.range(-20.0, 20.0) as f32, rng.range(-8.0, 8.0) as f32]);
            }
            i.extend([base, base + 1, base + 2]);
        }
        geom.push_mesh(&v, &i, 0, true);
        // A floor and a ceiling quad around the sensor (the axis passes through them), a
        // wall exactly behind the sensor (on the column-0 edge), degenerate and non-finite
        // triangles, a vertex at the origin and one on the z axis.
        let quads: [[[f32; 3]; 4]; 3] = [
            [[-30.0, -30.0, -1.8], [30.0, -30.0, -1.8], [30.0, 30.0, -1.8], [-30.0, 30.0, -1.8]],
            [[-30.0, -30.0, 3.0], [-30.0, 30.0, 3.0], [30.0, 30.0, 3.0], [30.0, -30.0, 3.0]],
            [[-5.0, 2.0, -3.0], [-5.0, -2.0, -3.0], [-5.0, -2.0, 2.0], [-5.0, 2.0, 2.0]],
        ];
        for q in quads {
            geom.push_mesh(&q, &[0, 1, 2, 0, 2, 3], 0, false);
        }
        let odd: Vec<[f32; 3]> = vec![
            [1.0, 1.0, 0.0],
            [2.0, 2.0, 0.0],
            [3.0, 3.0, 0.0], // collinear
            [0.0, 0.0, 0.0],
            [5.0, 1.0, -1.0],
            [5.0, -1.0, 1.0], // vertex at the origin
            [0.0, 0.0, 1.0],
            [4.0, 1.0, 0.5],
            [4.0, -1.0, 0.5], // vertex on the z axis
            [f32::NAN, 1.0, 0.0],
            [3.0, 0.0, 0.0],
            [3.0, 1.0, 1.0], // NaN
            [2e16, -3e16, -1e16],
            [2e16, 3e16, -1e16],
            [2e16, 0.0, 1e16], // all three too far for an azimuth cell (> 1e15 m)
        ];
        geom.push_mesh(&odd, &(0..15).collect::<Vec<u32>>(), 0, true);
        let hits = check_equal(&small_sensor(256), &geom, 100.0);
        assert!(hits > 4000, "{hits} hits");
        // A short max range keeps ties with the reference's `<=` rule; an unlimited one
        // reaches the far triangle.
        check_equal(&small_sensor(256), &geom, 4.0);
        check_equal(&small_sensor(256), &geom, f64::MAX);
        // The far triangle alone (its vertices have no azimuth cell).
        let mut far = FrameGeometry::default();
        far.push_mesh(&odd[12..15], &[0, 1, 2], 0, true);
        let hits = check_equal(&small_sensor(256), &far, f64::MAX);
        assert!(hits > 1000, "{hits} hits on the far triangle");
    }

    #[test]
    fn triangles_through_beam_directions_equal_brute_force() {
        // Vertices exactly on beam directions (edges through beams, shared edges and vertices
        // on beams): the bound must not drop a beam on its boundary.
        let sensor = small_sensor(128);
        let dirs = sensor.beam_dirs();
        let mut rng = Rng(3);
        let mut geom = FrameGeometry::default();
        let mut v = Vec::new();
        let mut idx = Vec::new();
        // A fan of triangles whose corners are beams of a 3x3 patch, at one depth: a closed
        // cap of shared edges along beams.
        for _ in 0..40 {
            let r = 1 + (rng.f() * (sensor.rows() - 2) as f64) as usize;
            let c = (rng.f() * sensor.columns as f64) as usize;
            let d = rng.range(2.0, 25.0);
            let at = |dr: i64, dc: i64| {
                let rr = (r as i64 + dr) as usize;
                let cc = (c as i64 + dc).rem_euclid(sensor.columns as i64) as usize;
                f32v(dirs[rr * sensor.columns + cc] * d)
            };
            let base = v.len() as u32;
            v.extend([at(0, 0), at(-1, -1), at(-1, 1), at(1, 1), at(1, -1)]);
            for k in 0..4u32 {
                idx.extend([base, base + 1 + (k + 1) % 4, base + 1 + k]);
            }
        }
        geom.push_mesh(&v, &idx, 1, true);
        let hits = check_equal(&sensor, &geom, 100.0);
        assert!(hits >= 40, "{hits} hits");
    }

    #[test]
    fn wide_triangles_with_corners_on_beams_equal_brute_force() {
        // Triangles tens of columns wide whose corners are beams, many at block ends, so an
        // edge of the triangle passes exactly through the first or last beam of a block.
        let sensor = small_sensor(256);
        let dirs = sensor.beam_dirs();
        let w = sensor.columns;
        let mut rng = Rng(5);
        let mut v = Vec::new();
        let mut idx = Vec::new();
        for k in 0..300u32 {
            let pick_col = |rng: &mut Rng| {
                let m = (rng.f() * (w / BLOCK) as f64) as usize;
                (m * BLOCK + if rng.f() < 0.5 { 0 } else { BLOCK - 1 }) % w
            };
            let c0 = pick_col(&mut rng);
            let c1 = (c0 + 17 + (rng.f() * 40.0) as usize) % w;
            let cm = (c0 + (c1 + w - c0) % w / 2) % w;
            let rows = sensor.rows();
            let r = |rng: &mut Rng| (rng.f() * rows as f64) as usize;
            let (ra, rb, rc) = (r(&mut rng), r(&mut rng), r(&mut rng));
            let depth = rng.range(3.0, 20.0);
            let base = v.len() as u32;
            v.push(f32v(dirs[ra * w + c0] * depth));
            v.push(f32v(dirs[rb * w + cm] * depth * rng.range(0.9, 1.1)));
            v.push(f32v(dirs[rc * w + c1] * depth * rng.range(0.9, 1.1)));
            if k % 2 == 0 {
                idx.extend([base, base + 1, base + 2]);
            } else {
                idx.extend([base, base + 2, base + 1]);
            }
        }
        let mut geom = FrameGeometry::default();
        geom.push_mesh(&v, &idx, 0, true);
        let hits = check_equal(&sensor, &geom, 100.0);
        assert!(hits > 1000, "{hits} hits");
    }

    #[test]
    #[should_panic(expected = "at least 8 columns")]
    fn grids_too_coarse_for_the_bounds_are_refused() {
        // With very few columns two neighbouring cells span most of a turn and the row-gap
        // shortcut would no longer hold.
        let s = small_sensor(4);
        BeamCaster::new(&s.beam_dirs(), s.rows(), s.columns);
    }

    #[test]
    #[should_panic(expected = "off the sensor's grid")]
    fn directions_off_the_grid_are_refused() {
        let s = small_sensor(64);
        let mut dirs = s.beam_dirs();
        dirs[70] = DVec3::new(1.0, 0.0, 0.0);
        BeamCaster::new(&dirs, s.rows(), s.columns);
    }
}
