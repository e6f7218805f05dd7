//! `pedscan bench`: run time against error. Sweeps the knobs that trade one for the other
//! (face resolution, level-of-detail bound, refinement) and the workload (people, columns).
//! Every point runs in a child process (`pedscan bench --point ...`) so its peak memory is its
//! own. A point generates real sequences end to end (pose, render, resample, composite, HDF5
//! with all outputs) into a temporary folder and times them; then, untimed, it measures the
//! human layer against the ray-cast reference over the FULL-detail people (LOD 0), so the
//! error includes what levels of detail cost. The ray-cast path is timed on the same frames.
//! Numbers are medians over frames; compare points as ratios within one run.

use crate::config::{Config, Refine};
use crate::error::{Error, Result};
use crate::output::{write_file, FrameOutput, SequenceWriter, WriterOptions};
use crate::config::BackendChoice;
use crate::generator::Generator;
use crate::backend::raycast::{self, Bvh};
use crate::commands::crosscheck::{median, ErrorStats, Tally};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One configuration of the sweep.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct PointSpec {
    /// `cube` (Vulkan raster into cube faces), `cylinder` (Vulkan raster into one cylindrical
    /// panorama), `beams` (Vulkan raster into the beam grid, exact per beam; resolution does
    /// not apply) or `raycast` (the CPU ray caster as the generation backend; resolution and
    /// refinement do not apply).
    pub projection: String,
    /// Face texels per beam spacing (`render.oversample`).
    pub resolution: f64,
    /// Level-of-detail bound, mrad (0 = full detail).
    pub lod: f64,
    pub refine: Refine,
    pub humans: usize,
    pub columns: usize,
    pub frames: usize,
}

impl std::fmt::Display for PointSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} res {} lod {} mrad refine {:?}, {} people, {} columns",
            self.projection, self.resolution, self.lod, self.refine, self.humans, self.columns
        )
    }
}

/// A measured point (`bench --json` writes a list of these).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Point {
    #[serde(flatten)]
    pub spec: PointSpec,
    pub frames_per_s: f64,
    pub ms_per_frame: f64,
    pub peak_rss_mb: f64,
    pub human_beam_agreement: f64,
    pub median_range_error_m: f64,
    pub p99_range_error_m: f64,
    pub triangles_per_frame: f64,
    /// The ray-cast path on the same frames (full-detail people): BVH build + cast.
    pub raycast: RaycastTiming,
    /// Median milliseconds per frame of the stages.
    pub stage_ms: StageMs,
}

#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct RaycastTiming {
    pub frames_per_s: f64,
    pub build_ms: f64,
    pub cast_ms: f64,
}

#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct StageMs {
    pub pose: f64,
    pub render_resample: f64,
    pub post: f64,
    pub write: f64,
}

/// Peak resident set of this process, MiB (Linux `VmHWM`; 0 where unknown).
pub fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok()))
        .map_or(0.0, |kb| kb / 1024.0)
}

/// The sweep: a base point (10 people, 1024 columns) varied one knob at a time, the
/// time/error trade-off grid (resolution x LOD x refinement) at 10 people, and the workload
/// scaling (people 1..100, columns 1024..4096) at the default settings; the cylindrical
/// panorama beside the cube faces at the same points (its resolution is rounded to whole
/// texels per column), so one run compares them.
pub fn sweep(quick: bool) -> Vec<PointSpec> {
    let frames = if quick { 4 } else { 16 };
    let p = |resolution: f64, lod: f64, refine: Refine, humans: usize, columns: usize| PointSpec {
        projection: "cube".into(),
        resolution,
        lod,
        refine,
        humans,
        columns,
        frames,
    };
    let mut v = Vec::new();
    if quick {
        for (res, lod, refine) in [(2.0, 1.0, Refine::Exact), (1.0, 10.0, Refine::Exact), (2.0, 1.0, Refine::None)] {
            v.push(p(res, lod, refine, 5, 1024));
        }
        v.push(PointSpec { projection: "raycast".into(), ..p(2.0, 1.0, Refine::Exact, 5, 1024) });
        for (res, refine) in [(2.0, Refine::Exact), (1.0, Refine::Exact), (2.0, Refine::None)] {
            v.push(PointSpec { projection: "cylinder".into(), ..p(res, 1.0, refine, 5, 1024) });
        }
        v.push(PointSpec { projection: "beams".into(), ..p(1.0, 1.0, Refine::Exact, 5, 1024) });
        return v;
    }
    let cyl = |s: PointSpec| PointSpec { projection: "cylinder".into(), ..s };
    let beams = |s: PointSpec| PointSpec { projection: "beams".into(), ..s };
    for res in [1.0, 2.0, 3.0] {
        for lod in [0.0, 1.0, 3.0, 10.0] {
            for refine in [Refine::None, Refine::Exact] {
                v.push(p(res, lod, refine, 10, 1024));
            }
        }
    }
    for res in [1.0, 2.0, 3.0] {
        for refine in [Refine::None, Refine::Exact] {
            v.push(cyl(p(res, 1.0, refine, 10, 1024)));
        }
    }
    for lod in [0.0, 3.0, 10.0] {
        v.push(cyl(p(2.0, lod, Refine::Exact, 10, 1024)));
    }
    v.push(cyl(p(1.0, 10.0, Refine::None, 10, 1024)));
    for lod in [0.0, 1.0, 3.0, 10.0] {
        v.push(PointSpec { projection: "raycast".into(), ..p(2.0, lod, Refine::Exact, 10, 1024) });
    }
    for lod in [0.0, 1.0, 3.0, 10.0] {
        v.push(beams(p(1.0, lod, Refine::Exact, 10, 1024)));
    }
    for humans in [1, 30, 100] {
        v.push(p(2.0, 1.0, Refine::Exact, humans, 1024));
        v.push(cyl(p(2.0, 1.0, Refine::Exact, humans, 1024)));
        v.push(beams(p(1.0, 1.0, Refine::Exact, humans, 1024)));
        v.push(PointSpec { projection: "raycast".into(), ..p(2.0, 1.0, Refine::Exact, humans, 1024) });
    }
    for columns in [2048, 4096] {
        v.push(p(2.0, 1.0, Refine::Exact, 10, columns));
        v.push(cyl(p(2.0, 1.0, Refine::Exact, 10, columns)));
        v.push(beams(p(1.0, 1.0, Refine::Exact, 10, columns)));
        v.push(PointSpec { projection: "raycast".into(), ..p(2.0, 1.0, Refine::Exact, 10, columns) });
    }
    v
}

