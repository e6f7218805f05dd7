//! Names and renames of a sequence's files: each is written under a temporary name and
//! renamed once complete, so a final name always holds a whole file (a leaf module: every
//! format's writer uses it, and it uses none of them).

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// The base name of sequence `index`: `seq_{index:06}`.
pub fn sequence_stem(index: usize) -> String {
    format!("seq_{index:06}")
}

/// The temporary name of final path `p`: `p` + `.tmp`.
pub(crate) fn tmp_name(p: &Path) -> PathBuf {
    let mut s = p.as_os_str().to_owned();
    s.push(".tmp");
    PathBuf::from(s)
}

/// The empty temporary directory of the final directory `fin` (`tmp_name`), created anew: a
/// leftover of an earlier, interrupted run is removed first.
pub(crate) fn fresh_tmp_dir(fin: &Path) -> Result<PathBuf> {
    let tmp = tmp_name(fin);
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
    }
    std::fs::create_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
    Ok(tmp)
}

pub(crate) fn rename(from: &Path, to: &Path) -> Result<()> {
    std::fs::rename(from, to).map_err(|e| Error::io(to, e))
}

/// Renames directory `tmp` to `fin`, replacing an existing `fin` (a rerun): the old one is
/// moved aside first and deleted after, so `fin` is never a mix of both.
pub(crate) fn replace_dir(tmp: &Path, fin: &Path) -> Result<()> {
    if fin.exists() {
        let old = {
            let mut s = fin.as_os_str().to_owned();
            s.push(".old");
            PathBuf::from(s)
        };
        if old.exists() {
            std::fs::remove_dir_all(&old).map_err(|e| Error::io(&old, e))?;
        }
        rename(fin, &old)?;
        rename(tmp, fin)?;
        std::fs::remove_dir_all(&old).map_err(|e| Error::io(&old, e))
    } else {
        rename(tmp, fin)
    }
}

/// Writes `bytes` to `path`, an error naming the path.
pub(crate) fn write_file(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    std::fs::write(path, bytes).map_err(|e| Error::io(path, e))
}
