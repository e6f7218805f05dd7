//! Production runs of the built binary: a killed run resumes to the same bytes, a stop
//! request leaves only complete sequences, two runs never touch each other's sequences,
//! shards add up to one run, and `pedscan verify` finds what is wrong.

use crate::common::{ok, pedscan, pedscan_with_env, HANG};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A job long enough to be stopped in the middle: 8 sequences on the ray caster.
const JOB: [&str; 10] = ["generate", "--backend", "raycast", "--sequences", "8", "--frames", "6", "--humans", "2..4", "--seed"];

fn job(out: &str, extra: &[&'static str]) -> Vec<String> {
    let mut v: Vec<String> = JOB.iter().map(|s| s.to_string()).collect();
    v.push("21".into());
    v.extend(["--out".to_string(), out.to_string()]);
    v.extend(extra.iter().map(|s| s.to_string()));
    v
}

fn spawn(args: &[String], dir: &Path) -> Child {
    Command::new(env!("CARGO_BIN_EXE_pedscan"))
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start pedscan")
}

fn run(args: &[String], dir: &Path) -> std::process::Output {
    pedscan(&args.iter().map(|s| s.as_str()).collect::<Vec<_>>(), dir)
}

/// Waits until `path` exists (a hang guard: it fails only after [`HANG`]).
fn wait_for(path: &Path) {
    let t0 = Instant::now();
    while !path.exists() {
        assert!(t0.elapsed() < HANG, "{} never appeared", path.display());
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

/// Every sequence file of `a` is in `b` with the same bytes, and the other way round.
fn same_sequences(a: &Path, b: &Path) {
    let seq = |d: &Path| names(d).into_iter().filter(|n| n.starts_with("seq_")).collect::<Vec<_>>();
    assert_eq!(seq(a), seq(b));
    for n in seq(a) {
        assert!(std::fs::read(a.join(&n)).unwrap() == std::fs::read(b.join(&n)).unwrap(), "{n} differs");
    }
}

fn verify(dir: &Path, out: &str) -> std::process::Output {
    pedscan(&["verify", out], dir)
}

#[test]
fn a_killed_run_resumes_to_the_bytes_of_an_uninterrupted_one() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    ok(&run(&job("full", &[]), dir));
    let mut child = spawn(&job("part", &[]), dir);
    wait_for(&dir.join("part/seq_000001.h5"));
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(!dir.join("part/seq_000007.h5").exists(), "the run ended before it was killed");
    ok(&run(&job("part", &["--resume"]), dir));
    same_sequences(&dir.join("full"), &dir.join("part"));
    ok(&verify(dir, "part"));
    // Resuming a complete folder writes nothing.
    let o = run(&job("part", &["--resume"]), dir);
    ok(&o);
    assert!(String::from_utf8_lossy(&o.stderr).contains("wrote 0 sequences"), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn sigint_and_sigterm_stop_between_frames_and_leave_only_complete_sequences() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    for (signal, code, out) in [("-INT", 130, "int"), ("-TERM", 143, "term")] {
        let child = spawn(&job(out, &[]), dir);
        wait_for(&dir.join(out).join("seq_000000.h5"));
        let sent = Command::new("kill").args([signal, &child.id().to_string()]).status().unwrap();
        assert!(sent.success());
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(code), "{signal}: {err}");
        assert!(err.contains("stopped by signal"), "{err}");
        let left = names(&dir.join(out));
        assert!(left.iter().all(|n| !n.ends_with(".tmp") && !n.ends_with(".lock")), "{signal} left {left:?}");
        assert!(!left.contains(&"seq_000007.h5".to_string()), "the run ended before the signal");
        ok(&verify(dir, out));
    }
}

#[test]
fn two_runs_never_write_the_same_sequence_or_replace_another_configuration() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let first = spawn(&job("out", &[]), dir);
    wait_for(&dir.join("out/seq_000000.lock"));
    // The second run stops at sequence 0: held by the first run (named), or, if the first
    // run got past it meanwhile, already there.
    let o = run(&job("out", &[]), dir);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    let held = err.contains("seq_000000.lock") && err.contains("being written by pedscan") && err.contains("pid");
    assert!(held || err.contains("sequence 0 is already there"), "{err}");
    // With --resume it cannot overtake the first run either.
    let o = run(&job("out", &["--resume"]), dir);
    if !o.status.success() {
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.code() == Some(2) && err.contains("being written by pedscan"), "{err}");
    }
    let o = first.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    ok(&verify(dir, "out"));
    // Another seed into the same folder: refused, nothing replaced.
    let before = std::fs::read(dir.join("out/seq_000000.h5")).unwrap();
    let mut other = job("out", &[]);
    let seed = other.iter().position(|a| a == "--seed").unwrap();
    other[seed + 1] = "22".into();
    let o = run(&other, dir);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("seq_000000") && err.contains("another configuration") && err.contains("--overwrite"), "{err}");
    assert!(std::fs::read(dir.join("out/seq_000000.h5")).unwrap() == before);
    // With --overwrite it is replaced, and the folder verifies.
    other.push("--overwrite".into());
    ok(&run(&other, dir));
    assert!(std::fs::read(dir.join("out/seq_000000.h5")).unwrap() != before);
    ok(&verify(dir, "out"));
}

