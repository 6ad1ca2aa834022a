//! The rigid-body wrappers over [`Runner`]: a scene run by an executor ([`run_scene`]), the
//! step-by-step reference [`Simulation`], and physics measurements of a state (energy,
//! speed, exact penetration) for summaries.

use super::options::RunOptions;
use super::report::KernelReport;
use super::runner::Runner;
use crate::exec::control::RunControl;
use crate::exec::error::ExecError;
use crate::exec::reference::ReferenceRun;
use crate::frame::{Event, Frame, StatesWanted};
use crate::grid::Grid;
use crate::hash::hex;
use crate::kernel::{Input, RunTrace};
use crate::model::Step;
use crate::physics::metrics::{
    environment_penetration, kinetic_energy, max_speed, pair_penetration, potential_energy,
};
use crate::physics::{Body, EventKind, RigidBodyModel};
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
    let mut walk = state.walk(grid, &[]);
    for i in state.occupied() {
        let nb = walk.at(i);
        for a in nb.own() {
            for b in nb.iter().filter(|b| b.id() > a.id()) {
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

/// Runs `scene` for `steps` steps on the executor `options` names, handing every committed
/// frame, in step order, to `sink`, with the committed states (sorted by id) of the steps
/// `wanted` asks for. Returns the report, whose `last` measures the final state. A thin
/// rigid-body wrapper over [`Runner`].
pub fn run_scene(
    scene: &Scene,
    options: &RunOptions,
    steps: u64,
    wanted: &StatesWanted,
    mut sink: impl FnMut(&Frame<EventKind>, Option<&[&Body]>),
) -> Result<RunReport, ExecError> {
    run_scene_controlled(scene, options, steps, wanted, Vec::new(), |f, s, _| {
        sink(f, s)
    })
}

/// [`run_scene`] with inputs scheduled before the run and a sink that also gets a
/// [`RunControl`] (schedule inputs during the run, or stop it). A stopped run's `last`
/// measures the state of the step it stopped at if `wanted` asked for it, else the initial
/// state (`last.step` says which); its `hash` is the last committed step's.
pub fn run_scene_controlled(
    scene: &Scene,
    options: &RunOptions,
    steps: u64,
    wanted: &StatesWanted,
    inputs: Vec<(Step, Input<Body>)>,
    sink: impl FnMut(&Frame<EventKind>, Option<&[&Body]>, &mut RunControl<'_, Body>),
) -> Result<RunReport, ExecError> {
    run_scene_from(scene, options, None, steps, wanted, inputs, sink)
}

/// Where a resumed scene run starts: the committed bodies of step `step` of an earlier run
/// of the same scene (read from a checkpoint, say).
#[derive(Clone, Debug)]
pub struct ResumeFrom {
    /// The committed step the bodies belong to.
    pub step: Step,
    /// The bodies at that step.
    pub bodies: Vec<Body>,
}

/// [`run_scene_controlled`] from the committed bodies of a later step than 0 (`from`), or
/// from the scene's own bodies (`None`): runs the steps `from.step + 1 ..= from.step +
/// steps`, which commit the uninterrupted run's bits on any executor (the scene supplies the
/// model and the grid; [`Runner::start_at`]). Frames, `wanted` and inputs name global steps.
pub fn run_scene_from(
    scene: &Scene,
    options: &RunOptions,
    from: Option<ResumeFrom>,
    steps: u64,
    wanted: &StatesWanted,
    inputs: Vec<(Step, Input<Body>)>,
    mut sink: impl FnMut(&Frame<EventKind>, Option<&[&Body]>, &mut RunControl<'_, Body>),
) -> Result<RunReport, ExecError> {
    let model = scene.model();
    let grid = scene.grid();
    // The run takes the starting bodies; a copy is kept only when they cannot be built
    // again (resumed from given bodies): a million bodies' copy is 68 MB.
    let resumed = from.is_some();
    let ResumeFrom {
        step: origin,
        bodies: initial,
    } = from.unwrap_or_else(|| ResumeFrom {
        step: 0,
        bodies: scene.initial_bodies(),
    });
    let given = resumed.then(|| initial.clone());
    let last_step = origin + steps;
    let mut want = wanted.clone();
    want.step = Some(last_step);
    let mut latest: Option<(Step, Vec<Body>)> = None;
    let report = Runner::new(model.clone(), grid.clone(), initial)
        .options(options.clone())
        .start_at(origin)
        .inputs(inputs)
        .states(want)
        .run(steps, |f, states, control| {
            let user_wants = wanted.wants(f.step, f.hash);
            sink(f, if user_wants { states } else { None }, control);
            // Only the state the report measures is copied: the last step's, or the step
            // the sink stopped at (if its states were handed over).
            if f.step == last_step || control.stopped() {
                if let Some(s) = states {
                    latest = Some((f.step, s.iter().map(|b| (*b).clone()).collect()));
                }
            }
        })?;
    let mut ignored = Vec::new();
    let (step, bodies) =
        latest.unwrap_or_else(|| (origin, given.unwrap_or_else(|| scene.initial_bodies())));
    let final_state = CellStates::binned::<RigidBodyModel>(&grid, bodies, step, &mut ignored);
    let last = measure_state(step, &final_state, &grid, &model);
    let count = |k: EventKind| report.events.get(k.name()).copied().unwrap_or(0) as usize;
    Ok(RunReport {
        scene: scene.name.clone(),
        executor: report.executor,
        steps: report.steps,
        dt: scene.dt,
        cell_edge: grid.edge,
        grid: grid.dims,
        wall_seconds: report.wall_seconds,
        steps_per_second: report.steps_per_second,
        body_steps_per_second: report.entity_steps_per_second,
        hash: report.hash,
        speed_capped_events: count(EventKind::SpeedCapped),
        left_domain_events: count(EventKind::LeftDomain),
        last,
        kernel: report.kernel,
        trace: report.trace,
    })
}

/// A scene ready to run in the reference executor.
pub struct Simulation {
    scene: Scene,
    run: ReferenceRun<RigidBodyModel>,
    initial_events: Vec<Event<EventKind>>,
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
    pub fn step(&mut self) -> Frame<EventKind> {
        self.run.advance()
    }

    /// Runs `steps` steps, handing every committed frame to `sink`, and reports.
    pub fn run(
        &mut self,
        steps: u64,
        mut sink: impl FnMut(&Frame<EventKind>, &CellStates<Body>),
    ) -> RunReport {
        let start = Instant::now();
        let first = self.run.step_number();
        let (mut capped, mut left) = (0, 0);
        for e in &self.initial_events {
            left += (e.kind == EventKind::LeftDomain) as usize;
        }
        self.initial_events.clear();
        let mut body_steps = 0u64;
        for _ in 0..steps {
            body_steps += self.run.state().len() as u64;
            let f = self.run.advance();
            for e in &f.events {
                match e.kind {
                    EventKind::SpeedCapped => capped += 1,
                    EventKind::LeftDomain => left += 1,
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
