//! `manifest.jsonl`: one JSON line per completed sequence of an output folder, appended after
//! its files have their final names: the sequence, every file with its size and SHA-256, the
//! frames, the people, the seconds it took, the pedscan version, the device and the hash of
//! the configuration that decides the content ([`config_hash`]). A sequence written again
//! (a rerun) gets a new line; the last line of a sequence is the one that counts.
//!
//! The manifest is what `generate --resume` trusts (a sequence is done when its last line's
//! files all exist with that size and hash) and what `pedscan verify` checks. Its file names
//! stay inside the folder: a name that is absolute, holds `..` or leads out through a symbolic
//! link is never opened ([`listed`]); `verify` reports it as a problem, `--resume` refuses the
//! manifest as bad input.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// The manifest's file name in an output folder.
pub const MANIFEST: &str = "manifest.jsonl";

/// One file of a sequence, relative to the output folder.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileRecord {
    pub name: String,
    pub bytes: u64,
    pub sha256: String,
}

/// One completed sequence.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ManifestEntry {
    pub sequence: usize,
    pub files: Vec<FileRecord>,
    pub frames: usize,
    pub people: usize,
    pub seconds: f64,
    pub version: String,
    pub device: String,
    pub config_hash: String,
    /// Points per class of the SemanticKITTI export, when written (its `content`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub class_points: Option<crate::output::semantickitti::ClassPoints>,
}

