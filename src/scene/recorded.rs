//! Where people may walk in a recorded background.
//!
//! The floor height is estimated per window (or set by `scene.floor_z_m`): the most
//! populated 5 cm height bin of the window's returns below the sensor, refined by the median
//! of the returns within 5 cm of it. The walkable area is a 10 cm grid: cells with a floor
//! return, grown by 1 m to bridge the gaps between rings, minus cells with a return between
//! 25 cm and 2 m above the floor (anything standing there at any frame of the window, moving
//! objects included), largest connected region only.

use super::{WalkableGrid, WALKABLE_CELL_M};
use crate::error::{Error, Result};
use crate::input::Recording;
use glam::{DVec2, DVec3};

/// Floor height (world z) and walkable area of the recording's window `frames`, from its
/// returns. `floor_z` overrides the estimate.
pub fn walkable(rec: &Recording, frames: std::ops::Range<usize>, floor_z: Option<f64>) -> Result<(f64, WalkableGrid)> {
    let pts = rec.window_points(frames.clone())?;
    let name = || rec.window_name(frames.clone());
    let floor = match floor_z {
        Some(z) => z,
        None => estimate_floor(&pts)
            .ok_or_else(|| Error::input(name(), "cannot find the floor: no returns below the sensor; set scene.floor_z_m"))?,
    };
    let grid = walkable_from_points(&pts, floor, WALKABLE_CELL_M).map_err(|m| Error::input(name(), m))?;
    Ok((floor, grid))
}

/// Horizontal distances (m) of the returns used for the floor.
const FLOOR_RING_M: [f64; 2] = [1.0, 30.0];
/// Heights above the floor that block a cell, m.
const BLOCK_Z_M: [f64; 2] = [0.25, 2.0];
/// Floor returns count within this height of the floor, m.
const FLOOR_TOLERANCE_M: f64 = 0.1;
/// Floor cells are grown by this much to bridge the gaps between rings, m.
const FLOOR_GROW_M: f64 = 1.0;

/// The floor: the most populated 5 cm bin of the returns at least 30 cm below their sensor,
/// refined to the median of the returns within 5 cm of it. The bins are counted along the
/// sorted heights, so memory follows the number of returns, never their height range.
pub fn estimate_floor(pts: &[(DVec3, DVec3)]) -> Option<f64> {
    let mut below: Vec<f64> = pts
        .iter()
        .filter(|(p, o)| {
            let d = (p.truncate() - o.truncate()).length();
            p.z < o.z - 0.3 && d >= FLOOR_RING_M[0] && d <= FLOOR_RING_M[1]
        })
        .map(|(p, _)| p.z)
        .collect();
    if below.len() < 50 {
        return None;
    }
    below.sort_by(f64::total_cmp);
    let lo = below[0];
    let bin = 0.05;
    // (bin, count) of the fullest bin so far; ties go to the lower bin (deterministic).
    let index = |z: f64| ((z - lo) / bin) as u64;
    let mut best = (0u64, 0usize);
    let mut run = (index(lo), 0usize);
    for &z in &below {
        let b = index(z);
        if b != run.0 {
            run = (b, 0);
        }
        run.1 += 1;
        if run.1 > best.1 {
            best = run;
        }
    }
    let centre = lo + (best.0 as f64 + 0.5) * bin;
    let mut near: Vec<f64> = below.into_iter().filter(|z| (z - centre).abs() <= bin).collect();
    near.sort_by(f64::total_cmp);
    Some(near[near.len() / 2])
}

/// Walkable area from world points (see the module docs). The error (the message only): no
/// cell is walkable, or the returns near their sensors span more than a grid may
/// ([`WalkableGrid::dims`]).
pub fn walkable_from_points(pts: &[(DVec3, DVec3)], floor: f64, cell_m: f64) -> Result<WalkableGrid, String> {
    let none = || format!("no walkable floor near z = {floor:.2} m in the recorded returns");
    let mut lo = DVec2::splat(f64::INFINITY);
    let mut hi = DVec2::splat(f64::NEG_INFINITY);
    for (p, o) in pts {
        if (p.truncate() - o.truncate()).length() <= FLOOR_RING_M[1] {
            lo = lo.min(p.truncate());
            hi = hi.max(p.truncate());
        }
    }
    if !lo.is_finite() {
        return Err(none());
    }
    let lo = lo - DVec2::splat(cell_m);
    let (nx, ny) = WalkableGrid::dims(lo, hi + DVec2::splat(cell_m), cell_m)
        .map_err(|m| format!("the returns within {} m of their sensor: {m}", FLOOR_RING_M[1]))?;
    let mut seen = vec![false; nx * ny];
    let mut blocked = vec![false; nx * ny];
    for (p, o) in pts {
        if (p.truncate() - o.truncate()).length() > FLOOR_RING_M[1] {
            continue;
        }
        let q = (p.truncate() - lo) / cell_m;
        let (i, j) = (q.x as usize, q.y as usize);
        if i >= nx || j >= ny {
            continue;
        }
        let h = p.z - floor;
        if h.abs() <= FLOOR_TOLERANCE_M {
            seen[j * nx + i] = true;
        } else if h >= BLOCK_Z_M[0] && h <= BLOCK_Z_M[1] {
            blocked[j * nx + i] = true;
        }
    }
    // Grow the floor cells (a separable square dilation: rows, then columns).
    let g = (FLOOR_GROW_M / cell_m).round() as usize;
    let mut rows = vec![false; nx * ny];
    for j in 0..ny {
        dilate_line(&seen, &mut rows, j * nx, 1, nx, g);
    }
    let mut floor_cells = vec![false; nx * ny];
    for i in 0..nx {
        dilate_line(&rows, &mut floor_cells, i, nx, ny, g);
    }
    if !floor_cells.iter().zip(&blocked).any(|(f, b)| *f && !*b) {
        return Err(none());
    }
    Ok(WalkableGrid::from_cells(lo, cell_m, nx, ny, &floor_cells, blocked))
}

