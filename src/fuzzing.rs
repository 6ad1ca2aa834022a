//! The checks behind the cargo-fuzz targets in `fuzz/` and the replay test
//! `tests/fuzz_replay.rs`, kept in the library so both call exactly the same code.
//!
//! - [`check_sync_order`]: a small structured input ([`SyncOrderInput`]) picks a cheap scene,
//!   a kernel configuration and the bytes that drive every decision of the virtual executor
//!   (which world acts, which in-flight message is delivered next); every committed frame
//!   must equal the single-threaded reference's. The fuzzer mutates the delivery order
//!   directly.
//! - [`check_scene_file`]: arbitrary bytes are parsed and validated as a TOML and as a JSON
//!   scene file; nothing may panic, an accepted scene must survive a write/read round trip,
//!   and a small accepted scene is stepped twice in the reference executor.
//!
//! Every input is valid: integers are mapped into their ranges with a modulo, and the
//! schedule bytes fall back to the deterministic FIFO schedule when they run out.
//!
//! ```
//! use soda::fuzzing::{check_sync_order, SyncOrderInput};
//! use soda::kernel::PlantedBug;
//!
//! let input = SyncOrderInput::from_fuzz_bytes(&[0, 30, 7, 0, 3, 0, 2, 0, 1, 12, 250, 3, 9, 77])
//!     .expect("long enough");
//! assert_eq!(check_sync_order(&input, PlantedBug::None), Ok(()));
//! ```

use crate::exec::reference::ReferenceRun;
use crate::exec::virtual_exec::{ScheduleSpec, VirtualOptions, VirtualRun};
use crate::frame::Frame;
use crate::grid::Grid;
use crate::kernel::synthetic::Particles;
use crate::kernel::{KernelConfig, PartitionKind, PlantedBug, RollbackMode};
use crate::model::{CellModel, Step};
use crate::scene::builtin::builtin;
use crate::scene::{parse_scene, Scene, SceneFormat};
use arbitrary::{Arbitrary, Unstructured};

/// The input of the `sync_order` fuzz target: a scene, a kernel configuration and the bytes
/// that drive the virtual executor's scheduler. Every field is mapped into its range with a
/// modulo ([`SyncOrderInput::case`]), so every value is a valid run.
///
/// Its [`Arbitrary`] implementation is written by hand so that the schedule is the raw tail
/// of the fuzz input: the derived one would read a `Vec<u8>` last field with a continuation
/// byte before every element, halving what each mutation of the tail means to the scheduler.
/// The layout is therefore the ten header bytes in field order, then the schedule bytes
/// ([`SyncOrderInput::to_fuzz_bytes`]).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct SyncOrderInput {
    /// Scene choice (modulo 8): 0–3 synthetic particles (odd: open x faces), 4–5
    /// `sparse-gas`, 6 `falling-cubes`, 7 `chain`.
    pub scene: u8,
    /// Body count within the scene's range: particles 2–61, `sparse-gas` 12–24,
    /// `falling-cubes` 8–27, `chain` 4–10.
    pub size: u8,
    /// Particle grid dimensions: x 2–6, y 1–4, z 1–4 cells (ignored by built-in scenes).
    pub dims: u8,
    /// Seed of the scene's random placement.
    pub seed: u8,
    /// Worlds, 1–8.
    pub worlds: u8,
    /// Rollback mode (modulo 3): cell, world, conservative.
    pub mode: u8,
    /// Optimism window, 1–16.
    pub window: u8,
    /// Partitioner (modulo 3): blocks, k-means, random.
    pub partition: u8,
    /// Seed of the k-means and random partitioners.
    pub partition_seed: u8,
    /// Steps to commit: 5–30 for particles, 5–20 for the rigid-body scenes.
    pub steps: u8,
    /// The scheduler's bytes ([`ScheduleSpec::Bytes`]): each decision
    /// consumes one byte (two when more than 256 choices are open), then the deterministic
    /// FIFO fallback takes over.
    pub schedule: Vec<u8>,
}

/// Bytes before the schedule in a fuzz input.
const HEADER: usize = 10;

impl SyncOrderInput {
    fn with_header(h: [u8; HEADER], schedule: Vec<u8>) -> Self {
        let [scene, size, dims, seed, worlds, mode, window, partition, partition_seed, steps] = h;
        SyncOrderInput {
            scene,
            size,
            dims,
            seed,
            worlds,
            mode,
            window,
            partition,
            partition_seed,
            steps,
            schedule,
        }
    }
}

