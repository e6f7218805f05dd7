//! The HDF5 sequence file (stage 5). Layout (T frames, H rows, W columns, N humans):
//!
//! ```text
//! /range f32[T,H,W]  /xyz f32[T,H,W,3]  /label u8[T,H,W] (0, 1 human, 255 not scored)  /instance u16[T,H,W]
//! /class u16[T,H,W] (SemanticKITTI ids)
//! /velocity f32[T,H,W,3]  /background/range f32[T,H,W]  /intensity f32[T,H,W]
//! /clean/range f32[T,H,W]  /clean/label u8[T,H,W]  /clean/instance u16[T,H,W]  (sensor model on)
//! /sensor/time_s f64[T]  /sensor/column_time_s f64[T,W]  /sensor/world_from_sensor f64[T,4,4]
//! /sensor/velocity_mps f64[T,3]  /sensor/yaw_rate_rps f64[T]
//! /sensor/elevation_deg f32[H]  /sensor/azimuth_deg f32[W]
//! /humans/height_m f32[N]  /humans/weight_kg f32[N]  /humans/model str[N]
//! /humans/position_m f64[T,N,3]  /humans/heading_rad f32[T,N]
//! /humans/velocity_mps f32[T,N,3]  /humans/gait_phase f32[T,N]
//! /movers/kind str[M]  /movers/length_m f32[M]  /movers/width_m f32[M]  (M movers, when any:
//! /movers/position_m f64[T,M,3]  /movers/heading_rad f32[T,M]    instance N + 1 + j is mover j)
//! /movers/velocity_mps f32[T,M,3]  /movers/yaw_rate_rps f32[T,M]  /movers/pushed_by u32[M] (0: nobody)
//! ```
//!
//! Per-beam datasets are chunked one frame per chunk. Each frame's chunks are shuffled and
//! deflated here (in parallel, one task per dataset) and stored with HDF5's direct chunk write,
//! so the file is an ordinary shuffle+deflate file that every reader opens, but compression is
//! not serialised inside libhdf5. Each frame's column times are a row of their own chunk,
//! written with it. Small per-frame records (times, poses, human and mover states) are kept in
//! memory (a few dozen bytes per frame and person) and written at the end.
//!
//! Reproducibility: object modification times are switched off on the file (root group),
//! every group and every dataset, and the compressor is deterministic, so identical inputs
//! give byte-identical files.

use super::{FrameOutput, SequenceMeta};
use crate::error::{Error, Result};
use hdf5::types::VarLenUnicode;
use hdf5::{Dataset, Group, H5Type, Location};
use hdf5_sys::h5::hsize_t;
use hdf5_sys::h5d::H5Dwrite_chunk;
use hdf5_sys::h5p::H5P_DEFAULT;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// Compression of the per-beam HDF5 datasets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Compression {
    /// Stored raw (fastest, ~1.1 MB per HDL-32E frame of all outputs).
    None,
    /// Shuffle + deflate (zlib) at this level (0..=9); readable by every HDF5 reader.
    Deflate(u8),
}

impl Default for Compression {
    fn default() -> Self {
        Compression::Deflate(1)
    }
}

/// Which per-beam grid a dataset stores.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Grid {
    Range,
    Xyz,
    Label,
    Instance,
    Velocity,
    Background,
    Intensity,
    CleanRange,
    CleanLabel,
    CleanInstance,
    Class,
}

struct BeamDataset {
    grid: Grid,
    ds: Dataset,
    /// Element size in bytes (the shuffle filter's byte stride).
    elem: usize,
    shuffled: Vec<u8>,
    packed: Vec<u8>,
    zip: Option<flate2::Compress>,
}

pub(crate) struct H5Writer {
    file: Option<hdf5::File>,
    /// The final name, for messages.
    name: PathBuf,
    compression: Compression,
    beams: Vec<BeamDataset>,
    frames: usize,
    humans: usize,
    time_s: Vec<f64>,
    /// `/sensor/column_time_s`, written a frame (a row) at a time: its size grows with the
    /// sequence's length and the sensor's columns, so it is not kept until the end.
    column_time: Option<Dataset>,
    world_from_sensor: Vec<f64>,
    sensor_velocity_mps: Vec<f64>,
    sensor_yaw_rate_rps: Vec<f64>,
    position_m: Vec<f64>,
    heading_rad: Vec<f32>,
    velocity_mps: Vec<f32>,
    gait_phase: Vec<f32>,
    /// The movers' states, frame after frame.
    mover_position_m: Vec<f64>,
    mover_heading_rad: Vec<f32>,
    mover_velocity_mps: Vec<f32>,
    mover_yaw_rate_rps: Vec<f32>,
}