/// Runs one point in this process (the child side of `bench`).
pub fn run_point(base: &Config, spec: &PointSpec) -> Result<Point> {
    let mut cfg = base.clone();
    cfg.render.backend = if spec.projection == "raycast" { BackendChoice::Raycast } else { BackendChoice::Raster };
    cfg.render.projection = match spec.projection.as_str() {
        "cube" | "raycast" => crate::config::Projection::Cube,
        "cylinder" => crate::config::Projection::Cylinder,
        "beams" => crate::config::Projection::Beams,
        other => return Err(Error::input("bench point", format!("unknown projection `{other}` (cube, cylinder, beams, raycast)"))),
    };
    cfg.render.oversample = spec.resolution;
    cfg.render.lod_max_error_mrad = spec.lod;
    cfg.render.refine = spec.refine;
    cfg.humans.count = [spec.humans, spec.humans];
    cfg.frames = spec.frames;
    cfg.sequences = 1;
    cfg.png = false;
    // The sweep measures the renderers on the same posed frames; the sensor model's own cost
    // is the table of its terms (`sensor_model_costs`).
    cfg.sensor_model = crate::config::SensorModelConfig::off();
    // A custom HDL-32E with more columns for the column sweep.
    let mut sensor = crate::sensor::Sensor::hdl32e();
    sensor.columns = spec.columns;
    let sensor_file = std::env::temp_dir().join(format!("pedscan-bench-sensor-{}-{}.toml", std::process::id(), spec.columns));
    let elev: Vec<String> = sensor.elevation_deg.iter().map(|e| format!("{e}")).collect();
    std::fs::write(&sensor_file, format!("name = \"hdl32e_{}\"\nelevation_deg = [{}]\ncolumns = {}\n", spec.columns, elev.join(", "), spec.columns))
        .map_err(|e| Error::io(&sensor_file, e))?;
    cfg.sensor = sensor_file.display().to_string();
    if spec.humans > 60 {
        cfg.humans.spawn_radius_m = 16.0;
        cfg.humans.min_separation_m = 0.5;
    }
    let out = tempdir_for_point()?;
    let mut gen = Generator::new(cfg)?;
    let _ = std::fs::remove_file(&sensor_file);
    let (mut t_pose, mut t_render, mut t_post, mut t_write, mut t_total) = (vec![], vec![], vec![], vec![], vec![]);
    let (mut t_build, mut t_cast) = (vec![], vec![]);
    let mut tally = Tally::default();
    let mut triangles = 0u64;
    let plan = gen.plan(0)?;
    let meta = gen.meta(0, &plan);
    let mut writer = SequenceWriter::create(&out, &meta, &WriterOptions::default())?;
    let mut frame = FrameOutput::default();
    let dirs = gen.beam_dirs().to_vec();
    for k in 0..plan.times_s.len() {
        let t0 = Instant::now();
        let state = gen.frame_state(&plan, k);
        gen.pose_frame(&plan, &state)?;
        let t1 = Instant::now();
        gen.render_posed()?;
        let t2 = Instant::now();
        if base.output.velocity == crate::config::VelocityModel::Limb && gen.outputs().velocity {
            gen.point_velocities(&plan, &state);
        }
        gen.post(&state, &mut frame);
        let t3 = Instant::now();
        writer.write_frame(&frame)?;
        let t4 = Instant::now();
        t_pose.push((t1 - t0).as_secs_f64() * 1e3);
        t_render.push((t2 - t1).as_secs_f64() * 1e3);
        t_post.push((t3 - t2).as_secs_f64() * 1e3);
        t_write.push((t4 - t3).as_secs_f64() * 1e3);
        t_total.push((t4 - t0).as_secs_f64() * 1e3);
        let posed = gen.posed();
        triangles += posed.people.triangle_count() as u64 + posed.background.triangle_count() as u64;
        // Untimed: the reference over full-detail people, and the raster human layer.
        let raster = gen.human_hits().clone();
        gen.pose_frame_full_detail(&plan, &state)?;
        let geom = gen.posed().people;
        let tb = Instant::now();
        let bvh = Bvh::build(geom);
        t_build.push(tb.elapsed().as_secs_f64() * 1e3);
        let tc = Instant::now();
        let reference = raycast::cast(geom, &bvh, &dirs, gen.sensor().max_range_m);
        t_cast.push(tc.elapsed().as_secs_f64() * 1e3);
        tally.add(&raster, &reference);
    }
    drop(writer); // not finished: the temporary files are removed
    let _ = std::fs::remove_dir_all(&out);
    let ms = median(&mut t_total);
    let errors = ErrorStats::from(&mut tally.errors);
    let build = median(&mut t_build);
    let cast = median(&mut t_cast);
    Ok(Point {
        spec: spec.clone(),
        frames_per_s: 1e3 / ms.max(1e-9),
        ms_per_frame: ms,
        peak_rss_mb: peak_rss_mb(),
        human_beam_agreement: tally.agreement(),
        median_range_error_m: errors.median,
        p99_range_error_m: errors.p99,
        triangles_per_frame: triangles as f64 / plan.times_s.len().max(1) as f64,
        raycast: RaycastTiming { frames_per_s: 1e3 / (build + cast).max(1e-9), build_ms: build, cast_ms: cast },
        stage_ms: StageMs { pose: median(&mut t_pose), render_resample: median(&mut t_render), post: median(&mut t_post), write: median(&mut t_write) },
    })
}