impl<'a> Arbitrary<'a> for SyncOrderInput {
    fn arbitrary(u: &mut Unstructured<'a>) -> arbitrary::Result<Self> {
        let header = <[u8; HEADER]>::arbitrary(u)?;
        Ok(Self::with_header(header, Vec::<u8>::arbitrary(u)?))
    }

    fn arbitrary_take_rest(mut u: Unstructured<'a>) -> arbitrary::Result<Self> {
        let header = <[u8; HEADER]>::arbitrary(&mut u)?;
        Ok(Self::with_header(header, u.take_rest().to_vec()))
    }

    fn size_hint(_depth: usize) -> (usize, Option<usize>) {
        (HEADER, None)
    }
}

/// The scene an input selects.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FuzzScene {
    /// Synthetic particles ([`Particles::scene`]): count, grid dims, open x faces, seed.
    Particles(usize, [i32; 3], bool, u64),
    /// A built-in rigid-body scene: name, bodies, seed.
    Builtin(&'static str, usize, u64),
    /// A user's own model and states ([`check_model_sync_order`]).
    Custom,
}

impl std::fmt::Display for FuzzScene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FuzzScene::Particles(n, d, open, seed) => write!(
                f,
                "{n} synthetic particles in {}x{}x{} cells{}, seed {seed}",
                d[0],
                d[1],
                d[2],
                if *open { " (open x faces)" } else { "" }
            ),
            FuzzScene::Builtin(name, n, seed) => {
                write!(f, "built-in `{name}` with {n} bodies, seed {seed}")
            }
            FuzzScene::Custom => write!(f, "the caller's model and states"),
        }
    }
}

/// A decoded [`SyncOrderInput`]: what is run.
#[derive(Clone, Debug, PartialEq)]
pub struct SyncOrderCase {
    /// The scene.
    pub scene: FuzzScene,
    /// Steps to commit.
    pub steps: u64,
    /// The kernel configuration.
    pub config: KernelConfig,
    /// The virtual executor's options (for an input: schedule `Bytes(input.schedule)`,
    /// decisions recorded).
    pub options: VirtualOptions,
}

impl SyncOrderInput {
    /// Decodes fuzz bytes exactly as `libfuzzer_sys::fuzz_target!` does for a structured
    /// input: `None` (the input is rejected) if `bytes` is shorter than the lower size
    /// hint, else `Arbitrary::arbitrary_take_rest(Unstructured::new(bytes))`.
    pub fn from_fuzz_bytes(bytes: &[u8]) -> Option<Self> {
        if bytes.len() < <Self as Arbitrary>::size_hint(0).0 {
            return None;
        }
        Self::arbitrary_take_rest(Unstructured::new(bytes)).ok()
    }

    /// Encodes this input as fuzz bytes that [`SyncOrderInput::from_fuzz_bytes`] decodes
    /// back to it (to write seed files).
    pub fn to_fuzz_bytes(&self) -> Vec<u8> {
        let mut v = vec![
            self.scene,
            self.size,
            self.dims,
            self.seed,
            self.worlds,
            self.mode,
            self.window,
            self.partition,
            self.partition_seed,
            self.steps,
        ];
        v.extend_from_slice(&self.schedule);
        v
    }

    /// The run this input selects, with `bug` planted.
    pub fn case(&self, bug: PlantedBug) -> SyncOrderCase {
        let seed = u64::from(self.seed);
        let size = usize::from(self.size);
        let rigid_steps = 5 + u64::from(self.steps) % 16;
        let (scene, steps) = match self.scene % 8 {
            k @ 0..=3 => {
                let d = usize::from(self.dims);
                let dims = [2 + d % 5, 1 + (d / 5) % 4, 1 + (d / 20) % 4].map(|x| x as i32);
                (
                    FuzzScene::Particles(2 + size % 60, dims, k % 2 == 1, seed),
                    5 + u64::from(self.steps) % 26,
                )
            }
            4 | 5 => (
                FuzzScene::Builtin("sparse-gas", 12 + size % 13, seed),
                rigid_steps,
            ),
            6 => (
                FuzzScene::Builtin("falling-cubes", 8 + size % 20, seed),
                rigid_steps,
            ),
            _ => (FuzzScene::Builtin("chain", 4 + size % 7, seed), rigid_steps),
        };
        let mode = [
            RollbackMode::Cell,
            RollbackMode::World,
            RollbackMode::Conservative,
        ][usize::from(self.mode % 3)];
        let partition = [
            PartitionKind::Blocks,
            PartitionKind::KMeans,
            PartitionKind::Random,
        ][usize::from(self.partition % 3)]
        .clone();
        let mut config = KernelConfig::new(1 + usize::from(self.worlds % 8))
            .mode(mode)
            .window(1 + u64::from(self.window % 16))
            .partition(partition)
            .partition_seed(u64::from(self.partition_seed));
        config.planted_bug = bug;
        SyncOrderCase {
            scene,
            steps,
            config,
            options: VirtualOptions::new(ScheduleSpec::Bytes(self.schedule.clone())),
        }
    }
}

