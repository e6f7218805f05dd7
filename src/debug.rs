//! Test hooks of a run (beside every stage, used by none of its results): `debug.kill` kills
//! the process with SIGKILL at a named stage of a sequence, so the tests of `generate --resume`
//! reach every stage without timing a kill from outside. The configuration reads the key
//! (`[debug] kill = "S:rename-N"`) into a [`KillPoint`]; the writer and the `generate` job
//! call [`kill_at`] where each stage is reached. One of the three places with `unsafe` (with
//! `gpu` and the HDF5 writer).

/// Where a run kills itself with SIGKILL (`debug.kill`), to test `--resume` at every stage of
/// a sequence without timing a kill from outside. Written `S:frame-K` (sequence S's frame K
/// is in its temporary files), `S:rename-N` (the N-th of sequence S's final renames is done:
/// PNG folder, SemanticKITTI folder, bag folder, XML, HDF5, those written, in that order) or
/// `S:manifest` (sequence S's files have their names, its manifest line is not written).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct KillPoint {
    pub sequence: usize,
    pub at: KillStage,
}

/// The stage of a sequence a [`KillPoint`] names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KillStage {
    /// Frame K (0-based) written to the temporary files.
    Frame(usize),
    /// N (1-based) of the sequence's final renames done.
    Rename(usize),
    /// Every file renamed, the manifest line not yet written.
    Manifest,
}

impl TryFrom<String> for KillPoint {
    type Error = String;
    fn try_from(s: String) -> std::result::Result<KillPoint, String> {
        let bad = || format!("`{s}` is not S:frame-K, S:rename-N or S:manifest");
        let (seq, stage) = s.split_once(':').ok_or_else(bad)?;
        let sequence = seq.parse().map_err(|_| bad())?;
        let at = match stage.split_once('-') {
            Some(("frame", k)) => KillStage::Frame(k.parse().map_err(|_| bad())?),
            Some(("rename", n)) => KillStage::Rename(n.parse().ok().filter(|n| *n >= 1).ok_or_else(bad)?),
            None if stage == "manifest" => KillStage::Manifest,
            _ => return Err(bad()),
        };
        Ok(KillPoint { sequence, at })
    }
}

impl From<KillPoint> for String {
    fn from(k: KillPoint) -> String {
        match k.at {
            KillStage::Frame(f) => format!("{}:frame-{f}", k.sequence),
            KillStage::Rename(n) => format!("{}:rename-{n}", k.sequence),
            KillStage::Manifest => format!("{}:manifest", k.sequence),
        }
    }
}

/// Kills this process ([`kill_self`]) when `reached` is the stage `planned` names; returns
/// otherwise.
pub fn kill_at(planned: Option<KillStage>, reached: KillStage) {
    if planned == Some(reached) {
        kill_self();
    }
}

/// Kills this process with SIGKILL, as `kill -9` from outside would: no destructor runs,
/// nothing is flushed or removed (`debug.kill`).
pub fn kill_self() -> ! {
    // SAFETY: kill(2) on this process's own id; it does not return for SIGKILL.
    unsafe {
        libc::kill(libc::getpid(), libc::SIGKILL);
    }
    loop {
        std::thread::park();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kill_points_read_and_write_their_text() {
        for (text, want) in [("0:frame-0", KillStage::Frame(0)), ("7:frame-12", KillStage::Frame(12)), ("1:manifest", KillStage::Manifest), ("3:rename-2", KillStage::Rename(2))] {
            let k = KillPoint::try_from(text.to_string()).unwrap();
            assert_eq!(k.at, want);
            assert_eq!(String::from(k), text);
        }
        for bad in ["", "1", "x:manifest", "1:rename-0", "1:frame", "1:frame-x", "1:write-2", "-1:manifest"] {
            let e = KillPoint::try_from(bad.to_string()).unwrap_err();
            assert!(e.contains("S:frame-K"), "{bad}: {e}");
        }
    }

    #[test]
    fn a_stage_not_planned_returns() {
        kill_at(None, KillStage::Manifest);
        kill_at(Some(KillStage::Frame(1)), KillStage::Frame(0));
        kill_at(Some(KillStage::Rename(1)), KillStage::Manifest);
    }
}
