//! The code's shape: no source file with more than 800 lines of non-test code, no import
//! circle between the modules of a crate (Cargo already forbids circles between crates), no
//! learner of `imitation` importing another learner, and `anyhow` only in the learner's
//! command line. A module's imports are its `crate::…` and `super::…` paths outside comments
//! and outside its `#[cfg(test)]` part.

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
    code_lines(text).into_iter().map(|(_, l)| l).collect()
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

/// The modules that `text`, the file of module `me`, imports: each non-test line's number
/// (from 1) and the module path of each of its `crate::…` and `super::…` paths.
fn imports(me: &[String], text: &str) -> Vec<(usize, Vec<String>)> {
    let mut out = Vec::new();
    for (k, line) in code_lines(text) {
        for p in paths_after(line, "crate::") {
            out.push((k, p.into_iter().map(String::from).collect()));
        }
        for p in paths_after(line, "super::") {
            let mut t = me[..me.len().saturating_sub(1)].to_vec();
            t.extend(p.into_iter().map(String::from));
            out.push((k, t));
        }
    }
    out
}

/// [`code`] with each line's number (from 1).
fn code_lines(text: &str) -> Vec<(usize, &str)> {
    text.lines()
        .enumerate()
        .take_while(|(_, l)| !l.trim_start().starts_with("#[cfg(test)]"))
        .filter(|(_, l)| !l.trim_start().starts_with("//"))
        .map(|(k, l)| (k + 1, l))
        .collect()
}

/// The learners of the `imitation` crate: the top-level modules with a non-test
/// `impl … Learn for …` (the one driver interface, `imitation::learn::Learn`), from
/// `(module, text)` of every file.
fn learners<'a>(files: impl IntoIterator<Item = (&'a [String], &'a str)>) -> BTreeSet<String> {
    files
        .into_iter()
        .filter(|(me, _)| me.first().is_some_and(|m| m != "learn"))
        .filter(|(_, text)| {
            code(text).iter().any(|l| {
                let l = l.trim_start();
                l.starts_with("impl") && (l.contains(" Learn for ") || l.contains("::Learn for "))
            })
        })
        .map(|(me, _)| me[0].clone())
        .collect()
}

/// Every import of one learner's file from another learner, as `file:line: a -> b`, from
/// `(file name, module, text)` of every file.
fn sibling_imports(
    learners: &BTreeSet<String>,
    files: &[(String, Vec<String>, String)],
) -> Vec<String> {
    let mut found = Vec::new();
    for (name, me, text) in files {
        let Some(mine) = me.first().filter(|m| learners.contains(*m)) else {
            continue;
        };
        for (k, t) in imports(me, text) {
            if let Some(other) = t.first().filter(|t| *t != mine && learners.contains(*t)) {
                found.push(format!("{name}:{k}: {mine} -> {other}"));
            }
        }
    }
    found
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
            for (_, t) in imports(&me, &text) {
                let common = me.iter().zip(&t).take_while(|(a, b)| a == b).count();
                if common < me.len() && common < t.len() {
                    let from = me[..=common].join("/");
                    let to = t[..=common].join("/");
                    edges.entry(from).or_default().insert(to);
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

/// What learners share (settings, the critic, the policies and their fits, the costs, the LQR
/// iteration) lives in modules below all of them, so that each can change without the others:
/// no learner module of `imitation` (a top-level module that implements `Learn`) imports
/// another, its tests included.
#[test]
fn no_learner_imports_another_learner() {
    let src = root().join("learner/imitation/src");
    let mut paths = Vec::new();
    rust_files(&src, &mut paths);
    let files: Vec<(String, Vec<String>, String)> = paths
        .iter()
        .filter_map(|f| {
            let me = module(&src, f)?;
            let rel = f.strip_prefix(&src).unwrap().display().to_string();
            Some((rel, me, std::fs::read_to_string(f).unwrap()))
        })
        .collect();
    let found = learners(files.iter().map(|(_, m, t)| (m.as_slice(), t.as_str())));
    // The scan must see today's learners, or the check below would pass on nothing.
    for l in [
        "bco",
        "expert",
        "gaifo",
        "mdgps",
        "offpolicy",
        "ppo",
        "replay_mean",
    ] {
        assert!(found.contains(l), "{l} not found as a learner: {found:?}");
    }
    let bad = sibling_imports(&found, &files);
    assert!(
        bad.is_empty(),
        "a learner imports another; move what they share below both (imitation::settings, \
         imitation::mlp_policy, …): {bad:#?}"
    );
}

/// The check above fails on a planted import of one learner from another, in a submodule and
/// through `super::`, and not on comments, a learner's own modules or its `#[cfg(test)]` part.
#[test]
fn the_learner_import_check_finds_a_planted_import() {
    let m = |p: &[&str]| p.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    let learner = |name: &str| format!("pub struct L;\nimpl Learn for L {{}}\n// {name}\n");
    let mut files = vec![
        ("a/mod.rs".to_string(), m(&["a"]), learner("a")),
        ("b.rs".to_string(), m(&["b"]), learner("b")),
        (
            "shared.rs".to_string(),
            m(&["shared"]),
            "pub struct S;\n".to_string(),
        ),
        (
            "a/inner.rs".to_string(),
            m(&["a", "inner"]),
            "use crate::shared::S;\nuse super::mod_item;\n// use crate::b::L;\n\
             #[cfg(test)]\nmod tests { use crate::b::L; }\n"
                .to_string(),
        ),
    ];
    let found = learners(files.iter().map(|(_, m, t)| (m.as_slice(), t.as_str())));
    assert_eq!(found, BTreeSet::from(["a".to_string(), "b".to_string()]));
    assert!(sibling_imports(&found, &files).is_empty());
    files[3].2.insert_str(0, "use crate::b::L;\n");
    files.push((
        "b/x.rs".to_string(),
        m(&["b", "x"]),
        "fn f() { let _ = super::super::shared::S; let _ = crate::a::inner::g(); }\n".to_string(),
    ));
    assert_eq!(
        sibling_imports(&found, &files),
        ["a/inner.rs:1: a -> b", "b/x.rs:1: b -> a"]
    );
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
