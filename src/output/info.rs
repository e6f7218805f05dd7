//! `pedscan info FILE.h5`: a human-readable summary of a sequence file (stage 5, read side).

use crate::error::{Error, Result};
use hdf5::types::VarLenUnicode;
use hdf5::{Dataset, Group};
use std::fmt::Write as _;
use std::path::Path;

/// Histogram resolution for the median range, metres.
const MEDIAN_BIN_M: f64 = 0.01;

/// Summarises a sequence file: frames, grid, sensor, seed, version, humans, dataset shapes
/// and compression, fraction of human beams, range statistics and time span.
///
/// A missing, non-HDF5 or non-pedscan file is an input error naming `path`.
pub fn info(path: &Path) -> Result<String> {
    let shown = path.display();
    if !path.exists() {
        return Err(Error::input(shown, "no such file"));
    }
    if path.is_dir() {
        return Err(Error::input(shown, "is a directory, not an HDF5 file"));
    }
    let file = hdf5::File::open(path)
        .map_err(|e| Error::input(&shown, format!("not a readable HDF5 file ({e})")))?;
    let bad = |m: String| Error::input(&shown, m);
    let range = file
        .dataset("range")
        .map_err(|_| bad("HDF5 file without /range: not a pedscan sequence".into()))?;
    let shape = range.shape();
    if shape.len() != 3 {
        return Err(bad(format!("/range has shape {shape:?}, expected [frames, rows, columns]")));
    }
    let (t, h, w) = (shape[0], shape[1], shape[2]);
    let h5 = |e: hdf5::Error| bad(format!("cannot read: {e}"));

    let mut s = String::new();
    let str_attr = |k: &str| -> String {
        file.attr(k)
            .and_then(|a| a.read_scalar::<VarLenUnicode>())
            .map(|v| v.as_str().to_string())
            .unwrap_or_else(|_| "?".into())
    };
    let u64_attr = |k: &str| -> String {
        file.attr(k)
            .and_then(|a| a.read_scalar::<u64>())
            .map(|v| v.to_string())
            .unwrap_or_else(|_| "?".into())
    };
    let _ = writeln!(s, "file:      {shown}");
    let _ = writeln!(s, "pedscan:   {}", str_attr("pedscan_version"));
    let _ = writeln!(s, "sensor:    {}", str_attr("sensor"));
    let _ = writeln!(s, "seed:      {}", u64_attr("seed"));
    let _ = writeln!(s, "frames:    {t}");
    let _ = writeln!(s, "grid:      {h} rows x {w} columns");
    let prov = str_attr("provenance");
    if prov != "?" && !prov.is_empty() {
        let _ = writeln!(s, "source:    {}", prov.lines().collect::<Vec<_>>().join(", "));
    }

    if let Ok(ts) = file.dataset("sensor/time_s").and_then(|d| d.read_raw::<f64>()) {
        if let (Some(a), Some(b)) = (ts.first(), ts.last()) {
            let _ = writeln!(s, "time:      {a:.3} .. {b:.3} s ({:.3} s)", b - a);
        }
    }

    // Humans.
    if let Ok(g) = file.group("humans") {
        let height = g.dataset("height_m").and_then(|d| d.read_raw::<f32>()).unwrap_or_default();
        let weight = g.dataset("weight_kg").and_then(|d| d.read_raw::<f32>()).unwrap_or_default();
        let model =
            g.dataset("model").and_then(|d| d.read_raw::<VarLenUnicode>()).unwrap_or_default();
        let _ = writeln!(s, "humans:    {}", height.len());
        for (k, hm) in height.iter().enumerate() {
            let m = model.get(k).map(|m| m.as_str()).unwrap_or("?");
            let wk = weight.get(k).copied().unwrap_or(f32::NAN);
            let _ = writeln!(s, "  {:>3}  {m:<24} {hm:.3} m  {wk:.1} kg", k + 1);
        }
    } else {
        let _ = writeln!(s, "humans:    (no /humans group)");
    }

    // Datasets.
    let _ = writeln!(s, "datasets:");
    let mut list = Vec::new();
    collect_datasets(&file, "", &mut list);
    for (name, ds) in &list {
        let dtype = ds
            .dtype()
            .ok()
            .and_then(|d| d.to_descriptor().ok())
            .map(|d| format!("{d}"))
            .unwrap_or_else(|| "?".into());
        let filters: Vec<String> = ds.filters().iter().map(|f| format!("{f:?}")).collect();
        let comp = if filters.is_empty() { "none".to_string() } else { filters.join(" + ") };
        let stored = ds.storage_size();
        let raw = ds.size() * ds.dtype().map(|d| d.size()).unwrap_or(0);
        let ratio =
            if stored > 0 { format!("{:.2}x", raw as f64 / stored as f64) } else { "-".into() };
        let _ = writeln!(
            s,
            "  /{name:<28} {dtype:<10} {:<22} {comp}  ({} stored, {ratio})",
            format!("{:?}", ds.shape()),
            human_bytes(stored)
        );
    }

    // Per-beam statistics, frame by frame (sequences can be long).
    let label = file.dataset("label").ok();
    let mut returns = 0u64;
    let mut human = 0u64;
    let mut min = f32::INFINITY;
    let mut max = 0f32;
    let mut hist: Vec<u64> = Vec::new();
    for f in 0..t {
        let r = range.read_slice_2d::<f32, _>((f, .., ..)).map_err(h5)?;
        for &v in r.iter() {
            if v > 0.0 && v.is_finite() {
                returns += 1;
                min = min.min(v);
                max = max.max(v);
                let bin = (v as f64 / MEDIAN_BIN_M) as usize;
                if bin >= hist.len() {
                    hist.resize(bin + 1, 0);
                }
                hist[bin] += 1;
            }
        }
        if let Some(l) = &label {
            let l = l.read_slice_2d::<u8, _>((f, .., ..)).map_err(h5)?;
            human += l.iter().filter(|&&v| v == 1).count() as u64;
        }
    }
    let beams = (t * h * w) as u64;
    let pct = |a: u64, b: u64| if b > 0 { 100.0 * a as f64 / b as f64 } else { 0.0 };
    let _ = writeln!(s, "returns:   {returns} of {beams} beams ({:.1} %)", pct(returns, beams));
    let _ = writeln!(
        s,
        "human:     {human} beams ({:.3} % of beams, {:.3} % of returns)",
        pct(human, beams),
        pct(human, returns)
    );
    if returns > 0 {
        let half = returns.div_ceil(2);
        let mut acc = 0u64;
        let mut median = 0.0;
        for (i, &c) in hist.iter().enumerate() {
            acc += c;
            if acc >= half {
                median = (i as f64 + 0.5) * MEDIAN_BIN_M;
                break;
            }
        }
        let _ = writeln!(s, "range:     min {min:.3} m, median {median:.2} m, max {max:.3} m");
    } else {
        let _ = writeln!(s, "range:     no returns");
    }
    Ok(s)
}