fn h5err(name: &Path) -> impl Fn(hdf5::Error) -> Error + '_ {
    move |e| write_error(name, e.to_string())
}

/// An HDF5 failure writing `name`. The library does not say why a write failed; a full disk
/// (the common cause) is checked for and said.
fn write_error(name: &Path, message: String) -> Error {
    let dir = name.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    Error::Hdf5 { path: name.to_path_buf(), message: with_disk_full(message, free_bytes(dir)) }
}

/// Below this many free bytes a failed write is put down to a full disk.
const DISK_FULL_BYTES: u64 = 16 << 20;

fn with_disk_full(message: String, free: Option<u64>) -> String {
    match free {
        Some(b) if b < DISK_FULL_BYTES => format!("{message} (disk full: {} KiB free on its file system)", b >> 10),
        _ => message,
    }
}

/// Bytes an unprivileged process may still write on the file system of `dir`.
fn free_bytes(dir: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: `c` is a NUL-terminated path and `st` a valid, writable statvfs.
    (unsafe { libc::statvfs(c.as_ptr(), &mut st) } == 0).then(|| st.f_bavail as u64 * st.f_frsize as u64)
}

fn vlu(name: &Path, s: &str) -> Result<VarLenUnicode> {
    VarLenUnicode::from_str(s).map_err(|e| Error::Hdf5 {
        path: name.to_path_buf(),
        message: format!(
            "string {:?} cannot be stored: {e}",
            s.chars().take(40).collect::<String>()
        ),
    })
}

fn attr_str(loc: &Location, key: &str, value: &str, name: &Path) -> Result<()> {
    let v = vlu(name, value)?;
    loc.new_attr::<VarLenUnicode>()
        .create(key)
        .and_then(|a| a.write_scalar(&v))
        .map_err(h5err(name))
}

fn attr_u64(loc: &Location, key: &str, value: u64, name: &Path) -> Result<()> {
    loc.new_attr::<u64>().create(key).and_then(|a| a.write_scalar(&value)).map_err(h5err(name))
}

fn group(parent: &Group, key: &str) -> hdf5::Result<Group> {
    parent.create_group_builder().obj_track_times(false).create(key)
}

/// A small contiguous dataset written in one go (`data.len()` = product of `shape`).
fn small<T: H5Type>(
    parent: &Group,
    key: &str,
    shape: &[usize],
    data: &[T],
) -> hdf5::Result<Dataset> {
    let ds = parent.new_dataset::<T>().shape(shape.to_vec()).obj_track_times(false).create(key)?;
    if !data.is_empty() {
        ds.write_raw(data)?;
    }
    Ok(ds)
}