fn tempdir_for_point() -> Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("pedscan-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    Ok(dir)
}

/// Runs the sweep, each point in a child process of `exe`; returns the points.
pub fn run_sweep(exe: &Path, config: Option<&Path>, specs: &[PointSpec], mut progress: impl FnMut(usize, &Point)) -> Result<Vec<Point>> {
    let mut points = Vec::new();
    for (i, spec) in specs.iter().enumerate() {
        let json = serde_json::to_string(spec).map_err(|e| Error::Internal(e.to_string()))?;
        let mut cmd = std::process::Command::new(exe);
        cmd.arg("bench").arg("--point").arg(&json);
        if let Some(c) = config {
            cmd.arg("--config").arg(c);
        }
        let out = cmd.output().map_err(|e| Error::io(exe, e))?;
        if !out.status.success() {
            return Err(Error::Internal(format!("bench point {json} failed: {}", String::from_utf8_lossy(&out.stderr))));
        }
        let text = String::from_utf8_lossy(&out.stdout);
        let line = text.lines().last().unwrap_or("");
        let p: Point = serde_json::from_str(line).map_err(|e| Error::Internal(format!("bench point output: {e}: {line}")))?;
        progress(i, &p);
        points.push(p);
    }
    Ok(points)
}

/// The Markdown table of a sweep.
pub fn markdown(points: &[Point]) -> String {
    let mut s = String::from(
        "| projection | resolution | LOD mrad | refine | people | columns | frames/s | ms/frame | pose | render+resample | post | write | triangles/frame | peak MiB | agreement | median err mm | p99 err mm | ray-cast frames/s |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for p in points {
        s += &format!(
            "| {} | {} | {} | {:?} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.0} | {:.0} | {:.4} % | {:.4} | {:.3} | {:.1} |\n",
            p.spec.projection,
            p.spec.resolution,
            p.spec.lod,
            p.spec.refine,
            p.spec.humans,
            p.spec.columns,
            p.frames_per_s,
            p.ms_per_frame,
            p.stage_ms.pose,
            p.stage_ms.render_resample,
            p.stage_ms.post,
            p.stage_ms.write,
            p.triangles_per_frame,
            p.peak_rss_mb,
            100.0 * p.human_beam_agreement,
            p.median_range_error_m * 1e3,
            p.p99_range_error_m * 1e3,
            p.raycast.frames_per_s
        );
    }
    s
}

/// Time against error: every trade-off point of the sweep's base workload (the people and
/// columns of its first point), by refinement, with the Pareto front and the ray-cast path.
pub fn plot(points: &[Point]) -> crate::plot::Plot {
    use crate::plot::{Draw, Marker, Plot, Series};
    let (humans, columns) = points.first().map_or((10, 1024), |p| (p.spec.humans, p.spec.columns));
    let tradeoff: Vec<&Point> = points.iter().filter(|p| p.spec.humans == humans && p.spec.columns == columns).collect();
    let err = |p: &Point| (1.0 - p.human_beam_agreement).max(1e-5);
    let mut series = Vec::new();
    for (refine, colour, marker) in [(Refine::Exact, [31, 119, 180], Marker::Circle), (Refine::None, [214, 39, 40], Marker::Square), (Refine::Plane, [44, 160, 44], Marker::Triangle)] {
        let pts: Vec<(f64, f64)> =
            tradeoff.iter().filter(|p| p.spec.projection == "cube" && p.spec.refine == refine).map(|p| (p.ms_per_frame, err(p))).collect();
        if !pts.is_empty() {
            series.push(Series { name: format!("cube, refine {refine:?}").to_lowercase(), points: pts, colour, draw: Draw::Points(marker) });
        }
    }
    for (refine, colour, marker) in [(Refine::Exact, [23, 190, 207], Marker::Circle), (Refine::None, [227, 119, 194], Marker::Square)] {
        let pts: Vec<(f64, f64)> =
            tradeoff.iter().filter(|p| p.spec.projection == "cylinder" && p.spec.refine == refine).map(|p| (p.ms_per_frame, err(p))).collect();
        if !pts.is_empty() {
            series.push(Series { name: format!("cylinder, refine {refine:?}").to_lowercase(), points: pts, colour, draw: Draw::Points(marker) });
        }
    }
    let beam_points: Vec<(f64, f64)> = tradeoff.iter().filter(|p| p.spec.projection == "beams").map(|p| (p.ms_per_frame, err(p))).collect();
    if !beam_points.is_empty() {
        series.push(Series { name: "beam grid (exact)".into(), points: beam_points, colour: [148, 103, 189], draw: Draw::Points(Marker::Triangle) });
    }
    let rc_points: Vec<(f64, f64)> = tradeoff.iter().filter(|p| p.spec.projection == "raycast").map(|p| (p.ms_per_frame, err(p))).collect();
    if !rc_points.is_empty() {
        series.push(Series { name: "ray-cast backend".into(), points: rc_points, colour: [255, 127, 14], draw: Draw::Points(Marker::Cross) });
    }
    let all: Vec<(f64, f64)> = tradeoff.iter().map(|p| (p.ms_per_frame, err(p))).collect();
    let front = crate::plot::pareto_front(&all);
    series.push(Series { name: "Pareto".into(), points: front.iter().map(|&i| all[i]).collect(), colour: [90, 90, 90], draw: Draw::Line(Marker::Cross) });
    // The reference has no error by definition: drawn at the bottom of the error range. Its
    // time is BVH build + cast of the full-detail people only (no background, post or writing).
    let floor = all.iter().map(|p| p.1).fold(f64::INFINITY, f64::min).min(1e-3) / 2.0;
    let mut rc: Vec<f64> = tradeoff.iter().map(|p| 1e3 / p.raycast.frames_per_s.max(1e-9)).collect();
    let rc_ms = median(&mut rc);
    if rc_ms > 0.0 {
        series.push(Series {
            name: "reference cast".into(),
            points: vec![(rc_ms, floor)],
            colour: [148, 103, 189],
            draw: Draw::Points(Marker::Triangle),
        });
    }
    Plot {
        title: format!("pedscan: time per frame vs human-beam disagreement ({humans} people, {columns} columns)"),
        x_label: "ms per frame (end to end, median)".into(),
        y_label: "1 - human beam agreement vs full-detail reference".into(),
        log_x: true,
        log_y: true,
        series,
        // Wide enough for the long title and a legend of eight entries in a corner.
        width: 1400,
        height: 650,
    }
}