/// Sets `dst` at every cell of the line `first + k * stride` (k < n) within `g` cells of a
/// set cell of `src` on the same line.
fn dilate_line(src: &[bool], dst: &mut [bool], first: usize, stride: usize, n: usize, g: usize) {
    let at = |k: usize| first + k * stride;
    let mut last: Option<usize> = None;
    for k in 0..n {
        if src[at(k)] {
            last = Some(k);
        }
        if last.is_some_and(|l| k - l <= g) {
            dst[at(k)] = true;
        }
    }
    let mut next: Option<usize> = None;
    for k in (0..n).rev() {
        if src[at(k)] {
            next = Some(k);
        }
        if next.is_some_and(|l| l - k <= g) {
            dst[at(k)] = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points of a flat floor at z = -1.7 around a sensor at the origin, with a 1 x 1 m pillar
    /// at (5, 0).
    fn floor_scene() -> Vec<(DVec3, DVec3)> {
        let o = DVec3::ZERO;
        let mut pts = Vec::new();
        for i in -150..150 {
            for j in -150..150 {
                let (x, y) = (i as f64 * 0.1, j as f64 * 0.1);
                pts.push((DVec3::new(x, y, -1.7), o));
            }
        }
        for k in 0..20 {
            for z in 0..10 {
                let (x, y) = (4.5 + k as f64 * 0.05, -0.5 + k as f64 * 0.05);
                pts.push((DVec3::new(x, -0.5, -1.5 + z as f64 * 0.15), o));
                pts.push((DVec3::new(x, 0.5, -1.5 + z as f64 * 0.15), o));
                pts.push((DVec3::new(4.5, y, -1.5 + z as f64 * 0.15), o));
                pts.push((DVec3::new(5.5, y, -1.5 + z as f64 * 0.15), o));
            }
        }
        pts
    }

    #[test]
    fn the_floor_is_found_under_obstacles_and_noise() {
        let mut pts = floor_scene();
        // A few low outliers (multipath) below the floor must not win.
        for k in 0..40 {
            pts.push((DVec3::new(3.0 + k as f64 * 0.1, 2.0, -3.0), DVec3::ZERO));
        }
        let z = estimate_floor(&pts).unwrap();
        assert!((z + 1.7).abs() < 1e-9, "{z}");
    }

    #[test]
    fn the_walkable_area_excludes_what_stands_on_the_floor() {
        let pts = floor_scene();
        let g = walkable_from_points(&pts, -1.7, 0.1).unwrap();
        assert_eq!(g.clearance(DVec2::new(5.0, -0.5)), 0.0, "on the pillar's wall");
        assert!(g.clearance(DVec2::new(3.5, 0.0)) > 0.7 && g.clearance(DVec2::new(3.5, 0.0)) < 1.1);
        assert!(g.clearance(DVec2::new(-5.0, 0.0)) > 3.0, "open floor");
        assert_eq!(g.clearance(DVec2::new(40.0, 0.0)), 0.0, "never seen");
    }

    #[test]
    fn a_glitched_sensor_height_costs_no_memory_for_the_floor() {
        // Floor returns under a sensor 2^32 m up and under one at 1e38 m: the bins follow the
        // sorted heights (the 687 GB histogram is gone); the fuller floor wins.
        let mut pts = floor_scene();
        for (z, n) in [(4294967296.0, 60), (1e38, 60)] {
            let o = DVec3::new(0.0, 0.0, z + 1.7);
            pts.extend((0..n).map(|k| (DVec3::new(2.0 + k as f64 * 0.1, 0.0, z), o)));
        }
        assert!((estimate_floor(&pts).unwrap() + 1.7).abs() < 1e-9);
    }

    #[test]
    fn a_window_wider_than_the_grid_cap_is_an_error_not_an_allocation() {
        let mut pts = floor_scene();
        let far = DVec3::new(5e4, 0.0, 0.0);
        pts.extend((0..100).map(|k| (far + DVec3::new(k as f64 * 0.1, 1.0, -1.7), far)));
        let m = walkable_from_points(&pts, -1.7, 0.1).unwrap_err();
        assert!(m.contains("spans 50025 x 30 m") && m.contains("more than the supported 50000000"), "{m}");
        // Infinite extents too (no pose is allowed there, but the grid does not rely on it).
        let inf = DVec3::new(f64::MAX, 0.0, 0.0);
        pts.push((inf, inf));
        assert!(walkable_from_points(&pts, -1.7, 0.1).unwrap_err().contains("cells"));
    }

    #[test]
    fn floor_gaps_between_rings_are_bridged() {
        // Rings of floor returns 0.8 m apart: the cells between them are floor too.
        let mut pts = Vec::new();
        for ring in 1..12 {
            let r = ring as f64 * 0.8;
            for a in 0..2000 {
                let t = a as f64 / 2000.0 * std::f64::consts::TAU;
                pts.push((DVec3::new(r * t.cos(), r * t.sin(), -1.0), DVec3::ZERO));
            }
        }
        let g = walkable_from_points(&pts, -1.0, 0.1).unwrap();
        assert!(g.clearance(DVec2::new(2.0, 0.0)) > 1.5, "between rings: {}", g.clearance(DVec2::new(2.0, 0.0)));
    }
}
