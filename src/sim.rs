//! The user-facing simulation: a scene run by an executor (reference, virtual or threaded,
//! [`run_scene`]), with physics measurements of the state (energy, speed, exact
//! penetration) for summaries.

use crate::exec::reference::ReferenceRun;
use crate::exec::sync::StdFacade;
use crate::exec::threaded::{run_threaded_with, ExecError, ThreadTimes};
use crate::exec::virtual_exec::VirtualRun;
use crate::frame::{Event, EventKind, Frame, StatesWanted};
use crate::grid::Grid;
use crate::hash::hex;
use crate::kernel::{Counters, KernelConfig, RunTrace};
use crate::physics::metrics::{
    environment_penetration, kinetic_energy, max_speed, pair_penetration, potential_energy,
};
use crate::physics::{Body, RigidBodyModel};
use crate::scene::Scene;
use crate::state::CellStates;
use serde::Serialize;
use std::time::Instant;

/// Physics measurements of one state (never fed back into the simulation).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StateReport {
    /// Step of the state.
    pub step: u64,
    /// Number of bodies.
    pub bodies: usize,
    /// Canonical hash, 16 hex digits.
    pub hash: String,
    /// Total kinetic energy, J.
    pub kinetic_energy: f64,
    /// Total potential energy (height 0 as reference), J.
    pub potential_energy: f64,
    /// Largest linear speed, m/s.
    pub max_speed: f32,
    /// Largest exact penetration between two bodies or a body and static geometry, m
    /// (parry's contact query).
    pub max_penetration: f32,
    /// Lowest body centre height, m.
    pub min_height: f32,
    /// Highest body centre height, m.
    pub max_height: f32,
}

/// Measures the current state of a reference run.
pub fn measure(run: &ReferenceRun<RigidBodyModel>) -> StateReport {
    measure_state(run.step_number(), run.state(), run.grid(), run.model())
}

/// Measures the state `state` of step `step`.
pub fn measure_state(
    step: u64,
    state: &CellStates<Body>,
    grid: &Grid,
    model: &RigidBodyModel,
) -> StateReport {
    let sorted: Vec<&Body> = state.sorted::<RigidBodyModel>();
    let mut pen = 0.0f32;
    for b in &sorted {
        pen = pen.max(environment_penetration(b, &model.environment));
    }
    for i in state.occupied() {
        let nb = state.neighbourhood(grid, grid.coord(i));
        for a in nb.own() {
            for b in nb.iter().filter(|b| b.id > a.id) {
                pen = pen.max(pair_penetration(a, b));
            }
        }
    }
    StateReport {
        step,
        bodies: sorted.len(),
        hash: hex(state.hash::<RigidBodyModel>()),
        kinetic_energy: kinetic_energy(sorted.iter().copied()),
        potential_energy: potential_energy(sorted.iter().copied(), model.gravity),
        max_speed: max_speed(sorted.iter().copied()),
        max_penetration: pen,
        min_height: sorted
            .iter()
            .map(|b| b.position.y)
            .fold(f32::INFINITY, f32::min),
        max_height: sorted
            .iter()
            .map(|b| b.position.y)
            .fold(f32::NEG_INFINITY, f32::max),
    }
}

/// What a finished run reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RunReport {
    /// Scene name.
    pub scene: String,
    /// Executor used.
    pub executor: String,
    /// Steps computed.
    pub steps: u64,
    /// Seconds per step.
    pub dt: f32,
    /// Cell edge, m.
    pub cell_edge: f32,
    /// Grid dimensions.
    pub grid: [i32; 3],
    /// Wall time of the stepping, s.
    pub wall_seconds: f64,
    /// Steps per wall-clock second.
    pub steps_per_second: f64,
    /// Body-steps per wall-clock second.
    pub body_steps_per_second: f64,
    /// Final hash (16 hex digits).
    pub hash: String,
    /// Events by kind over the run.
    pub speed_capped_events: usize,
    /// Bodies removed for leaving the domain.
    pub left_domain_events: usize,
    /// Measurements of the final state.
    pub last: StateReport,
    /// The Time Warp side of the run (virtual and threaded executors only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kernel: Option<KernelReport>,
    /// The run trace, when `options.kernel.trace` was on (virtual and threaded executors);
    /// written separately (`soda run --trace`), never part of the report's JSON.
    #[serde(skip)]
    pub trace: Option<RunTrace>,
}

/// Which executor runs a scene (DESIGN.md §5): all three commit the same bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ExecutorKind {
    /// One thread, no worlds: the oracle.
    #[default]
    Reference,
    /// One thread runs the worlds under a seeded, replayable schedule.
    Virtual,
    /// OS threads run the worlds as tasks, the laggard (at equal step the heaviest) first.
    Threaded,
}

