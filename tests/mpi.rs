//! The MPI executor (cargo feature `mpi`; SPEC.md §14): `mpirun -np 2/3/4 soda run --executor
//! mpi` commits the reference's hash on every built-in scene and rollback mode with random
//! partitions, with balancing across ranks, inputs and the registered models; rank 0 alone
//! writes the outputs; a planted fault in the transport is caught, and a rank that panics
//! stops every rank within seconds, naming the rank and the step.
//!
//! Needs Open MPI and a `soda` built with the `mpi` feature. `scripts/test-mpi.sh` does it all
//! (and `.ci/run` calls it): it installs Open MPI, builds that binary alone, and runs these
//! tests with `SODA_MPI_BIN` naming it. The test binary itself needs no MPI, so it is built with
//! the default features and the dev-dependencies are not rebuilt. Without the feature the
//! tests are ignored; `cargo test --release --features mpi --test mpi` runs them against the
//! build's own binary. Scenes are small and runs short (the whole file takes well under a
//! minute on two cores).

mod cli_support;

use cli_support::{hash_line, ok, stderr, stdout};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

/// The `soda` binary built with the `mpi` feature: this build's own when the tests are built
/// with the feature, else the one `SODA_MPI_BIN` names (`scripts/test-mpi.sh` sets it).
fn soda_mpi() -> String {
    if cfg!(feature = "mpi") {
        return env!("CARGO_BIN_EXE_soda").to_string();
    }
    let bin = std::env::var("SODA_MPI_BIN").unwrap_or_else(|_| {
        panic!(
            "SODA_MPI_BIN is not set: run scripts/test-mpi.sh, which builds soda with \
             `--features mpi` and names it, or `cargo test --release --features mpi --test mpi`"
        )
    });
    assert!(
        std::path::Path::new(&bin).is_file(),
        "SODA_MPI_BIN={bin} is not a file: scripts/test-mpi.sh builds it"
    );
    bin
}

/// Runs `mpirun -np ranks soda args` (as root if need be, more ranks than cores allowed).
fn mpirun(ranks: usize, args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new("mpirun");
    cmd.args(["--allow-run-as-root", "--oversubscribe", "-np"])
        .arg(ranks.to_string())
        .arg(soda_mpi())
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"));
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output()
        .expect("mpirun runs (scripts/install-mpi-deps.sh installs it)")
}

/// Runs under MPI and expects success; returns stdout.
fn mpi_ok(ranks: usize, args: &[&str]) -> String {
    let o = mpirun(ranks, args, &[]);
    assert!(
        o.status.success(),
        "mpirun -np {ranks} soda {args:?} failed ({}):\n{}",
        o.status,
        stderr(&o)
    );
    stdout(&o)
}

/// The summary's hash line of `out`.
fn hash(out: &str) -> String {
    hash_line(out).unwrap_or_else(|| panic!("no hash line in:\n{out}"))
}

#[test]
#[cfg_attr(
    not(feature = "mpi"),
    ignore = "needs a soda built with the mpi feature: scripts/test-mpi.sh"
)]
fn every_scene_and_mode_commits_the_reference_hash_on_2_3_and_4_ranks() {
    let scenes = [
        "falling-cubes",
        "sparse-gas",
        "dense-pile",
        "skewed",
        "chain",
        "peak",
    ];
    let modes = ["cell", "world", "conservative"];
    let mut run = 0usize;
    for scene in scenes {
        let base = ["run", "--scene", scene, "--objects", "120", "--steps", "30"];
        let reference = hash(&ok(&base));
        for mode in modes {
            let ranks = 2 + run % 3;
            let worlds = (ranks + 1 + run % 4).to_string();
            let seed = run.to_string();
            let mut args = base.to_vec();
            args.extend([
                "--executor",
                "mpi",
                "--worlds",
                &worlds,
                "--mode",
                mode,
                "--partition",
                "random",
                "--partition-seed",
                &seed,
            ]);
            if run % 2 == 1 {
                args.extend(["--ghosts", "full"]);
            }
            let got = hash(&mpi_ok(ranks, &args));
            assert_eq!(got, reference, "{scene}, {mode}, {ranks} ranks: {args:?}");
            run += 1;
        }
    }
}

