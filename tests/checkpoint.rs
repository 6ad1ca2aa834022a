//! Checkpoint and resume (`soda run --checkpoint`, `soda resume`): a resumed run ends with
//! the uninterrupted run's hash on every executor, even after `kill -9` at random moments
//! (during a checkpoint write too), and a damaged, edited or foreign file is refused.

mod cli_support;

use cli_support::{fails, hash_of, ok, stderr};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn s(p: &Path) -> &str {
    p.to_str().expect("temporary paths are UTF-8")
}

#[test]
fn resumed_run_ends_with_the_uninterrupted_hash_on_every_executor() {
    let dir = tempfile::tempdir().unwrap();
    let scene = ["--scene", "sparse-gas"];
    let whole = hash_of(&ok(&[&["run"], &scene[..], &["--steps", "150"]].concat()));
    for executor in [
        vec!["--executor", "reference"],
        vec!["--executor", "virtual", "--worlds", "5", "--mode", "world"],
        vec!["--executor", "threaded", "--threads", "2", "--worlds", "3"],
    ] {
        let file = dir.path().join("gas.ckpt");
        // The first part on the virtual executor, the rest on each executor.
        let first = ok(&[
            &["run"],
            &scene[..],
            &[
                "--steps",
                "90",
                "--executor",
                "virtual",
                "--checkpoint",
                s(&file),
                "--checkpoint-every",
                "40",
            ],
        ]
        .concat());
        assert!(first.contains("at step 90"), "{first}");
        let resumed = ok(&[&["resume", s(&file), "--steps", "150"], &executor[..]].concat());
        assert_eq!(
            hash_of(&resumed),
            whole,
            "resumed with {executor:?}:\n{resumed}"
        );
        assert!(resumed.contains("resumed"), "{resumed}");
    }
}

#[test]
fn resume_without_executor_options_continues_on_the_checkpointed_executor() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("cubes.ckpt");
    let whole = hash_of(&ok(&["run", "--objects", "300", "--steps", "80"]));
    // A threaded run on 4 worlds stopped at step 60, resumed to 80 with no executor option.
    ok(&[
        "run",
        "--objects",
        "300",
        "--steps",
        "60",
        "--executor",
        "threaded",
        "--threads",
        "2",
        "--worlds",
        "4",
        "--checkpoint",
        s(&file),
    ]);
    let resumed = ok(&["resume", s(&file), "--steps", "80"]);
    assert!(resumed.contains("threaded executor"), "{resumed}");
    assert!(resumed.contains("4 (blocks partition)"), "{resumed}");
    assert_eq!(hash_of(&resumed), whole);
}

/// A checkpoint's text with its document rewritten by `edit` and its checksum made to match.
fn rewritten(text: &str, edit: impl FnOnce(&mut serde_json::Value)) -> String {
    let (first, rest) = text.split_once('\n').unwrap();
    let body_end = rest.trim_end_matches('\n').rfind('\n').unwrap() + 1;
    let mut doc: serde_json::Value = serde_json::from_str(&rest[..body_end]).unwrap();
    edit(&mut doc);
    let content = format!("{first}\n{doc}\n");
    let mut fnv: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in content.as_bytes() {
        fnv = (fnv ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{content}checksum {fnv:016x}\n")
}

/// The summary lines of the kernel's counters (they depend on the virtual schedule).
fn counter_lines(summary: &str) -> Vec<&str> {
    summary
        .lines()
        .filter(|l| {
            let label = l.split_whitespace().next().unwrap_or("");
            ["efficiency", "rollbacks", "messages"].contains(&label)
        })
        .collect()
}

#[test]
fn a_checkpoint_written_with_the_schedule_inside_the_kernel_configuration_resumes_with_it() {
    // Checkpoints written before the virtual executor's schedule left `KernelConfig` hold it
    // as `run.options.kernel.schedule` (and `record_schedule`): such a file resumes on the
    // same schedule, so the same counters, as the file written today.
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("gas.ckpt");
    let scene = ["--scene", "sparse-gas", "--objects", "150"];
    let whole = hash_of(&ok(&[&["run"], &scene[..], &["--steps", "80"]].concat()));
    let virtual_run = [
        "--executor",
        "virtual",
        "--worlds",
        "5",
        "--schedule-seed",
        "7",
    ];
    ok(&[
        &["run"],
        &scene[..],
        &virtual_run[..],
        &["--steps", "40", "--checkpoint", s(&file)],
    ]
    .concat());
    let text = std::fs::read_to_string(&file).unwrap();
    assert!(text.contains("\"schedule\":{\"seeded\":7}"), "{text}");
    let resume = |name: &str, contents: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, contents).unwrap();
        let out = ok(&["resume", s(&path), "--steps", "80"]);
        assert_eq!(hash_of(&out), whole, "{name}:\n{out}");
        out
    };
    let today = resume("today.ckpt", &text);
    let older = resume(
        "older.ckpt",
        &rewritten(&text, |doc| {
            let options = doc["run"]["options"].as_object_mut().unwrap();
            let schedule = options.remove("schedule").unwrap();
            let record = options.remove("record_schedule").unwrap();
            options["kernel"]["schedule"] = schedule;
            options["kernel"]["record_schedule"] = record;
        }),
    );
    assert!(!counter_lines(&today).is_empty(), "{today}");
    assert_eq!(counter_lines(&older), counter_lines(&today));
    // Without any schedule in the file the run resumes on seed 0: other counters.
    let seedless = resume(
        "seedless.ckpt",
        &rewritten(&text, |doc| {
            doc["run"]["options"]
                .as_object_mut()
                .unwrap()
                .remove("schedule");
        }),
    );
    assert_ne!(counter_lines(&seedless), counter_lines(&today));
}

