//! What a threaded run starts from ([`ThreadedSetup`]) and how it runs ([`ThreadedOptions`]).

use crate::frame::StatesWanted;
use crate::grid::Grid;
use crate::kernel::message::Input;
use crate::kernel::KernelConfig;
use crate::model::{CellModel, Step};

/// How a threaded run runs: the kernel configuration, the threads, the steps to commit and
/// the committed states its sink wants.
#[derive(Clone, Debug)]
pub struct ThreadedOptions<'a> {
    /// The kernel configuration (worlds, mode, window, balancing, …).
    pub config: &'a KernelConfig,
    /// The number of OS threads (at least 1 is used).
    pub threads: usize,
    /// The number of steps to commit.
    pub steps: u64,
    /// The steps whose committed states (sorted by id) the sink gets.
    pub wanted: StatesWanted,
    /// Optimistic modes: how many steps a world may compute ahead of the slowest of its
    /// neighbour worlds before it lets laggards run first (SPEC.md §10). 0 runs the worlds
    /// nearly in lockstep (few rollbacks); more lets a world speculate past a slower
    /// neighbour, up to the window. Pacing only: the committed bits never depend on it.
    pub lead: u64,
    /// Whether a postponed world computes its interior ahead (SPEC.md §K5 item 4, §10; on
    /// by default). Pacing only: the committed bits never depend on it.
    pub compute_ahead: bool,
}

impl<'a> ThreadedOptions<'a> {
    /// `steps` steps on `threads` threads under `config`, no states wanted.
    pub fn new(config: &'a KernelConfig, threads: usize, steps: u64) -> Self {
        ThreadedOptions {
            config,
            threads,
            steps,
            wanted: StatesWanted::none(),
            lead: 0,
            compute_ahead: true,
        }
    }

    /// The same options with computing ahead on or off (see
    /// [`ThreadedOptions::compute_ahead`]).
    pub fn compute_ahead(mut self, on: bool) -> Self {
        self.compute_ahead = on;
        self
    }

    /// The same options with the laggard lead `lead` (see [`ThreadedOptions::lead`]).
    pub fn lead(mut self, lead: u64) -> Self {
        self.lead = lead;
        self
    }

    /// The same options, handing the sink the committed states of the steps `wanted` asks
    /// for.
    pub fn wanted(mut self, wanted: StatesWanted) -> Self {
        self.wanted = wanted;
        self
    }
}

/// What a threaded run starts from: the model, the grid, the initial states and the inputs
/// scripted before the run (step, input), applied in this order at each step.
pub struct ThreadedSetup<M: CellModel> {
    /// The model.
    pub model: M,
    /// The grid.
    pub grid: Grid,
    /// The states at step 0.
    pub initial: Vec<M::State>,
    /// Inputs scheduled before the run starts.
    pub inputs: Vec<(Step, Input<M::State>)>,
    /// Whether the report keeps every committed frame (`ThreadedReport::frames`; about 50
    /// bytes per step, so a long run that hands frames to a sink should not).
    pub keep_frames: bool,
}

impl<M: CellModel> ThreadedSetup<M> {
    /// `model` on `grid` from `initial`, no scripted inputs, every frame kept.
    pub fn new(model: M, grid: Grid, initial: Vec<M::State>) -> Self {
        ThreadedSetup {
            model,
            grid,
            initial,
            inputs: Vec::new(),
            keep_frames: true,
        }
    }
}