#[test]
#[cfg_attr(
    not(feature = "mpi"),
    ignore = "needs a soda built with the mpi feature: scripts/test-mpi.sh"
)]
fn balancing_across_ranks_commits_the_reference_hash() {
    let base = [
        "run",
        "--scene",
        "skewed",
        "--objects",
        "200",
        "--steps",
        "40",
    ];
    let reference = hash(&ok(&base));
    for (ranks, mode) in [(2, "cell"), (3, "world"), (4, "conservative")] {
        let mut args = base.to_vec();
        args.extend([
            "--executor",
            "mpi",
            "--worlds",
            "6",
            "--mode",
            mode,
            "--balance",
            "on",
            "--balance-period",
            "8",
            "--json",
        ]);
        let out = mpi_ok(ranks, &args);
        let report: serde_json::Value = serde_json::from_str(&out).expect("--json prints JSON");
        assert_eq!(report["hash"].as_str(), Some(reference.as_str()));
        let kernel = &report["kernel"];
        assert!(
            kernel["counters"]["balance"]["rounds"].as_u64().unwrap() >= 3,
            "{kernel}"
        );
        assert_eq!(kernel["mpi"]["ranks"], ranks);
    }
}

#[test]
#[cfg_attr(
    not(feature = "mpi"),
    ignore = "needs a soda built with the mpi feature: scripts/test-mpi.sh"
)]
fn registered_models_and_inputs_commit_the_reference_hash() {
    for model in ["epidemic", "phold"] {
        let base = [
            "run",
            "--model",
            model,
            "--entities",
            "300",
            "--steps",
            "30",
        ];
        let reference = hash(&ok(&base));
        let mut args = base.to_vec();
        args.extend([
            "--executor",
            "mpi",
            "--worlds",
            "5",
            "--partition",
            "random",
        ]);
        assert_eq!(hash(&mpi_ok(3, &args)), reference, "{model}");
    }
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("in.toml");
    std::fs::write(
        &script,
        "[[inputs]]\nstep = 10\naction = \"push\"\nid = 3\nimpulse = [0.0, 8.0, 2.0]\n\n\
         [[inputs]]\nstep = 15\naction = \"remove\"\nid = 7\n",
    )
    .unwrap();
    let script = script.to_str().unwrap();
    let base = [
        "run",
        "--objects",
        "150",
        "--steps",
        "30",
        "--inputs",
        script,
    ];
    let reference = hash(&ok(&base));
    let mut args = base.to_vec();
    args.extend(["--executor", "mpi", "--worlds", "4"]);
    assert_eq!(hash(&mpi_ok(2, &args)), reference);
}

#[test]
#[cfg_attr(
    not(feature = "mpi"),
    ignore = "needs a soda built with the mpi feature: scripts/test-mpi.sh"
)]
fn rank_0_alone_writes_the_record_and_the_counters() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let (reference_csv, mpi_csv, counters) = (path("ref.csv"), path("mpi.csv"), path("c.json"));
    let base = [
        "run",
        "--objects",
        "100",
        "--steps",
        "20",
        "--record-every",
        "5",
    ];
    let mut args = base.to_vec();
    args.extend(["--record", &reference_csv]);
    let reference = hash(&ok(&args));
    let mut args = base.to_vec();
    args.extend([
        "--record",
        &mpi_csv,
        "--counters",
        &counters,
        "--executor",
        "mpi",
        "--worlds",
        "3",
    ]);
    let out = mpi_ok(3, &args);
    assert_eq!(hash(&out), reference);
    // One summary (rank 0's), the same recording to the byte, one report.
    assert_eq!(out.matches("hash ").count(), 1, "{out}");
    assert_eq!(
        std::fs::read(&mpi_csv).unwrap(),
        std::fs::read(&reference_csv).unwrap()
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&counters).unwrap()).unwrap();
    assert_eq!(report["executor"], "mpi");
    assert_eq!(report["kernel"]["worlds"], 3);
    assert!(report["kernel"]["mpi"]["batches_sent"].as_u64().unwrap() > 0);
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(names.len(), 3, "no temporary file left behind");
}

/// Runs a planted fault and expects every rank to stop soon with an error.
fn fails_soon(ranks: usize, args: &[&str], bug: &str) -> String {
    let started = Instant::now();
    let o = mpirun(ranks, args, &[("SODA_MPI_PLANTED_BUG", bug)]);
    assert!(
        started.elapsed() < Duration::from_secs(30),
        "the ranks took {:?} to stop",
        started.elapsed()
    );
    assert!(!o.status.success(), "{bug}: the run did not fail");
    stderr(&o)
}

#[test]
#[cfg_attr(
    not(feature = "mpi"),
    ignore = "needs a soda built with the mpi feature: scripts/test-mpi.sh"
)]
fn a_damaged_batch_stops_every_rank_with_an_error() {
    let args = [
        "run",
        "--objects",
        "200",
        "--steps",
        "30",
        "--executor",
        "mpi",
        "--worlds",
        "4",
    ];
    let err = fails_soon(2, &args, "corrupt");
    assert!(err.contains("does not decode"), "{err}");
    assert!(err.contains("checksum"), "{err}");
    assert!(err.contains("MPI rank "), "{err}");
}

