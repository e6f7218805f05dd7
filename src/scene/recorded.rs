//! Where people may walk in a recorded background.
//!
//! The floor height is estimated per window (or set by `scene.floor_z_m`): the most
//! populated 5 cm height bin of the window's returns below the sensor, refined by the median
//! of the returns within 5 cm of it. The walkable area is a 10 cm grid: cells with a floor
//! return within 50 m of its sensor, grown to bridge the gaps between rings, minus cells with a
//! return between 25 cm and 2 m above the floor (anything standing there at any frame of the
//! window, moving objects included), each connected region of 4 m² or more (parked cars,
//! fences and kerbs split a street's floor, and people stand on every side of them: the
//! largest region alone can be a far one, with no floor left near the sensor).
//!
//! **Far floor.** The rings on the floor spread with the square of their distance (a ring gap
//! of angle a seen from height h lands d² a / h apart at distance d: 0.4 deg from 1.73 m, an
//! HDL-64E on a car, puts them 1.6 m apart at 20 m and 6.5 m at 40 m), and a street's floor is
//! neither flat nor one plane (camber, slopes, kerbs). So a floor return counts within
//! `0.1 m + 0.6 %` of its distance of the floor, and grows by `max(1 m, d² / 500 m)`: far
//! floor stays one region with the near floor, where people can stand at the distances a street
//! shows them (without this, people composited into KITTI streets stood at a median 6 m).

use super::{height_cm, Regions, WalkableGrid, WALKABLE_CELL_M};
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

/// Horizontal distances (m) of the returns used for the floor height.
const FLOOR_RING_M: [f64; 2] = [1.0, 30.0];
/// Horizontal distance (m) of the returns the walkable area is built from.
const WALKABLE_RING_M: f64 = 50.0;
/// Heights above the floor that block a cell, m.
const BLOCK_Z_M: [f64; 2] = [0.25, 2.0];
/// Floor returns count within this height of the floor, m, plus [`FLOOR_TOLERANCE_SLOPE`] of
/// their horizontal distance.
const FLOOR_TOLERANCE_M: f64 = 0.1;
const FLOOR_TOLERANCE_SLOPE: f64 = 0.006;
/// Floor cells are grown by at least this much to bridge the gaps between rings, m ...
const FLOOR_GROW_M: f64 = 1.0;
/// ... and by d² / this at a distance d (m), the gap of rings 0.4 deg apart seen from 1.73 m.
const FLOOR_GROW_DIVISOR_M: f64 = 500.0;
/// The smallest connected floor region kept, m² (room for somebody to stand and step about).
const MIN_REGION_M2: f64 = 4.0;

/// The height band (± m) of a floor return at horizontal distance `d_m` from its sensor.
fn floor_tolerance_m(d_m: f64) -> f64 {
    FLOOR_TOLERANCE_M + FLOOR_TOLERANCE_SLOPE * d_m
}

/// How far (m) a floor return at horizontal distance `d_m` from its sensor grows the floor.
fn floor_grow_m(d_m: f64) -> f64 {
    FLOOR_GROW_M.max(d_m * d_m / FLOOR_GROW_DIVISOR_M)
}

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
        if (p.truncate() - o.truncate()).length() <= WALKABLE_RING_M {
            lo = lo.min(p.truncate());
            hi = hi.max(p.truncate());
        }
    }
    if !lo.is_finite() {
        return Err(none());
    }
    let lo = lo - DVec2::splat(cell_m);
    let (nx, ny) = WalkableGrid::dims(lo, hi + DVec2::splat(cell_m), cell_m)
        .map_err(|m| format!("the returns within {WALKABLE_RING_M} m of their sensor: {m}"))?;
    // Per cell: 0, or 1 + the cells a floor return there grows the floor by (the largest).
    let mut seen = vec![0u16; nx * ny];
    let mut blocked = vec![false; nx * ny];
    // How high each cell's returns reach over the floor, up to 2 m (`WalkableGrid::top_cm`).
    let mut top = vec![0u8; nx * ny];
    for (p, o) in pts {
        let d = (p.truncate() - o.truncate()).length();
        if d > WALKABLE_RING_M {
            continue;
        }
        let q = (p.truncate() - lo) / cell_m;
        let (i, j) = (q.x as usize, q.y as usize);
        if i >= nx || j >= ny {
            continue;
        }
        let h = p.z - floor;
        if h.abs() <= floor_tolerance_m(d) {
            let g = (floor_grow_m(d) / cell_m).round() as u16 + 1;
            seen[j * nx + i] = seen[j * nx + i].max(g);
        } else if h >= BLOCK_Z_M[0] && h <= BLOCK_Z_M[1] {
            blocked[j * nx + i] = true;
            top[j * nx + i] = top[j * nx + i].max(height_cm(h));
        }
    }
    // Grow the floor cells: each by its own reach along its row, then every cell so reached by
    // that reach along its column (a square per floor return, its side twice its reach).
    let mut rows = vec![0u16; nx * ny];
    for j in 0..ny {
        grow_line(&seen, &mut rows, j * nx, 1, nx);
    }
    let mut reach = vec![0u16; nx * ny];
    for i in 0..nx {
        grow_line(&rows, &mut reach, i, nx, ny);
    }
    let floor_cells: Vec<bool> = reach.iter().map(|&r| r > 0).collect();
    if !floor_cells.iter().zip(&blocked).any(|(f, b)| *f && !*b) {
        return Err(none());
    }
    let min_cells = (MIN_REGION_M2 / (cell_m * cell_m)).ceil() as usize;
    Ok(WalkableGrid { top_cm: top, ..WalkableGrid::from_cells_keeping(lo, cell_m, nx, ny, &floor_cells, blocked, Regions::AtLeast(min_cells)) })
}

