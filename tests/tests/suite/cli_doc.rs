//! `docs/cli.md`, the command reference, is written from the binaries' own `--help` (clap's
//! definitions), every subcommand reached from the top: the test fails when the page is stale,
//! and `UPDATE_CLI_DOC=1 cargo test --release -p integration-tests --test suite cli_doc` rewrites it.

use std::path::PathBuf;
use std::process::Command;

use integration_tests::bin;

/// The long help of `program` with `path` (the subcommand words before `--help`).
fn help(program: &str, path: &[String]) -> String {
    let out = Command::new(bin(program))
        .args(path)
        .arg("--help")
        .env("COLUMNS", "100")
        .output()
        .unwrap();
    assert!(out.status.success(), "{program} {path:?} --help failed");
    String::from_utf8(out.stdout).unwrap()
}

/// The subcommand names listed under `Commands:` in `text` (without clap's own `help`).
fn subcommands(text: &str) -> Vec<String> {
    text.lines()
        .skip_while(|l| l.trim_end() != "Commands:")
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        // An entry starts with two spaces and a name; its wrapped description lines start deeper.
        .filter(|l| l.starts_with("  ") && !l.starts_with("   "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|n| *n != "help")
        .map(str::to_owned)
        .collect()
}

/// One section per command, depth first, in the order `--help` lists them.
fn document(program: &str, path: &mut Vec<String>, page: &mut String) {
    let text = help(program, path);
    let title = std::iter::once(program.to_owned())
        .chain(path.iter().cloned())
        .collect::<Vec<_>>()
        .join(" ");
    let hashes = "#".repeat((path.len() + 2).min(4));
    page.push_str(&format!(
        "{hashes} `{title}`\n\n```text\n{}\n```\n\n",
        text.trim_end()
    ));
    for sub in subcommands(&text) {
        path.push(sub);
        document(program, path, page);
        path.pop();
    }
}

fn page() -> String {
    let mut page = String::from(
        "# Command reference\n\n\
         Written from the binaries' own `--help` by the test `cli_doc` (tests/tests/suite/cli_doc.rs),\n\
         which fails when this page is stale. `rt-controller bench` and `bench-ur` exist only in a\n\
         build with the `testkit` feature (the workspace build and test turn it on).\n\n",
    );
    for program in ["learner", "rt-controller", "hil-sim"] {
        document(program, &mut Vec::new(), &mut page);
    }
    page
}

#[test]
fn the_command_reference_is_the_binaries_own_help() {
    let path: PathBuf = [env!("CARGO_MANIFEST_DIR"), "..", "docs", "cli.md"]
        .iter()
        .collect();
    let fresh = page();
    if std::env::var_os("UPDATE_CLI_DOC").is_some() {
        std::fs::write(&path, &fresh).unwrap();
        return;
    }
    let stored = std::fs::read_to_string(&path).unwrap_or_default();
    if stored != fresh {
        let line = stored
            .lines()
            .zip(fresh.lines())
            .position(|(a, b)| a != b)
            .map_or(stored.lines().count().min(fresh.lines().count()), |i| i);
        panic!(
            "docs/cli.md is stale from line {} on (the help says {:?}); rewrite it with \
             UPDATE_CLI_DOC=1 cargo test --release -p integration-tests --test suite cli_doc",
            line + 1,
            fresh.lines().nth(line).unwrap_or("(end)")
        );
    }
}

#[test]
fn the_subcommand_list_is_read_from_the_help() {
    let text = "Usage: x <COMMAND>\n\nCommands:\n  run    Runs\n         more text\n  bench  B\n  help   Print\n\nOptions:\n  -h\n";
    assert_eq!(subcommands(text), ["run", "bench"]);
}