/// Runs the input's scene for its steps in the reference executor and in the virtual
/// executor driven by the input's schedule bytes, and compares every committed frame
/// (step, hash, body count, events).
///
/// On a mismatch the error names the first differing step, both hashes, the scene, the
/// configuration and the schedule string that replays the run
/// (`ScheduleSpec::Replay(parse_schedule(..))`, see [`crate::exec::virtual_exec`]).
///
/// # Panics
/// If the kernel itself panics (a locality violation it detects, a deadlock): that is a
/// finding too.
pub fn check_sync_order(input: &SyncOrderInput, bug: PlantedBug) -> Result<(), SyncOrderError> {
    check_case(&input.case(bug))
}

/// [`check_sync_order`] for an explicit case, e.g. one whose schedule was replaced by the
/// replay string of a failure.
pub fn check_case(case: &SyncOrderCase) -> Result<(), SyncOrderError> {
    match case.scene {
        FuzzScene::Particles(n, dims, open, seed) => {
            let (model, grid, bodies) = Particles::scene(n, dims, open, seed);
            compare(model, grid, bodies, case)
        }
        FuzzScene::Builtin(name, n, seed) => {
            let scene = builtin(name, Some(n), seed)
                .unwrap_or_else(|e| panic!("built-in scene {name} with {n} bodies: {e}"));
            compare(scene.model(), scene.grid(), scene.initial_bodies(), case)
        }
        FuzzScene::Custom => Err(SyncOrderError::CustomScene),
    }
}

/// A case of [`FuzzScene::Custom`] from fuzz bytes, for fuzzing the synchronisation order
/// of *any* model ([`check_model_sync_order`]): six header bytes give the kernel
/// configuration and the step count (worlds 1–8, rollback mode, window 1–16, partitioner,
/// partition seed, steps 1–`max_steps`), the rest drive every decision of the virtual
/// executor (its schedule, decisions recorded). `None` if fewer than six bytes.
///
/// A cargo-fuzz target for your own model is then a few lines (see `fuzz/README.md`):
///
/// ```
/// use soda::fuzzing::{check_model_sync_order, fuzz_case};
/// use soda::kernel::synthetic::Particles;
///
/// let data = [3u8, 0, 5, 2, 9, 12, 250, 3, 7, 1];
/// if let Some(case) = fuzz_case(&data, 20) {
///     let (model, grid, initial) = Particles::scene(24, [4, 2, 2], false, 1);
///     check_model_sync_order(model, grid, initial, &case).unwrap();
/// }
/// ```
pub fn fuzz_case(bytes: &[u8], max_steps: u64) -> Option<SyncOrderCase> {
    let [worlds, mode, window, partition, partition_seed, steps] = *bytes.get(..6)? else {
        return None;
    };
    let mode = [
        RollbackMode::Cell,
        RollbackMode::World,
        RollbackMode::Conservative,
    ][usize::from(mode % 3)];
    let partition = [
        PartitionKind::Blocks,
        PartitionKind::KMeans,
        PartitionKind::Random,
    ][usize::from(partition % 3)]
    .clone();
    let config = KernelConfig::new(1 + usize::from(worlds % 8))
        .mode(mode)
        .window(1 + u64::from(window % 16))
        .partition(partition)
        .partition_seed(u64::from(partition_seed));
    Some(SyncOrderCase {
        scene: FuzzScene::Custom,
        steps: 1 + u64::from(steps) % max_steps.max(1),
        config,
        options: VirtualOptions::new(ScheduleSpec::Bytes(bytes[6..].to_vec())),
    })
}

