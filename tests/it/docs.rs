//! The documents a newcomer reads (README.md and docs/*.md) hold to the built binary: every
//! `pedscan` command, `--flag` and configuration key they name exists, every command, flag and
//! key that exists is named somewhere, the configuration block of docs/usage.md holds the
//! defaults, and every relative link and picture resolves.
//!
//! What counts as naming (code only, never prose): a code span or a fenced shell line with
//! `pedscan SUB --flag ...` (also `target/release/pedscan`, `tools/setup.sh SUB`, and
//! `python -m pedscan_data.MODULE --flag` against that module's argparse flags); a code span
//! that starts with a subcommand (`generate --resume`) or a Python module
//! (`train --range-change`); a code span that starts with `--flag`, which must be a flag of
//! pedscan, of a Python entry point or of one of the other tools the documents name
//! ([`OTHER_TOOLS_FLAGS`]), and documents that flag for the subcommands its paragraph, table
//! row, list item or heading names; the keys of ```toml blocks (commented-out keys included)
//! and code spans `section.key`, `[section]`, `[section] key = ...`. The truth comes from
//! `pedscan help` and `pedscan SUB --help`, from the configuration's own deserializer (which
//! refuses unknown keys and names the ones it takes) and from the Python modules' source.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// Flags of the other tools the documents show (cargo, cargo-mutants, mutmut, pip), so that a
/// code span naming one is not taken for a pedscan flag.
const OTHER_TOOLS_FLAGS: &[&str] = &[
    "--lib", "--test", "--release", "--locked", "--re", "--file", "--timeout", "--build-timeout",
    "--sharding", "--shard", "--in-place", "--max-children", "--no-run",
];

/// File extensions that make a dotted code span a file name, not a configuration key.
const FILE_EXTENSIONS: &[&str] = &["rs", "py", "md", "json", "toml", "png", "h5", "glb", "gltf", "txt", "yaml", "xml", "sh", "pt", "onnx"];

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// What the binary, the configuration and the Python entry points accept.
struct Truth {
    /// Every subcommand with its long flags (`--json`), aliases included.
    commands: BTreeMap<String, BTreeSet<String>>,
    /// Flag aliases (`--environment`): accepted, never required in the documents.
    aliases: BTreeSet<String>,
    /// Every Python entry point (`train`) with its flags.
    python: BTreeMap<String, BTreeSet<String>>,
    /// Every configuration key, dotted (`humans.count`, `sensor_model.platform.min_m`).
    keys: BTreeSet<String>,
    /// The keys that are tables (`humans`, `humans.tracks_transform`, `sensor_model.platform`).
    tables: BTreeSet<String>,
}

impl Truth {
    fn is_pedscan_flag(&self, flag: &str) -> bool {
        self.commands.values().any(|f| f.contains(flag))
    }
    fn is_python_flag(&self, flag: &str) -> bool {
        self.python.values().any(|f| f.contains(flag))
    }
}

fn truth() -> &'static Truth {
    static TRUTH: OnceLock<Truth> = OnceLock::new();
    TRUTH.get_or_init(|| {
        let mut aliases = BTreeSet::new();
        let commands = subcommands()
            .into_iter()
            .map(|sub| {
                let flags = if sub == "help" { BTreeSet::from(["--help".to_string()]) } else { flags_of(&sub, &mut aliases) };
                (sub, flags)
            })
            .collect();
        let (mut keys, mut tables) = (BTreeSet::new(), BTreeSet::new());
        config_keys("", &mut keys, &mut tables);
        Truth { commands, aliases, python: python_flags(), keys, tables }
    })
}