fn collect_datasets(g: &Group, prefix: &str, out: &mut Vec<(String, Dataset)>) {
    let Ok(names) = g.member_names() else { return };
    for n in names {
        let full = if prefix.is_empty() { n.clone() } else { format!("{prefix}/{n}") };
        if let Ok(ds) = g.dataset(&n) {
            out.push((full, ds));
        } else if let Ok(sub) = g.group(&n) {
            collect_datasets(&sub, &full, out);
        }
    }
}

fn human_bytes(b: u64) -> String {
    match b {
        b if b >= 1 << 30 => format!("{:.2} GiB", b as f64 / (1u64 << 30) as f64),
        b if b >= 1 << 20 => format!("{:.2} MiB", b as f64 / (1u64 << 20) as f64),
        b if b >= 1 << 10 => format!("{:.1} KiB", b as f64 / 1024.0),
        b => format!("{b} B"),
    }
}

#[cfg(test)]
mod tests {
    use super::human_bytes;

    #[test]
    fn sizes_take_the_largest_unit_they_fill() {
        assert_eq!(human_bytes(0), "0 B");
        assert_eq!(human_bytes(1023), "1023 B");
        assert_eq!(human_bytes(1024), "1.0 KiB");
        assert_eq!(human_bytes(1536), "1.5 KiB");
        assert_eq!(human_bytes((1 << 20) - 1), "1024.0 KiB");
        assert_eq!(human_bytes(1 << 20), "1.00 MiB");
        assert_eq!(human_bytes(5 << 29), "2.50 GiB");
    }
}