impl H5Writer {
    /// Creates the file at `tmp` (truncating), all groups, attributes and the per-beam datasets.
    pub(crate) fn create(
        tmp: &Path,
        name: &Path,
        meta: &SequenceMeta,
        compression: Compression,
    ) -> Result<H5Writer> {
        let e = h5err(name);
        let (t, h, w) = (meta.frames, meta.sensor.rows(), meta.sensor.columns);
        let file = hdf5::File::with_options()
            .with_fcpl(|p| p.obj_track_times(false))
            .create(tmp)
            .map_err(&e)?;

        attr_str(&file, "pedscan_version", crate::version(), name)?;
        attr_u64(&file, "seed", meta.seed, name)?;
        attr_str(&file, "sensor", &meta.sensor.name, name)?;
        attr_str(&file, "config", &meta.config_toml, name)?;
        attr_u64(&file, "frames", t as u64, name)?;
        attr_u64(&file, "rows", h as u64, name)?;
        attr_u64(&file, "columns", w as u64, name)?;
        attr_u64(&file, "index", meta.index as u64, name)?;
        let prov: String = meta.provenance.iter().map(|(k, v)| format!("{k}={v}\n")).collect();
        attr_str(&file, "provenance", &prov, name)?;

        let mut specs: Vec<(Grid, &str, usize, &str, &str)> = vec![(
            Grid::Range,
            "range",
            0,
            "m",
            "Euclidean range of the first return per beam, 0 = no return",
        )];
        if meta.outputs.xyz {
            specs.push((
                Grid::Xyz,
                "xyz",
                3,
                "m",
                "Return point in the sensor frame (x forward, y left, z up), 0 = no return",
            ));
        }
        specs.push((Grid::Label, "label", 0, "1", "0 = background or no return, 1 = human, 255 = not scored (a recorded background's own person or other return that scene.ignore_moving or scene.ignore_labels marks: losses and evaluation skip it)"));
        specs.push((Grid::Instance, "instance", 0, "1", "0 = none, k <= N = k-th human of /humans, k > N = mover k - N of /movers"));
        if meta.outputs.class {
            specs.push((Grid::Class, "class", 0, "1", "SemanticKITTI class: 30 person, 254 moving person, else the class of the background surface hit (50 where the background does not say: a glTF without extras.class, a recording); 0 = no return or not scored"));
        }
        if meta.outputs.velocity {
            specs.push((
                Grid::Velocity,
                "velocity",
                3,
                "m/s",
                "Velocity of the hit surface point relative to the sensor, sensor frame",
            ));
        }
        if meta.outputs.background {
            specs.push((
                Grid::Background,
                "background/range",
                0,
                "m",
                "Range of the background alone (no humans), 0 = no return",
            ));
        }
        specs.push((
            Grid::Intensity,
            "intensity",
            0,
            "1",
            "Return intensity: the recording's own on recorded beams, else intensity_scale x reflectance x cos(incidence) (docs/sensor-model.md); 0 = no return",
        ));
        if meta.outputs.clean {
            specs.push((Grid::CleanRange, "clean/range", 0, "m", "Range before the sensor model (no noise, dropout or divergence), 0 = no return"));
            specs.push((Grid::CleanLabel, "clean/label", 0, "1", "Label before the sensor model"));
            specs.push((Grid::CleanInstance, "clean/instance", 0, "1", "Instance before the sensor model"));
        }
        let bg = if meta.outputs.background {
            Some(group(&file, "background").map_err(&e)?)
        } else {
            None
        };
        let clean = if meta.outputs.clean { Some(group(&file, "clean").map_err(&e)?) } else { None };

        let mut beams = Vec::with_capacity(specs.len());
        for (grid, key, comps, units, desc) in specs {
            let mut shape = vec![t, h, w];
            if comps > 0 {
                shape.push(comps);
            }
            let mut chunk = shape.clone();
            chunk[0] = 1;
            let (parent, leaf): (&Group, &str) = match key.split_once('/') {
                Some(("clean", leaf)) => (clean.as_ref().expect("clean group exists"), leaf),
                Some((_, leaf)) => (bg.as_ref().expect("background group exists"), leaf),
                None => (&file, key),
            };
            let (ds, elem) = match grid {
                Grid::Label | Grid::CleanLabel => (beam_dataset::<u8>(parent, leaf, shape, chunk, compression), 1),
                Grid::Instance | Grid::CleanInstance | Grid::Class => (beam_dataset::<u16>(parent, leaf, shape, chunk, compression), 2),
                _ => (beam_dataset::<f32>(parent, leaf, shape, chunk, compression), 4),
            };
            let ds = ds.map_err(&e)?;
            attr_str(&ds, "units", units, name)?;
            attr_str(&ds, "description", desc, name)?;
            let zip = match compression {
                Compression::None => None,
                Compression::Deflate(level) => {
                    Some(flate2::Compress::new(flate2::Compression::new(level as u32), true))
                }
            };
            beams.push(BeamDataset {
                grid,
                ds,
                elem,
                shuffled: Vec::new(),
                packed: Vec::new(),
                zip,
            });
        }

        // The beam table is known up front.
        let sensor = group(&file, "sensor").map_err(&e)?;
        let column_time = sensor
            .new_dataset::<f64>()
            .shape(vec![t, w])
            .chunk(vec![1, w])
            .obj_track_times(false)
            .create("column_time_s")
            .map_err(&e)?;
        attr_str(&column_time, "units", "s", name)?;
        attr_str(
            &column_time,
            "description",
            "Time each column's beams were fired, since the start of the sequence (rolling shutter; all the frame's time without)",
            name,
        )?;
        let el: Vec<f32> = meta.sensor.elevation_deg.iter().map(|&d| d as f32).collect();
        let az: Vec<f32> = (0..w).map(|c| meta.sensor.azimuth_rad(c).to_degrees() as f32).collect();
        let ds = small(&sensor, "elevation_deg", &[h], &el).map_err(&e)?;
        attr_str(&ds, "units", "deg", name)?;
        attr_str(&ds, "description", "Elevation of each row's beam, row 0 = highest", name)?;
        let ds = small(&sensor, "azimuth_deg", &[w], &az).map_err(&e)?;
        attr_str(&ds, "units", "deg", name)?;
        attr_str(
            &ds,
            "description",
            "Azimuth of each column's centre, counter-clockwise from +x",
            name,
        )?;

        let n = meta.humans.len();
        Ok(H5Writer {
            file: Some(file),
            name: name.to_path_buf(),
            compression,
            beams,
            frames: t,
            humans: n,
            time_s: Vec::with_capacity(t),
            column_time: Some(column_time),
            world_from_sensor: Vec::with_capacity(t * 16),
            sensor_velocity_mps: Vec::with_capacity(t * 3),
            sensor_yaw_rate_rps: Vec::with_capacity(t),
            position_m: Vec::with_capacity(t * n * 3),
            heading_rad: Vec::with_capacity(t * n),
            velocity_mps: Vec::with_capacity(t * n * 3),
            gait_phase: Vec::with_capacity(t * n),
            mover_position_m: Vec::with_capacity(t * meta.movers.len() * 3),
            mover_heading_rad: Vec::with_capacity(t * meta.movers.len()),
            mover_velocity_mps: Vec::with_capacity(t * meta.movers.len() * 3),
            mover_yaw_rate_rps: Vec::with_capacity(t * meta.movers.len()),
        })
    }