fn help(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_pedscan")).args(args).output().expect("run pedscan");
    assert!(out.status.success(), "pedscan {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).expect("help is UTF-8")
}

/// The subcommands `pedscan help` lists (clap's own `help` among them).
fn subcommands() -> Vec<String> {
    let text = help(&["help"]);
    let list = text.split("Commands:\n").nth(1).expect("`pedscan help` lists its commands");
    let subs: Vec<String> = list
        .lines()
        .take_while(|l| !l.trim().is_empty())
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .collect();
    assert!(subs.len() >= 5 && subs.iter().any(|s| s == "generate"), "commands parsed from `pedscan help`: {subs:?}");
    subs
}

/// The long flags `pedscan SUB --help` lists, and its `[alias: --x]` lines into `aliases`.
fn flags_of(sub: &str, aliases: &mut BTreeSet<String>) -> BTreeSet<String> {
    let text = help(&[sub, "--help"]);
    let mut flags = BTreeSet::new();
    for line in text.lines() {
        let t = line.trim_start();
        let t = if t.len() > 4 && t.starts_with('-') && t.as_bytes()[2] == b',' { t[4..].trim_start() } else { t };
        if let Some(flag) = t.strip_prefix("--").map(|r| flag_name(r)) {
            flags.insert(format!("--{flag}"));
        }
        if let Some(rest) = t.strip_prefix("[alias: ").or_else(|| t.strip_prefix("[aliases: ")) {
            for a in rest.trim_end_matches(']').split(',').map(str::trim) {
                flags.insert(a.to_string());
                aliases.insert(a.to_string());
            }
        }
    }
    assert!(flags.contains("--help"), "no flags parsed from `pedscan {sub} --help`:\n{text}");
    flags
}

/// The name part of a flag (`sequences` of `sequences <SEQUENCES>`).
fn flag_name(after_dashes: &str) -> &str {
    let end = after_dashes.find(|c: char| !(c.is_ascii_alphanumeric() || c == '-')).unwrap_or(after_dashes.len());
    &after_dashes[..end]
}

/// Every `"--flag"` literal of each Python module that parses arguments, and of the module
/// whose `add_arguments` it calls.
fn python_flags() -> BTreeMap<String, BTreeSet<String>> {
    let dir = root().join("tools/python/pedscan_data");
    let mut out = BTreeMap::new();
    let mut shared = Vec::new();
    for entry in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let path = entry.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap_or_default();
        if path.extension().is_some_and(|e| e == "py") && text.contains("add_argument(") {
            let mut flags: BTreeSet<String> = ["\"--", "'--"]
                .iter()
                .flat_map(|q| text.match_indices(q).map(|(i, _)| format!("--{}", flag_name(&text[i + 3..]))))
                .filter(|f| f.len() > 2)
                .collect();
            flags.insert("--help".into());
            out.insert(path.file_stem().unwrap().to_string_lossy().into_owned(), flags);
            // A module that takes another's arguments (`from .calibrate import add_arguments`).
            if let Some(i) = text.find(" import add_arguments") {
                let from = text[..i].rsplit("from .").next().unwrap_or("").trim().to_string();
                shared.push((path.file_stem().unwrap().to_string_lossy().into_owned(), from));
            }
        }
    }
    for (module, from) in shared {
        let more = out.get(&from).cloned().unwrap_or_else(|| panic!("{module} takes the arguments of {from}, which has none"));
        out.get_mut(&module).unwrap().extend(more);
    }
    assert!(out.contains_key("train") && out.contains_key("evaluate"), "Python entry points found: {:?}", out.keys());
    out
}

/// The fields serde names when refusing an unknown key in table `prefix` (`""`: the top),
/// written as a table or as an array of tables; `None` when `prefix` is no table.
fn probe_table(prefix: &str) -> Option<Vec<String>> {
    let forms = if prefix.is_empty() { vec![String::new()] } else { vec![format!("[{prefix}]\n"), format!("[[{prefix}]]\n")] };
    for form in forms {
        let text = format!("{form}__probe__ = 0\n");
        match toml::from_str::<pedscan::config::Config>(&text) {
            Ok(_) => panic!("configuration table `{prefix}` accepts unknown keys (the documents promise they are errors)"),
            Err(e) => {
                let msg = e.to_string();
                if let Some(rest) = msg.split("unknown field `__probe__`").nth(1) {
                    let line = rest.lines().next().unwrap_or("");
                    return Some(line.split('`').skip(1).step_by(2).map(str::to_string).collect());
                }
            }
        }
    }
    None
}

