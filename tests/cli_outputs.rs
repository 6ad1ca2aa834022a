//! The `soda` binary's output files (issue 18, "nothing lost"): every output path checked
//! before step 1, files renamed into place whole, the summary and hash printed even when a
//! write fails, Ctrl-C keeping whole recorded frames, and the messages of bad numbers.

mod cli_support;

use cli_support::{fails, hash_line, soda, stderr, stdout, usage_error};
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// A run long enough to notice if it is computed: the checks must refuse before step 1.
const LONG: &[&str] = &["run", "--objects", "1000", "--steps", "100000"];

fn long_with<'a>(extra: &[&'a str]) -> Vec<&'a str> {
    LONG.iter().chain(extra).copied().collect()
}

/// Expects `args` (a long run) to fail within a few seconds, i.e. before computing.
fn refused_before_the_run(args: &[&str]) -> String {
    let start = Instant::now();
    let err = fails(args);
    assert!(
        start.elapsed() < Duration::from_secs(20),
        "soda {args:?} took {:?}: the check came after the run",
        start.elapsed()
    );
    err
}

/// Every hidden temporary file (`.NAME.tmp-PID`) left in `dir`.
fn temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.') && n.contains(".tmp-"))
        .collect()
}

#[test]
fn csv_output_to_device_is_refused_before_the_run() {
    let err = refused_before_the_run(&long_with(&["--csv", "/dev/full"]));
    assert!(
        err.contains("--csv") && err.contains("/dev/full") && err.contains("regular file"),
        "{err}"
    );
    let err = refused_before_the_run(&long_with(&["--record", "/dev/null"]));
    assert!(err.contains("--record") && err.contains("device"), "{err}");
}

#[test]
fn csv_with_another_header_is_refused_before_the_run_and_read_only_to_its_first_line() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("other.csv");
    // A huge second "line": only the first line may be read.
    let mut text = String::from("a,b,c\n");
    text.push_str(&"x".repeat(4 << 20));
    std::fs::write(&csv, &text).unwrap();
    let err = refused_before_the_run(&long_with(&["--csv", csv.to_str().unwrap()]));
    assert!(
        err.contains("other columns") && err.contains("a,b,c"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_to_string(&csv).unwrap(),
        text,
        "left untouched"
    );
}

#[test]
fn missing_output_directories_are_refused_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-dir");
    for flag in ["--counters", "--trace", "--record", "--csv"] {
        let file = missing.join("out.json");
        let mut args = long_with(&[flag, file.to_str().unwrap()]);
        if flag == "--trace" {
            args.extend(["--executor", "virtual"]);
        }
        let err = refused_before_the_run(&args);
        assert!(
            err.contains(flag) && err.contains("does not exist"),
            "{flag}: {err}"
        );
    }
    // --territories DIR is created, but not under a file.
    let file = dir.path().join("a-file");
    std::fs::write(&file, "x").unwrap();
    let under = file.join("maps");
    let err = refused_before_the_run(&long_with(&[
        "--executor",
        "virtual",
        "--territories",
        under.to_str().unwrap(),
    ]));
    assert!(err.contains("--territories"), "{err}");
}

#[test]
fn same_path_for_two_outputs_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("out.json");
    let f = f.to_str().unwrap();
    let err = refused_before_the_run(&long_with(&[
        "--executor",
        "virtual",
        "--trace",
        f,
        "--counters",
        f,
    ]));
    assert!(
        err.contains("--trace") && err.contains("--counters") && err.contains("same file"),
        "{err}"
    );
    assert!(!Path::new(f).exists());
    // Spelled differently, still the same file.
    let other = format!("{}/./out.json", dir.path().display());
    let err = refused_before_the_run(&long_with(&["--record", f, "--csv", &other]));
    assert!(err.contains("same file"), "{err}");
}

#[test]
fn an_output_that_is_the_scene_file_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("two.toml");
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/two-cubes.toml"),
        &scene,
    )
    .unwrap();
    let before = std::fs::read(&scene).unwrap();
    let s = scene.to_str().unwrap();
    let err = fails(&["run", "--scene", s, "--steps", "3", "--record", s]);
    assert!(
        err.contains("--record") && err.contains("scene file"),
        "{err}"
    );
    assert_eq!(std::fs::read(&scene).unwrap(), before, "the scene survives");
}