#[test]
fn shards_write_together_exactly_what_one_run_writes() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let small = |out: &str, extra: &[&str]| {
        let mut v = vec!["generate", "--backend", "raycast", "--sequences", "5", "--frames", "2", "--humans", "1..3", "--out", out];
        v.extend_from_slice(extra);
        v.into_iter().map(String::from).collect::<Vec<_>>()
    };
    ok(&run(&small("one", &[]), dir));
    // Three shards into one folder, the last through Slurm's variables.
    ok(&run(&small("shards", &["--shard", "0/3"]), dir));
    ok(&run(&small("shards", &["--shard", "1/3"]), dir));
    let args = small("shards", &["--shard", "auto"]);
    let slurm = [("SLURM_ARRAY_TASK_ID", "3"), ("SLURM_ARRAY_TASK_MIN", "1"), ("SLURM_ARRAY_TASK_COUNT", "3")];
    ok(&pedscan_with_env(&args.iter().map(|s| s.as_str()).collect::<Vec<_>>(), dir, &slurm));
    same_sequences(&dir.join("one"), &dir.join("shards"));
    ok(&verify(dir, "shards"));
    let o = run(&small("x", &["--shard", "3/3"]), dir);
    assert_eq!(o.status.code(), Some(2));
    assert!(!dir.join("x").exists());
}

#[test]
fn verify_finds_altered_and_stray_files_and_resume_repairs_them() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let args: Vec<String> = ["generate", "--backend", "raycast", "--sequences", "2", "--frames", "2", "--out", "out"].map(String::from).to_vec();
    ok(&run(&args, dir));
    let h5 = dir.join("out/seq_000001.h5");
    let good = std::fs::read(&h5).unwrap();
    let mut bad = good.clone();
    let mid = bad.len() / 2;
    bad[mid] ^= 1;
    std::fs::write(&h5, &bad).unwrap();
    std::fs::write(dir.join("out/seq_000009.xml"), "<stray/>").unwrap();
    let o = verify(dir, "out");
    let text = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{text}");
    assert!(text.contains("seq_000001.h5: SHA-256") && text.contains("seq_000009.xml"), "{text}");
    std::fs::remove_file(dir.join("out/seq_000009.xml")).unwrap();
    let mut resume = args.clone();
    resume.push("--resume".into());
    ok(&run(&resume, dir));
    assert!(std::fs::read(&h5).unwrap() == good);
    ok(&verify(dir, "out"));
    // Not an output folder: bad input.
    assert_eq!(verify(dir, "nowhere").status.code(), Some(2));
}