/// Every key of the configuration under `prefix`, by asking its deserializer.
fn config_keys(prefix: &str, keys: &mut BTreeSet<String>, tables: &mut BTreeSet<String>) {
    let fields = probe_table(prefix).unwrap_or_else(|| panic!("configuration table `{prefix}` did not name its keys"));
    for field in fields {
        let key = if prefix.is_empty() { field } else { format!("{prefix}.{field}") };
        keys.insert(key.clone());
        if probe_table(&key).is_some() {
            tables.insert(key.clone());
            config_keys(&key, keys, tables);
        }
    }
}

/// What the documents name, gathered over all of them, to hold against the truth the other way.
#[derive(Default)]
struct Found {
    /// Subcommands named.
    commands: BTreeSet<String>,
    /// (subcommand, flag) pairs named.
    flags: BTreeSet<(String, String)>,
    /// Configuration keys named.
    keys: BTreeSet<String>,
}

/// A piece of a document the checks read as one: a paragraph, a table row, a list item, or
/// one logical line of a fenced block (`lang` its info string).
struct Unit {
    line: usize,
    text: String,
    fenced: Option<String>,
    heading: String,
}

/// The document's units, in order.
fn units(text: &str) -> Vec<Unit> {
    let mut out: Vec<Unit> = Vec::new();
    let (mut fence, mut heading, mut open) = (None::<(String, String)>, String::new(), false);
    let mut continued: Option<Unit> = None;
    for (k, line) in text.lines().enumerate() {
        let n = k + 1;
        let trimmed = line.trim_start();
        if let Some((marker, lang)) = &fence {
            if trimmed.starts_with(marker.as_str()) {
                fence = None;
            } else if let Some(mut u) = continued.take() {
                u.text.push(' ');
                u.text.push_str(trimmed.trim_end_matches('\\'));
                if line.trim_end().ends_with('\\') { continued = Some(u) } else { out.push(u) }
            } else {
                let u = Unit { line: n, text: line.trim_end_matches('\\').to_string(), fenced: Some(lang.clone()), heading: heading.clone() };
                if line.trim_end().ends_with('\\') { continued = Some(u) } else { out.push(u) }
            }
            continue;
        }
        if trimmed.starts_with("```") || trimmed.starts_with("~~~") {
            let marker = trimmed[..3].to_string();
            fence = Some((marker.clone(), trimmed.trim_start_matches(marker.chars().next().unwrap()).trim().to_string()));
            open = false;
            continue;
        }
        if trimmed.is_empty() {
            open = false;
            continue;
        }
        if trimmed.starts_with('#') {
            heading = trimmed.to_string();
            out.push(Unit { line: n, text: trimmed.trim_start_matches('#').to_string(), fenced: None, heading: heading.clone() });
            open = false;
            continue;
        }
        let item = trimmed.starts_with('|') || trimmed.starts_with("- ") || trimmed.starts_with("* ") || trimmed.split_once(". ").is_some_and(|(d, _)| !d.is_empty() && d.chars().all(|c| c.is_ascii_digit()));
        match out.last_mut() {
            Some(u) if open && !item && !trimmed.starts_with('|') => {
                u.text.push(' ');
                u.text.push_str(trimmed);
            }
            _ => out.push(Unit { line: n, text: trimmed.to_string(), fenced: None, heading: heading.clone() }),
        }
        open = !trimmed.starts_with('|');
    }
    out
}