#[test]
fn outputs_are_renamed_into_place_and_leave_no_temporary_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let (rec, counters, trace, csv, maps) = (
        p("r.csv"),
        p("c.json"),
        p("t.json"),
        p("runs.csv"),
        p("maps"),
    );
    std::fs::write(&counters, "old").unwrap();
    let o = soda(&[
        "run",
        "--objects",
        "27",
        "--steps",
        "10",
        "--executor",
        "virtual",
        "--record",
        &rec,
        "--counters",
        &counters,
        "--trace",
        &trace,
        "--csv",
        &csv,
        "--territories",
        &maps,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&counters).unwrap()).unwrap();
    assert_eq!(
        report["hash"].as_str().map(String::from),
        hash_line(&stdout(&o))
    );
    assert_eq!(
        std::fs::read_to_string(&rec).unwrap().lines().count(),
        1 + 27 * 11
    );
    assert!(std::fs::read_to_string(&trace).unwrap().starts_with('{'));
    assert_eq!(std::fs::read_to_string(&csv).unwrap().lines().count(), 2);
    assert!(Path::new(&maps).join("territory-000000.svg").exists());
    assert_eq!(temporaries(dir.path()), Vec::<String>::new());
    assert_eq!(temporaries(Path::new(&maps)), Vec::<String>::new());
}