#[test]
#[cfg_attr(
    not(feature = "mpi"),
    ignore = "needs a soda built with the mpi feature: scripts/test-mpi.sh"
)]
fn a_panicking_rank_stops_every_rank_naming_the_rank_and_step() {
    let args = [
        "run",
        "--objects",
        "200",
        "--steps",
        "60",
        "--executor",
        "mpi",
        "--worlds",
        "4",
    ];
    let err = fails_soon(3, &args, "panic:1:10");
    assert!(err.contains("MPI rank 1 of 3"), "{err}");
    assert!(
        err.contains("panicked while computing from step 1"),
        "{err}"
    );
    assert!(err.contains("planted panic"), "{err}");
}

#[test]
#[cfg_attr(
    not(feature = "mpi"),
    ignore = "needs a soda built with the mpi feature: scripts/test-mpi.sh"
)]
fn lost_anti_messages_stop_every_rank_with_an_error() {
    // Random territories: rollbacks send anti-messages between ranks, and the planted fault
    // loses every one of them (counted as sent, never sent). The next GVT round finds them
    // missing and, after its timeout, stops the run instead of waiting forever.
    let args = [
        "run",
        "--scene",
        "peak",
        "--objects",
        "200",
        "--steps",
        "80",
        "--executor",
        "mpi",
        "--worlds",
        "8",
        "--partition",
        "random",
        "--window",
        "32",
    ];
    let started = Instant::now();
    let o = mpirun(
        2,
        &args,
        &[
            ("SODA_MPI_PLANTED_BUG", "drop-anti"),
            ("SODA_MPI_ROUND_TIMEOUT", "2"),
        ],
    );
    assert!(started.elapsed() < Duration::from_secs(30));
    let err = stderr(&o);
    assert!(
        !o.status.success(),
        "the lost anti-messages went unnoticed:\n{err}"
    );
    assert!(err.contains("lost in transit"), "{err}");
    assert!(err.contains("aborting every rank"), "{err}");
}