/// The code spans of a line of Markdown (`\|` read as `|`, as in a table).
fn code_spans(text: &str) -> Vec<String> {
    let b = text.as_bytes();
    let (mut out, mut i) = (Vec::new(), 0);
    while i < b.len() {
        if b[i] != b'`' {
            i += 1;
            continue;
        }
        let run = b[i..].iter().take_while(|&&c| c == b'`').count();
        let start = i + run;
        let mut j = start;
        let mut close = None;
        while j < b.len() {
            if b[j] == b'`' {
                let r = b[j..].iter().take_while(|&&c| c == b'`').count();
                if r == run {
                    close = Some(j);
                    break;
                }
                j += r;
            } else {
                j += 1;
            }
        }
        match close {
            Some(j) => {
                out.push(text[start..j].trim().replace("\\|", "|"));
                i = j + run;
            }
            None => i = start,
        }
    }
    out
}

/// The text of a line with its code spans taken out (for links).
fn without_code(text: &str) -> String {
    let mut out = text.to_string();
    for span in code_spans(text) {
        out = out.replacen(&span, "", 1);
    }
    out
}

/// The `--flags` among the words.
fn flags_in(words: &[&str]) -> Vec<String> {
    words
        .iter()
        .map(|w| w.trim_start_matches(['[', '(', '"', '\'']))
        .filter_map(|w| w.strip_prefix("--"))
        .map(flag_name)
        .filter(|f| !f.is_empty())
        .map(|f| format!("--{f}"))
        .collect()
}

/// A word that stands for something to fill in (`<command>`, `SUB`).
fn placeholder(word: &str) -> bool {
    word.starts_with('<') || word.chars().all(|c| c.is_ascii_uppercase() || c == '_' || c == '.')
}

/// The subcommands a piece of code names, and its errors.
fn check_code(code: &str, whole_span: bool, t: &Truth, found: &mut Found, errors: &mut Vec<String>) -> BTreeSet<String> {
    let mut named = BTreeSet::new();
    for segment in code.split("&&").flat_map(|s| s.split(';')).flat_map(|s| s.split(" | ")) {
        let words: Vec<&str> = segment.split_whitespace().map(|w| w.trim_matches(['"', '\''])).collect();
        let first = words.first().copied().unwrap_or("");
        let pedscan = words.iter().position(|w| !w.contains('=') && (*w == "pedscan" || w.ends_with("/pedscan")));
        let setup = words.iter().position(|w| w.ends_with("tools/setup.sh")).filter(|&i| words.get(i + 1).is_some_and(|s| t.commands.contains_key(*s)));
        let python = words.windows(2).position(|w| w[0] == "-m" && w[1].starts_with("pedscan_data."));
        if let Some(i) = pedscan.or(setup) {
            match words.get(i + 1) {
                None => {}
                Some(w) if w.starts_with('-') => {
                    for f in flags_in(&words[i + 1..]).into_iter().filter(|f| f != "--help" && f != "--version") {
                        errors.push(format!("`{}`: pedscan itself has no flag `{f}`", segment.trim()));
                    }
                }
                Some(w) if placeholder(w) => {}
                Some(sub) => match t.commands.get(*sub) {
                    None => errors.push(format!("`{}`: pedscan has no subcommand `{sub}`", segment.trim())),
                    Some(flags) => {
                        named.insert(sub.to_string());
                        for f in flags_in(&words[i + 2..]) {
                            if !flags.contains(&f) {
                                errors.push(format!("`{}`: `pedscan {sub}` has no flag `{f}`", segment.trim()));
                            }
                            found.flags.insert((sub.to_string(), f));
                        }
                    }
                },
            }
        } else if let Some(i) = python {
            let module = &words[i + 1]["pedscan_data.".len()..];
            check_python(segment, module, &words[i + 2..], t, errors);
        } else if whole_span && t.commands.contains_key(first) {
            named.insert(first.to_string());
            for f in flags_in(&words[1..]) {
                if !t.commands[first].contains(&f) {
                    errors.push(format!("`{}`: `pedscan {first}` has no flag `{f}`", segment.trim()));
                }
                found.flags.insert((first.to_string(), f));
            }
        } else if whole_span && t.python.contains_key(first) && words.len() > 1 {
            check_python(segment, first, &words[1..], t, errors);
        }
    }
    named
}