/// `soda args` with a limit of `bytes` on the size of any file it writes (RLIMIT_FSIZE, with
/// SIGXFSZ ignored so a write past it fails with EFBIG): a disk that fills up mid-run.
fn soda_with_file_limit(args: &[&str], bytes: u64) -> Output {
    use std::os::unix::process::CommandExt;
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_soda"));
    cmd.args(args).current_dir(env!("CARGO_MANIFEST_DIR"));
    // SAFETY: only async-signal-safe calls between fork and exec.
    unsafe {
        cmd.pre_exec(move || {
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            let limit = libc::rlimit {
                rlim_cur: bytes,
                rlim_max: bytes,
            };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    cmd.output().expect("the soda binary runs")
}

#[test]
fn a_failed_write_after_the_run_still_prints_the_summary_and_hash() {
    let dir = tempfile::tempdir().unwrap();
    let base = ["run", "--objects", "64", "--steps", "20"];
    let expected = hash_line(&stdout(&soda(&base))).expect("a hash line");
    let rec = dir.path().join("rec.csv");
    let counters = dir.path().join("c.json");
    std::fs::write(&rec, "the old recording\n").unwrap();
    let mut args = base.to_vec();
    args.extend([
        "--record",
        rec.to_str().unwrap(),
        "--counters",
        counters.to_str().unwrap(),
    ]);
    // 64 bodies x 21 frames x ~125 bytes: far past 20 kB, while the report fits.
    let o = soda_with_file_limit(&args, 20_000);
    let (out, err) = (stdout(&o), stderr(&o));
    assert_eq!(o.status.code(), Some(1), "{out}\n{err}");
    assert_eq!(hash_line(&out), Some(expected), "{out}");
    assert!(
        err.contains("summary and hash are above") && err.contains("rec.csv"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(
        std::fs::read_to_string(&rec).unwrap(),
        "the old recording\n",
        "a failed recording leaves the old file"
    );
    assert!(counters.exists(), "the outputs that could be written are");
    assert_eq!(temporaries(dir.path()), Vec::<String>::new());
}

#[test]
fn a_csv_append_that_fails_leaves_the_old_table() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("runs.csv");
    let base = ["run", "--objects", "8", "--steps", "2", "--csv"];
    let mut args = base.to_vec();
    args.push(csv.to_str().unwrap());
    let o = soda(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let table = std::fs::read(&csv).unwrap();
    // Room for part of a second row only.
    let o = soda_with_file_limit(&args, table.len() as u64 + 40);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(hash_line(&stdout(&o)).is_some());
    assert!(err.contains("--csv") && err.contains("cut back"), "{err}");
    assert_eq!(std::fs::read(&csv).unwrap(), table, "the old table, whole");
}

/// Starts a long `soda run` recording to `dir/rec.csv`, waits until it has committed some
/// steps, sends `signal`, and returns its output.
fn interrupt_a_recording(dir: &Path, signal: libc::c_int, extra: &[&str]) -> Output {
    let rec = dir.join("rec.csv");
    let child = Command::new(env!("CARGO_BIN_EXE_soda"))
        .args(["run", "--objects", "200", "--steps", "1000000", "--record"])
        .arg(&rec)
        .args(extra)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait for the temporary recording to grow past a few frames.
    let start = Instant::now();
    loop {
        let big = temporaries(dir)
            .iter()
            .any(|t| std::fs::metadata(dir.join(t)).is_ok_and(|m| m.len() > 200 * 125 * 20));
        if big || start.elapsed() > Duration::from_secs(60) {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let sent = Instant::now();
    // SAFETY: kill(2) on the child this test started.
    assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, signal) }, 0);
    let out = child.wait_with_output().unwrap();
    assert!(
        sent.elapsed() < Duration::from_secs(5),
        "stopping took {:?}",
        sent.elapsed()
    );
    out
}

#[test]
fn record_is_whole_rows_after_interrupt() {
    let dir = tempfile::tempdir().unwrap();
    let o = interrupt_a_recording(dir.path(), libc::SIGINT, &[]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(130), "{err}");
    let note = err
        .lines()
        .find(|l| l.starts_with("interrupted at step "))
        .unwrap_or_else(|| panic!("no note: {err}"));
    let words: Vec<&str> = note.split_whitespace().collect();
    let step: u64 = words[3].trim_end_matches(',').parse().unwrap();
    let hash = words[5].trim_end_matches(';');
    assert_eq!(hash.len(), 16, "{note}");
    // The hash is the one a run of exactly that many steps ends with.
    let steps = step.to_string();
    let full = soda(&["run", "--objects", "200", "--steps", &steps]);
    assert_eq!(hash_line(&stdout(&full)).as_deref(), Some(hash), "{note}");
    // The recording: the header and whole frames of 200 rows, steps 0..=last.
    let text = std::fs::read_to_string(dir.path().join("rec.csv")).unwrap();
    assert!(text.ends_with('\n'));
    let rows: Vec<&str> = text.lines().skip(1).collect();
    assert_eq!(rows.len() % 200, 0, "whole frames only");
    assert!(rows.iter().all(|r| r.split(',').count() == 15));
    let last: u64 = rows
        .last()
        .unwrap()
        .split(',')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(rows.len() as u64, 200 * (last + 1));
    assert!(last <= step, "{note}");
    assert!(note.contains(&format!("up to step {last}")), "{note}");
    assert_eq!(temporaries(dir.path()), Vec::<String>::new());
}

#[test]
fn interrupted_runs_write_no_other_output() {
    let dir = tempfile::tempdir().unwrap();
    let counters = dir.path().join("c.json");
    let csv = dir.path().join("runs.csv");
    let o = interrupt_a_recording(
        dir.path(),
        libc::SIGTERM,
        &[
            "--counters",
            counters.to_str().unwrap(),
            "--csv",
            csv.to_str().unwrap(),
        ],
    );
    assert_eq!(o.status.code(), Some(143), "{}", stderr(&o));
    assert!(!counters.exists() && !csv.exists());
    assert_eq!(temporaries(dir.path()), Vec::<String>::new());
}

#[test]
fn negative_and_zero_numbers_get_messages_that_say_what_to_give() {
    for (args, flag) in [
        (&["run", "--steps", "-1"][..], "--steps"),
        (&["run", "--seed", "-1"][..], "--seed"),
        (&["run", "--objects", "-5"][..], "--objects"),
        (&["verify", "--schedules", "-2"][..], "--schedules"),
        (
            &["scenes", "--dump", "chain", "--objects", "-1"][..],
            "--objects",
        ),
    ] {
        let err = usage_error(args);
        assert!(
            err.contains(flag) && err.contains("negative numbers are not allowed"),
            "{args:?}: {err}"
        );
    }
    let err = usage_error(&["run", "--record", "x.csv", "--record-every", "0"]);
    assert!(
        err.contains("--record-every") && err.contains("1 or more"),
        "{err}"
    );
    assert!(!err.contains("18446744073709551615"), "{err}");
}

#[test]
fn json_scene_with_nan_says_json_has_no_nan() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("nan.json");
    std::fs::write(
        &scene,
        r#"{"domain": {"min": [-1, -1, -1], "max": [1, 1, 1]},
            "bodies": [{"id": 0, "shape": {"type": "ball", "radius": 0.1},
                        "position": [NaN, 0, 0]}]}"#,
    )
    .unwrap();
    let err = fails(&["run", "--scene", scene.to_str().unwrap(), "--steps", "1"]);
    assert!(err.contains("NaN") && err.contains("finite"), "{err}");
    std::fs::write(
        &scene,
        r#"{"domain": {"min": [-Infinity, -1, -1], "max": [1, 1, 1]}}"#,
    )
    .unwrap();
    let err = fails(&["run", "--scene", scene.to_str().unwrap(), "--steps", "1"]);
    assert!(err.contains("Infinity") && err.contains("finite"), "{err}");
}

#[test]
fn schedule_with_the_reference_names_the_virtual_executor_only() {
    let err = usage_error(&["run", "--steps", "1", "--schedule", "v1:00"]);
    assert!(err.contains("--executor virtual"), "{err}");
    assert!(!err.contains("threaded`"), "{err}");
}

#[test]
fn partition_seed_without_a_seeded_partitioner_is_refused() {
    let err = usage_error(&[
        "run",
        "--steps",
        "1",
        "--executor",
        "virtual",
        "--partition-seed",
        "3",
    ]);
    assert!(
        err.contains("--partition-seed") && err.contains("kmeans"),
        "{err}"
    );
    let err = usage_error(&["verify", "--steps", "1", "--partition-seed", "3"]);
    assert!(err.contains("--partition-seed"), "{err}");
    // Equal blocks have nothing to seed either, on both commands.
    for command in [&["run", "--executor", "virtual"][..], &["verify"]] {
        let err = usage_error(
            &[
                command,
                &[
                    "--steps",
                    "1",
                    "--partition",
                    "equal-blocks",
                    "--partition-seed",
                    "3",
                ],
            ]
            .concat(),
        );
        assert!(
            err.contains("--partition-seed") && err.contains("equal-blocks has nothing random"),
            "{command:?}: {err}"
        );
    }
}

#[test]
fn verify_with_no_run_to_check_is_refused() {
    let err = usage_error(&["verify", "--schedules", "0", "--repeats", "0"]);
    assert!(
        err.contains("--schedules") && err.contains("--repeats"),
        "{err}"
    );
}

#[test]
fn help_about_help_succeeds() {
    let o = soda(&["help", "--help"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).contains("Usage"));
}

#[test]
fn help_says_what_the_tool_does() {
    let verify = stdout(&soda(&["verify", "--help"]));
    let objects = verify
        .split("--objects")
        .nth(1)
        .unwrap_or_default()
        .split("\n  -")
        .next()
        .unwrap_or_default();
    assert!(objects.contains("125"), "{objects}");
    assert!(verify.contains("--partition-seed"), "listed and accepted");
    let run = stdout(&soda(&["run", "--help"]));
    assert!(!run.contains("printed by `soda verify`"), "{run}");
    assert!(run.contains("bytes per body"), "--record states its size");
}

#[test]
fn summaries_spell_the_partition_as_the_flag_does() {
    let out = stdout(&soda(&[
        "run",
        "--objects",
        "8",
        "--steps",
        "2",
        "--executor",
        "virtual",
        "--partition",
        "kmeans",
    ]));
    assert!(out.contains("(kmeans partition)"), "{out}");
    let out = stdout(&soda(&[
        "verify",
        "--objects",
        "8",
        "--steps",
        "2",
        "--schedules",
        "1",
        "--repeats",
        "0",
        "--modes",
        "cell",
    ]));
    assert!(out.contains("(blocks partition)"), "{out}");
}

#[test]
fn recording_a_huge_run_warns_of_its_size() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("big.csv");
    // 1,000 bodies over 100,000 steps: ~12 GB. Stopped at once by an interrupt.
    let child = Command::new(env!("CARGO_BIN_EXE_soda"))
        .args(["run", "--objects", "1000", "--steps", "100000", "--record"])
        .arg(&rec)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    // SAFETY: kill(2) on the child this test started.
    unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) };
    let o = child.wait_with_output().unwrap();
    let err = stderr(&o);
    assert!(
        err.contains("warning: --record") && err.contains("GB"),
        "{err}"
    );
}

