//! Replays every input saved for the cargo-fuzz targets in `fuzz/` (the seed corpora under
//! `fuzz/seeds/<target>/` and the kept crash inputs under `fuzz/regressions/<target>/`)
//! through the same checks the targets run, so a saved input keeps guarding on stable
//! `cargo test` without cargo-fuzz or a nightly toolchain.
//!
//! `sync_order` files are decoded exactly as `libfuzzer_sys::fuzz_target!` decodes a
//! structured input ([`SyncOrderInput::from_fuzz_bytes`]); `scene_file` files are raw bytes.
//!
//! And the proof that the `sync_order` check can fire: with a planted kernel bug it reports a
//! divergence on a saved seed, and the printed schedule string replays that divergence.

use soda::exec::virtual_exec::parse_schedule;
use soda::fuzzing::{check_case, check_scene_file, check_sync_order, SyncOrderInput};
use soda::kernel::PlantedBug;
use std::path::{Path, PathBuf};

/// The saved inputs of `target`: every regular file under `fuzz/seeds/<target>/` and
/// `fuzz/regressions/<target>/`, except dot files and READMEs, in name order.
fn saved_inputs(target: &str) -> Vec<PathBuf> {
    let fuzz = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz");
    let mut files = Vec::new();
    for dir in ["seeds", "regressions"] {
        let Ok(entries) = std::fs::read_dir(fuzz.join(dir).join(target)) else {
            continue;
        };
        for e in entries {
            let path = e.expect("a directory entry").path();
            let name = path.file_name().unwrap().to_string_lossy().to_string();
            if path.is_file() && !name.starts_with('.') && !name.starts_with("README") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

fn decode(path: &Path) -> SyncOrderInput {
    let bytes = std::fs::read(path).unwrap();
    let input = SyncOrderInput::from_fuzz_bytes(&bytes).unwrap_or_else(|| {
        panic!(
            "{}: {} bytes is too short for a sync_order input (libFuzzer would reject it)",
            path.display(),
            bytes.len()
        )
    });
    assert_eq!(
        input.to_fuzz_bytes(),
        bytes,
        "{}: decoding is exact",
        path.display()
    );
    input
}

#[test]
fn every_saved_fuzz_input_replays_without_divergence_or_panic() {
    let sync = saved_inputs("sync_order");
    assert!(sync.len() >= 5, "sync_order seeds missing: {sync:?}");
    for path in &sync {
        let input = decode(path);
        if let Err(e) = check_sync_order(&input, PlantedBug::None) {
            panic!("{}: {input:?}\n{e}", path.display());
        }
    }

    let scenes = saved_inputs("scene_file");
    assert!(scenes.len() >= 5, "scene_file seeds missing: {scenes:?}");
    let mut accepted = 0;
    let mut simulated = 0;
    for path in &scenes {
        let outcome = check_scene_file(&std::fs::read(path).unwrap());
        let name = path.file_name().unwrap().to_string_lossy();
        // The seeds named `valid-*` are good scene files: they must be accepted.
        if name.starts_with("valid-") {
            assert!(
                outcome.toml || outcome.json,
                "{}: a valid scene was rejected: {outcome:?}",
                path.display()
            );
        }
        accepted += usize::from(outcome.toml || outcome.json);
        simulated += usize::from(outcome.simulated);
    }
    assert!(
        accepted >= 3 && simulated >= 3,
        "{accepted} accepted, {simulated} simulated"
    );
}

/// Saved `sync_order` seeds diverge under `bug`, among them `planted-<name>` (the input the
/// fuzzer found with that bug on); the error names the step, and the schedule string in it
/// replays the divergence.
fn planted_bug_is_caught_on_a_saved_seed(bug: PlantedBug, name: &str) {
    let mut caught = Vec::new();
    for path in saved_inputs("sync_order") {
        let input = decode(&path);
        let Err(e) = check_sync_order(&input, bug) else {
            continue;
        };
        assert!(e.to_string().contains("first divergence at step"), "{e}");
        let replay = e.schedule().expect("a replay string");
        let mut case = input.case(bug);
        case.options.schedule = parse_schedule(replay).expect("a replay string");
        assert!(
            check_case(&case).is_err(),
            "{}: the printed schedule does not replay the divergence",
            path.display()
        );
        caught.push(path);
    }
    assert!(
        caught
            .iter()
            .any(|p| p.file_name().unwrap() == format!("planted-{name}").as_str()),
        "the seed planted-{name} does not catch the planted bug {bug:?}; caught by {caught:?}"
    );
}

#[test]
fn planted_bug_drop_lone_anti_is_caught_by_a_saved_sync_order_seed() {
    planted_bug_is_caught_on_a_saved_seed(PlantedBug::DropLoneAnti, "drop-lone-anti");
}

#[test]
fn planted_bug_cutoff_by_ids_only_is_caught_by_a_saved_sync_order_seed() {
    planted_bug_is_caught_on_a_saved_seed(PlantedBug::CutoffByIdsOnly, "cutoff-by-ids-only");
}

/// The generic sync-order check runs any model: the example epidemic, under fuzz-chosen
/// configurations and schedules, commits the reference's frames.
#[test]
fn the_generic_sync_order_check_runs_a_users_model() {
    use soda::fuzzing::{check_model_sync_order, fuzz_case};
    use soda::models::epidemic::Epidemic;
    for seed in 0u8..12 {
        let bytes: Vec<u8> = (0..64u8)
            .map(|k| k.wrapping_mul(37).wrapping_add(seed.wrapping_mul(11)))
            .collect();
        let case = fuzz_case(&bytes, 25).expect("long enough");
        let (model, grid, initial) = Epidemic::default().scene(60, 6, [4, 2, 3], u64::from(seed));
        if let Err(e) = check_model_sync_order(model, grid, initial, &case) {
            panic!("{e}");
        }
    }
}