    /// Writes frame `index` (already validated by the caller).
    pub(crate) fn write_frame(&mut self, index: usize, f: &FrameOutput) -> Result<()> {
        let sources: Vec<&[u8]> = self
            .beams
            .iter()
            .map(|b| -> &[u8] {
                match b.grid {
                    Grid::Range => bytemuck::cast_slice(&f.range),
                    Grid::Xyz => bytemuck::cast_slice(&f.xyz),
                    Grid::Label => &f.label,
                    Grid::Instance => bytemuck::cast_slice(&f.instance),
                    Grid::Velocity => bytemuck::cast_slice(&f.velocity),
                    Grid::Background => bytemuck::cast_slice(&f.background_range),
                    Grid::Intensity => bytemuck::cast_slice(&f.intensity),
                    Grid::CleanRange => bytemuck::cast_slice(&f.clean_range),
                    Grid::CleanLabel => &f.clean_label,
                    Grid::CleanInstance => bytemuck::cast_slice(&f.clean_instance),
                    Grid::Class => bytemuck::cast_slice(&f.class),
                }
            })
            .collect();
        if let Compression::Deflate(_) = self.compression {
            let name = &self.name;
            self.beams.par_iter_mut().zip(sources.par_iter()).try_for_each(|(b, src)| {
                shuffle(src, b.elem, &mut b.shuffled);
                let zip = b.zip.as_mut().expect("deflate writer has a compressor");
                deflate(zip, &b.shuffled, &mut b.packed).map_err(|m| Error::Hdf5 {
                    path: name.clone(),
                    message: format!("deflate of frame {index} failed: {m}"),
                })
            })?;
        }
        for (b, src) in self.beams.iter().zip(&sources) {
            let data: &[u8] = match self.compression {
                Compression::None => src,
                Compression::Deflate(_) => &b.packed,
            };
            write_chunk(&b.ds, index, data).map_err(|m| write_error(&self.name, format!("writing frame {index} of {}: {m}", b.ds.name())))?;
        }
        self.time_s.push(f.time_s);
        if let Some(ds) = &self.column_time {
            write_chunk(ds, index, bytemuck::cast_slice(&f.column_time_s))
                .map_err(|m| write_error(&self.name, format!("writing frame {index} of {}: {m}", ds.name())))?;
        }
        self.world_from_sensor.extend(f.world_from_sensor.iter().flatten());
        self.sensor_velocity_mps.extend_from_slice(&f.sensor_velocity_mps);
        self.sensor_yaw_rate_rps.push(f.sensor_yaw_rate_rps);
        for hs in &f.humans {
            self.position_m.extend_from_slice(&hs.position_m);
            self.heading_rad.push(hs.heading_rad);
            self.velocity_mps.extend_from_slice(&hs.velocity_mps);
            self.gait_phase.push(hs.gait_phase);
        }
        for ms in &f.movers {
            self.mover_position_m.extend_from_slice(&ms.position_m);
            self.mover_heading_rad.push(ms.heading_rad);
            self.mover_velocity_mps.extend_from_slice(&ms.velocity_mps);
            self.mover_yaw_rate_rps.push(ms.yaw_rate_rps);
        }
        Ok(())
    }

