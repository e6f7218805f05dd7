//! The library's layering: dependencies between its modules go one way (no two children of a
//! module use each other, directly or through others: the stages at the top, the parts of a
//! stage below), and `unsafe` lives only in `gpu`, the HDF5 writer and `debug`.
//!
//! Both read the code, not the comments or strings: a small lexer drops those, and the items
//! under `#[cfg(test)]` (a module's unit tests may drive the whole pipeline). A module uses
//! another where its code names it by path (`crate::input::recording::X`, `super::tracks`,
//! `use crate::{config::Config, input}`), through the re-exports of the modules on the way
//! (`crate::input::Recording` is `input::recording`'s).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// A source file's tokens: identifiers and keywords, `::`, and single punctuation characters;
/// comments dropped, string and character literals each one placeholder token.
fn tokens(text: &str) -> Vec<String> {
    let c: Vec<char> = text.chars().collect();
    let at = |i: usize| c.get(i).copied().unwrap_or('\0');
    let ident = |ch: char| ch.is_alphanumeric() || ch == '_';
    let mut out = Vec::new();
    let mut i = 0;
    while i < c.len() {
        let ch = c[i];
        if ch.is_whitespace() {
            i += 1;
        } else if ch == '/' && at(i + 1) == '/' {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && at(i + 1) == '*' {
            let mut depth = 0;
            loop {
                if at(i) == '/' && at(i + 1) == '*' {
                    depth += 1;
                    i += 2;
                } else if at(i) == '*' && at(i + 1) == '/' {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else if i >= c.len() {
                    break;
                } else {
                    i += 1;
                }
            }
        } else if ch == '"' {
            i = after_string(&c, i + 1, None);
            out.push("\"\"".to_string());
        } else if ch == '\'' {
            if at(i + 1) == '\\' {
                // An escaped character: '\n', '\'', '\u{..}'.
                i += 3;
                while i < c.len() && c[i] != '\'' {
                    i += 1;
                }
                i += 1;
                out.push("'c'".to_string());
            } else if at(i + 2) == '\'' {
                i += 3;
                out.push("'c'".to_string());
            } else {
                // A lifetime or a label.
                i += 1;
                out.push("'".to_string());
            }
        } else if ident(ch) {
            let start = i;
            while i < c.len() && ident(c[i]) {
                i += 1;
            }
            let word: String = c[start..i].iter().collect();
            let raw = matches!(word.as_str(), "r" | "br" | "cr");
            if raw && (at(i) == '"' || (at(i) == '#' && (at(i + 1) == '#' || at(i + 1) == '"'))) {
                let mut hashes = 0;
                while at(i) == '#' {
                    hashes += 1;
                    i += 1;
                }
                i = after_string(&c, i + 1, Some(hashes));
                out.push("\"\"".to_string());
            } else if word == "r" && at(i) == '#' {
                // A raw identifier: r#type.
                i += 1;
            } else if matches!(word.as_str(), "b" | "c") && at(i) == '"' {
                i = after_string(&c, i + 1, None);
                out.push("\"\"".to_string());
            } else if !(word == "b" && at(i) == '\'') {
                out.push(word);
            }
        } else if ch == ':' && at(i + 1) == ':' {
            out.push("::".to_string());
            i += 2;
        } else {
            out.push(ch.to_string());
            i += 1;
        }
    }
    out
}

/// The index after a string literal whose text starts at `i`: a raw string (`Some(hashes)`)
/// ends at `"` and that many `#`, another at the first `"` not escaped.
fn after_string(c: &[char], mut i: usize, raw: Option<usize>) -> usize {
    let hashes = raw.unwrap_or(0);
    while i < c.len() {
        if c[i] == '\\' && raw.is_none() {
            i += 2;
        } else if c[i] == '"' && (0..hashes).all(|k| c.get(i + 1 + k) == Some(&'#')) {
            return i + 1 + hashes;
        } else {
            i += 1;
        }
    }
    i
}

/// `#[cfg(test)]` at `t[i..]`.
fn is_cfg_test(t: &[String], i: usize) -> bool {
    t.len() >= i + 7 && t[i..i + 7].iter().map(String::as_str).eq(["#", "[", "cfg", "(", "test", ")", "]"])
}

/// `#![cfg(test)]` at `t[i..]`: the whole file is test code.
fn is_inner_cfg_test(t: &[String], i: usize) -> bool {
    t.len() >= i + 8 && t[i..i + 8].iter().map(String::as_str).eq(["#", "!", "[", "cfg", "(", "test", ")", "]"])
}

/// The index after the bracketed group opening at `t[i]` (`(`, `[` or `{`).
fn after_group(t: &[String], mut i: usize) -> usize {
    let mut depth = 0;
    while i < t.len() {
        match t[i].as_str() {
            "(" | "[" | "{" => depth += 1,
            ")" | "]" | "}" => {
                depth -= 1;
                if depth == 0 {
                    return i + 1;
                }
            }
            _ => {}
        }
        i += 1;
    }
    i
}

/// The tokens outside the items marked `#[cfg(test)]`, and the names of the test modules
/// whose files lie beside (`#[cfg(test)] mod tests;`). A file under `#![cfg(test)]` is all
/// test code.
fn without_tests(t: &[String]) -> (Vec<String>, Vec<String>) {
    if (0..t.len()).any(|i| is_inner_cfg_test(t, i)) {
        return (Vec::new(), Vec::new());
    }
    let (mut code, mut test_mods) = (Vec::new(), Vec::new());
    let mut i = 0;
    while i < t.len() {
        if !is_cfg_test(t, i) {
            code.push(t[i].clone());
            i += 1;
            continue;
        }
        i += 7;
        // Further attributes and a visibility, then the item itself.
        while t.get(i).is_some_and(|s| s == "#") {
            i = after_group(t, i + 1);
        }
        if t.get(i).is_some_and(|s| s == "pub") {
            i += 1;
            if t.get(i).is_some_and(|s| s == "(") {
                i = after_group(t, i);
            }
        }
        if t.get(i).is_some_and(|s| s == "mod") && t.get(i + 2).is_some_and(|s| s == ";") {
            test_mods.push(t[i + 1].clone());
        }
        while i < t.len() {
            match t[i].as_str() {
                ";" => {
                    i += 1;
                    break;
                }
                "{" => {
                    i = after_group(t, i);
                    break;
                }
                "(" | "[" => i = after_group(t, i),
                _ => i += 1,
            }
        }
    }
    (code, test_mods)
}

fn is_ident(s: &str) -> bool {
    s.chars().next().is_some_and(|c| c.is_alphabetic() || c == '_')
}

/// One path of a use tree or an expression, with the name a `use` gives it (`as`).
type Leaf = (Vec<String>, Option<String>);

/// Reads the path (or use tree, its `{}` groups expanded) at `t[i..]` under `prefix` into
/// `out`; returns the index after it.
fn read_tree(t: &[String], mut i: usize, prefix: Vec<String>, out: &mut Vec<Leaf>) -> usize {
    let mut path = prefix;
    loop {
        match t.get(i).map(String::as_str) {
            Some("{") => {
                i += 1;
                while i < t.len() && t[i] != "}" {
                    i = read_tree(t, i, path.clone(), out);
                    if t.get(i).is_some_and(|s| s == ",") {
                        i += 1;
                    } else if t.get(i).is_some_and(|s| s != "}") {
                        break;
                    }
                }
                return i + 1;
            }
            Some("*") => {
                path.push("*".into());
                out.push((path, None));
                return i + 1;
            }
            Some(s) if is_ident(s) => {
                path.push(s.to_string());
                i += 1;
            }
            _ => {
                out.push((path, None));
                return i;
            }
        }
        if t.get(i).is_some_and(|s| s == "::") {
            i += 1;
            continue;
        }
        let alias = (t.get(i).is_some_and(|s| s == "as")).then(|| t.get(i + 1).cloned()).flatten();
        if alias.is_some() {
            i += 2;
        }
        out.push((path, alias));
        return i;
    }
}

/// The library as modules: each module's path (`[]` the crate, `["input", "recording"]`), the
/// paths its code names (with where: file), and the names it re-exports.
#[derive(Default)]
struct Library {
    /// Module -> (file, the paths its code names from `crate`, `self` or `super`).
    modules: BTreeMap<Vec<String>, (String, Vec<Vec<String>>)>,
    /// (module, name) -> the absolute path it re-exports.
    reexports: BTreeMap<(Vec<String>, String), Vec<String>>,
}

/// The module a file under `src/` holds: `a/b.rs` and `a/b/mod.rs` hold `a::b`, `lib.rs` the
/// crate itself.
fn module_of(rel: &str) -> Vec<String> {
    let mut parts: Vec<String> = rel.trim_end_matches(".rs").split('/').map(String::from).collect();
    if matches!(parts.last().map(String::as_str), Some("mod") | Some("lib")) {
        parts.pop();
    }
    parts
}

impl Library {
    /// The library from its files (path under `src/` and text); `main.rs`, the binary, is not
    /// part of it.
    fn read(files: &[(String, String)]) -> Library {
        let mut lib = Library::default();
        let mut test_modules: BTreeSet<Vec<String>> = BTreeSet::new();
        let mut code: BTreeMap<Vec<String>, (String, Vec<String>)> = BTreeMap::new();
        for (rel, text) in files.iter().filter(|(rel, _)| rel != "main.rs") {
            let module = module_of(rel);
            let (tokens, tests) = without_tests(&tokens(text));
            test_modules.extend(tests.into_iter().map(|name| [module.clone(), vec![name]].concat()));
            code.insert(module, (rel.clone(), tokens));
        }
        code.retain(|m, _| !(1..=m.len()).any(|k| test_modules.contains(&m[..k])));
        let known: BTreeSet<Vec<String>> = code.keys().cloned().collect();
        for (module, (rel, t)) in &code {
            let mut named = Vec::new();
            for i in 0..t.len() {
                let starts = matches!(t[i].as_str(), "crate" | "self" | "super") && t.get(i + 1).is_some_and(|s| s == "::");
                if starts && (i == 0 || t[i - 1] != "::") {
                    let mut leaves = Vec::new();
                    read_tree(t, i, Vec::new(), &mut leaves);
                    named.extend(leaves.into_iter().map(|(p, _)| p));
                }
                let public = i > 0 && (t[i - 1] == "pub" || (t[i - 1] == ")" && t[..i].iter().rev().take(8).any(|s| s == "pub")));
                if t[i] == "use" && public {
                    let mut leaves = Vec::new();
                    read_tree(t, i + 1, Vec::new(), &mut leaves);
                    for (mut path, alias) in leaves {
                        if path.last().is_some_and(|s| s == "self") {
                            path.pop();
                        }
                        let child = path.first().is_some_and(|s| known.contains(&[module.clone(), vec![s.clone()]].concat()));
                        let relative = path.first().is_some_and(|s| matches!(s.as_str(), "crate" | "self" | "super"));
                        if let (Some(name), true) = (alias.or_else(|| path.last().cloned()), child || relative) {
                            if name != "*" {
                                let base = if child { module.clone() } else { Vec::new() };
                                let abs = absolute(module, &[base, path].concat());
                                lib.reexports.insert((module.clone(), name), abs);
                            }
                        }
                    }
                }
            }
            lib.modules.insert(module.clone(), (rel.clone(), named));
        }
        lib
    }

    /// The module a path from `crate` names: its longest known module prefix, followed
    /// through the re-exports of the module it stops at.
    fn module_named(&self, path: &[String]) -> Vec<String> {
        let mut path = path.to_vec();
        for _ in 0..8 {
            let k = (0..=path.len()).rev().find(|&k| self.modules.contains_key(&path[..k])).unwrap_or(0);
            let Some(next) = path.get(k) else { return path };
            match self.reexports.get(&(path[..k].to_vec(), next.clone())) {
                Some(target) if target != &path[..=k] => path = [target.clone(), path[k + 1..].to_vec()].concat(),
                _ => return path[..k].to_vec(),
            }
        }
        path
    }

    /// Per module, the graph of its children: child -> child it uses -> (a file, a path named
    /// there), from every use between two of them (or their parts).
    fn graphs(&self) -> BTreeMap<Vec<String>, Graph> {
        let mut graphs: BTreeMap<Vec<String>, Graph> = BTreeMap::new();
        for (module, (rel, named)) in &self.modules {
            for path in named {
                let target = self.module_named(&absolute(module, path));
                let k = module.iter().zip(&target).take_while(|(a, b)| a == b).count();
                if k < module.len() && k < target.len() {
                    let evidence = (format!("src/{rel}"), path.join("::"));
                    graphs.entry(module[..k].to_vec()).or_default().entry(module[k].clone()).or_default().entry(target[k].clone()).or_insert(evidence);
                }
            }
        }
        graphs
    }
}

/// Child -> child it uses -> (file, path): one use that makes the edge, for the message.
type Graph = BTreeMap<String, BTreeMap<String, (String, String)>>;

/// `path` from `module`, from the crate: `crate::` dropped, `self` and `super` resolved.
fn absolute(module: &[String], path: &[String]) -> Vec<String> {
    let (mut base, mut rest) = match path.first().map(String::as_str) {
        Some("crate") => (Vec::new(), &path[1..]),
        Some("self") => (module.to_vec(), &path[1..]),
        Some("super") => (module.to_vec(), path),
        _ => (Vec::new(), path),
    };
    while rest.first().is_some_and(|s| s == "super") {
        base.pop();
        rest = &rest[1..];
    }
    base.extend(rest.iter().filter(|s| *s != "self").cloned());
    base
}

/// A cycle of `g`, as its nodes with the first repeated at the end, if it has one.
fn cycle(g: &Graph) -> Option<Vec<String>> {
    fn visit<'a>(g: &'a Graph, node: &'a str, state: &mut BTreeMap<&'a str, bool>, stack: &mut Vec<&'a str>) -> Option<Vec<String>> {
        state.insert(node, true);
        stack.push(node);
        for next in g.get(node).into_iter().flat_map(|e| e.keys()) {
            match state.get(next.as_str()) {
                Some(true) => {
                    let from = stack.iter().position(|n| *n == next.as_str()).expect("on the stack");
                    return Some(stack[from..].iter().map(|s| s.to_string()).chain([next.clone()]).collect());
                }
                Some(false) => {}
                None => {
                    if let Some(c) = visit(g, next, state, stack) {
                        return Some(c);
                    }
                }
            }
        }
        stack.pop();
        state.insert(node, false);
        None
    }
    let mut state = BTreeMap::new();
    g.keys().find_map(|n| if state.contains_key(n.as_str()) { None } else { visit(g, n, &mut state, &mut Vec::new()) })
}

/// The nodes `from` reaches in `g`.
fn reached(g: &Graph, from: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut todo = vec![from.to_string()];
    while let Some(n) = todo.pop() {
        for next in g.get(&n).into_iter().flat_map(|e| e.keys()) {
            if seen.insert(next.clone()) {
                todo.push(next.clone());
            }
        }
    }
    seen
}

/// The modules that use each other, per parent module and per group that does (a strongly
/// connected component): one cycle of the group, then every use between its members with a
/// file and the path that makes it.
fn cycles(lib: &Library) -> Vec<String> {
    let mut found = Vec::new();
    for (parent, g) in lib.graphs() {
        let mut placed = BTreeSet::new();
        for n in g.keys() {
            let reach = reached(&g, n);
            if placed.contains(n) || !reach.contains(n) {
                continue;
            }
            let group: BTreeSet<String> = reach.into_iter().filter(|m| reached(&g, m).contains(n)).collect();
            placed.extend(group.iter().cloned());
            let inside: Graph = group
                .iter()
                .map(|m| (m.clone(), g[m].iter().filter(|(to, _)| group.contains(*to)).map(|(to, e)| (to.clone(), e.clone())).collect()))
                .collect();
            let c = cycle(&inside).expect("a group that reaches itself has a cycle");
            let uses: Vec<String> =
                inside.iter().flat_map(|(from, e)| e.iter().map(move |(to, (file, path))| format!("  {from} -> {to}: {file} names {path}"))).collect();
            let within = if parent.is_empty() { "crate".to_string() } else { parent.join("::") };
            found.push(format!("in `{within}`: {} (the uses among {}:\n{})", c.join(" -> "), Vec::from_iter(group).join(", "), uses.join("\n")));
        }
    }
    found
}

/// Every `.rs` file under `src/`: its path there and its text.
fn library_files() -> Vec<(String, String)> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<(String, String)>) {
        for entry in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(root, &path, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let rel = path.strip_prefix(root).unwrap().to_string_lossy().replace('\\', "/");
                out.push((rel, std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))));
            }
        }
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut out = Vec::new();
    walk(&root, &root, &mut out);
    out.sort();
    out
}