/// One row of [`triangle_rates`]: the same `triangles` drawn by the raster renderer and cast
/// by the binned ray caster, median milliseconds of each.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct RateRow {
    pub triangles: usize,
    /// Vulkan: upload, draw into the beam-resolution panorama (the people layer's target),
    /// read back the range and ID images. No refinement.
    pub raster_ms: f64,
    /// The binned ray caster (exact hits of every beam).
    pub raycast_ms: f64,
    /// Texels the raster drew / beams the caster hit (both should see the same patches).
    pub raster_texels: usize,
    pub raycast_beams: usize,
}

impl RateRow {
    /// Triangles per second of each path.
    pub fn rates(&self) -> (f64, f64) {
        (self.triangles as f64 / (self.raster_ms * 1e-3), self.triangles as f64 / (self.raycast_ms * 1e-3))
    }
}

/// What bounds the raster path on a device: `counts` patches of person-sized detail (5 cm
/// triangles, 5 to 17 m away, in front of the sensor) drawn by the raster renderer at beam
/// resolution and cast by the binned ray caster, `repeats` times each, interleaved; medians.
/// Per triangle, the Vulkan driver's setup and binning is what the raster path pays that the
/// caster does not: on lavapipe it is the bound of any design that draws every triangle.
pub fn triangle_rates(ctx: &std::sync::Arc<crate::gpu::Context>, counts: &[usize], repeats: usize) -> Result<Vec<RateRow>> {
    use crate::backend::raster::{projection::Panorama, renderer::Renderer};
    let sensor = crate::sensor::Sensor::hdl32e();
    let pano = Panorama::new(&sensor, 1.0);
    let mut renderer = Renderer::new_panorama(ctx, &pano)?;
    let dirs = sensor.beam_dirs();
    let mut caster = raycast::BeamCaster::new(&dirs, sensor.rows(), sensor.columns);
    let mut hits = Vec::new();
    let mut rows = Vec::new();
    for &n in counts {
        let geom = rate_patches(n);
        let (mut raster_ms, mut raycast_ms) = (Vec::new(), Vec::new());
        let (mut raster_texels, mut raycast_beams) = (0, 0);
        for _ in 0..repeats.max(1) {
            let t = Instant::now();
            let frame = renderer.render(&geom)?;
            raster_ms.push(t.elapsed().as_secs_f64() * 1e3);
            raster_texels = frame.faces[0].id.iter().filter(|&&id| id != 0).count();
            let t = Instant::now();
            caster.cast(&geom, f64::MAX, &mut hits);
            raycast_ms.push(t.elapsed().as_secs_f64() * 1e3);
            raycast_beams = hits.iter().filter(|h| h.is_hit()).count();
        }
        rows.push(RateRow { triangles: n, raster_ms: median(&mut raster_ms), raycast_ms: median(&mut raycast_ms), raster_texels, raycast_beams });
    }
    Ok(rows)
}

/// `n` little triangles (5 cm sides) scattered 5 to 17 m in front of the sensor, within
/// +-40 degrees of azimuth and the HDL-32E's elevations, as one double-sided mesh.
fn rate_patches(n: usize) -> crate::geometry::FrameGeometry {
    let mut positions = Vec::with_capacity(3 * n);
    for i in 0..n {
        // Low-discrepancy spread, deterministic.
        let a = -0.7 + 1.4 * ((i * 7919) % 10007) as f32 / 10007.0;
        let e = -0.5 + 0.6 * ((i * 104_729) % 9973) as f32 / 9973.0;
        let r = 5.0 + (i % 13) as f32;
        let c = [r * a.cos() * e.cos(), r * a.sin() * e.cos(), r * e.sin()];
        positions.extend([c, [c[0], c[1] + 0.05, c[2]], [c[0], c[1], c[2] + 0.05]]);
    }
    let indices: Vec<u32> = (0..3 * n as u32).collect();
    let mut geom = crate::geometry::FrameGeometry::default();
    geom.push_mesh(&positions, &indices, 1, true);
    geom
}

/// The Markdown table of [`triangle_rates`].
pub fn rates_markdown(device: &str, rows: &[RateRow]) -> String {
    let mut s = format!(
        "\nTriangle rate on {device} (the same triangles drawn by the raster renderer at beam resolution and cast by the binned ray caster):\n\n\
         | triangles | raster ms | ray-cast ms | raster Mtri/s | ray-cast Mtri/s | raster / ray-cast time | texels drawn | beams hit |\n\
         |---|---|---|---|---|---|---|---|\n"
    );
    for r in rows {
        let (a, b) = r.rates();
        s += &format!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.1} | {:.1}x | {} | {} |\n",
            r.triangles,
            r.raster_ms,
            r.raycast_ms,
            a * 1e-6,
            b * 1e-6,
            r.raster_ms / r.raycast_ms.max(1e-9),
            r.raster_texels,
            r.raycast_beams
        );
    }
    s
}

