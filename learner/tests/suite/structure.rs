//! The code's shape: no source file with more than 800 lines of non-test code, no import
//! circle between the modules of a crate (Cargo already forbids circles between crates), and
//! `anyhow` only in the learner's command line. A module's imports are its `crate::…` and
//! `super::…` paths outside comments and outside its `#[cfg(test)]` part.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The crates of the workspace, relative to the workspace root.
const CRATES: [&str; 8] = [
    "shared",
    "shared/ur-protocol",
    "hil-sim",
    "rt-controller",
    "learner/gps",
    "learner/imitation",
    "learner",
    "tests",
];

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("learner/ has a parent")
        .to_owned()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The non-test code of a file: the lines before its first `#[cfg(test)]`, without comments.
fn code(text: &str) -> Vec<&str> {
    text.lines()
        .take_while(|l| !l.trim_start().starts_with("#[cfg(test)]"))
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect()
}

/// The module path of `file` below `src`: `a/b.rs` and `a/b/mod.rs` are `["a", "b"]`; the
/// crate roots (`lib.rs`, `main.rs`, `bin/…`) are `None`.
fn module(src: &Path, file: &Path) -> Option<Vec<String>> {
    let rel = file.strip_prefix(src).ok()?;
    let mut parts: Vec<String> = rel
        .iter()
        .map(|c| c.to_string_lossy().into_owned())
        .collect();
    if parts.first().is_some_and(|p| p == "bin") {
        return None;
    }
    let last = parts.pop()?;
    match last.as_str() {
        "lib.rs" | "main.rs" if parts.is_empty() => return None,
        "mod.rs" => {}
        f => parts.push(f.trim_end_matches(".rs").to_owned()),
    }
    Some(parts)
}

/// Identifiers after `prefix` in `line` (`crate::a::b` gives `["a", "b"]` for `crate::`).
fn paths_after<'a>(line: &'a str, prefix: &str) -> Vec<Vec<&'a str>> {
    line.match_indices(prefix)
        .map(|(i, _)| {
            line[i + prefix.len()..]
                .split("::")
                .map(|seg| {
                    let end = seg
                        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                        .unwrap_or(seg.len());
                    &seg[..end]
                })
                .take_while(|s| !s.is_empty() && s.chars().next().unwrap().is_ascii_lowercase())
                .collect()
        })
        .collect()
}

#[test]
fn no_source_file_has_more_than_800_lines_of_non_test_code() {
    let mut too_long = Vec::new();
    for krate in CRATES {
        let mut files = Vec::new();
        rust_files(&root().join(krate).join("src"), &mut files);
        for f in files {
            let text = std::fs::read_to_string(&f).unwrap();
            let n = text
                .lines()
                .take_while(|l| !l.trim_start().starts_with("#[cfg(test)]"))
                .count();
            if n > 800 {
                too_long.push(format!("{}: {n}", f.display()));
            }
        }
    }
    assert!(too_long.is_empty(), "split these by job: {too_long:#?}");
}

#[test]
fn no_import_circle_between_the_modules_of_a_crate() {
    for krate in CRATES {
        let src = root().join(krate).join("src");
        let mut files = Vec::new();
        rust_files(&src, &mut files);
        // Edges between modules at the depth where they differ: `a/x` → `a/y` inside `a`,
        // `a/…` → `b/…` between top-level modules.
        let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for f in &files {
            let Some(me) = module(&src, f) else { continue };
            let text = std::fs::read_to_string(f).unwrap();
            for line in code(&text) {
                let mut targets: Vec<Vec<String>> = paths_after(line, "crate::")
                    .into_iter()
                    .map(|p| p.into_iter().map(String::from).collect())
                    .collect();
                for p in paths_after(line, "super::") {
                    let mut t = me[..me.len().saturating_sub(1)].to_vec();
                    t.extend(p.into_iter().map(String::from));
                    targets.push(t);
                }
                for t in targets {
                    let common = me.iter().zip(&t).take_while(|(a, b)| a == b).count();
                    if common < me.len() && common < t.len() {
                        let from = me[..=common].join("/");
                        let to = t[..=common].join("/");
                        edges.entry(from).or_default().insert(to);
                    }
                }
            }
        }
        // A circle is a path back to its start.
        for start in edges.keys() {
            let mut stack = vec![vec![start.clone()]];
            while let Some(path) = stack.pop() {
                for next in edges.get(path.last().unwrap()).into_iter().flatten() {
                    assert!(
                        next != start,
                        "{krate}: import circle {} -> {start}",
                        path.join(" -> ")
                    );
                    if !path.contains(next) {
                        let mut p = path.clone();
                        p.push(next.clone());
                        stack.push(p);
                    }
                }
            }
        }
    }
}

/// Typed errors below the binaries (docs/dev.md, "Errors"): `anyhow` only in the learner's
/// command line (`src/cli/`) and `main.rs`, which turn the library's error enums into a
/// printed cause chain; outside comments.
#[test]
fn anyhow_only_in_the_command_line() {
    let src = root().join("learner").join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut found = Vec::new();
    for f in files {
        let rel = f.strip_prefix(&src).unwrap();
        if rel.starts_with("cli") || rel == Path::new("main.rs") {
            continue;
        }
        let text = std::fs::read_to_string(&f).unwrap();
        for (k, line) in text.lines().enumerate() {
            if !line.trim_start().starts_with("//") && line.contains("anyhow") {
                found.push(format!("{}:{}: {}", rel.display(), k + 1, line.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "library code returns its module's error enum, not anyhow: {found:#?}"
    );
}
