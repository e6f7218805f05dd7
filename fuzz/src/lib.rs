//! What every fuzz target shares: pedscan's readers take paths, so each input is written to a
//! file in a folder made once per fuzzing process, then read back by the real reader.
//!
//! A target treats `Err` as the right answer to bad input; only a panic, an abort, a timeout
//! or running out of memory is a finding (libFuzzer reports those).

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// This process's scratch folder under the system temporary folder (`TMPDIR`), made on first
/// use. `tools/fuzz.sh` points `TMPDIR` at a folder it removes after the run.
fn scratch_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("pedscan-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("cannot create the fuzzing scratch folder");
        dir
    })
}

/// Writes `data` to `name` in the scratch folder (replacing the last input) and returns the
/// path, for a reader to open.
pub fn input_file(name: &str, data: &[u8]) -> PathBuf {
    let path = scratch_dir().join(name);
    std::fs::write(&path, data).expect("cannot write the fuzz input to the scratch folder");
    path
}

/// Projects a scan onto the HDL-32E grid, as a recording does with every frame it reads.
pub fn project(scan: &pedscan::input::Scan) {
    static PROJECTOR: OnceLock<pedscan::input::project::Projector> = OnceLock::new();
    let projector = PROJECTOR.get_or_init(|| pedscan::input::project::Projector::new(&pedscan::sensor::Sensor::hdl32e()));
    let mut ranges = Vec::new();
    projector.project(scan, &mut ranges);
}

/// Reads a track file in `format` and samples every track that is long enough to be used, at
/// its start, middle and end, as the planner does.
pub fn tracks(data: &[u8], format: pedscan::input::tracks::TrackFormat) {
    use pedscan::input::tracks;
    let path = input_file("tracks.txt", data);
    if let Ok(all) = tracks::read_tracks(&path, format, &tracks::TrackOptions::default()) {
        for t in tracks::drop_short(all, 0.0) {
            let (first, last) = (t.times_s[0], *t.times_s.last().unwrap());
            for s in [first, 0.5 * (first + last), last] {
                let _ = t.sample(s);
            }
        }
    }
}