/// One term of the sensor model timed on one backend (see [`sensor_model_costs`]).
#[derive(Clone, Debug, Serialize)]
pub struct TermRow {
    pub backend: String,
    pub variant: String,
    /// Median milliseconds per frame (pose, cast, post; no writing).
    pub ms_per_frame: f64,
}

/// The sensor model's variants timed: everything off, each term alone, everything on.
pub fn sensor_model_variants() -> Vec<(&'static str, crate::config::SensorModelConfig)> {
    use crate::config::SensorModelConfig;
    // Every term off but the master switch: detection certain, no noise, knife edges.
    let none = SensorModelConfig {
        rolling_shutter: false,
        range_noise_m: 0.0,
        laser_bias_m: 0.0,
        dropout_rate: 0.0,
        detection_range_m: 1e9,
        grazing_deg: [90.0, 90.0],
        divergence_mrad: [0.0, 0.0],
        ..SensorModelConfig::on()
    };
    let d = SensorModelConfig::on();
    vec![
        ("off", SensorModelConfig::off()),
        ("intensity only", none.clone()),
        ("rolling shutter", SensorModelConfig { rolling_shutter: true, ..none.clone() }),
        (
            "noise + dropout",
            SensorModelConfig {
                range_noise_m: d.range_noise_m,
                laser_bias_m: d.laser_bias_m,
                dropout_rate: d.dropout_rate,
                detection_range_m: d.detection_range_m,
                grazing_deg: d.grazing_deg,
                ..none.clone()
            },
        ),
        ("divergence", SensorModelConfig { divergence_mrad: d.divergence_mrad, ..none }),
        ("all (default)", d),
    ]
}

/// The cost of each sensor-model term on each backend: `frames` frames of sequence 0 of
/// `base` per variant, `repeats` rounds interleaved over the variants, medians of the rounds.
pub fn sensor_model_costs(base: &Config, backends: &[crate::config::BackendChoice], frames: usize, repeats: usize) -> Result<Vec<TermRow>> {
    let variants = sensor_model_variants();
    let mut rows = Vec::new();
    for &backend in backends {
        let configs: Vec<Config> = variants
            .iter()
            .map(|(_, m)| {
                let mut cfg = base.clone();
                cfg.render.backend = backend;
                cfg.sensor_model = m.clone();
                cfg.frames = frames;
                cfg
            })
            .collect();
        let times = frame_costs(&configs, repeats)?;
        let name = if backend == crate::config::BackendChoice::Raycast { "raycast" } else { "raster" };
        for ((variant, _), ms) in variants.iter().zip(times) {
            rows.push(TermRow { backend: name.into(), variant: variant.to_string(), ms_per_frame: ms });
        }
    }
    Ok(rows)
}

/// Milliseconds per frame (pose, cast and post; no writing) of sequence 0 of each of
/// `configs` (its `frames` frames a round), `repeats` rounds interleaved over the configs;
/// medians of the rounds.
fn frame_costs(configs: &[Config], repeats: usize) -> Result<Vec<f64>> {
    let mut gens = Vec::new();
    for cfg in configs {
        let gen = crate::generator::Generator::new(cfg.clone())?;
        let plan = gen.plan(0)?;
        gens.push((gen, plan));
    }
    let mut times = vec![Vec::new(); configs.len()];
    let mut out = crate::output::FrameOutput::default();
    for _ in 0..repeats.max(1) {
        for (v, (gen, plan)) in gens.iter_mut().enumerate() {
            gen.begin_sequence(0, plan);
            let t = Instant::now();
            for k in 0..plan.times_s.len() {
                gen.frame(plan, k, &mut out)?;
            }
            times[v].push(t.elapsed().as_secs_f64() * 1e3 / plan.times_s.len() as f64);
        }
    }
    for (gen, _) in gens {
        gen.finish()?;
    }
    Ok(times.iter_mut().map(|t| median(t)).collect())
}

/// One row of [`host_share_costs`].
#[derive(Clone, Debug, Serialize)]
pub struct ShareRow {
    /// `environment only, background cast` or `whole frame`.
    pub workload: String,
    /// The backend, and for the raster one its `render.host_cast_beams`.
    pub variant: String,
    /// Median milliseconds: per background cast, or per frame (pose, cast, post).
    pub ms: f64,
    /// The raster background's own figures (medians), where measured.
    pub raster: Option<ShareDetail>,
}

/// Where a raster background cast's time went ([`crate::backend::raster::beam_exact::BeamExactStats`]).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct ShareDetail {
    /// Bounding, staging, submitting and the host's own cast.
    pub host_ms: f64,
    /// From the submit until the draw and read-back were done.
    pub device_ms: f64,
    /// The f64 confirmation of the drawn triangles.
    pub confirm_ms: f64,
    pub rectangles: f64,
    pub texels: f64,
}

