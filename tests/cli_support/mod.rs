//! Shared by the `soda` binary's tests (`tests/cli.rs`, `tests/cli_outputs.rs`): run the
//! binary and read what it printed.
#![allow(dead_code)]

use std::process::{Command, Output};

/// Runs `soda args` in the repository's root.
pub fn soda(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_soda"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("the soda binary runs")
}

/// What the run printed on stdout.
pub fn stdout(o: &Output) -> String {
    String::from_utf8(o.stdout.clone()).expect("stdout is UTF-8")
}

/// What the run printed on stderr.
pub fn stderr(o: &Output) -> String {
    String::from_utf8(o.stderr.clone()).expect("stderr is UTF-8")
}

/// Runs `soda args` and expects success; returns stdout.
pub fn ok(args: &[&str]) -> String {
    let o = soda(args);
    assert!(
        o.status.success(),
        "soda {args:?} failed ({}):\n{}",
        o.status,
        stderr(&o)
    );
    stdout(&o)
}

/// Runs `soda args` and expects exit status 1 with an error message; returns stderr.
pub fn fails(args: &[&str]) -> String {
    let o = soda(args);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "soda {args:?}: {err}");
    assert!(err.starts_with("error: "), "soda {args:?}: {err}");
    assert!(!err.contains("panicked"), "soda {args:?} panicked: {err}");
    err
}

/// Runs `soda args`, expects a usage error (status 2) and returns stderr.
pub fn usage_error(args: &[&str]) -> String {
    let o = soda(args);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "soda {args:?}: {err}");
    assert!(!err.contains("panicked"), "soda {args:?} panicked: {err}");
    err
}

/// The value of a summary's `hash` line, if it has one.
pub fn hash_line(out: &str) -> Option<String> {
    out.lines()
        .find(|l| l.split_whitespace().next() == Some("hash"))
        .map(|l| l.split_whitespace().nth(1).unwrap_or("").to_string())
}

/// The value of a summary's `hash` line; fails the test if there is none.
pub fn hash_of(summary: &str) -> String {
    hash_line(summary).unwrap_or_else(|| panic!("no hash line in:\n{summary}"))
}