    /// Writes the per-frame records and the human table, then closes the file.
    pub(crate) fn finish(mut self, meta: &SequenceMeta) -> Result<()> {
        let name = self.name.clone();
        let e = h5err(&name);
        let file = self.file.take().expect("file is open until finish");
        let (t, n) = (self.frames, self.humans);
        {
            let sensor = file.group("sensor").map_err(&e)?;
            let ds = small(&sensor, "time_s", &[t], &self.time_s).map_err(&e)?;
            attr_str(&ds, "units", "s", &name)?;
            attr_str(
                &ds,
                "description",
                "Time of each frame since the start of the sequence",
                &name,
            )?;
            let ds = small(&sensor, "world_from_sensor", &[t, 4, 4], &self.world_from_sensor)
                .map_err(&e)?;
            attr_str(&ds, "units", "m", &name)?;
            attr_str(&ds, "description", "Row-major 4x4 pose of the sensor in the world", &name)?;
            let ds = small(&sensor, "velocity_mps", &[t, 3], &self.sensor_velocity_mps).map_err(&e)?;
            attr_str(&ds, "units", "m/s", &name)?;
            attr_str(&ds, "description", "Velocity of the sensor, world frame (derivative of its trajectory)", &name)?;
            let ds = small(&sensor, "yaw_rate_rps", &[t], &self.sensor_yaw_rate_rps).map_err(&e)?;
            attr_str(&ds, "units", "rad/s", &name)?;
            attr_str(&ds, "description", "Yaw rate of the sensor about the world z axis", &name)?;

            let hg = group(&file, "humans").map_err(&e)?;
            let height: Vec<f32> = meta.humans.iter().map(|h| h.height_m).collect();
            let weight: Vec<f32> = meta.humans.iter().map(|h| h.weight_kg).collect();
            let model =
                meta.humans.iter().map(|h| vlu(&name, &h.model)).collect::<Result<Vec<_>>>()?;
            let recs: [(&str, &str, &str, Dataset); 7] = [
                (
                    "height_m",
                    "m",
                    "Body height",
                    small(&hg, "height_m", &[n], &height).map_err(&e)?,
                ),
                (
                    "weight_kg",
                    "kg",
                    "Body weight",
                    small(&hg, "weight_kg", &[n], &weight).map_err(&e)?,
                ),
                (
                    "model",
                    "",
                    "Model name (glTF file stem, +clothesMM where dressed, +backpack, +bag or +bags where carrying)",
                    small(&hg, "model", &[n], &model).map_err(&e)?,
                ),
                (
                    "position_m",
                    "m",
                    "Position in the world frame",
                    small(&hg, "position_m", &[t, n, 3], &self.position_m).map_err(&e)?,
                ),
                (
                    "heading_rad",
                    "rad",
                    "Heading in the world frame",
                    small(&hg, "heading_rad", &[t, n], &self.heading_rad).map_err(&e)?,
                ),
                (
                    "velocity_mps",
                    "m/s",
                    "Velocity in the world frame",
                    small(&hg, "velocity_mps", &[t, n, 3], &self.velocity_mps).map_err(&e)?,
                ),
                (
                    "gait_phase",
                    "1",
                    "Gait phase in [0, 1)",
                    small(&hg, "gait_phase", &[t, n], &self.gait_phase).map_err(&e)?,
                ),
            ];
            for (_, units, desc, ds) in &recs {
                if !units.is_empty() {
                    attr_str(ds, "units", units, &name)?;
                }
                attr_str(ds, "description", desc, &name)?;
            }
            let m = meta.movers.len();
            if m > 0 {
                let mg = group(&file, "movers").map_err(&e)?;
                let kind = meta.movers.iter().map(|v| vlu(&name, &v.kind)).collect::<Result<Vec<_>>>()?;
                let length: Vec<f32> = meta.movers.iter().map(|v| v.length_m).collect();
                let width: Vec<f32> = meta.movers.iter().map(|v| v.width_m).collect();
                let pushed_by: Vec<u32> = meta.movers.iter().map(|v| v.pushed_by).collect();
                let recs: [(&str, &str, Dataset); 8] = [
                    ("", "What it is (car, cyclist, robot, cart, stroller, trolley); its instance is the number of people + 1 + its index", small(&mg, "kind", &[m], &kind).map_err(&e)?),
                    ("m", "Length of its footprint", small(&mg, "length_m", &[m], &length).map_err(&e)?),
                    ("m", "Width of its footprint", small(&mg, "width_m", &[m], &width).map_err(&e)?),
                    ("m", "Centre of its footprint on the ground, world frame", small(&mg, "position_m", &[t, m, 3], &self.mover_position_m).map_err(&e)?),
                    ("rad", "Heading in the world frame", small(&mg, "heading_rad", &[t, m], &self.mover_heading_rad).map_err(&e)?),
                    ("m/s", "Velocity in the world frame", small(&mg, "velocity_mps", &[t, m, 3], &self.mover_velocity_mps).map_err(&e)?),
                    ("rad/s", "Turning rate about the world's vertical: a point r from the centre moves at velocity + w z x r", small(&mg, "yaw_rate_rps", &[t, m], &self.mover_yaw_rate_rps).map_err(&e)?),
                    ("", "The person pushing it (their instance, 1..N; a stroller, a trolley), 0 where nobody does", small(&mg, "pushed_by", &[m], &pushed_by).map_err(&e)?),
                ];
                for (units, desc, ds) in &recs {
                    if !units.is_empty() {
                        attr_str(ds, "units", units, &name)?;
                    }
                    attr_str(ds, "description", desc, &name)?;
                }
            }
        }
        // Every handle into the file must be gone before the close, or libhdf5 defers it.
        self.beams.clear();
        self.column_time = None;
        file.close().map_err(&e)?;
        Ok(())
    }
}