/// Where the raster backend's background work should run: the binned ray caster against the
/// raster backend with the device drawing every triangle (`render.host_cast_beams = 0`), the
/// default split, and the host casting every triangle (nothing drawn). First the fixed cost,
/// the background alone (`base`'s environment, no person): `frames` posed frames, each cast
/// `repeats` times by every variant in turn, medians. Then whole frames of `base` (pose, cast
/// and post) on each variant, as [`frame_costs`]. Needs a Vulkan device; returns its name
/// beside the rows. With `base.debug.validation`, fails if the validation layer reported
/// anything.
pub fn host_share_costs(base: &Config, frames: usize, repeats: usize) -> Result<(String, Vec<ShareRow>)> {
    use crate::backend::raster::beam_exact::{BeamExact, HOST_BEAMS};
    let own = base.render.host_cast_beams;
    let own_name = if own == HOST_BEAMS { format!("{own} (default)") } else { format!("{own} (configured)") };
    let shares = [(0, "0 (device draws all)".to_string()), (own, own_name), (i64::MAX as u64, "max (host casts all)".to_string())];
    let mut rows = Vec::new();
    let mut cfg = base.clone();
    cfg.render.backend = BackendChoice::Raycast;
    cfg.humans.count = [0, 0];
    cfg.frames = frames;
    let mut gen = Generator::new(cfg)?;
    let ctx = crate::backend::Gpu::new(&base.device, base.debug.validation).context()?;
    let device = ctx.device_name();
    let validation = ctx.validation_counter();
    let mut caster = raycast::BeamCaster::new(gen.beam_dirs(), gen.sensor().rows(), gen.sensor().columns);
    let mut rasters = shares.iter().map(|&(h, _)| BeamExact::new(&ctx, gen.sensor(), h)).collect::<Result<Vec<_>>>()?;
    let plan = gen.plan(0)?;
    let (mut cast, mut hits) = (Vec::new(), crate::backend::BeamHits::default());
    let mut ms = vec![Vec::new(); 1 + shares.len()];
    let mut stats = vec![Vec::new(); shares.len()];
    for k in 0..plan.times_s.len() {
        let state = gen.frame_state(&plan, k);
        gen.pose_frame(&plan, &state)?;
        let geom = gen.posed().background;
        for _ in 0..repeats.max(1) {
            let t = Instant::now();
            caster.cast(geom, f64::MAX, &mut cast);
            ms[0].push(t.elapsed().as_secs_f64() * 1e3);
            for (v, raster) in rasters.iter_mut().enumerate() {
                let t = Instant::now();
                raster.cast(geom, &mut hits)?;
                ms[v + 1].push(t.elapsed().as_secs_f64() * 1e3);
                stats[v].push(raster.stats());
            }
        }
    }
    drop(rasters);
    drop(ctx);
    gen.finish()?;
    match validation.load(std::sync::atomic::Ordering::SeqCst) {
        0 => {}
        n => return Err(Error::Gpu(format!("{n} Vulkan validation errors (see the messages above)"))),
    }
    let hall = "environment only, background cast";
    rows.push(ShareRow { workload: hall.into(), variant: "raycast".into(), ms: median(&mut ms[0]), raster: None });
    for (v, (_, name)) in shares.iter().enumerate() {
        let m = |f: &dyn Fn(&crate::backend::raster::beam_exact::BeamExactStats) -> f64| median(&mut stats[v].iter().map(f).collect::<Vec<_>>());
        let detail = ShareDetail {
            host_ms: m(&|s| s.stage_s * 1e3),
            device_ms: m(&|s| s.draw_s * 1e3),
            confirm_ms: m(&|s| s.resolve_s * 1e3),
            rectangles: m(&|s| s.instances as f64),
            texels: m(&|s| s.texels as f64),
        };
        rows.push(ShareRow { workload: hall.into(), variant: format!("raster, host_cast_beams {name}"), ms: median(&mut ms[v + 1]), raster: Some(detail) });
    }
    let mut configs = Vec::new();
    let mut names = vec!["raycast".to_string()];
    let mut c = base.clone();
    c.frames = frames;
    c.render.projection = crate::config::Projection::Beams;
    c.render.backend = BackendChoice::Raycast;
    configs.push(c.clone());
    c.render.backend = BackendChoice::Raster;
    for (h, name) in &shares {
        c.render.host_cast_beams = *h;
        configs.push(c.clone());
        names.push(format!("raster, host_cast_beams {name}"));
    }
    for (name, ms) in names.into_iter().zip(frame_costs(&configs, repeats)?) {
        rows.push(ShareRow { workload: "whole frame".into(), variant: name, ms, raster: None });
    }
    Ok((device, rows))
}

/// The Markdown table of [`host_share_costs`].
pub fn shares_markdown(device: &str, rows: &[ShareRow], frames: usize, repeats: usize) -> String {
    let mut s = format!(
        "\nWhere the raster background's work runs on {device} (`render.host_cast_beams`, the projection the beam grid; environment only, no person: {frames} frames, each background cast {repeats} times by every variant in turn; whole frames of the configuration: {frames} frames x {repeats} interleaved rounds, pose + cast + post; medians; the time over the ray caster's):\n\n\
         | workload | variant | ms | over raycast | raster background (host: bound, stage, submit, host cast) |\n|---|---|---|---|---|\n"
    );
    for r in rows {
        let rc = rows.iter().find(|o| o.workload == r.workload && o.variant == "raycast").map_or(r.ms, |o| o.ms);
        let detail = r.raster.map_or_else(String::new, |d| {
            if d.rectangles == 0.0 {
                format!("host {:.2} ms (nothing drawn), confirm {:.2} ms", d.host_ms, d.confirm_ms)
            } else {
                format!(
                    "host {:.2} ms, submit to read-back {:.2} ms, confirm {:.2} ms; {:.0} rectangles, {:.0} texels",
                    d.host_ms, d.device_ms, d.confirm_ms, d.rectangles, d.texels
                )
            }
        });
        s += &format!("| {} | {} | {:.2} | {:.2}x | {} |\n", r.workload, r.variant, r.ms, r.ms / rc.max(1e-9), detail);
    }
    s
}

/// The Markdown table of [`sensor_model_costs`].
pub fn terms_markdown(rows: &[TermRow], frames: usize, repeats: usize) -> String {
    let mut s = format!(
        "\nSensor model cost per term (ms per frame: pose, cast and post, not writing; {frames} frames x {repeats} interleaved rounds, medians; the difference to `off` in brackets):\n\n\
         | backend | variant | ms/frame | over off |\n|---|---|---|---|\n"
    );
    for r in rows {
        let off = rows.iter().find(|o| o.backend == r.backend && o.variant == "off").map_or(r.ms_per_frame, |o| o.ms_per_frame);
        s += &format!("| {} | {} | {:.2} | {:+.2} |\n", r.backend, r.variant, r.ms_per_frame, r.ms_per_frame - off);
    }
    s
}

