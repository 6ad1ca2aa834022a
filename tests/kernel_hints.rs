//! The hints a Time Warp world hands a cell computation (`Neighbourhood::hints`, prepared
//! once per advanced step in global cell order) are exactly the model's hints of the
//! neighbourhood's entities, row by row in slot order, whatever the partition: a model
//! wrapped to recompute and compare them on every computation runs the kernel executors
//! and commits the reference's hashes. In a sparse scene the computations also read a
//! world's states from its prepared copy (a row's cells side by side in memory), and the
//! same hashes are committed.

use soda::frame::Event;
use soda::grid::Grid;
use soda::hash::StateHash;
use soda::kernel::{KernelConfig, PartitionKind, RollbackMode};
use soda::model::{BodyId, CellModel, Hint, Neighbourhood, Step};
use soda::physics::{Body, EventKind, RigidBodyModel};
use soda::scene::builtin::builtin;
use soda::sim::{RunOptions, Runner};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// The rigid-body model, checking on every computation that each row's hints (when given)
/// are its entities' hints in slot order, and counting the rows it checked and the rows
/// whose cells it was handed side by side in memory (one array, not one allocation per
/// cell).
#[derive(Clone)]
struct HintChecked {
    inner: RigidBodyModel,
    rows_checked: Arc<AtomicU64>,
    rows_side_by_side: Arc<AtomicU64>,
}

/// Whether two non-empty cells of row `r` follow each other in memory.
fn side_by_side(nb: &Neighbourhood<'_, Body>, r: usize) -> bool {
    let row = &nb.cells[3 * r..3 * r + 3];
    row.windows(2).any(|w| {
        !w[0].is_empty() && !w[1].is_empty() && w[0].as_ptr_range().end == w[1].as_ptr_range().start
    })
}

impl CellModel for HintChecked {
    type State = Body;
    type Event = EventKind;

    fn id(state: &Body) -> BodyId {
        RigidBodyModel::id(state)
    }

    fn position(state: &Body) -> [f32; 3] {
        RigidBodyModel::position(state)
    }

    fn step_cell(
        &self,
        step: Step,
        grid: &Grid,
        nb: &Neighbourhood<'_, Body>,
        out: &mut Vec<Body>,
        events: &mut Vec<Event<EventKind>>,
    ) {
        for r in 0..9 {
            if let Some(given) = nb.row_hints(r) {
                let expected: Vec<Hint> = nb.cells[3 * r..3 * r + 3]
                    .iter()
                    .flat_map(|c| c.iter())
                    .map(|b| self.inner.hint(b).expect("the model gives hints"))
                    .collect();
                let bits = |h: &[Hint]| -> Vec<[u32; 4]> {
                    h.iter().map(|h| h.map(f32::to_bits)).collect()
                };
                assert_eq!(
                    bits(given),
                    bits(&expected),
                    "row {r} of cell {:?} at step {step}",
                    nb.centre
                );
                self.rows_checked.fetch_add(1, Ordering::Relaxed);
            }
            if side_by_side(nb, r) {
                self.rows_side_by_side.fetch_add(1, Ordering::Relaxed);
            }
        }
        self.inner.step_cell(step, grid, nb, out, events);
    }

    fn hint(&self, state: &Body) -> Option<Hint> {
        self.inner.hint(state)
    }

    fn may_affect(&self, reader: &Body, other: &Body) -> bool {
        self.inner.may_affect(reader, other)
    }

    fn at_rest(&self, state: &Body) -> bool {
        self.inner.at_rest(state)
    }

    fn hash_state(state: &Body, hasher: &mut StateHash) {
        RigidBodyModel::hash_state(state, hasher)
    }

    fn same_bits(a: &Body, b: &Body) -> bool {
        RigidBodyModel::same_bits(a, b)
    }
}

/// What a run of the checked model saw.
struct Seen {
    /// Every committed hash.
    hashes: Vec<u64>,
    /// Hint rows checked.
    rows: u64,
    /// Rows handed with two cells side by side in memory.
    side_by_side: u64,
}

/// A run of `options` on built-in scene `name` with `objects` bodies.
fn run_scene(name: &str, objects: usize, options: RunOptions, steps: u64) -> Seen {
    let scene = builtin(name, Some(objects), 0).expect("scene");
    let rows_checked = Arc::new(AtomicU64::new(0));
    let rows_side_by_side = Arc::new(AtomicU64::new(0));
    let model = HintChecked {
        inner: scene.model(),
        rows_checked: rows_checked.clone(),
        rows_side_by_side: rows_side_by_side.clone(),
    };
    let mut hashes = Vec::new();
    Runner::new(model, scene.grid(), scene.initial_bodies())
        .options(options)
        .run(steps, |f, _, _| hashes.push(f.hash))
        .expect("the run succeeds");
    Seen {
        hashes,
        rows: rows_checked.load(Ordering::Relaxed),
        side_by_side: rows_side_by_side.load(Ordering::Relaxed),
    }
}

/// The kernel executors each test runs with `kernel`: the virtual executor with blocks and
/// a random partition in cell mode and with blocks in world mode, the threaded executor
/// with blocks and k-means (it computes a postponed world's interior ahead, and the advance
/// then prepares its border again or computes it from the log).
fn kernel_executors(kernel: &KernelConfig) -> [RunOptions; 5] {
    [
        RunOptions::virtual_exec(kernel.clone()),
        RunOptions::virtual_exec(
            kernel
                .clone()
                .partition(PartitionKind::Random)
                .partition_seed(3),
        ),
        RunOptions::virtual_exec(kernel.clone().mode(RollbackMode::World)),
        RunOptions::threaded(kernel.clone(), 2),
        RunOptions::threaded(kernel.clone().partition(PartitionKind::KMeans), 2),
    ]
}

/// Every committed hash of `options` on 400 falling cubes (the landing, then rest), and the
/// number of hint rows the model checked.
fn run(options: RunOptions, steps: u64) -> (Vec<u64>, u64) {
    let seen = run_scene("falling-cubes", 400, options, steps);
    (seen.hashes, seen.rows)
}

#[test]
fn worlds_hand_each_computation_its_neighbourhoods_hints_in_slot_order() {
    let steps = 150;
    let (expected, reference_rows) = run(RunOptions::reference(), steps);
    assert!(reference_rows > 0, "the reference hands hints");
    for options in kernel_executors(&KernelConfig::new(5).window(8)) {
        let label = format!("{options:?}");
        let (hashes, rows) = run(options, steps);
        assert_eq!(hashes, expected, "{label}");
        assert!(rows > 0, "the worlds handed no hints: {label}");
    }
}

#[test]
fn sparse_worlds_read_the_prepared_copy_and_commit_the_reference_bits() {
    let steps = 60;
    let expected = run_scene("sparse-gas", 1000, RunOptions::reference(), steps);
    assert!(
        expected.side_by_side > 0,
        "the reference hands its one array"
    );
    for options in kernel_executors(&KernelConfig::new(4).window(8)) {
        let label = format!("{options:?}");
        let seen = run_scene("sparse-gas", 1000, options, steps);
        assert_eq!(seen.hashes, expected.hashes, "{label}");
        assert!(seen.rows > 0, "the worlds handed no hints: {label}");
        assert!(
            seen.side_by_side > 0,
            "no computation read the prepared copy: {label}"
        );
    }
}