/// Runs `model` from `initial` for `case.steps` steps in the reference executor and in the
/// virtual executor under `case.config` and `case.options` (whose schedule drives the
/// synchronisation order), and compares every committed frame (step, hash, entity count,
/// events); `case.scene` is not looked at (the model and states are these). On a mismatch
/// the error names the first differing step, both hashes, the configuration and the
/// schedule string that replays the run. Works for any model: the public face of the
/// `sync_order` fuzz target.
///
/// # Panics
/// If the kernel itself panics (a locality violation it detects, a deadlock): that is a
/// finding too.
pub fn check_model_sync_order<M: CellModel + Clone>(
    model: M,
    grid: Grid,
    initial: Vec<M::State>,
    case: &SyncOrderCase,
) -> Result<(), SyncOrderError> {
    compare(model, grid, initial, case)
}

fn compare<M: CellModel + Clone>(
    model: M,
    grid: Grid,
    bodies: Vec<M::State>,
    case: &SyncOrderCase,
) -> Result<(), SyncOrderError> {
    let (mut reference, _) = ReferenceRun::new(model.clone(), grid.clone(), bodies.clone());
    let expected: Vec<Frame<M::Event>> = (0..case.steps).map(|_| reference.advance()).collect();
    let (mut run, _) = VirtualRun::new(model, grid, bodies, &case.config, &case.options);
    let frames = run.run(case.steps);
    let c = &case.config;
    let case_text = format!(
        "scene: {}, {} steps\nconfig: {} worlds, mode {}, window {}, partition {:?} \
         (seed {}), planted bug {:?}",
        case.scene,
        case.steps,
        c.worlds,
        c.mode,
        c.window,
        c.partition,
        c.partition_seed,
        c.planted_bug,
    );
    if frames.len() != expected.len() {
        return Err(SyncOrderError::FrameCount {
            committed: frames.len(),
            expected: expected.len(),
            case: case_text,
            schedule: run.schedule_string(),
        });
    }
    match frames.iter().zip(&expected).find(|(a, b)| a != b) {
        None => Ok(()),
        Some((a, b)) => Err(SyncOrderError::Diverged {
            step: b.step,
            kernel: FrameSummary::of(a),
            reference: FrameSummary::of(b),
            case: case_text,
            schedule: run.schedule_string(),
        }),
    }
}

/// Why a synchronisation-order check failed ([`check_sync_order`], [`check_case`],
/// [`check_model_sync_order`]). The messages of a failed comparison end with the case and
/// the schedule string that replays it.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SyncOrderError {
    /// [`check_case`] was given a [`FuzzScene::Custom`] case, whose model it does not hold.
    #[error("a custom scene is checked with check_model_sync_order, which holds the model")]
    CustomScene,
    /// The virtual executor committed another number of frames than the reference.
    #[error(
        "{committed} committed frames, expected {expected}\n{case}\nreplay with \
         ScheduleSpec::Replay(parse_schedule(..)): {schedule}"
    )]
    FrameCount {
        /// Frames the virtual executor committed.
        committed: usize,
        /// Frames the reference committed.
        expected: usize,
        /// The scene, steps and configuration.
        case: String,
        /// The schedule string that replays the run.
        schedule: String,
    },
    /// A committed frame differs from the reference's.
    #[error(
        "first divergence at step {step}: kernel hash {kernel} vs reference {reference}\n{case}\n\
         replay with ScheduleSpec::Replay(parse_schedule(..)): {schedule}"
    )]
    Diverged {
        /// The first step whose frames differ.
        step: Step,
        /// The virtual executor's frame there.
        kernel: FrameSummary,
        /// The reference's frame there.
        reference: FrameSummary,
        /// The scene, steps and configuration.
        case: String,
        /// The schedule string that replays the run.
        schedule: String,
    },
}

impl SyncOrderError {
    /// The schedule string that replays the failed run (`parse_schedule` reads it), if the
    /// check ran.
    pub fn schedule(&self) -> Option<&str> {
        match self {
            Self::CustomScene => None,
            Self::FrameCount { schedule, .. } | Self::Diverged { schedule, .. } => Some(schedule),
        }
    }
}