fn check_python(segment: &str, module: &str, words: &[&str], t: &Truth, errors: &mut Vec<String>) {
    match t.python.get(module) {
        None => errors.push(format!("`{}`: no Python entry point `pedscan_data.{module}`", segment.trim())),
        Some(flags) => {
            for f in flags_in(words).into_iter().filter(|f| !flags.contains(f)) {
                errors.push(format!("`{}`: `python -m pedscan_data.{module}` has no flag `{f}`", segment.trim()));
            }
        }
    }
}

/// The configuration keys a code span names: `section.key`, `[section]`, `[section] key = ...`.
fn span_keys(span: &str, t: &Truth) -> Vec<String> {
    let top = |path: &str| t.tables.contains(path.split('.').next().unwrap_or(""));
    if let Some(rest) = span.strip_prefix('[') {
        let rest = rest.trim_start_matches('[');
        let Some((table, after)) = rest.split_once(']') else { return vec![] };
        if !top(table) {
            return vec![];
        }
        let after = after.trim_start_matches(']').trim();
        let mut keys = vec![table.to_string()];
        if let Some((key, _)) = after.split_once('=') {
            keys.push(format!("{table}.{}", key.trim()));
        }
        return keys;
    }
    let path = span.split(|c: char| c.is_whitespace() || c == '=').next().unwrap_or("");
    let dotted = path.contains('.') && path.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_' || c == '.');
    let file = path.rsplit('.').next().is_some_and(|ext| FILE_EXTENSIONS.contains(&ext));
    if dotted && top(path) && !file { vec![path.to_string()] } else { vec![] }
}