/// Commands whose standard output is full (`> /dev/full`) or closed by its reader (`| head
/// -c0`) end without a panic: the full device is an error naming standard output, the
/// closed pipe a quiet success (the model commands and `plot` used `println!`, which panics).
#[test]
fn a_full_or_closed_standard_output_ends_commands_without_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let trace = dir.path().join("t.json");
    let trace = trace.to_str().unwrap();
    let charts = dir.path().join("charts");
    let charts = charts.to_str().unwrap();
    soda(&[
        "run",
        "--objects",
        "20",
        "--steps",
        "10",
        "--executor",
        "virtual",
        "--worlds",
        "2",
        "--trace",
        trace,
    ]);
    let commands: &[&[&str]] = &[
        &["models"],
        &["run", "--model", "epidemic", "--steps", "20"],
        &["verify", "--model", "phold", "--steps", "20"],
        &["plot", trace, "--out", charts],
        &["run", "--objects", "20", "--steps", "10"],
    ];
    for args in commands {
        let full = Command::new(env!("CARGO_BIN_EXE_soda"))
            .args(*args)
            .stdout(std::fs::File::create("/dev/full").unwrap())
            .stderr(Stdio::piped())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&full.stderr);
        assert!(!err.contains("panicked"), "{args:?} > /dev/full: {err}");
        assert_eq!(full.status.code(), Some(1), "{args:?} > /dev/full: {err}");
        assert!(
            err.contains("cannot write to standard output"),
            "{args:?} > /dev/full: {err}"
        );
        let mut child = Command::new(env!("CARGO_BIN_EXE_soda"))
            .args(*args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let closed = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&closed.stderr);
        assert!(!err.contains("panicked"), "{args:?} | head -c0: {err}");
        assert_eq!(closed.status.code(), Some(0), "{args:?} | head -c0: {err}");
    }
}