/// One workload of the per-stage table: milliseconds per frame per stage of `generate`.
#[derive(Clone, Debug, Serialize)]
pub struct StageRow {
    pub variant: String,
    /// plan, pose + skin, BVH refit (`debug.caster = "bvh"` only), background, people, post,
    /// write (on the writer thread), and the frame thread's sum.
    pub ms: [f64; 8],
}

/// The stages of `generate` (plan, pose, cast, post, write) on three workloads of `base`: its
/// own, the sensor model off, and 30 people. Each round writes sequence 0 (`frames` frames)
/// of every workload into a temporary folder, the workloads interleaved; medians of `repeats`
/// rounds (what `--timings` reports, per round).
pub fn stage_costs(base: &Config, frames: usize, repeats: usize) -> Result<Vec<StageRow>> {
    let mut off = base.clone();
    off.sensor_model.enabled = false;
    let mut crowd = base.clone();
    crowd.humans.count = [30, 30];
    let variants = [("as configured", base.clone()), ("sensor model off", off), ("30 people", crowd)];
    let dir = tempdir_for_point()?.join("stages");
    let mut gens = Vec::new();
    for (name, cfg) in &variants {
        let mut cfg = cfg.clone();
        cfg.frames = frames;
        let out = dir.join(name.replace(' ', "-"));
        std::fs::create_dir_all(&out).map_err(|e| Error::io(&out, e))?;
        gens.push((crate::generator::Generator::new(cfg)?, out));
    }
    let mut samples = vec![vec![Vec::new(); 8]; variants.len()];
    for _ in 0..repeats.max(1) {
        for (v, (gen, out)) in gens.iter_mut().enumerate() {
            let before = gen.timings();
            gen.write_sequence(0, out, || Ok(()))?;
            let after = gen.timings();
            let n = (after.frames - before.frames).max(1) as f64;
            let d = |a: f64, b: f64| 1e3 * (a - b) / n;
            let stages = [
                d(after.plan_s, before.plan_s),
                d(after.pose_s, before.pose_s),
                d(after.bvh_s, before.bvh_s),
                d(after.background_s, before.background_s),
                d(after.humans_s, before.humans_s),
                d(after.post_s, before.post_s),
                d(after.write_s, before.write_s),
            ];
            let thread: f64 = stages[..6].iter().sum();
            for (k, ms) in stages.iter().chain(std::iter::once(&thread)).enumerate() {
                samples[v][k].push(*ms);
            }
        }
    }
    for (gen, _) in gens {
        gen.finish()?;
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(variants
        .iter()
        .zip(samples)
        .map(|((name, _), mut s)| StageRow { variant: name.to_string(), ms: std::array::from_fn(|k| median(&mut s[k])) })
        .collect())
}

/// The Markdown table of [`stage_costs`].
pub fn stages_markdown(rows: &[StageRow], frames: usize, repeats: usize) -> String {
    let mut s = format!(
        "\nWhere a frame's time goes (ms per frame, `generate`'s stages as `--timings` reports them; sequence 0, {frames} frames x {repeats} interleaved rounds, medians; write runs on its own thread, overlapping the next frame):\n\n\
         | workload | plan | pose + skin | bvh refit | background | people | post | frame thread | write |\n|---|---|---|---|---|---|---|---|---|\n"
    );
    for r in rows {
        let m = r.ms;
        s += &format!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |\n",
            r.variant, m[0], m[1], m[2], m[3], m[4], m[5], m[7], m[6]
        );
    }
    s
}

/// What `pedscan bench` is asked for (its flags).
#[derive(Clone, Debug, clap::Args)]
pub struct BenchRequest {
    /// A reduced sweep (under a minute).
    #[arg(long)]
    pub quick: bool,
    /// Base configuration (the sweep overrides its render and workload keys).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Write the points as JSON.
    #[arg(long, default_value = "bench.json")]
    pub json: PathBuf,
    /// Write a Markdown table.
    #[arg(long, default_value = "bench.md")]
    pub markdown: PathBuf,
    /// Write the time-vs-error plot.
    #[arg(long, default_value = "bench.png")]
    pub plot: PathBuf,
    /// Run one point (internal: the sweep runs each point in a child process).
    #[arg(long, hide = true)]
    pub point: Option<String>,
    /// Redraw the table and plot from the points of an earlier `--json` file; runs nothing.
    #[arg(long)]
    pub from_json: Option<PathBuf>,
}