fn beam_dataset<T: H5Type>(
    parent: &Group,
    key: &str,
    shape: Vec<usize>,
    chunk: Vec<usize>,
    compression: Compression,
) -> hdf5::Result<Dataset> {
    let b = parent.new_dataset::<T>().shape(shape).chunk(chunk).obj_track_times(false);
    let b = match compression {
        Compression::None => b,
        // Order matters: the pipeline is shuffle, then deflate, exactly as done in `shuffle`
        // and `deflate` below before the direct chunk write.
        Compression::Deflate(level) => b.shuffle().deflate(level),
    };
    b.create(key)
}

/// HDF5's shuffle filter: byte `j` of element `i` goes to `j * n + i`.
fn shuffle(src: &[u8], elem: usize, dst: &mut Vec<u8>) {
    dst.clear();
    dst.resize(src.len(), 0);
    if elem <= 1 {
        dst.copy_from_slice(src);
        return;
    }
    let n = src.len() / elem;
    match elem {
        2 => {
            let (a, b) = dst.split_at_mut(n);
            for (i, e) in src.chunks_exact(2).enumerate() {
                a[i] = e[0];
                b[i] = e[1];
            }
        }
        4 => {
            let (a, rest) = dst.split_at_mut(n);
            let (b, rest) = rest.split_at_mut(n);
            let (c, d) = rest.split_at_mut(n);
            for (i, e) in src.chunks_exact(4).enumerate() {
                a[i] = e[0];
                b[i] = e[1];
                c[i] = e[2];
                d[i] = e[3];
            }
        }
        _ => {
            for (i, e) in src.chunks_exact(elem).enumerate() {
                for (j, &byte) in e.iter().enumerate() {
                    dst[j * n + i] = byte;
                }
            }
        }
    }
    // Trailing bytes that do not fill an element stay in place (as in libhdf5).
    let tail = n * elem;
    dst[tail..].copy_from_slice(&src[tail..]);
}