impl ExecutorKind {
    /// Parses `reference`, `virtual` or `threaded`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "reference" => Some(Self::Reference),
            "virtual" => Some(Self::Virtual),
            "threaded" => Some(Self::Threaded),
            _ => None,
        }
    }

    /// The name [`parse`](Self::parse) accepts.
    pub fn name(self) -> &'static str {
        match self {
            Self::Reference => "reference",
            Self::Virtual => "virtual",
            Self::Threaded => "threaded",
        }
    }
}

/// How to run a scene: the executor, the kernel configuration (ignored by the reference)
/// and the thread count (threaded executor only).
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// The executor.
    pub executor: ExecutorKind,
    /// Worlds, mode, window, partition, schedule.
    pub kernel: KernelConfig,
    /// OS threads of the threaded executor (at least 1).
    pub threads: usize,
}

/// The kernel's statistics of a virtual or threaded run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct KernelReport {
    /// Worlds (logical processes).
    pub worlds: usize,
    /// OS threads (1 for the virtual executor).
    pub threads: usize,
    /// Rollback mode.
    pub mode: crate::kernel::RollbackMode,
    /// Optimism window.
    pub window: u64,
    /// Partitioner.
    pub partition: crate::kernel::PartitionKind,
    /// The virtual executor's schedule as a replay string (`None` for threaded runs, which
    /// are not replayable, or when recording was off).
    pub schedule: Option<String>,
    /// `cells_committed / cells_computed` over all worlds.
    pub efficiency: f64,
    /// Counters per world and in total.
    pub counters: Counters,
    /// Busy, GVT and idle time of the threads (threaded executor only).
    pub thread_times: Option<ThreadTimes>,
    /// Load balancing configuration.
    pub balance: crate::kernel::BalanceConfig,
    /// The balancing rounds: step, loads, imbalance, cells moved, famines (owner maps are
    /// kept in memory for charts, not written to JSON).
    pub balance_rounds: Vec<crate::kernel::RoundRecord>,
}

/// Runs `scene` for `steps` steps on the executor `options` names, handing every committed
/// frame, in step order, to `sink`, with the committed states (sorted by id) of the steps
/// `wanted` asks for. Returns the report, whose `last` measures the final state.
pub fn run_scene(
    scene: &Scene,
    options: &RunOptions,
    steps: u64,
    wanted: &StatesWanted,
    mut sink: impl FnMut(&Frame, Option<&[&Body]>),
) -> Result<RunReport, ExecError> {
    let model = scene.model();
    let grid = scene.grid();
    let mut want = wanted.clone();
    let last_step = steps;
    let mut final_states: Option<Vec<Body>> = None;
    let mut capped = 0;
    let mut left = 0;
    let mut body_steps = 0u64;
    let mut prev_bodies = scene
        .bodies
        .iter()
        .filter(|b| grid.cell_of(b.position).is_some())
        .count();
    let initial_events;
    let mut trace = None;
    let start = Instant::now();
    let mut on_frame = |f: &Frame, states: Option<&[&Body]>| {
        for e in &f.events {
            match e.kind {
                EventKind::SpeedCapped => capped += 1,
                EventKind::LeftDomain => left += 1,
            }
        }
        body_steps += prev_bodies as u64;
        prev_bodies = f.bodies;
        if f.step == last_step {
            final_states = states.map(|s| s.iter().map(|b| (*b).clone()).collect());
        }
        let user_wants = wanted.wants(f.step, f.hash);
        sink(f, if user_wants { states } else { None });
    };
    let kernel = match options.executor {
        ExecutorKind::Reference => {
            let (mut run, events) =
                ReferenceRun::new(model.clone(), grid.clone(), scene.initial_bodies());
            initial_events = events;
            for _ in 0..steps {
                let f = run.advance();
                if want.wants(f.step, f.hash) || f.step == last_step {
                    let sorted = run.state().sorted::<RigidBodyModel>();
                    on_frame(&f, Some(&sorted));
                } else {
                    on_frame(&f, None);
                }
            }
            None
        }
        ExecutorKind::Virtual => {
            want.step = Some(last_step);
            let (mut run, events) = VirtualRun::new(
                model.clone(),
                grid.clone(),
                scene.initial_bodies(),
                &options.kernel,
            );
            initial_events = events;
            run.run_with_states(steps, &want, |f, s| on_frame(&f, s));
            let counters = run.counters();
            if options.kernel.trace {
                trace = Some(run.take_trace());
            }
            Some(kernel_report(
                options,
                1,
                options
                    .kernel
                    .record_schedule
                    .then(|| run.schedule_string()),
                counters,
                None,
                run.balance_history().to_vec(),
            ))
        }
        ExecutorKind::Threaded => {
            want.step = Some(last_step);
            let report = run_threaded_with::<RigidBodyModel, StdFacade>(
                model.clone(),
                grid.clone(),
                scene.initial_bodies(),
                &options.kernel,
                options.threads.max(1),
                steps,
                want,
                &mut on_frame,
            )?;
            initial_events = report.initial_events;
            trace = report.trace;
            Some(kernel_report(
                options,
                report.threads,
                None,
                report.counters,
                Some(report.times),
                report.balance,
            ))
        }
    };
    let wall = start.elapsed().as_secs_f64();
    left += initial_events
        .iter()
        .filter(|e| e.kind == EventKind::LeftDomain)
        .count();
    let mut ignored = Vec::new();
    let final_state = match final_states {
        Some(bodies) => {
            CellStates::binned::<RigidBodyModel>(&grid, bodies, last_step, &mut ignored)
        }
        None => {
            CellStates::binned::<RigidBodyModel>(&grid, scene.initial_bodies(), 0, &mut ignored)
        }
    };
    let last = measure_state(last_step, &final_state, &grid, &model);
    Ok(RunReport {
        scene: scene.name.clone(),
        executor: options.executor.name().into(),
        steps,
        dt: scene.dt,
        cell_edge: grid.edge,
        grid: grid.dims,
        wall_seconds: wall,
        steps_per_second: steps as f64 / wall.max(1e-9),
        body_steps_per_second: body_steps as f64 / wall.max(1e-9),
        hash: last.hash.clone(),
        speed_capped_events: capped,
        left_domain_events: left,
        last,
        kernel,
        trace,
    })
}