/// A manifest whose entry names a file outside its folder (the issue's `../secret.txt`, an
/// absolute path, a symbolic link in the folder that leads out of it), with that file's true
/// size and hash: `verify` names it as a problem (exit 1) and `generate --resume` refuses the
/// manifest as bad input (exit 2) before writing anything; neither opens the file.
#[test]
fn a_manifest_naming_files_outside_its_folder_fails_verify_and_resume() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let out = dir.join("out");
    std::fs::create_dir(&out).unwrap();
    let secret = dir.join("secret.txt");
    std::fs::write(&secret, "not pedscan's").unwrap();
    std::os::unix::fs::symlink(&secret, out.join("link.h5")).unwrap();
    let (sha256, bytes) = pedscan::output::manifest::sha256_file(&secret).unwrap();
    let absolute = secret.to_string_lossy().into_owned();
    for name in ["../secret.txt", absolute.as_str(), "link.h5"] {
        let line = format!(
            r#"{{"sequence":0,"files":[{{"name":"{name}","bytes":{bytes},"sha256":"{sha256}"}}],"frames":2,"people":1,"seconds":0.5,"version":"0.1.0","device":"cpu","config_hash":"0123456789abcdef"}}"#
        );
        std::fs::write(out.join("manifest.jsonl"), format!("{line}\n")).unwrap();
        let o = verify(dir, "out");
        let text = String::from_utf8_lossy(&o.stdout);
        assert_eq!(o.status.code(), Some(1), "{name}: {text}");
        assert!(text.contains(&format!("problem: sequence 0: {name}: ")) && text.contains("not opened") && text.ends_with("1 problems\n"), "{name}: {text}");
        let o = run(&job("out", &["--resume"]), dir);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{name}: {err}");
        assert!(err.contains("manifest.jsonl") && err.contains(&format!("sequence 0 lists `{name}`")), "{name}: {err}");
        assert_eq!(names(&out), ["link.h5", "manifest.jsonl"], "{name}: nothing written");
    }
}

#[test]
fn a_sequence_whose_final_name_is_taken_by_a_folder_leaves_none_of_its_files() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::create_dir_all(dir.join("out/seq_000000.h5")).unwrap();
    let o = pedscan(&["generate", "--backend", "raycast", "--frames", "2", "--out", "out", "--overwrite"], dir);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("seq_000000.h5") && err.contains("not a file"), "{err}");
    assert_eq!(names(&dir.join("out")), vec!["seq_000000.h5".to_string()]);
}

#[test]
fn a_run_killed_between_its_renames_and_its_manifest_line_is_resumed() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let args: Vec<String> = ["generate", "--backend", "raycast", "--sequences", "2", "--frames", "2", "--out", "out"].map(String::from).to_vec();
    ok(&run(&args, dir));
    let good = std::fs::read(dir.join("out/seq_000001.h5")).unwrap();
    // What SIGKILL leaves after sequence 1's files got their names, before its manifest line:
    // the files, no line, and its lock file.
    let manifest = dir.join("out/manifest.jsonl");
    let first = std::fs::read_to_string(&manifest).unwrap().lines().next().unwrap().to_string();
    std::fs::write(&manifest, format!("{first}\n")).unwrap();
    let mut resume = args.clone();
    resume.push("--resume".into());
    // Without the lock file nothing says whose files these are: refused.
    let o = run(&resume, dir);
    assert_eq!(o.status.code(), Some(2), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::write(dir.join("out/seq_000001.lock"), "pedscan (pid 1 on gone)").unwrap();
    ok(&run(&resume, dir));
    assert!(std::fs::read(dir.join("out/seq_000001.h5")).unwrap() == good);
    assert!(!dir.join("out/seq_000001.lock").exists());
    ok(&verify(dir, "out"));
}