/// Ctrl-C on `mpirun` stops every rank within seconds at a committed step: rank 0 says
/// where (`interrupted at step N, hash H`), `H` is the reference's hash at step `N`, the
/// record holds whole frames only, and no rank is left running.
#[test]
#[cfg_attr(
    not(feature = "mpi"),
    ignore = "needs a soda built with the mpi feature: scripts/test-mpi.sh"
)]
fn ctrl_c_on_mpirun_stops_every_rank_at_a_committed_step_and_says_where() {
    use std::process::Stdio;
    let dir = tempfile::tempdir().unwrap();
    let record = dir.path().join("run.csv");
    let scene = ["--scene", "falling-cubes", "--objects", "300"];
    let mut child = Command::new("mpirun")
        .args(["--allow-run-as-root", "--oversubscribe", "-np", "2"])
        .arg(soda_mpi())
        .arg("run")
        .args(scene)
        .args(["--steps", "1000000", "--executor", "mpi", "--worlds", "3"])
        .arg("--record")
        .arg(&record)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mpirun runs (scripts/install-mpi-deps.sh installs it)");
    std::thread::sleep(Duration::from_secs(4));
    // SAFETY: sends SIGINT to the child we spawned and still own (not yet waited for).
    assert_eq!(
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) },
        0
    );
    let signalled = Instant::now();
    while child.try_wait().unwrap().is_none() {
        assert!(
            signalled.elapsed() < Duration::from_secs(30),
            "mpirun still running 30 s after Ctrl-C"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    let err = stderr(&out);
    assert!(!out.status.success(), "an interrupted run does not succeed");
    let line = err
        .lines()
        .find(|l| l.starts_with("interrupted at step "))
        .unwrap_or_else(|| panic!("rank 0 does not say where it stopped:\n{err}"));
    let rest = &line["interrupted at step ".len()..];
    let (step, rest) = rest.split_once(", hash ").expect(line);
    let shown = rest.split(|c: char| !c.is_ascii_hexdigit()).next().unwrap();
    let mut args = vec!["run"];
    args.extend(scene);
    args.extend(["--steps", step]);
    assert_eq!(hash(&ok(&args)), shown, "{line}");
    let text = std::fs::read_to_string(&record).unwrap();
    let last = text.lines().last().unwrap();
    assert!(
        last.starts_with(&format!("{step},")),
        "the record ends at step {step}: {last}"
    );
}

#[test]
#[cfg_attr(
    not(feature = "mpi"),
    ignore = "needs a soda built with the mpi feature: scripts/test-mpi.sh"
)]
fn verify_under_mpirun_checks_mpi_runs_and_names_a_planted_kernel_bug() {
    // Correct: every MPI run (per mode) and the in-process runs commit the reference's
    // hashes; rank 0 alone prints.
    let args = [
        "verify",
        "--scene",
        "sparse-gas",
        "--objects",
        "200",
        "--steps",
        "30",
        "--worlds",
        "5",
        "--partition",
        "random",
        "--mpi-repeats",
        "1",
        "--schedules",
        "1",
        "--repeats",
        "0",
    ];
    let out = mpi_ok(3, &args);
    assert_eq!(out.matches("verify ").count(), 1, "{out}");
    for mode in ["cell", "world", "conservative"] {
        let line = out
            .lines()
            .find(|l| l.starts_with("ok       mpi") && l.contains(mode))
            .unwrap_or_else(|| panic!("no MPI {mode} line in:\n{out}"));
        assert!(line.contains("3 ranks: 30 steps match"), "{line}");
    }
    assert!(out.contains("all 6 runs committed"), "{out}");
    // A registered model, too.
    let out = mpi_ok(
        2,
        &[
            "verify",
            "--model",
            "phold",
            "--steps",
            "15",
            "--mpi-repeats",
            "1",
            "--schedules",
            "0",
            "--repeats",
            "0",
        ],
    );
    assert!(out.contains("2 ranks: 15 steps match"), "{out}");
    // A kernel bug (the cutoff compares ids only): the MPI runs diverge, the first difference
    // is named and the reproducing command runs under mpirun.
    let bad = [
        "verify",
        "--scene",
        "sparse-gas",
        "--objects",
        "400",
        "--steps",
        "60",
        "--worlds",
        "6",
        "--partition",
        "random",
        "--modes",
        "cell",
        "--mpi-repeats",
        "3",
        "--schedules",
        "0",
        "--repeats",
        "0",
        "--planted-bug",
        "cutoff-by-ids-only",
    ];
    let o = mpirun(3, &bad, &[]);
    assert!(!o.status.success(), "the planted bug was not caught");
    let out = stdout(&o);
    let line = out
        .lines()
        .find(|l| l.starts_with("DIVERGED mpi"))
        .unwrap_or_else(|| panic!("no diverged MPI run in:\n{out}\n{}", stderr(&o)));
    assert!(line.contains("first divergence at step"), "{line}");
    assert!(
        out.contains("reproduce: mpirun -np 3 soda run") && out.contains("--executor mpi"),
        "{out}"
    );
}

#[test]
#[cfg_attr(
    not(feature = "mpi"),
    ignore = "needs a soda built with the mpi feature: scripts/test-mpi.sh"
)]
fn several_threads_per_rank_commit_the_reference_hash_and_a_panic_on_one_stops_every_rank() {
    // Ranks × threads × worlds × mode, random partitions: the same hash as the reference.
    let base = [
        "run",
        "--scene",
        "sparse-gas",
        "--objects",
        "300",
        "--steps",
        "40",
    ];
    let reference = hash(&ok(&base));
    for (ranks, threads, worlds, mode, seed) in [
        (2, "2", "6", "cell", "1"),
        (3, "2", "7", "world", "2"),
        (2, "3", "5", "conservative", "3"),
    ] {
        let mut args = base.to_vec();
        args.extend([
            "--executor",
            "mpi",
            "--threads",
            threads,
            "--worlds",
            worlds,
            "--mode",
            mode,
            "--partition",
            "random",
            "--partition-seed",
            seed,
        ]);
        let out = mpi_ok(ranks, &args);
        assert_eq!(
            hash(&out),
            reference,
            "{ranks} ranks × {threads} threads, {mode}"
        );
        assert!(
            out.contains(&format!("{threads} threads per rank, {ranks} ranks")),
            "{out}"
        );
    }
    // A world panicking on any of a rank's threads stops every rank, naming rank and step.
    let args = [
        "run",
        "--objects",
        "200",
        "--steps",
        "60",
        "--executor",
        "mpi",
        "--worlds",
        "6",
        "--threads",
        "2",
    ];
    let err = fails_soon(3, &args, "panic:1:10");
    assert!(err.contains("MPI rank 1 of 3"), "{err}");
    assert!(err.contains("panicked while computing from step"), "{err}");
    assert!(err.contains("planted panic"), "{err}");
}