fn kernel_report(
    options: &RunOptions,
    threads: usize,
    schedule: Option<String>,
    counters: Counters,
    thread_times: Option<ThreadTimes>,
    balance_rounds: Vec<crate::kernel::RoundRecord>,
) -> KernelReport {
    KernelReport {
        worlds: counters.worlds.len(),
        threads,
        mode: options.kernel.mode,
        window: options.kernel.window,
        partition: options.kernel.partition.clone(),
        schedule,
        efficiency: counters.total.efficiency(),
        counters,
        thread_times,
        balance: options.kernel.balance.clone(),
        balance_rounds,
    }
}

/// A scene ready to run in the reference executor.
pub struct Simulation {
    scene: Scene,
    run: ReferenceRun<RigidBodyModel>,
    initial_events: Vec<Event>,
}

impl Simulation {
    /// Prepares a (validated) scene.
    pub fn new(scene: Scene) -> Self {
        let (run, initial_events) =
            ReferenceRun::new(scene.model(), scene.grid(), scene.initial_bodies());
        Simulation {
            scene,
            run,
            initial_events,
        }
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The reference run.
    pub fn reference(&self) -> &ReferenceRun<RigidBodyModel> {
        &self.run
    }

    /// The current state.
    pub fn state(&self) -> &CellStates<Body> {
        self.run.state()
    }

    /// Advances one step, returning its committed frame.
    pub fn step(&mut self) -> Frame {
        self.run.advance()
    }

    /// Runs `steps` steps, handing every committed frame to `sink`, and reports.
    pub fn run(
        &mut self,
        steps: u64,
        mut sink: impl FnMut(&Frame, &CellStates<Body>),
    ) -> RunReport {
        let start = Instant::now();
        let first = self.run.step_number();
        let (mut capped, mut left) = (0, 0);
        for e in &self.initial_events {
            left += (e.kind == crate::frame::EventKind::LeftDomain) as usize;
        }
        self.initial_events.clear();
        let mut body_steps = 0u64;
        for _ in 0..steps {
            body_steps += self.run.state().len() as u64;
            let f = self.run.advance();
            for e in &f.events {
                match e.kind {
                    crate::frame::EventKind::SpeedCapped => capped += 1,
                    crate::frame::EventKind::LeftDomain => left += 1,
                }
            }
            sink(&f, self.run.state());
        }
        let wall = start.elapsed().as_secs_f64();
        let last = measure(&self.run);
        let grid = self.run.grid();
        RunReport {
            scene: self.scene.name.clone(),
            executor: "reference".into(),
            steps: self.run.step_number() - first,
            dt: self.scene.dt,
            cell_edge: grid.edge,
            grid: grid.dims,
            wall_seconds: wall,
            steps_per_second: steps as f64 / wall.max(1e-9),
            body_steps_per_second: body_steps as f64 / wall.max(1e-9),
            hash: last.hash.clone(),
            speed_capped_events: capped,
            left_domain_events: left,
            last,
            kernel: None,
            trace: None,
        }
    }
}