/// The hash of a recorded configuration (`Config::to_recorded_toml`): 16 hex digits of its
/// SHA-256. Two runs with the same hash write the same bytes for the same sequence.
pub fn config_hash(recorded_toml: &str) -> String {
    hex(&Sha256::digest(recorded_toml.as_bytes()))[..16].to_string()
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// SHA-256 (hex) and size of a file.
pub fn sha256_file(path: &Path) -> std::io::Result<(String, u64)> {
    let mut f = std::fs::File::open(path)?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut bytes = 0u64;
    loop {
        let n = f.read(&mut buf)?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
        bytes += n as u64;
    }
    Ok((hex(&hasher.finalize()), bytes))
}

/// The files of `p`: itself, or the files under the folder `p` at any depth, sorted.
fn files_under(p: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    if !p.is_dir() {
        out.push(p.to_path_buf());
        return Ok(());
    }
    let mut inner: Vec<PathBuf> =
        std::fs::read_dir(p).map_err(|e| Error::io(p, e))?.map(|d| d.map(|d| d.path()).map_err(|e| Error::io(p, e))).collect::<Result<_>>()?;
    inner.sort();
    for q in inner {
        files_under(&q, out)?;
    }
    Ok(())
}

/// Records of `paths` (files, or folders whose files are listed one by one, sorted), named
/// relative to `out_dir`.
pub fn file_records(out_dir: &Path, paths: &[PathBuf]) -> Result<Vec<FileRecord>> {
    let mut files = Vec::new();
    for p in paths {
        files_under(p, &mut files)?;
    }
    files
        .iter()
        .map(|f| {
            let (sha256, bytes) = sha256_file(f).map_err(|e| Error::io(f, e))?;
            let name = f.strip_prefix(out_dir).unwrap_or(f).to_string_lossy().into_owned();
            Ok(FileRecord { name, bytes, sha256 })
        })
        .collect()
}

/// The manifest of an output folder: the last entry of every sequence.
#[derive(Clone, Debug, Default)]
pub struct Manifest {
    pub latest: BTreeMap<usize, ManifestEntry>,
    /// Entries read (every line, reruns included).
    pub lines: usize,
    /// The last line was cut short (a run killed while appending); it is ignored.
    pub torn_tail: bool,
}

impl Manifest {
    /// Reads `out_dir/manifest.jsonl`; an absent file is an empty manifest. A line that is
    /// not an entry is a bad-input error naming the file and line, except an unterminated
    /// last line, which a killed run may leave and which is ignored.
    pub fn load(out_dir: &Path) -> Result<Manifest> {
        let path = out_dir.join(MANIFEST);
        let text = match std::fs::read(&path) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Manifest::default()),
            Err(e) => return Err(Error::io(&path, e)),
        };
        let text = String::from_utf8(text).map_err(|_| Error::input(path.display(), "not UTF-8 text"))?;
        let mut m = Manifest::default();
        let complete = text.ends_with('\n');
        let lines: Vec<&str> = text.lines().collect();
        for (i, line) in lines.iter().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            match serde_json::from_str::<ManifestEntry>(line) {
                Ok(e) => {
                    m.lines += 1;
                    m.latest.insert(e.sequence, e);
                }
                Err(_) if i + 1 == lines.len() && !complete => m.torn_tail = true,
                Err(e) => return Err(Error::input(format!("{}:{}", path.display(), i + 1), format!("not a manifest entry: {e}"))),
            }
        }
        Ok(m)
    }

    /// What `generate --resume` checks before it trusts the entries of `sequences`: none
    /// names a file outside `out_dir` ([`outside_file`]; such a file is never opened). The
    /// first that does is a bad-input error naming the manifest, the sequence and the file.
    pub fn check_inside(&self, out_dir: &Path, sequences: &[usize]) -> Result<()> {
        for (sequence, e) in sequences.iter().filter_map(|s| self.latest.get(s).map(|e| (s, e))) {
            if let Some(why) = outside_file(out_dir, e) {
                return Err(Error::input(
                    out_dir.join(MANIFEST).display(),
                    format!(
                        "sequence {sequence} lists {why}; pedscan writes only files inside the folder, so this manifest was edited \
                         and --resume does not trust it: remove that sequence's lines, or write to another --out"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Appends `entry` as one line (under an exclusive lock, so concurrent runs of one job
    /// never interleave their lines) and syncs it.
    pub fn append(out_dir: &Path, entry: &ManifestEntry) -> Result<()> {
        let path = out_dir.join(MANIFEST);
        let mut line = serde_json::to_string(entry).map_err(|e| Error::Internal(format!("manifest entry: {e}")))?;
        line.push('\n');
        let mut f = std::fs::OpenOptions::new().create(true).append(true).open(&path).map_err(|e| Error::io(&path, e))?;
        f.lock().map_err(|e| Error::io(&path, e))?;
        // A torn line left by a killed run would glue onto ours: cut it off first.
        let whole = complete_length(&path)?;
        if whole < f.metadata().map_err(|e| Error::io(&path, e))?.len() {
            f.set_len(whole).map_err(|e| Error::io(&path, e))?;
        }
        f.write_all(line.as_bytes()).and_then(|_| f.sync_data()).map_err(|e| Error::io(&path, e))
    }
}

/// The length of `path` up to and including its last newline (read backwards from the end,
/// so appending stays cheap however long the manifest grows).
fn complete_length(path: &Path) -> Result<u64> {
    use std::io::{Seek, SeekFrom};
    let io = |e| Error::io(path, e);
    let mut f = std::fs::File::open(path).map_err(io)?;
    let mut end = f.metadata().map_err(io)?.len();
    let mut buf = vec![0u8; 64 << 10];
    while end > 0 {
        let n = (buf.len() as u64).min(end) as usize;
        f.seek(SeekFrom::Start(end - n as u64)).and_then(|_| f.read_exact(&mut buf[..n])).map_err(io)?;
        if let Some(i) = buf[..n].iter().rposition(|&b| b == b'\n') {
            return Ok(end - n as u64 + i as u64 + 1);
        }
        end -= n as u64;
    }
    Ok(0)
}

/// Where a file name of the manifest leads, found without opening the file.
#[derive(Debug)]
pub enum Listed {
    /// A file inside the output folder: its path, symbolic links resolved.
    Inside(PathBuf),
    /// Nothing there, or a path that cannot be resolved (the error).
    Unresolved(std::io::Error),
    /// Outside the output folder, why: an absolute name, one with `..`, or a symbolic link
    /// out of the folder. pedscan never writes such a name: the manifest was edited.
    Outside(String),
}

/// Where `name`, a file of `out_dir`'s manifest, leads ([`Listed`]). A name is relative and
/// made of plain components; it must resolve, through every symbolic link on the way, to a
/// path inside the folder.
pub fn listed(out_dir: &Path, name: &str) -> Listed {
    use std::path::Component;
    let components: Vec<Component> = Path::new(name).components().collect();
    if Path::new(name).has_root() {
        return Listed::Outside("an absolute path, outside the output folder".into());
    }
    if components.contains(&Component::ParentDir) {
        return Listed::Outside("holds `..`, which leads out of the output folder".into());
    }
    if components.is_empty() || !components.iter().all(|c| matches!(c, Component::Normal(_))) {
        return Listed::Outside("not the name of a file inside the output folder".into());
    }
    let real = match (out_dir.canonicalize(), out_dir.join(name).canonicalize()) {
        (Ok(dir), Ok(real)) if real.starts_with(&dir) => return Listed::Inside(real),
        (Ok(_), Ok(real)) => real,
        (Err(e), _) | (_, Err(e)) => return Listed::Unresolved(e),
    };
    Listed::Outside(format!("a symbolic link out of the output folder (to {})", real.display()))
}

/// The first file of `e` that lies outside `out_dir` ([`Listed::Outside`]): its name and why.
pub fn outside_file(out_dir: &Path, e: &ManifestEntry) -> Option<String> {
    e.files.iter().find_map(|f| match listed(out_dir, &f.name) {
        Listed::Outside(why) => Some(format!("`{}`: {why}", f.name)),
        _ => None,
    })
}

/// Why a recorded sequence does not verify, or None when all its files are there, complete.
/// A file outside the output folder ([`listed`]) is a reason, and is never opened.
pub fn check_entry(out_dir: &Path, e: &ManifestEntry) -> Option<String> {
    for f in &e.files {
        let path = match listed(out_dir, &f.name) {
            Listed::Inside(path) => path,
            Listed::Unresolved(err) => return Some(format!("{}: {err}", f.name)),
            Listed::Outside(why) => return Some(format!("{}: {why}; not opened", f.name)),
        };
        match sha256_file(&path) {
            Err(err) => return Some(format!("{}: {err}", f.name)),
            Ok((_, bytes)) if bytes != f.bytes => return Some(format!("{}: {bytes} bytes, the manifest says {}", f.name, f.bytes)),
            Ok((sha, _)) if sha != f.sha256 => return Some(format!("{}: SHA-256 differs from the manifest's", f.name)),
            Ok(_) => {}
        }
    }
    None
}

/// What `pedscan verify` found in an output folder.
#[derive(Clone, Debug, Default)]
pub struct VerifyReport {
    pub sequences: usize,
    pub files: usize,
    pub bytes: u64,
    /// Failures: missing, short or altered files, sequence files the manifest does not list.
    pub problems: Vec<String>,
    /// Worth knowing, not failures: temporaries of a run in progress or killed, sequences of
    /// more than one configuration.
    pub notes: Vec<String>,
}

impl VerifyReport {
    pub fn ok(&self) -> bool {
        self.problems.is_empty()
    }
}

impl std::fmt::Display for VerifyReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for p in &self.problems {
            writeln!(f, "problem: {p}")?;
        }
        for n in &self.notes {
            writeln!(f, "note: {n}")?;
        }
        write!(
            f,
            "{} sequences, {} files, {:.1} MB: {}",
            self.sequences,
            self.files,
            self.bytes as f64 / 1e6,
            if self.ok() { "all verified".to_string() } else { format!("{} problems", self.problems.len()) }
        )
    }
}

/// The folder entry a listed file stands for: its first path component, or for the
/// SemanticKITTI export the sequence folder (`semantickitti/sequences/SS`).
fn listed_name(name: &str) -> String {
    let parts: Vec<&str> = name.split('/').collect();
    match parts[..] {
        [sk, "sequences", ss, ..] if sk == crate::output::semantickitti::FOLDER => format!("{sk}/sequences/{ss}"),
        _ => parts[0].to_string(),
    }
}

/// Checks every file the manifest of `out_dir` lists (size and SHA-256) and that every
/// sequence file in the folder is listed. A folder without a manifest is a bad-input error.
pub fn verify_dir(out_dir: &Path) -> Result<VerifyReport> {
    if !out_dir.is_dir() {
        return Err(Error::input(out_dir.display(), "not a folder"));
    }
    if !out_dir.join(MANIFEST).is_file() {
        return Err(Error::input(out_dir.display(), format!("no {MANIFEST}: not a folder written by `pedscan generate`")));
    }
    let m = Manifest::load(out_dir)?;
    let mut r = VerifyReport { sequences: m.latest.len(), ..Default::default() };
    let mut listed = std::collections::BTreeSet::new();
    for e in m.latest.values() {
        for f in &e.files {
            listed.insert(listed_name(&f.name));
            r.files += 1;
            r.bytes += f.bytes;
        }
        if let Some(why) = check_entry(out_dir, e) {
            r.problems.push(format!("sequence {}: {why}", e.sequence));
        }
    }
    if m.torn_tail {
        r.notes.push(format!("{MANIFEST}: the last line was cut short (a run was killed while appending); ignored"));
    }
    let hashes: std::collections::BTreeSet<&str> = m.latest.values().map(|e| e.config_hash.as_str()).collect();
    if hashes.len() > 1 {
        r.notes.push(format!("sequences of {} configurations ({})", hashes.len(), hashes.into_iter().collect::<Vec<_>>().join(", ")));
    }
    let mut names: Vec<String> = std::fs::read_dir(out_dir)
        .map_err(|e| Error::io(out_dir, e))?
        .filter_map(|d| d.ok().map(|d| d.file_name().to_string_lossy().into_owned()))
        .collect();
    names.sort();
    let sequences = out_dir.join(crate::output::semantickitti::FOLDER).join("sequences");
    if let Ok(dir) = std::fs::read_dir(&sequences) {
        let mut sk: Vec<String> = dir
            .filter_map(|d| d.ok().map(|d| format!("{}/sequences/{}", crate::output::semantickitti::FOLDER, d.file_name().to_string_lossy())))
            .collect();
        sk.sort();
        names.extend(sk);
    }
    for name in names {
        let sk = name.starts_with(&format!("{}/", crate::output::semantickitti::FOLDER));
        if !name.starts_with("seq_") && !sk {
            continue;
        }
        if name.ends_with(".tmp") || name.ends_with(".lock") || name.ends_with(".old") {
            // Temporaries of a run in flight or killed.
            r.notes.push(format!("{name}: left by a run that is still writing or was killed (`generate --resume` cleans it up)"));
        } else if !listed.contains(&name) {
            r.problems.push(format!("{name}: a sequence file the manifest does not list"));
        }
    }
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(out: &Path, seq: usize, hash: &str) -> ManifestEntry {
        let name = format!("seq_{seq:06}.h5");
        std::fs::write(out.join(&name), format!("data {seq}")).unwrap();
        entry_of(seq, file_records(out, &[out.join(&name)]).unwrap(), hash)
    }

    fn entry_of(seq: usize, files: Vec<FileRecord>, hash: &str) -> ManifestEntry {
        ManifestEntry {
            sequence: seq,
            files,
            frames: 2,
            people: 1,
            seconds: 0.5,
            version: "test".into(),
            device: "cpu".into(),
            config_hash: hash.into(),
            class_points: None,
        }
    }

    #[test]
    fn the_sha256_of_a_known_text() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("abc");
        std::fs::write(&p, "abc").unwrap();
        let (sha, n) = sha256_file(&p).unwrap();
        assert_eq!(n, 3);
        assert_eq!(sha, "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    }

    #[test]
    fn the_last_line_of_a_sequence_counts_and_verify_finds_altered_and_unlisted_files() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        Manifest::append(out, &entry(out, 0, "a")).unwrap();
        Manifest::append(out, &entry(out, 1, "a")).unwrap();
        let r = verify_dir(out).unwrap();
        assert!(r.ok() && r.notes.is_empty(), "one configuration, nothing to note: {r}");
        Manifest::append(out, &entry(out, 0, "b")).unwrap();
        let m = Manifest::load(out).unwrap();
        assert_eq!((m.lines, m.latest.len()), (3, 2));
        assert_eq!(m.latest[&0].config_hash, "b");
        let r = verify_dir(out).unwrap();
        assert!(r.ok(), "{r}");
        assert_eq!(r.notes, ["sequences of 2 configurations (a, b)"], "two configurations: {r}");
        let files: usize = m.latest.values().map(|e| e.files.len()).sum();
        let bytes: u64 = m.latest.values().flat_map(|e| &e.files).map(|f| f.bytes).sum();
        assert!(files > 0 && bytes > 0);
        assert_eq!((r.sequences, r.files, r.bytes), (2, files, bytes), "the latest entry of each sequence counts");
        assert!(r.to_string().ends_with(&format!("2 sequences, {files} files, {:.1} MB: all verified", bytes as f64 / 1e6)), "{r}");

        std::fs::write(out.join("seq_000001.h5"), "data 9").unwrap();
        std::fs::write(out.join("seq_000002.h5"), "stray").unwrap();
        let r = verify_dir(out).unwrap();
        assert_eq!(r.problems.len(), 2, "{r}");
        assert!(r.problems[0].contains("SHA-256") && r.problems[1].contains("seq_000002.h5"), "{r}");
    }

    /// An entry for sequence 0 whose one file is named `name`, with the size and hash of
    /// `target` (a file that exists): only where the name leads can make it fail.
    fn naming(name: &str, target: &Path) -> ManifestEntry {
        let (sha256, bytes) = sha256_file(target).unwrap();
        entry_of(0, vec![FileRecord { name: name.into(), bytes, sha256 }], "a")
    }

    #[test]
    fn names_that_lead_out_of_the_folder_are_problems_never_opened() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        std::fs::create_dir(&out).unwrap();
        let secret = dir.path().join("secret.txt");
        std::fs::write(&secret, "not pedscan's").unwrap();
        std::os::unix::fs::symlink(&secret, out.join("link.h5")).unwrap();
        std::os::unix::fs::symlink(dir.path(), out.join("up")).unwrap();
        let absolute = secret.to_string_lossy().into_owned();
        for (name, why) in [
            (absolute.as_str(), "an absolute path"),
            ("../secret.txt", "holds `..`"),
            ("link.h5/../../secret.txt", "holds `..`"),
            ("link.h5", "a symbolic link out of the output folder"),
            ("up/secret.txt", "a symbolic link out of the output folder"),
            ("./link.h5", "not the name of a file inside"),
        ] {
            std::fs::write(out.join(MANIFEST), "").unwrap();
            Manifest::append(&out, &naming(name, &secret)).unwrap();
            let r = verify_dir(&out).unwrap();
            assert_eq!(r.problems.len(), 1, "{name}: {r}");
            assert!(r.problems[0].starts_with(&format!("sequence 0: {name}: {why}")) && r.problems[0].ends_with("; not opened"), "{name}: {r}");
            assert!(matches!(listed(&out, name), Listed::Outside(_)), "{name}");
            let m = Manifest::load(&out).unwrap();
            let e = m.check_inside(&out, &[0]).unwrap_err();
            assert!(e.is_input() && e.to_string().contains(&format!("sequence 0 lists `{name}`: {why}")), "{name}: {e}");
            assert!(m.check_inside(&out, &[1]).is_ok(), "{name}: only the sequences resumed are checked");
        }
    }

    #[test]
    fn names_inside_the_folder_verify_through_symbolic_links_too() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        let e = entry(out, 0, "a");
        std::fs::create_dir(out.join("inner")).unwrap();
        std::os::unix::fs::symlink(out.join("seq_000000.h5"), out.join("inner/link.h5")).unwrap();
        let mut linked = naming("inner/link.h5", &out.join("seq_000000.h5"));
        linked.files.extend(e.files);
        Manifest::append(out, &linked).unwrap();
        let r = verify_dir(out).unwrap();
        assert!(r.ok(), "{r}");
        Manifest::load(out).unwrap().check_inside(out, &[0]).unwrap();
        assert!(matches!(listed(out, "missing.h5"), Listed::Unresolved(_)));
    }

    #[test]
    fn a_torn_last_line_is_ignored_and_the_next_entry_starts_a_fresh_line() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        Manifest::append(out, &entry(out, 0, "a")).unwrap();
        let mut f = std::fs::OpenOptions::new().append(true).open(out.join(MANIFEST)).unwrap();
        f.write_all(b"{\"sequence\": 1, \"fil").unwrap();
        let m = Manifest::load(out).unwrap();
        assert!(m.torn_tail);
        assert_eq!(m.latest.len(), 1);
        Manifest::append(out, &entry(out, 1, "a")).unwrap();
        let m = Manifest::load(out).unwrap();
        assert_eq!(m.latest.len(), 2);
        // A bad line in the middle is an error naming the file and line.
        let e = {
            let text = std::fs::read_to_string(out.join(MANIFEST)).unwrap();
            std::fs::write(out.join(MANIFEST), format!("{text}{{\"sequence\": 3}}\n")).unwrap();
            Manifest::load(out).unwrap_err()
        };
        assert!(e.is_input() && e.to_string().contains("manifest.jsonl:3"), "{e}");
    }
}