/// One zlib stream (what HDF5's deflate filter stores) of `src` into `dst`.
fn deflate(
    zip: &mut flate2::Compress,
    src: &[u8],
    dst: &mut Vec<u8>,
) -> std::result::Result<(), String> {
    zip.reset();
    dst.clear();
    dst.reserve(src.len() + src.len() / 16 + 1024);
    loop {
        let done = zip.total_in() as usize;
        let status = zip
            .compress_vec(&src[done..], dst, flate2::FlushCompress::Finish)
            .map_err(|e| e.to_string())?;
        match status {
            flate2::Status::StreamEnd => return Ok(()),
            _ => dst.reserve(dst.capacity().max(4096)),
        }
    }
}

/// Stores `data` (already filtered) as the chunk of frame `frame`.
fn write_chunk(ds: &Dataset, frame: usize, data: &[u8]) -> std::result::Result<(), String> {
    let offset: [hsize_t; 4] = [frame as hsize_t, 0, 0, 0];
    let id = ds.id();
    // SAFETY: `id` is a live dataset of rank <= 4 (the offset array covers every dimension),
    // `data` is a valid byte buffer of `data.len()` bytes for the duration of the call, and the
    // call is made under hdf5-metno's global lock like every other libhdf5 call.
    let rc = hdf5::sync::sync(|| unsafe {
        H5Dwrite_chunk(id, H5P_DEFAULT, 0, offset.as_ptr(), data.len(), data.as_ptr().cast())
    });
    if rc < 0 {
        Err(format!("H5Dwrite_chunk failed ({} bytes)", data.len()))
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_on_a_full_file_system_says_so() {
        let m = with_disk_full("H5Dwrite_chunk(): can't write".into(), Some(4096));
        assert!(m.starts_with("H5Dwrite_chunk(): can't write") && m.contains("disk full: 4 KiB free"), "{m}");
        assert_eq!(with_disk_full("x".into(), Some(1 << 40)), "x");
        assert_eq!(with_disk_full("x".into(), None), "x");
        let free = free_bytes(Path::new(".")).expect("statvfs of the working folder");
        assert!(free > 0);
        assert!(free_bytes(Path::new("/no/such/folder")).is_none());
    }

    /// The free bytes are what `df` (coreutils, its own arithmetic over the same counters)
    /// reports as available, to within what other processes write meanwhile.
    #[test]
    fn free_bytes_agree_with_df() {
        let out = std::process::Command::new("df").args(["-B1", "--output=avail", "."]).output().expect("df runs");
        assert!(out.status.success(), "df failed: {out:?}");
        let text = String::from_utf8(out.stdout).expect("df prints text");
        let df: u64 = text.lines().nth(1).and_then(|l| l.trim().parse().ok()).unwrap_or_else(|| panic!("df printed {text:?}"));
        let ours = free_bytes(Path::new(".")).expect("statvfs of the working folder");
        let apart = ours.abs_diff(df);
        assert!(apart <= (64 << 20).max(df / 100), "free_bytes {ours} against df's {df}");
    }

    /// A raw chunk lands where it is written, and a write libhdf5 refuses (a frame past the
    /// dataset's extent) is an error, not a silent success.
    #[test]
    fn a_raw_chunk_is_written_in_place_or_refused() {
        let dir = tempfile::tempdir().unwrap();
        let file = hdf5::File::create(dir.path().join("c.h5")).unwrap();
        let ds = file.new_dataset::<u8>().shape([2, 3]).chunk([1, 3]).create("d").unwrap();
        write_chunk(&ds, 1, &[7, 8, 9]).unwrap();
        assert_eq!(ds.read_raw::<u8>().unwrap(), vec![0, 0, 0, 7, 8, 9]);
        let e = write_chunk(&ds, 5, &[1, 2, 3]).unwrap_err();
        assert_eq!(e, "H5Dwrite_chunk failed (3 bytes)");
    }

    #[test]
    fn shuffle_matches_hdf5_layout() {
        let src: Vec<u8> = (0..12).collect();
        let mut dst = Vec::new();
        shuffle(&src, 4, &mut dst);
        assert_eq!(dst, vec![0, 4, 8, 1, 5, 9, 2, 6, 10, 3, 7, 11]);
        shuffle(&src, 2, &mut dst);
        assert_eq!(dst, vec![0, 2, 4, 6, 8, 10, 1, 3, 5, 7, 9, 11]);
        shuffle(&src[..7], 3, &mut dst);
        assert_eq!(dst, vec![0, 3, 1, 4, 2, 5, 6]);
    }
}
