//! Every input kept in `fuzz/corpus/` replayed through its fuzz target's code, without the
//! fuzzer: the readers' regression test on every machine that runs `cargo test` (coverage-guided
//! campaigns, `tools/fuzz.sh`, need the instrumented build). The targets are `fuzz/src/lib.rs`
//! itself, included here, so the two never drift apart.

#[path = "../../fuzz/src/lib.rs"]
mod pedscan_fuzz;

use std::path::Path;

/// Every file of every target's corpus is read by its target without a panic (an `Err` is the
/// right answer to bad input), and no target's folder is empty.
#[test]
fn every_kept_fuzz_input_is_read_without_a_panic() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus");
    let mut replayed = 0;
    for &(name, target) in pedscan_fuzz::TARGETS {
        let dir = root.join(name);
        let mut files: Vec<_> =
            std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())).map(|e| e.unwrap().path()).collect();
        files.sort();
        assert!(!files.is_empty(), "{name}: nothing kept in {}", dir.display());
        for f in &files {
            let data = std::fs::read(f).unwrap();
            if std::panic::catch_unwind(|| target(&data)).is_err() {
                panic!("fuzz target {name} panics on {} (tools/fuzz.sh repro {name} FILE replays it)", f.display());
            }
            replayed += 1;
        }
    }
    let _ = std::fs::remove_dir_all(pedscan_fuzz::scratch_dir());
    assert!(replayed >= 2000, "only {replayed} inputs replayed: was the corpus emptied?");
}

/// The targets replayed here are the ones `tools/fuzz.sh` fuzzes and `fuzz/corpus/` holds.
#[test]
fn the_replayed_targets_are_the_fuzzed_ones() {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut replayed: Vec<&str> = pedscan_fuzz::TARGETS.iter().map(|&(n, _)| n).collect();
    replayed.sort();
    let script = std::fs::read_to_string(here.join("tools/fuzz.sh")).unwrap();
    let list = script.split("targets=\"").nth(1).and_then(|s| s.split('"').next()).expect("tools/fuzz.sh lists its targets");
    let mut fuzzed: Vec<&str> = list.split_whitespace().map(|t| t.split(':').next().unwrap()).collect();
    fuzzed.sort();
    assert_eq!(replayed, fuzzed, "fuzz/src/lib.rs TARGETS against tools/fuzz.sh");
    let mut kept: Vec<String> =
        std::fs::read_dir(here.join("fuzz/corpus")).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    kept.sort();
    assert_eq!(replayed, kept, "fuzz/src/lib.rs TARGETS against the folders of fuzz/corpus");
}
