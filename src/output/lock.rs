//! [`SequenceLock`]: while a run writes sequence N, it holds an advisory lock (`flock`) on
//! `seq_NNNNNN.lock` in the output folder. A second run that reaches the same sequence fails
//! with a bad-input error naming the holder instead of deleting or replacing the first run's
//! temporaries; runs that write different sequences (shards of one job) never wait for each
//! other. The kernel drops the lock when its process dies, however it dies, so a file left
//! by a killed run is taken over by the next one.

use crate::error::{Error, Result};
use std::io::{Read, Seek, Write};
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

/// The lock on one sequence of an output folder; released (and its file removed) on drop.
#[derive(Debug)]
pub struct SequenceLock {
    path: PathBuf,
    file: Option<std::fs::File>,
    taken_over: bool,
}

impl SequenceLock {
    /// Locks sequence `index` of `out_dir` (which must exist), or fails naming the run that
    /// holds it.
    pub fn acquire(out_dir: &Path, index: usize) -> Result<SequenceLock> {
        let path = out_dir.join(format!("{}.lock", super::sequence_stem(index)));
        // A holder may remove the file between our open and our lock: then we locked a file
        // that no longer has the name, and try again on the new one.
        for _ in 0..16 {
            let existed = path.exists();
            let mut file = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
                .map_err(|e| match e.kind() {
                    // The first file a run writes: a folder it may not write in (or a lock file
                    // another user left) is the user's to fix.
                    std::io::ErrorKind::PermissionDenied | std::io::ErrorKind::ReadOnlyFilesystem => {
                        Error::input(path.display(), format!("cannot open the run's lock file in the output folder: {e}"))
                    }
                    _ => Error::io(&path, e),
                })?;
            match file.try_lock() {
                Ok(()) => {}
                Err(std::fs::TryLockError::WouldBlock) => {
                    let mut holder = String::new();
                    let _ = file.read_to_string(&mut holder);
                    let holder = holder.trim();
                    let holder = if holder.is_empty() { "another pedscan run".to_string() } else { holder.to_string() };
                    return Err(Error::input(
                        path.display(),
                        format!("sequence {index} is being written by {holder}; wait for it, or write to another --out"),
                    ));
                }
                Err(std::fs::TryLockError::Error(e)) => return Err(Error::io(&path, e)),
            }
            let ours = file.metadata().map_err(|e| Error::io(&path, e))?.ino();
            if std::fs::metadata(&path).map(|m| m.ino()).ok() != Some(ours) {
                continue;
            }
            let holder = format!(
                "pedscan {} (pid {} on {})",
                env!("CARGO_PKG_VERSION"),
                std::process::id(),
                hostname().unwrap_or_else(|| "this host".into())
            );
            file.set_len(0)
                .and_then(|_| file.rewind())
                .and_then(|_| file.write_all(holder.as_bytes()))
                .map_err(|e| Error::io(&path, e))?;
            return Ok(SequenceLock { path, file: Some(file), taken_over: existed });
        }
        Err(Error::Internal(format!("{}: the lock file keeps being replaced", path.display())))
    }
}

impl SequenceLock {
    /// Whether the lock file was there, unlocked, before this run locked it: a run died while
    /// writing the sequence (a lock file lives from the sequence's start until its manifest
    /// line is written).
    pub fn taken_over(&self) -> bool {
        self.taken_over
    }
}

impl Drop for SequenceLock {
    fn drop(&mut self) {
        // Remove the name while still holding the lock (a run that opened it meanwhile sees
        // the name gone and retries), then unlock by closing.
        let _ = std::fs::remove_file(&self.path);
        drop(self.file.take());
    }
}

fn hostname() -> Option<String> {
    let h = std::fs::read_to_string("/proc/sys/kernel/hostname").ok()?;
    let h = h.trim();
    (!h.is_empty()).then(|| h.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_locked_sequence_is_refused_naming_the_holder_and_freed_on_drop() {
        let dir = tempfile::tempdir().unwrap();
        let a = SequenceLock::acquire(dir.path(), 3).unwrap();
        let e = SequenceLock::acquire(dir.path(), 3).unwrap_err();
        assert!(e.is_input(), "{e}");
        let msg = e.to_string();
        assert!(msg.contains("seq_000003.lock") && msg.contains(&format!("pid {}", std::process::id())), "{msg}");
        // Another sequence of the same folder is free.
        let b = SequenceLock::acquire(dir.path(), 4).unwrap();
        drop(a);
        assert!(!dir.path().join("seq_000003.lock").exists());
        let _again = SequenceLock::acquire(dir.path(), 3).unwrap();
        drop(b);
        assert!(!dir.path().join("seq_000004.lock").exists());
    }

    #[test]
    fn a_lock_file_left_by_a_dead_run_is_taken_over() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("seq_000000.lock"), "pedscan (pid 1 on gone)").unwrap();
        let lock = SequenceLock::acquire(dir.path(), 0).unwrap();
        assert!(lock.taken_over());
        assert!(!SequenceLock::acquire(dir.path(), 1).unwrap().taken_over());
        let text = std::fs::read_to_string(dir.path().join("seq_000000.lock")).unwrap();
        assert!(text.contains(&format!("pid {}", std::process::id())), "{text}");
        drop(lock);
    }
}