/// What [`SyncOrderError::Diverged`] shows of a frame: written as its hash (16 hex digits)
/// and its body and event counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameSummary {
    /// The frame's hash.
    pub hash: u64,
    /// Its number of bodies.
    pub bodies: usize,
    /// Its number of events.
    pub events: usize,
}

impl FrameSummary {
    fn of<E>(frame: &Frame<E>) -> Self {
        FrameSummary {
            hash: frame.hash,
            bodies: frame.bodies,
            events: frame.events.len(),
        }
    }
}

impl std::fmt::Display for FrameSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:016x} ({} bodies, {} events)",
            self.hash, self.bodies, self.events
        )
    }
}

/// Largest accepted scene [`check_scene_file`] still simulates: bodies.
pub const SIMULATE_MAX_BODIES: usize = 24;
/// Largest accepted scene [`check_scene_file`] still simulates: grid cells.
pub const SIMULATE_MAX_CELLS: usize = 20_000;
/// Largest accepted scene [`check_scene_file`] still simulates: solver substeps × sweeps
/// (the default is 20).
pub const SIMULATE_MAX_ITERATIONS: u32 = 200;

/// What [`check_scene_file`] found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SceneFileOutcome {
    /// The bytes were valid UTF-8.
    pub utf8: bool,
    /// The text parsed and validated as a TOML scene.
    pub toml: bool,
    /// The text parsed and validated as a JSON scene.
    pub json: bool,
    /// An accepted scene was small enough to be stepped (twice) in the reference executor.
    pub simulated: bool,
}

/// Feeds `bytes` (as UTF-8, invalid sequences replaced) to the scene file parser and
/// validator as TOML and as JSON. It must never panic. Each accepted scene must be written
/// back by [`SceneFormat::render`] to a text that parses to an equal scene (in both
/// formats; TOML may refuse a scene without ground), and an accepted scene with at most
/// [`SIMULATE_MAX_BODIES`] bodies, [`SIMULATE_MAX_CELLS`] cells and
/// [`SIMULATE_MAX_ITERATIONS`] solver iterations is stepped twice in the reference executor.
///
/// # Panics
/// On a violation: a panic inside soda, or a round trip that changes the scene.
pub fn check_scene_file(bytes: &[u8]) -> SceneFileOutcome {
    let text = String::from_utf8_lossy(bytes);
    let mut outcome = SceneFileOutcome {
        utf8: std::str::from_utf8(bytes).is_ok(),
        ..SceneFileOutcome::default()
    };
    for format in [SceneFormat::Toml, SceneFormat::Json] {
        let Ok(scene) = parse_scene(&text, format, "fuzz input") else {
            continue;
        };
        match format {
            SceneFormat::Toml => outcome.toml = true,
            SceneFormat::Json => outcome.json = true,
        }
        round_trip(&scene);
        if small(&scene) {
            let (mut run, _) =
                ReferenceRun::new(scene.model(), scene.grid(), scene.initial_bodies());
            run.advance();
            run.advance();
            outcome.simulated = true;
        }
    }
    outcome
}

/// Whether an accepted scene is cheap enough to simulate inside a fuzz iteration.
fn small(scene: &Scene) -> bool {
    scene.bodies.len() <= SIMULATE_MAX_BODIES
        && scene.grid().cell_count() <= SIMULATE_MAX_CELLS
        && scene.solver.substeps.saturating_mul(scene.solver.sweeps) <= SIMULATE_MAX_ITERATIONS
}

/// Writes `scene` in both formats and reads it back: the same scene (or, for TOML, the
/// documented refusal of a scene without ground).
fn round_trip(scene: &Scene) {
    for format in [SceneFormat::Toml, SceneFormat::Json] {
        let text = match format.render(scene) {
            Ok(t) => t,
            Err(e) => {
                assert!(
                    format == SceneFormat::Toml && scene.environment.ground.is_none(),
                    "an accepted scene could not be written as {format:?}: {e}\nscene: {scene:?}"
                );
                continue;
            }
        };
        match parse_scene(&text, format, "round trip") {
            Ok(back) => assert!(
                back == *scene,
                "{format:?} round trip changed the scene\nbefore: {scene:?}\nafter:  {back:?}\ntext:\n{text}"
            ),
            Err(e) => panic!(
                "an accepted scene written as {format:?} does not read back: {e}\ntext:\n{text}"
            ),
        }
    }
}