/// The keys of a TOML block's line, within `table` (commented-out keys and tables included);
/// a table header updates `table`.
fn toml_line_keys(line: &str, table: &mut String) -> Vec<String> {
    let mut l = line.trim();
    if let Some(rest) = l.strip_prefix('#') {
        let rest = rest.trim_start();
        let is_key = rest.split_once('=').is_some_and(|(k, _)| !k.trim().is_empty() && k.trim().chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_'));
        if !(rest.starts_with('[') || is_key) {
            return vec![];
        }
        l = rest;
    }
    if l.starts_with('[') {
        *table = l.trim_start_matches('[').split(']').next().unwrap_or("").trim().to_string();
        return vec![table.clone()];
    }
    let Some((key, value)) = l.split_once('=') else { return vec![] };
    let key = if table.is_empty() { key.trim().to_string() } else { format!("{table}.{}", key.trim()) };
    let mut keys = vec![key.clone()];
    if let Some(inner) = value.trim().strip_prefix('{') {
        let inner = inner.split('}').next().unwrap_or("");
        keys.extend(inner.split(',').filter_map(|kv| kv.split_once('=')).map(|(k, _)| format!("{key}.{}", k.trim())));
    }
    keys
}

/// A configuration key a document names: it must exist.
fn claim_key(key: String, t: &Truth, found: &mut Found, errs: &mut Vec<String>) {
    if !t.keys.contains(&key) {
        errs.push(format!("configuration key `{key}` does not exist"));
    }
    found.keys.insert(key);
}

/// Checks one document's text: every command, flag and key it names exists. Returns the errors
/// (each naming the document and line); adds what it names to `found`.
fn check_doc(name: &str, text: &str, t: &Truth, found: &mut Found) -> Vec<String> {
    let mut errors = Vec::new();
    let mut table = String::new();
    for unit in units(text) {
        if unit.fenced.as_deref() != Some("toml") {
            table.clear();
        }
        let mut errs = Vec::new();
        match unit.fenced.as_deref() {
            Some("toml") => {
                for key in toml_line_keys(&unit.text, &mut table) {
                    claim_key(key, t, found, &mut errs);
                }
            }
            Some("" | "sh" | "bash" | "console" | "shell") => {
                let code = if unit.text.trim_start().starts_with('#') { "" } else { unit.text.split(" #").next().unwrap_or("") };
                let named = check_code(code, false, t, found, &mut errs);
                found.commands.extend(named);
            }
            Some(_) => {}
            None => {
                let spans = code_spans(&unit.text);
                let mut named: BTreeSet<String> = code_spans(&unit.heading).into_iter().filter(|s| t.commands.contains_key(s)).collect();
                let mut standalone = Vec::new();
                for span in &spans {
                    named.extend(check_code(span, true, t, found, &mut errs));
                    if t.commands.contains_key(span.as_str()) {
                        named.insert(span.clone());
                    }
                    if span.starts_with("--") {
                        standalone.extend(flags_in(&span.split_whitespace().collect::<Vec<_>>()));
                    }
                    for key in span_keys(span, t) {
                        claim_key(key, t, found, &mut errs);
                    }
                }
                for f in standalone {
                    if !t.is_pedscan_flag(&f) && !t.is_python_flag(&f) && !OTHER_TOOLS_FLAGS.contains(&f.as_str()) {
                        errs.push(format!("`{f}` is no flag of pedscan, of a Python entry point or of the other tools listed in tests/it/docs.rs"));
                    }
                    for sub in named.iter().filter(|s| t.commands[*s].contains(&f)) {
                        found.flags.insert((sub.clone(), f.clone()));
                    }
                }
                found.commands.extend(named);
            }
        }
        errors.extend(errs.into_iter().map(|e| format!("{name}:{}: {e}", unit.line)));
    }
    errors
}

/// What exists but no document names.
fn check_coverage(found: &Found, t: &Truth) -> Vec<String> {
    let mut errors = Vec::new();
    for (sub, flags) in t.commands.iter().filter(|(sub, _)| *sub != "help") {
        if !found.commands.contains(sub) {
            errors.push(format!("subcommand `pedscan {sub}` is named in no document"));
        }
        for f in flags.iter().filter(|f| !["--help", "--version"].contains(&f.as_str()) && !t.aliases.contains(*f)) {
            if !found.flags.contains(&(sub.clone(), f.clone())) {
                errors.push(format!("flag `{f}` of `pedscan {sub}` is documented nowhere (name it in a `pedscan {sub} ...` span, or in a paragraph, row or section naming `{sub}`)"));
            }
        }
    }
    for key in t.keys.iter().filter(|k| !found.keys.contains(*k)) {
        errors.push(format!("configuration key `{key}` is documented nowhere (the defaults block of docs/usage.md lists every key)"));
    }
    errors
}

/// GitHub's anchors for the headings of a Markdown text.
fn anchors(text: &str) -> BTreeSet<String> {
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let mut out = BTreeSet::new();
    for unit in units(text).into_iter().filter(|u| u.fenced.is_none() && u.heading.starts_with('#') && u.text == u.heading.trim_start_matches('#')) {
        let slug: String = unit.text.trim().to_lowercase().chars().filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        }).collect();
        let n = seen.entry(slug.clone()).or_insert(0);
        out.insert(if *n == 0 { slug.clone() } else { format!("{slug}-{n}") });
        *n += 1;
    }
    out
}

/// The targets of the Markdown links and pictures of a line (code left out).
fn link_targets(text: &str) -> Vec<String> {
    let text = without_code(text);
    let mut out: Vec<String> = text.match_indices("](").filter_map(|(i, _)| {
        let rest = &text[i + 2..];
        rest.find(')').map(|end| rest[..end].split_whitespace().next().unwrap_or("").trim_matches(['<', '>']).to_string())
    }).collect();
    if let Some((label, target)) = text.trim().split_once("]: ") {
        if label.starts_with('[') {
            out.push(target.split_whitespace().next().unwrap_or("").to_string());
        }
    }
    out
}