/// Along the line `first + k * stride` (k < n): every cell within `src - 1` cells of a cell
/// whose `src` is nonzero gets at least that `src` in `dst`.
fn grow_line(src: &[u16], dst: &mut [u16], first: usize, stride: usize, n: usize) {
    let at = |k: usize| first + k * stride;
    for k in 0..n {
        let v = src[at(k)];
        if v == 0 {
            continue;
        }
        let g = usize::from(v - 1);
        for m in k.saturating_sub(g)..(k + g + 1).min(n) {
            let c = &mut dst[at(m)];
            *c = (*c).max(v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Returns of a flat floor at z = -1.7 every 10 cm, cells `xs` x `ys` (in tenths of a
    /// metre), seen by a sensor at the origin.
    fn flat_floor(xs: std::ops::Range<i32>, ys: std::ops::Range<i32>) -> Vec<(DVec3, DVec3)> {
        let ys = &ys;
        xs.flat_map(|i| ys.clone().map(move |j| (DVec3::new(i as f64 * 0.1, j as f64 * 0.1, -1.7), DVec3::ZERO))).collect()
    }

    /// Points of a flat floor at z = -1.7 around a sensor at the origin, with a 1 x 1 m pillar
    /// at (5, 0).
    fn floor_scene() -> Vec<(DVec3, DVec3)> {
        let o = DVec3::ZERO;
        let mut pts = flat_floor(-150..150, -150..150);
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

    /// A tall obstacle in a recording is a cell with a return 1.2-2 m over the floor, a low one
    /// 0.7-1.2 m: the pillar (returns to 1.55 m) stands behind a person before it and hides
    /// all of one behind it; a bench (returns to 0.9 m) hides the legs of one behind it only.
    #[test]
    fn obstacles_are_tall_or_low_by_how_high_their_returns_reach() {
        let mut pts = floor_scene();
        for k in 0..10 {
            for z in 0..5 {
                pts.push((DVec3::new(-4.5, -0.5 + k as f64 * 0.1, -1.4 + z as f64 * 0.15), DVec3::ZERO));
            }
        }
        let g = walkable_from_points(&pts, -1.7, 0.1).unwrap();
        assert_eq!(g.clearance(DVec2::new(-4.5, 0.0)), 0.0, "the bench blocks the floor");
        assert!(g.obstacle_behind(DVec2::ZERO, DVec2::new(3.5, 0.0), 2.0), "the pillar behind");
        assert!(!g.obstacle_behind(DVec2::ZERO, DVec2::new(-3.5, 0.0), 2.0), "the bench behind");
        assert!(g.low_obstacle_before(DVec2::ZERO, DVec2::new(-5.5, 0.0), 1.5), "the bench in front");
        assert!(!g.low_obstacle_before(DVec2::ZERO, DVec2::new(6.5, 0.0), 1.5), "the pillar in front");
        assert!(!g.low_obstacle_before(DVec2::ZERO, DVec2::new(-3.5, 0.0), 1.5), "nothing in front");
    }

    /// A street's floor split by a row of parked cars: a small floor by the sensor and a larger
    /// one beyond them both stay walkable (the largest region alone left the sensor's side
    /// without floor: people could only stand 30 m away); a patch smaller than 4 m² does not.
    #[test]
    fn floor_split_by_obstacles_stays_walkable_on_every_side() {
        let o = DVec3::ZERO;
        let mut pts = flat_floor(-250..250, -100..300);
        // A wall of cars across the whole width at y = 5-7 m; a 1.6 x 1.6 m square of floor
        // walled in at (-20, -8).
        for i in -620..620 {
            for k in 0..40 {
                pts.push((DVec3::new(i as f64 * 0.05, 5.0 + k as f64 * 0.05, -1.0), o));
            }
        }
        for k in 0..=32 {
            let t = k as f64 * 0.05;
            for (x, y) in [(-20.8 + t, -8.8), (-20.8 + t, -7.2), (-20.8, -8.8 + t), (-19.2, -8.8 + t)] {
                pts.push((DVec3::new(x, y, -1.0), o));
            }
        }
        let g = walkable_from_points(&pts, -1.7, 0.1).unwrap();
        // Two regions: no walkable cell of the sensor's side reaches one of the far side.
        let cell = |p: DVec2| {
            let q = ((p - g.origin) / g.cell_m).floor();
            q.y as usize * g.nx + q.x as usize
        };
        let mut seen = vec![false; g.nx * g.ny];
        let mut queue = vec![cell(DVec2::ZERO)];
        while let Some(k) = queue.pop() {
            if seen[k] || g.clearance_m[k] <= 0.0 {
                continue;
            }
            seen[k] = true;
            let (i, j) = (k % g.nx, k / g.nx);
            queue.extend([(i > 0).then(|| k - 1), (i + 1 < g.nx).then(|| k + 1), (j > 0).then(|| k - g.nx), (j + 1 < g.ny).then(|| k + g.nx)].into_iter().flatten());
        }
        assert!(!seen[cell(DVec2::new(0.0, 20.0))], "the cars part the floor");
        assert!(g.clearance(DVec2::new(0.0, 0.0)) > 2.0, "the sensor's side of the cars");
        assert!(g.clearance(DVec2::new(0.0, 20.0)) > 2.0, "the far side, the larger");
        assert_eq!(g.clearance(DVec2::new(0.0, 6.0)), 0.0, "the cars");
        assert_eq!(g.clearance(DVec2::new(-20.0, -8.0)), 0.0, "a patch walled in, under 4 m²");
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

    #[test]
    fn far_floor_rings_spread_by_distance_stay_one_walkable_region() {
        // The floor rings of 0.4 deg steps seen from 1.73 m, out to 45 m (the last gaps 5-8 m),
        // on a floor rising 0.5 % away from the sensor (a road's slope): people can stand at 40 m,
        // and a 1 x 1 m box at 30 m still blocks.
        let h = 1.73;
        let mut pts = Vec::new();
        let mut depression = (h / 45.0f64).atan();
        while depression < 0.5 {
            let r = h / depression.tan();
            for a in 0..4000 {
                let t = a as f64 / 4000.0 * std::f64::consts::TAU;
                pts.push((DVec3::new(r * t.cos(), r * t.sin(), -h + 0.005 * r), DVec3::ZERO));
            }
            depression += 0.4f64.to_radians();
        }
        for k in 0..20 {
            for z in 0..10 {
                let y = -0.5 + k as f64 * 0.05;
                pts.push((DVec3::new(29.5, y, -h + 0.3 + 0.5 + z as f64 * 0.1), DVec3::ZERO));
            }
        }
        let g = walkable_from_points(&pts, -h, 0.1).unwrap();
        assert!(g.clearance(DVec2::new(0.0, 40.0)) > 1.0, "at 40 m: {}", g.clearance(DVec2::new(0.0, 40.0)));
        assert!(g.clearance(DVec2::new(-25.0, 0.0)) > 1.0, "at 25 m: {}", g.clearance(DVec2::new(-25.0, 0.0)));
        assert_eq!(g.clearance(DVec2::new(29.5, 0.0)), 0.0, "on the box at 30 m");
    }
}
