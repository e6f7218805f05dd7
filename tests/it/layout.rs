//! The layout the README promises a newcomer: no source file over 1,000 lines, anywhere a
//! reader of the code goes (the library, the binary, the tests, the fuzz targets, the shaders,
//! the tools and the Python package). Unit tests that outgrow their module's file move to a
//! file of their own beside it (`#[cfg(test)] mod tests;`). The binary and the generator stay
//! thin: `src/main.rs` at most 200 lines, `src/generator/mod.rs` at most 400.

use std::path::{Path, PathBuf};

/// The longest a source file may be, in lines.
const MAX_LINES: usize = 1000;

/// Extensions of the files written by hand (code and shaders).
const SOURCE_EXTENSIONS: &[&str] = &["rs", "py", "sh", "glsl", "vert", "frag", "comp", "mjs"];

/// Every source file under `dir`, skipping what is built or installed there rather than
/// written: hidden folders (virtual environments, caches), build outputs and node modules.
fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    for entry in entries {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if path.is_dir() {
            let generated = ["target", "build", "node_modules", "__pycache__", "corpus", "artifacts"];
            if !name.starts_with('.') && !generated.contains(&name.as_str()) && !name.ends_with(".egg-info") {
                sources(&path, out);
            }
        } else if path.extension().and_then(|e| e.to_str()).is_some_and(|e| SOURCE_EXTENSIONS.contains(&e)) {
            out.push(path);
        }
    }
}

/// Lines of a file (a last line without its newline counts).
fn line_count(path: &Path) -> usize {
    let text = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.iter().filter(|&&b| b == b'\n').count() + usize::from(text.last().is_some_and(|&b| b != b'\n'))
}

fn repository_sources() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = vec![root.join("build.rs")];
    for dir in ["src", "tests", "fuzz", "shaders", "tools"] {
        sources(&root.join(dir), &mut files);
    }
    files
}

#[test]
fn no_source_file_is_over_1000_lines() {
    let files = repository_sources();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // The walk reaches every part, so a mis-rooted or empty walk cannot pass.
    for expected in ["src/lib.rs", "src/main.rs", "tests/it/layout.rs", "fuzz/fuzz_targets", "shaders/common.glsl", "tools/setup.sh", "tools/python/pedscan_data/reader.py"] {
        let expected = root.join(expected);
        assert!(files.iter().any(|f| f.starts_with(&expected)), "{} is not among the sources walked", expected.display());
    }
    let mut long: Vec<(usize, String)> = files
        .iter()
        .map(|p| (line_count(p), p.strip_prefix(root).unwrap().display().to_string()))
        .filter(|(lines, _)| *lines > MAX_LINES)
        .collect();
    long.sort();
    assert!(long.is_empty(), "source files over {MAX_LINES} lines: {long:?}");
}

/// Lines of a repository file.
fn lines_of(rel: &str) -> usize {
    line_count(&Path::new(env!("CARGO_MANIFEST_DIR")).join(rel))
}

/// The binary only parses the command line and calls the library; the generator only runs the
/// stages, which live in their own modules.
#[test]
fn the_binary_and_the_generator_stay_thin() {
    let main = lines_of("src/main.rs");
    assert!(main <= 200, "src/main.rs has {main} lines (at most 200: commands belong in src/commands/)");
    let generator = lines_of("src/generator/mod.rs");
    assert!(generator <= 400, "src/generator/mod.rs has {generator} lines (at most 400: stages belong in their modules)");
}