#[test]
fn modules_use_each_other_one_way_only() {
    let lib = Library::read(&library_files());
    let graphs = lib.graphs();
    // The reading reaches the stages: a mis-rooted walk or a lexer that loses the code fails.
    let top = &graphs[&Vec::new()];
    for (from, to) in [("generator", "pose"), ("pose", "scene"), ("scene", "input"), ("commands", "generator"), ("backend", "config"), ("config", "input")] {
        assert!(top.get(from).is_some_and(|e| e.contains_key(to)), "{from} -> {to} not seen: {top:?}");
    }
    let found = cycles(&lib);
    assert!(found.is_empty(), "modules that use each other (break one use, e.g. move what is shared to the module that is used):\n{}", found.join("\n"));
}

/// `unsafe` only where its reason lives: the Vulkan calls (`gpu`), the HDF5 library's C calls
/// (`output/h5.rs`) and the test hook that kills the process (`debug.rs`).
#[test]
fn unsafe_code_lives_only_in_gpu_the_hdf5_writer_and_debug() {
    let allowed = |rel: &str| rel.starts_with("gpu/") || rel == "output/h5.rs" || rel == "debug.rs";
    let with_unsafe: Vec<String> =
        library_files().into_iter().filter(|(_, text)| tokens(text).iter().any(|t| t == "unsafe")).map(|(rel, _)| rel).collect();
    assert!(with_unsafe.iter().any(|f| f.starts_with("gpu/")), "no `unsafe` found in gpu/: the reading is broken ({with_unsafe:?})");
    let elsewhere: Vec<&String> = with_unsafe.iter().filter(|f| !allowed(f)).collect();
    assert!(elsewhere.is_empty(), "`unsafe` outside gpu/, output/h5.rs and debug.rs: {elsewhere:?}");
}