/// Every relative link and picture of the document at `path` (its text `text`) resolves;
/// `#anchor`s into Markdown files name a heading there.
fn check_links(path: &Path, text: &str) -> Vec<String> {
    let name = path.strip_prefix(root()).unwrap_or(path).display().to_string();
    let dir = path.parent().unwrap();
    let mut errors = Vec::new();
    for unit in units(text).into_iter().filter(|u| u.fenced.is_none()) {
        for target in link_targets(&unit.text) {
            if target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            let (file, anchor) = target.split_once('#').map_or((target.as_str(), None), |(f, a)| (f, Some(a)));
            let resolved: PathBuf = if file.is_empty() { path.to_path_buf() } else { dir.join(file) };
            if !resolved.exists() {
                errors.push(format!("{name}:{}: link `{target}`: {} does not exist", unit.line, resolved.display()));
            } else if let Some(anchor) = anchor.filter(|_| resolved.extension().is_some_and(|e| e == "md")) {
                let other = std::fs::read_to_string(&resolved).unwrap_or_default();
                if !anchors(&other).contains(anchor) {
                    errors.push(format!("{name}:{}: link `{target}`: no heading with that anchor", unit.line));
                }
            }
        }
    }
    errors
}

/// README.md and every docs/*.md, with their text.
fn documents() -> Vec<(PathBuf, String)> {
    let mut paths = vec![root().join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs")).expect("docs/").map(|e| e.unwrap().path()).filter(|p| p.extension().is_some_and(|e| e == "md")).collect();
    docs.sort();
    paths.extend(docs);
    assert!(paths.len() >= 10, "README.md and the docs/ topics: {paths:?}");
    paths.into_iter().map(|p| {
        let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        (p, text)
    }).collect()
}

fn rel(p: &Path) -> String {
    p.strip_prefix(root()).unwrap().display().to_string()
}

/// Every document checked, with what they name together.
fn check_all(docs: &[(PathBuf, String)]) -> (Vec<String>, Found) {
    let mut found = Found::default();
    let errors = docs.iter().flat_map(|(p, text)| check_doc(&rel(p), text, truth(), &mut found)).collect();
    (errors, found)
}

#[test]
fn every_command_flag_and_key_the_documents_name_exists() {
    let (errors, found) = check_all(&documents());
    assert!(errors.is_empty(), "the documents name what the binary does not have:\n{}", errors.join("\n"));
    // The check reads something: the two commands of the README and a key of each kind.
    assert!(found.flags.contains(&("generate".into(), "--png".into())), "{:?}", found.flags);
    assert!(found.keys.contains("sensor_model.platform.min_m") && found.keys.contains("humans.tracks_transform.scale"));
}

#[test]
fn every_command_flag_and_key_is_documented() {
    let (_, found) = check_all(&documents());
    let errors = check_coverage(&found, truth());
    assert!(errors.is_empty(), "the binary has what no document names:\n{}", errors.join("\n"));
}

#[test]
fn every_relative_link_and_picture_resolves() {
    let docs = documents();
    let errors: Vec<String> = docs.iter().flat_map(|(p, text)| check_links(p, text)).collect();
    assert!(errors.is_empty(), "broken links:\n{}", errors.join("\n"));
    let pictures = docs.iter().flat_map(|(_, t)| t.lines().flat_map(link_targets)).filter(|l| l.ends_with(".png")).count();
    assert!(pictures >= 9, "the pictures of data/readme/ are shown ({pictures} found)");
}

/// The first ```toml block of docs/usage.md is the configuration's defaults, value for value.
#[test]
fn the_configuration_block_holds_the_defaults() {
    let usage = std::fs::read_to_string(root().join("docs/usage.md")).unwrap();
    let block = usage.split("```toml\n").nth(1).and_then(|b| b.split("\n```").next()).expect("docs/usage.md has a ```toml block");
    let data = pedscan::config::data_dir();
    let text = block.replace("<data>", &data.display().to_string());
    let parsed: pedscan::config::Config = toml::from_str(&text).unwrap_or_else(|e| panic!("the defaults block does not parse: {e}"));
    assert!(parsed == pedscan::config::Config::default(), "the defaults block differs from the defaults:\n{}\nagainst\n{}", parsed.to_toml(), pedscan::config::Config::default().to_toml());
}

/// Mistakes planted in a copy of a document fail the check, and the message names them.
#[test]
fn planted_mistakes_fail_the_check_and_are_named() {
    let usage = std::fs::read_to_string(root().join("docs/usage.md")).unwrap();
    let (clean, _) = check_all(&[(root().join("docs/usage.md"), usage.clone())]);
    assert!(clean.is_empty(), "{clean:?}");
    let cases: &[(&str, &str)] = &[
        ("Run `pedscan generate --no-such-flag` for more.", "`pedscan generate` has no flag `--no-such-flag`"),
        ("```sh\npedscan crosscheck --frames 2 \\\n    --strip-pngs x.png\n```", "`pedscan crosscheck` has no flag `--strip-pngs`"),
        ("```sh\nbash tools/setup.sh generate --sequence 3\n```", "no flag `--sequence`"),
        ("Then `generate --resumes`.", "`pedscan generate` has no flag `--resumes`"),
        ("| `--no-such-flag N` | does nothing |", "`--no-such-flag` is no flag"),
        ("`pedscan frobnicate DIR`", "pedscan has no subcommand `frobnicate`"),
        ("`python -m pedscan_data.train DATA --no-such-flag`", "`python -m pedscan_data.train` has no flag `--no-such-flag`"),
        ("Set `render.no_such_key = 3`.", "configuration key `render.no_such_key` does not exist"),
        ("`[debug] no_such_switch = true`", "configuration key `debug.no_such_switch` does not exist"),
        ("```toml\n[scene]\nno_such_key = 1\n```", "configuration key `scene.no_such_key` does not exist"),
    ];
    for (plant, expected) in cases {
        let text = format!("{usage}\n{plant}\n");
        let (errors, _) = check_all(&[(root().join("docs/usage.md"), text)]);
        assert!(errors.iter().any(|e| e.contains(expected) && e.starts_with("docs/usage.md:")), "planting {plant:?} gave {errors:?}, not {expected:?}");
    }
    // A link to nothing, and an anchor to no heading.
    let path = root().join("docs/usage.md");
    for (plant, expected) in [("[x](no-such-file.md)", "no-such-file.md"), ("[x](inputs.md#no-such-heading)", "no heading")] {
        let errors = check_links(&path, &format!("{usage}\n{plant}\n"));
        assert!(errors.iter().any(|e| e.contains(expected)), "planting {plant:?} gave {errors:?}");
    }
    assert!(check_links(&path, &format!("{usage}\n[x](inputs.md#recorded-backgrounds)\n")).is_empty());
}

/// A flag or key taken out of every document is reported as undocumented, by name.
#[test]
fn an_undocumented_flag_or_key_is_named() {
    let docs: Vec<(PathBuf, String)> = documents().into_iter().map(|(p, t)| (p, t.replace("--strip-png", "--json").replace("mixed_return_m", "range_noise_m"))).collect();
    let (_, found) = check_all(&docs);
    let errors = check_coverage(&found, truth());
    assert!(errors.iter().any(|e| e.contains("`--strip-png` of `pedscan crosscheck`")), "{errors:?}");
    assert!(errors.iter().any(|e| e.contains("`sensor_model.mixed_return_m`")), "{errors:?}");
}