/// A checkpoint asked of a run that computes no step is refused, not silently skipped.
#[test]
fn a_checkpoint_of_a_run_without_steps_is_refused_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let ckpt = dir.path().join("z.ckpt");
    let err = usage_error(&[
        "run",
        "--objects",
        "30",
        "--steps",
        "0",
        "--checkpoint",
        ckpt.to_str().unwrap(),
    ]);
    assert!(
        err.contains("--checkpoint") && err.contains("give --steps 1 or more"),
        "{err}"
    );
    assert!(!ckpt.exists());
}

/// A two-step `virtual` run of `soda run ARGS --worlds WORLDS`.
fn virtual_run_with_worlds(args: &[&str], worlds: &str) -> std::process::Output {
    let mut all = vec!["run"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--steps", "2", "--executor", "virtual", "--worlds", worlds]);
    soda(&all)
}

#[test]
fn more_worlds_than_cells_is_run_with_a_warning_naming_the_grid() {
    // falling-cubes with 27 cubes has a 9 x 4 x 9 grid: 324 cells.
    let with_worlds = |worlds| virtual_run_with_worlds(&["--objects", "27"], worlds);
    let out = with_worlds("500");
    assert!(out.status.success(), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("500 worlds on a grid of 324 cells")
            && err.contains("176 of them own no cell")
            && err.contains("--worlds 324 or fewer"),
        "{err}"
    );
    let out = with_worlds("8");
    assert!(!stderr(&out).contains("own no cell"), "{}", stderr(&out));
}

#[test]
fn more_worlds_than_cells_warns_for_a_registered_model_too() {
    // phold with 10 jobs at 4 per cell has a 1 x 1 x 4 grid: 4 cells.
    let with_worlds =
        |worlds| virtual_run_with_worlds(&["--model", "phold", "--entities", "10"], worlds);
    let out = with_worlds("6");
    assert!(out.status.success(), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("6 worlds on a grid of 4 cells")
            && err.contains("2 of them own no cell")
            && err.contains("--worlds 4 or fewer")
            && !err.contains("solver.max_speed"),
        "{err}"
    );
    let out = with_worlds("4");
    assert!(!stderr(&out).contains("own no cell"), "{}", stderr(&out));
}