/// The checker on planted sources: the cycle `config` <-> `input` that the library had (a
/// re-export, a grouped `use` and `super` on the way), one inside a stage, and what does not
/// count (comments, strings, unit tests).
#[test]
fn the_checker_names_planted_cycles_and_ignores_comments_strings_and_tests() {
    let lib = |files: &[(&str, &str)]| Library::read(&files.iter().map(|(a, b)| (a.to_string(), b.to_string())).collect::<Vec<_>>());
    let base = [
        ("lib.rs", "pub mod config;\npub mod input;\npub mod scene;"),
        ("config/mod.rs", "use crate::{error::Error, input::tracks::{self, Track}};\npub struct SceneConfig;"),
        ("input/mod.rs", "pub mod recording;\npub mod tracks;\npub use recording::Recording;"),
        ("input/tracks.rs", "pub struct Track;"),
        ("scene/mod.rs", "fn f(r: &crate::input::Recording) {}"),
    ];
    let with = |extra: &[(&'static str, &'static str)]| lib(&[&base[..], extra].concat());
    // Before the fix: the recording read the scene's configuration.
    let found = cycles(&with(&[("input/recording.rs", "pub struct Recording;\nfn open(s: &crate::config::SceneConfig) {}")]));
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(found[0].starts_with("in `crate`: config -> input -> config ("), "{found:?}");
    assert!(found[0].contains("src/input/recording.rs names crate::config::SceneConfig"), "{found:?}");
    // The recording naming the scene through `super`, the scene the recording through a
    // re-export.
    let found = cycles(&with(&[("input/recording.rs", "pub struct Recording;\nuse super::super::scene as s;")]));
    assert!(found.len() == 1 && found[0].contains("input -> scene -> input"), "{found:?}");
    // Inside a stage: two parts of `input` using each other.
    let found = cycles(&with(&[("input/recording.rs", "pub struct Recording;\nfn f() { super::tracks::Track; }"), ("input/tracks.rs", "fn g(r: crate::input::Recording) {}")]));
    assert!(found.len() == 1 && found[0].starts_with("in `input`: recording -> tracks -> recording"), "{found:?}");
    // Not uses: comments, strings, characters, unit tests inline and beside.
    let quiet = r####"
        pub struct Recording;
        // crate::config::SceneConfig
        /* crate::config /* nested */ crate::config */
        /// [`crate::config::SceneConfig`]
        const A: &str = "crate::config::X \" crate::config";
        const B: &str = r#"crate::config::"X"#;
        const C: char = '"'; const D: char = '\''; fn e<'a>(x: &'a u8) -> &'a u8 { x }
        #[cfg(test)]
        mod tests { use crate::config::SceneConfig; fn t() { let b = [0u8; 2]; } }
        #[cfg(test)]
        pub(crate) mod beside;
        fn after() { let s = "unsafe"; }
    "####;
    let l = with(&[("input/recording.rs", quiet), ("input/recording/beside.rs", "use crate::config::SceneConfig;")]);
    assert!(cycles(&l).is_empty(), "{:?}", cycles(&l));
    assert!(l.modules.contains_key(&vec!["input".to_string(), "recording".to_string()]) && !l.modules.contains_key(&vec!["input".to_string(), "recording".to_string(), "beside".to_string()]));
    let code = without_tests(&tokens(quiet)).0;
    assert!(!code.iter().any(|t| t == "unsafe" || t == "config") && code.ends_with(&["}".to_string()]), "{code:?}");
}