/// When a run is killed.
#[derive(Clone, Copy, Debug)]
enum KillAt {
    /// After this long.
    Delay(Duration),
    /// As soon as a checkpoint's temporary file is seen (a write under way).
    DuringWrite,
}

/// The temporary files of checkpoint `file` in its directory.
fn temporaries(file: &Path) -> Vec<std::path::PathBuf> {
    let temp_prefix = format!(".{}.tmp-", file.file_name().unwrap().to_string_lossy());
    std::fs::read_dir(file.parent().unwrap())
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_name().to_string_lossy().starts_with(&temp_prefix))
        .map(|e| e.path())
        .collect()
}

/// Runs `soda run` with a checkpoint every step and kills it with SIGKILL at `when`;
/// returns whether a checkpoint's temporary file was left (the kill hit a write).
fn run_and_kill(args: &[&str], file: &Path, when: KillAt) -> bool {
    let mut child = Command::new(env!("CARGO_BIN_EXE_soda"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("soda starts");
    match when {
        KillAt::Delay(delay) => std::thread::sleep(delay),
        KillAt::DuringWrite => {
            let deadline = Instant::now() + Duration::from_secs(60);
            while temporaries(file).is_empty()
                && Instant::now() < deadline
                && child.try_wait().unwrap().is_none()
            {
                std::thread::sleep(Duration::from_micros(100));
            }
        }
    }
    // SIGKILL: no handler, no destructor, no cleanup runs.
    let _ = child.kill();
    let _ = child.wait();
    let left = temporaries(file);
    for t in &left {
        std::fs::remove_file(t).unwrap();
    }
    !left.is_empty()
}

#[test]
fn run_killed_at_random_moments_resumes_to_the_uninterrupted_hash() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("pile.ckpt");
    let scene = ["run", "--objects", "2000", "--steps", "240"];
    let started = Instant::now();
    let whole = hash_of(&ok(&scene));
    let mut rng = ChaCha8Rng::seed_from_u64(18);
    let mut killed_during_write = 0;
    let mut resumed = 0;
    let executors = [
        vec!["--executor", "reference"],
        vec!["--executor", "virtual", "--worlds", "4"],
        vec!["--executor", "threaded", "--threads", "2", "--worlds", "2"],
    ];
    // Nine kills at random moments, then one per executor as soon as a checkpoint write is
    // seen under way (random moments alone hit a write only now and then).
    for (i, executor) in executors.iter().cycle().take(12).enumerate() {
        let _ = std::fs::remove_file(&file);
        let args = [
            &scene[..],
            executor,
            &["--checkpoint", s(&file), "--checkpoint-every", "1"],
        ]
        .concat();
        // Once the first run shows how long a checkpointed run takes, kill at random moments
        // of it; the first kill of each executor comes early, the others anywhere.
        let span = started.elapsed().as_millis().clamp(300, 4_000) as u64;
        let when = match i {
            0..3 => KillAt::Delay(Duration::from_millis(rng.random_range(150..300))),
            3..9 => KillAt::Delay(Duration::from_millis(rng.random_range(150..150 + span))),
            _ => KillAt::DuringWrite,
        };
        if run_and_kill(&args, &file, when) {
            killed_during_write += 1;
        }
        if !file.exists() {
            // Killed before the first checkpoint was whole: nothing to resume, nothing lost.
            continue;
        }
        let out = ok(&["resume", s(&file), "--steps", "240"]);
        assert_eq!(
            hash_of(&out),
            whole,
            "killed at {when:?} on {executor:?}, resumed:\n{out}"
        );
        resumed += 1;
    }
    assert!(resumed >= 4, "only {resumed} of 12 kills left a checkpoint");
    assert!(
        killed_during_write >= 1,
        "no kill of 12 hit a checkpoint write (each leaves its temporary file)"
    );
}

#[test]
fn damaged_edited_or_foreign_checkpoints_are_refused_with_a_reason() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("gas.ckpt");
    ok(&[
        "run",
        "--scene",
        "sparse-gas",
        "--steps",
        "30",
        "--checkpoint",
        s(&file),
    ]);
    let text = std::fs::read_to_string(&file).unwrap();
    let bad = dir.path().join("bad.ckpt");
    let refused = |contents: &str| {
        std::fs::write(&bad, contents).unwrap();
        fails(&["resume", s(&bad)])
    };
    // Cut off in the middle.
    let err = refused(&text[..text.len() / 2]);
    assert!(err.contains("truncated"), "{err}");
    // Cut off just before the end of the checksum line.
    let err = refused(&text[..text.len() - 1]);
    assert!(err.contains("truncated"), "{err}");
    // One digit of a body changed: the second digit of the first body's twelfth word (the
    // bits of its position's x, a large number).
    let states = text.find("\"states\":[[").unwrap() + "\"states\":[[".len();
    let twelfth = states + text[states..].match_indices(',').nth(10).unwrap().0 + 1;
    let at = twelfth + 1;
    let mut edited = text.clone().into_bytes();
    assert!(edited[at].is_ascii_digit());
    edited[at] = b'0' + (edited[at] - b'0' + 1) % 10;
    let err = refused(std::str::from_utf8(&edited).unwrap());
    assert!(err.contains("damaged or was edited"), "{err}");
    // A body edited and the checksum made to match: the states' hash refuses it.
    let body_end = text.trim_end_matches('\n').rfind('\n').unwrap() + 1;
    let content = std::str::from_utf8(&edited[..body_end]).unwrap();
    let mut fnv: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in content.as_bytes() {
        fnv = (fnv ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
    }
    let err = refused(&format!("{content}checksum {fnv:016x}\n"));
    assert!(err.contains("not the committed states of step 30"), "{err}");
    // Another program's file, a scene file, an empty file, binary junk.
    for foreign in ["name = \"x\"\n", "", "\u{0}\u{1}\u{2}"] {
        let err = refused(foreign);
        assert!(err.contains("not a SODA checkpoint"), "{foreign:?}: {err}");
    }
    // A later format version.
    let err = refused(&text.replacen("soda-checkpoint 2", "soda-checkpoint 3", 1));
    assert!(err.contains("format version 3"), "{err}");
    // Missing file.
    let err = fails(&["resume", s(&dir.path().join("missing.ckpt"))]);
    assert!(err.contains("cannot read the checkpoint"), "{err}");
}

#[test]
fn checkpoint_path_is_checked_before_the_run_like_every_output() {
    let dir = tempfile::tempdir().unwrap();
    let nowhere = dir.path().join("no/such/dir/x.ckpt");
    let err = fails(&["run", "--steps", "5", "--checkpoint", s(&nowhere)]);
    assert!(err.contains("--checkpoint"), "{err}");
    let same = dir.path().join("same.out");
    let err = fails(&[
        "run",
        "--steps",
        "5",
        "--checkpoint",
        s(&same),
        "--counters",
        s(&same),
    ]);
    assert!(
        err.contains("--checkpoint") && err.contains("--counters"),
        "{err}"
    );
    let o = cli_support::soda(&["run", "--steps", "5", "--checkpoint-every", "3"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
}

#[test]
fn registered_models_resume_from_their_checkpoints_to_the_uninterrupted_hash() {
    let dir = tempfile::tempdir().unwrap();
    for (model, size) in [("epidemic", "400"), ("phold", "1500")] {
        let base = ["run", "--model", model, "--entities", size];
        let whole = hash_of(&ok(&[&base[..], &["--steps", "90"]].concat()));
        let file = dir.path().join(format!("{model}.ckpt"));
        let first = ok(&[
            &base[..],
            &[
                "--steps",
                "50",
                "--executor",
                "threaded",
                "--worlds",
                "3",
                "--checkpoint",
                s(&file),
                "--checkpoint-every",
                "20",
            ],
        ]
        .concat());
        assert!(first.contains("at step 50"), "{first}");
        for executor in [
            vec![],
            vec!["--executor", "reference"],
            vec!["--executor", "virtual", "--worlds", "5"],
        ] {
            // Each resume keeps writing to the file: start from step 50's copy every time.
            let copy = dir.path().join(format!("{model}-copy.ckpt"));
            std::fs::copy(&file, &copy).unwrap();
            let out = ok(&[&["resume", s(&copy), "--steps", "90"], &executor[..]].concat());
            assert_eq!(
                hash_of(&out),
                whole,
                "{model} resumed with {executor:?}:\n{out}"
            );
        }
    }
}

/// Ctrl-C (SIGINT) stops a registered model's run at a committed step with status 130,
/// names the checkpoint to resume from, leaves no temporary file, and the resumed run ends
/// with the uninterrupted hash.
#[test]
fn interrupted_model_run_says_where_it_stopped_and_resumes_to_the_same_hash() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("epi.ckpt");
    let base = ["run", "--model", "epidemic", "--entities", "3000"];
    let whole = hash_of(&ok(&[&base[..], &["--steps", "400"]].concat()));
    let child = Command::new(env!("CARGO_BIN_EXE_soda"))
        .args(base)
        .args([
            "--steps",
            "400",
            "--checkpoint",
            s(&file),
            "--checkpoint-every",
            "10",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait for the first checkpoint, then interrupt.
    let started = Instant::now();
    while !file.exists() && started.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(20));
    }
    // SAFETY: sends SIGINT to the child we spawned and still own (not yet waited for).
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGINT);
    }
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    if out.status.code() == Some(0) {
        // The run finished before the signal arrived: nothing to resume.
        assert_eq!(hash_of(&String::from_utf8_lossy(&out.stdout)), whole);
        return;
    }
    assert_eq!(out.status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted at step"), "{err}");
    assert!(err.contains("continues from step"), "{err}");
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
    let resumed = ok(&["resume", s(&file)]);
    assert_eq!(hash_of(&resumed), whole);
}

#[test]
fn resumed_territory_map_starts_at_the_checkpoint_step() {
    // A resumed run partitions the checkpoint's bodies: its first map is of that step.
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("skewed.ckpt");
    let maps = dir.path().join("maps");
    let first = ok(&[
        "run",
        "--scene",
        "skewed",
        "--objects",
        "64",
        "--steps",
        "20",
        "--executor",
        "virtual",
        "--worlds",
        "4",
        "--checkpoint",
        s(&file),
    ]);
    assert!(first.contains("at step 20"), "{first}");
    ok(&[
        "resume",
        s(&file),
        "--steps",
        "30",
        "--territories",
        s(&maps),
    ]);
    let svg = std::fs::read_to_string(maps.join("territory-000020.svg"))
        .expect("the map of the checkpoint's step");
    assert!(svg.contains("<svg"));
    assert!(
        !maps.join("territory-000000.svg").exists(),
        "no map of a step the resumed run did not start from"
    );
}

/// A checkpoint whose checksum matches but whose run options are out of the command line's
/// ranges is refused naming the option, not run: `checkpoint_every` 0 divided by zero, 0
/// worlds panicked.
#[test]
fn an_edited_checkpoints_out_of_range_options_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("run.ckpt");
    ok(&[
        "run",
        "--objects",
        "40",
        "--steps",
        "20",
        "--executor",
        "virtual",
        "--checkpoint",
        s(&file),
    ]);
    let text = std::fs::read_to_string(&file).unwrap();
    type Edit = fn(&mut serde_json::Value);
    let cases: [(&str, Edit, &str); 3] = [
        (
            "every.ckpt",
            |doc| doc["run"]["checkpoint_every"] = 0.into(),
            "checkpoint_every is 0",
        ),
        (
            "worlds.ckpt",
            |doc| doc["run"]["options"]["kernel"]["worlds"] = 0.into(),
            "options.kernel.worlds is 0",
        ),
        (
            "threads.ckpt",
            |doc| doc["run"]["options"]["threads"] = 100_000.into(),
            "options.threads is 100000",
        ),
    ];
    for (name, edit, expected) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, rewritten(&text, edit)).unwrap();
        let err = fails(&["resume", s(&path), "--steps", "30"]);
        assert!(err.contains(expected), "{name}: {err}");
    }
}