/// `pedscan bench`: the sweep (each point in a child process of `exe`), then the triangle
/// rates, the sensor model's terms, where the raster background's work runs and where a
/// frame's time goes, stage by stage; writes the
/// JSON, the Markdown tables and the plot, and returns the tables. With `point`, runs that one
/// point here and returns its JSON line.
pub fn bench(exe: &Path, req: &BenchRequest) -> Result<String> {
    if let Some(src) = &req.from_json {
        let text = std::fs::read_to_string(src).map_err(|e| Error::io(src, e))?;
        let points: Vec<Point> =
            serde_json::from_str(&text).map_err(|e| Error::input(src.display(), format!("not a bench JSON: {e}")))?;
        let table = markdown(&points);
        write_file(&req.markdown, &table)?;
        plot(&points).save(&req.plot)?;
        return Ok(table);
    }
    let base = match &req.config {
        Some(p) => Config::from_file(p)?,
        None => Config::default(),
    };
    if let Some(spec) = &req.point {
        let spec: PointSpec = serde_json::from_str(spec).map_err(|e| Error::input("--point", e))?;
        let p = run_point(&base, &spec)?;
        return serde_json::to_string(&p).map(|s| s + "\n").map_err(|e| Error::Internal(format!("a bench point as JSON: {e}")));
    }
    let specs = sweep(req.quick);
    let n = specs.len();
    let points = run_sweep(exe, req.config.as_deref(), &specs, |i, p| {
        eprintln!(
            "[{}/{n}] {}: {:.1} frames/s, agreement {:.4} %, median error {:.4} mm, peak {:.0} MiB",
            i + 1,
            p.spec,
            p.frames_per_s,
            100.0 * p.human_beam_agreement,
            p.median_range_error_m * 1e3,
            p.peak_rss_mb
        );
    })?;
    let json = serde_json::to_string_pretty(&points).map_err(|e| Error::Internal(format!("bench points as JSON: {e}")))?;
    write_file(&req.json, json)?;
    let mut table = markdown(&points);
    table += &bench_rates(&base, req.quick);
    table += &bench_terms(&base, req.quick);
    table += &bench_shares(&base, req.quick);
    table += &bench_stages(&base, req.quick);
    table += &bench_worlds(&base, req.quick);
    write_file(&req.markdown, &table)?;
    plot(&points).save(&req.plot)?;
    Ok(table)
}

/// The sensor model's terms timed on both backends (the raster one where Vulkan opens).
fn bench_terms(base: &Config, quick: bool) -> String {
    let (frames, repeats) = if quick { (4, 3) } else { (16, 5) };
    let mut rows = Vec::new();
    let mut notes = String::new();
    for backend in [BackendChoice::Raycast, BackendChoice::Raster] {
        match sensor_model_costs(base, &[backend], frames, repeats) {
            Ok(r) => rows.extend(r),
            Err(e) => notes += &format!("\n{backend:?}: not measured ({e})\n"),
        }
    }
    terms_markdown(&rows, frames, repeats) + &notes
}

/// The table of where the raster background's work runs, or a line saying why there is none.
fn bench_shares(base: &Config, quick: bool) -> String {
    let (frames, repeats) = if quick { (8, 3) } else { (32, 5) };
    match host_share_costs(base, frames, repeats) {
        Ok((device, rows)) => shares_markdown(&device, &rows, frames, repeats),
        Err(e) => format!("\nWhere the raster background's work runs: not measured ({e})\n"),
    }
}

/// The worlds table, or a line saying why there is none.
fn bench_worlds(base: &Config, quick: bool) -> String {
    let (frames, repeats) = if quick { (4, 3) } else { (16, 5) };
    match crate::commands::bench_worlds::world_costs(base, frames, repeats) {
        Ok(rows) => crate::commands::bench_worlds::worlds_markdown(&rows, frames, repeats),
        Err(e) => format!("\nFrames/s per world: not measured ({e})\n"),
    }
}

/// The per-stage table, or a line saying why there is none.
fn bench_stages(base: &Config, quick: bool) -> String {
    let (frames, repeats) = if quick { (4, 3) } else { (32, 5) };
    match stage_costs(base, frames, repeats) {
        Ok(rows) => stages_markdown(&rows, frames, repeats),
        Err(e) => format!("\nWhere a frame's time goes: not measured ({e})\n"),
    }
}

/// The triangle-rate table, or a line saying why there is none.
fn bench_rates(base: &Config, quick: bool) -> String {
    let counts: &[usize] = if quick { &[1_000, 16_000] } else { &[1_000, 4_000, 16_000, 64_000] };
    let mut gpu = crate::backend::Gpu::new(&base.device, false);
    match gpu.context().and_then(|ctx| Ok((ctx.device_name(), triangle_rates(&ctx, counts, 9)?))) {
        Ok((device, rows)) => rates_markdown(&device, &rows),
        Err(e) => format!("\nTriangle rate: not measured ({e})\n"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plot::tests::ink;

    fn point(projection: &str, refine: Refine, ms_per_frame: f64, agreement: f64) -> Point {
        Point {
            spec: PointSpec { projection: projection.into(), resolution: 1.0, lod: 0.0, refine, humans: 10, columns: 1024, frames: 4 },
            frames_per_s: 1e3 / ms_per_frame,
            ms_per_frame,
            peak_rss_mb: 100.0,
            human_beam_agreement: agreement,
            median_range_error_m: 0.0,
            p99_range_error_m: 0.0,
            triangles_per_frame: 1e5,
            raycast: RaycastTiming { frames_per_s: 5.0, build_ms: 50.0, cast_ms: 150.0 },
            stage_ms: StageMs { pose: 1.0, render_resample: 5.0, post: 1.0, write: 1.0 },
        }
    }

    #[test]
    fn the_figure_has_each_family_the_front_and_text() {
        let points = [
            point("cube", Refine::Exact, 40.0, 0.999),
            point("cube", Refine::None, 20.0, 0.99),
            point("cube", Refine::Plane, 25.0, 0.995),
            point("cylinder", Refine::Exact, 30.0, 0.998),
            point("beams", Refine::Exact, 60.0, 0.9995),
            point("raycast", Refine::Exact, 200.0, 1.0),
        ];
        let p = plot(&points);
        let names: Vec<&str> = p.series.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["cube, refine exact", "cube, refine none", "cube, refine plane", "cylinder, refine exact", "beam grid (exact)", "ray-cast backend", "Pareto", "reference cast"]);
        let img = p.render();
        assert_eq!(img.dimensions(), (1400, 650));
        // Every series' colour is drawn (markers, the front's line) and the title is text.
        for s in &p.series {
            assert!(img.pixels().filter(|px| px.0 == s.colour).count() > 20, "{} not drawn", s.name);
        }
        assert!(ink(&img, (300, 1100), (0, 40)) > 300);
    }
}