/// Every file under `root` (relative paths, sorted) but the manifest, whose lines hold each
/// sequence's wall-clock seconds.
fn tree(root: &Path) -> Vec<(String, Vec<u8>)> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<(String, Vec<u8>)>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                let rel = p.strip_prefix(root).unwrap().to_string_lossy().into_owned();
                if rel != "manifest.jsonl" {
                    out.push((rel, std::fs::read(&p).unwrap()));
                }
            }
        }
    }
    let mut v = Vec::new();
    walk(root, root, &mut v);
    v.sort();
    v
}

/// A run killed (SIGKILL, from `debug.kill`, so the stage is chosen, not timed) at every stage
/// of a sequence: after its first and its last frame are in the temporary files, after each
/// of its five renames (PNG folder, SemanticKITTI folder, bag folder, XML, HDF5), and between
/// its last rename and its manifest line; and in the first sequence, before anything is
/// complete. Every format at once. `--resume` then leaves exactly the files of an
/// uninterrupted run, byte for byte: no temporary left, no stale PNG, label or bag file.
#[test]
fn a_run_killed_at_any_stage_of_a_sequence_resumes_to_the_bytes_of_an_uninterrupted_one() {
    use std::os::unix::process::ExitStatusExt;
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let args = |out: &str| -> Vec<String> {
        ["generate", "--backend", "raycast", "--sequences", "3", "--frames", "3", "--humans", "2", "--seed", "4", "--png", "--formats", "h5,semantickitti,mcap", "--out", out]
            .map(String::from)
            .to_vec()
    };
    ok(&run(&args("full"), dir));
    let full = tree(&dir.join("full"));
    assert!(full.iter().any(|(n, _)| n.contains("_png/")) && full.iter().any(|(n, _)| n.contains("_bag/")), "every format written");
    let stages = ["0:frame-1", "1:frame-0", "1:frame-2", "1:rename-1", "1:rename-2", "1:rename-3", "1:rename-4", "1:rename-5", "1:manifest"];
    for (i, stage) in stages.iter().enumerate() {
        let out = format!("k{i}");
        let config = format!("kill{i}.toml");
        std::fs::write(dir.join(&config), format!("[debug]\nkill = \"{stage}\"\n")).unwrap();
        let mut killed = args(&out);
        killed.extend(["--config".into(), config]);
        let o = run(&killed, dir);
        assert_eq!(o.status.signal(), Some(9), "{stage}: the run was not killed: {}", String::from_utf8_lossy(&o.stderr));
        let left = tree(&dir.join(&out));
        assert!(left.iter().any(|(n, _)| n.contains(".tmp") || n.ends_with(".lock")), "{stage}: a killed run leaves its traces");
        let mut resume = args(&out);
        resume.push("--resume".into());
        ok(&run(&resume, dir));
        let now = tree(&dir.join(&out));
        let names = |t: &[(String, Vec<u8>)]| t.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
        assert_eq!(names(&now), names(&full), "{stage}: the resumed folder holds other files");
        for ((n, a), (_, b)) in now.iter().zip(&full) {
            assert!(a == b, "{stage}: {n} differs from the uninterrupted run's");
        }
        ok(&verify(dir, &out));
    }
    // A run of another configuration (5 frames) killed in its fourth frame leaves temporaries
    // with more frames than this configuration writes; a new run here must not inherit them.
    std::fs::write(dir.join("kill5.toml"), "[debug]\nkill = \"0:frame-3\"\n").unwrap();
    let mut longer = args("other");
    let frames = longer.iter().position(|a| a == "--frames").unwrap() + 1;
    longer[frames] = "5".into();
    longer.extend(["--config".into(), "kill5.toml".into()]);
    assert_eq!(run(&longer, dir).status.signal(), Some(9));
    ok(&run(&args("other"), dir));
    let other = tree(&dir.join("other"));
    let stray: Vec<_> = other.iter().map(|(n, _)| n).filter(|n| !full.iter().any(|(m, _)| m == *n)).collect();
    assert!(stray.is_empty(), "files of the killed 5-frame run survived: {stray:?}");
    assert!(other == full, "the new run's files differ from an uninterrupted run's");
}
