//! One generic way to run any [`CellModel`] on any executor: [`Runner`] (and the shorthand
//! [`run_model`]) returns one [`ModelReport`] or one [`ExecError`] whichever executor runs.

use super::offset::Offset;
use super::options::{ExecutorKind, RunOptions};
use super::report::{KernelReport, ModelReport};
use crate::exec::control::RunControl;
use crate::exec::error::{ExecError, InputError};
use crate::exec::reference::ReferenceRun;
use crate::exec::sync::StdFacade;
use crate::exec::threaded::{run_threaded_controlled, ThreadTimes, ThreadedOptions, ThreadedSetup};
use crate::exec::virtual_exec::VirtualRun;
use crate::frame::{Event, Frame, StatesWanted};
use crate::grid::Grid;
use crate::hash::hex;
use crate::kernel::{Counters, Input, RoundRecord};
use crate::model::{CellModel, Step};
use crate::state::CellStates;
use std::collections::BTreeMap;
use std::time::Instant;

/// A run of a model, configured step by step, then [`run`](Self::run):
///
/// ```
/// use soda::prelude::*;
/// use soda::kernel::synthetic::Particles;
///
/// let (model, grid, initial) = Particles::scene(40, [4, 2, 2], false, 7);
/// let reference = Runner::new(model.clone(), grid.clone(), initial.clone()).run_quiet(20)?;
/// let threaded = Runner::new(model, grid, initial)
///     .options(RunOptions::threaded(KernelConfig::new(4), 2))
///     .run_quiet(20)?;
/// assert_eq!(reference.hash, threaded.hash);
/// # Ok::<(), soda::ExecError>(())
/// ```
pub struct Runner<M: CellModel> {
    model: M,
    grid: Grid,
    initial: Vec<M::State>,
    inputs: Vec<(Step, Input<M::State>)>,
    options: RunOptions,
    wanted: StatesWanted,
    check_contract: bool,
    origin: Step,
}

impl<M: CellModel + 'static> Runner<M> {
    /// A run of `model` over `grid` from the states `initial` at step 0, on the reference
    /// executor unless [`options`](Self::options) say otherwise.
    pub fn new(model: M, grid: Grid, initial: Vec<M::State>) -> Self {
        Runner {
            model,
            grid,
            initial,
            inputs: Vec::new(),
            options: RunOptions::default(),
            wanted: StatesWanted::none(),
            check_contract: false,
            origin: 0,
        }
    }

    /// Starts from states that are those of step `step` (not 0): the model sees the steps
    /// `step, step + 1, …`, frames and events carry them, and inputs name them — so a run
    /// resumed from the committed states of step `step` of an earlier run (saved, say, by a
    /// sink that asked for them) commits that run's bits from there, on any executor.
    pub fn start_at(mut self, step: Step) -> Self {
        self.origin = step;
        self
    }

    /// The executor, kernel configuration and threads.
    pub fn options(mut self, options: RunOptions) -> Self {
        self.options = options;
        self
    }

    /// Schedules an input at `step` before the run starts (applied at that step, after the
    /// inputs scheduled before it; SPEC.md §K12).
    pub fn input(mut self, step: Step, input: Input<M::State>) -> Self {
        self.inputs.push((step, input));
        self
    }

    /// Schedules every `(step, input)` of `inputs` ([`input`](Self::input)).
    pub fn inputs(mut self, inputs: impl IntoIterator<Item = (Step, Input<M::State>)>) -> Self {
        self.inputs.extend(inputs);
        self
    }

    /// The committed steps whose full states the sink receives (others: frames only).
    pub fn states(mut self, wanted: StatesWanted) -> Self {
        self.wanted = wanted;
        self
    }

    /// Runs the contract checker ([`crate::exec::contract`]) on every step (reference
    /// executor only; about twice the reference's cost).
    pub fn check_contract(mut self, on: bool) -> Self {
        self.check_contract = on;
        self
    }

    /// Runs `steps` steps without looking at the frames.
    pub fn run_quiet(self, steps: u64) -> Result<ModelReport, ExecError> {
        self.run(steps, |_, _, _| {})
    }

    /// Runs `steps` steps, handing every committed frame in step order to `sink` with the
    /// committed states (sorted by id) of the steps [`states`](Self::states) asks for, and a
    /// [`RunControl`] to schedule inputs or stop the run.
    pub fn run(
        self,
        steps: u64,
        mut sink: impl FnMut(&Frame<M::Event>, Option<&[&M::State]>, &mut RunControl<'_, M::State>),
    ) -> Result<ModelReport, ExecError> {
        if self.origin == 0 {
            return self.run_from_zero(steps, sink);
        }
        let origin = self.origin;
        let mut inputs = Vec::with_capacity(self.inputs.len());
        for (step, input) in self.inputs {
            if step <= origin {
                return Err(InputError::TooLate {
                    step,
                    earliest: origin + 1,
                }
                .into());
            }
            inputs.push((step - origin, input));
        }
        let asked = self.wanted.clone();
        let shifted = Runner {
            model: Offset {
                inner: self.model,
                origin,
            },
            grid: self.grid,
            initial: self.initial,
            inputs,
            options: self.options,
            wanted: shift_wanted(self.wanted, origin),
            check_contract: self.check_contract,
            origin: 0,
        };
        let mut report = shifted.run_from_zero(steps, |f, states, control| {
            let mut frame = f.clone();
            frame.step += origin;
            for e in &mut frame.events {
                e.step += origin;
            }
            let earliest = control.earliest_input_step() + origin;
            let mut post = |step: Step, input: Input<M::State>| {
                if step <= origin {
                    return Err(InputError::TooLate { step, earliest });
                }
                control.input(step - origin, input)
            };
            let mut global = RunControl::new(earliest, &mut post);
            let states = states.filter(|_| asked.wants(frame.step, frame.hash));
            sink(&frame, states, &mut global);
            if global.stopped() {
                control.stop();
            }
        })?;
        report.stopped_at = report.stopped_at.map(|s| s + origin);
        Ok(report)
    }

    /// [`run`](Self::run) from step 0.
    fn run_from_zero(
        self,
        steps: u64,
        mut sink: impl FnMut(&Frame<M::Event>, Option<&[&M::State]>, &mut RunControl<'_, M::State>),
    ) -> Result<ModelReport, ExecError> {
        let Runner {
            model,
            grid,
            initial,
            inputs,
            options,
            wanted,
            check_contract,
            origin: _,
        } = self;
        let mut tally = Tally::<M>::new(&grid, &initial);
        let start = Instant::now();
        let mut on_frame =
            |f: &Frame<M::Event>, s: Option<&[&M::State]>, c: &mut RunControl<'_, M::State>| {
                tally.frame(f);
                sink(f, s, c);
                if c.stopped() {
                    tally.stopped = true;
                }
            };
        let (kernel, initial_events, trace) = match options.executor {
            ExecutorKind::Reference => {
                let (mut run, events) = ReferenceRun::new(model, grid, initial);
                for (step, input) in inputs {
                    run.add_input(step, input)?;
                }
                run.check_contract(check_contract)?;
                for _ in 0..steps {
                    let f = run.try_advance()?;
                    let floor = run.step_number() + 1;
                    let mut pending = Vec::new();
                    let run_grid = run.grid().clone();
                    let mut post = |step: Step, input: Input<M::State>| {
                        crate::exec::check_input::<M>(&run_grid, floor, step, &input)?;
                        pending.push((step, input));
                        Ok(())
                    };
                    let mut control = RunControl::new(floor, &mut post);
                    if wanted.wants(f.step, f.hash) {
                        let sorted = run.state().sorted::<M>();
                        on_frame(&f, Some(&sorted), &mut control);
                    } else {
                        on_frame(&f, None, &mut control);
                    }
                    let stop = control.stopped();
                    for (step, input) in pending {
                        run.add_input(step, input)?;
                    }
                    if stop {
                        break;
                    }
                }
                (None, events, None)
            }
            ExecutorKind::Virtual => {
                let (mut run, events) = VirtualRun::new(
                    model,
                    grid,
                    initial,
                    &options.kernel,
                    &options.virtual_options(),
                );
                for (step, input) in inputs {
                    run.try_add_input(step, input)?;
                }
                run.run_controlled(steps, &wanted, |f, s, c| on_frame(&f, s, c))?;
                let trace = options.kernel.trace.then(|| run.take_trace());
                let kernel = kernel_report(
                    &options,
                    1,
                    options.record_schedule.then(|| run.schedule_string()),
                    run.counters(),
                    None,
                    run.balance_history().to_vec(),
                );
                (Some(kernel), events, trace)
            }
            ExecutorKind::Threaded => {
                let report = run_threaded_controlled::<M, StdFacade>(
                    ThreadedSetup {
                        model,
                        grid,
                        initial,
                        inputs,
                        keep_frames: false,
                    },
                    &ThreadedOptions::new(&options.kernel, options.threads.max(1), steps)
                        .lead(options.lead)
                        .wanted(wanted),
                    &mut on_frame,
                )?;
                let kernel = kernel_report(
                    &options,
                    report.threads,
                    None,
                    report.counters,
                    Some(report.times),
                    report.balance,
                );
                (Some(kernel), report.initial_events, report.trace)
            }
            ExecutorKind::Mpi => run_on_mpi(
                MpiStart {
                    model,
                    grid,
                    initial,
                    inputs,
                },
                &options,
                steps,
                wanted,
                &mut on_frame,
            )?,
        };
        let wall = start.elapsed().as_secs_f64();
        Ok(tally.report(&options, wall, &initial_events, kernel, trace))
    }
}

/// The steps `wanted` names (global) as the shifted run's local steps.
fn shift_wanted(mut wanted: StatesWanted, origin: Step) -> StatesWanted {
    wanted.step = wanted.step.and_then(|s| s.checked_sub(origin));
    if wanted.every > 0 {
        // Local step `t` is global `t + origin`: it is wanted when `(t + origin) % every == 0`,
        // which a local `every` can say only when `origin` is a multiple of it.
        if origin % wanted.every != 0 {
            wanted.every = 1;
        }
    }
    if let Some(expected) = &wanted.unexpected {
        let local: Vec<u64> = expected.iter().skip(origin as usize).copied().collect();
        wanted.unexpected = Some(std::sync::Arc::new(local));
    }
    wanted
}

/// Runs `model` from `initial` for `steps` steps with `options`, handing every committed
/// frame to `sink` ([`Runner::run`]).
pub fn run_model<M: CellModel + 'static>(
    model: M,
    grid: Grid,
    initial: Vec<M::State>,
    options: &RunOptions,
    steps: u64,
    sink: impl FnMut(&Frame<M::Event>, Option<&[&M::State]>, &mut RunControl<'_, M::State>),
) -> Result<ModelReport, ExecError> {
    Runner::new(model, grid, initial)
        .options(options.clone())
        .run(steps, sink)
}

/// What the runner counts from the frames as they pass.
struct Tally<M: CellModel> {
    /// Entities at the previous committed step.
    previous: usize,
    entity_steps: u64,
    steps: u64,
    last_step: Step,
    hash: u64,
    entities: usize,
    events: BTreeMap<String, u64>,
    stopped: bool,
    _model: std::marker::PhantomData<M>,
}

impl<M: CellModel> Tally<M> {
    fn new(grid: &Grid, initial: &[M::State]) -> Self {
        let mut ignored = Vec::new();
        let state = CellStates::binned::<M>(grid, initial.to_vec(), 0, &mut ignored);
        Tally {
            previous: state.len(),
            entity_steps: 0,
            steps: 0,
            last_step: 0,
            hash: state.hash::<M>(),
            entities: state.len(),
            events: BTreeMap::new(),
            stopped: false,
            _model: std::marker::PhantomData,
        }
    }

    fn count(&mut self, events: &[Event<M::Event>]) {
        for e in events {
            *self.events.entry(M::event_name(&e.kind)).or_default() += 1;
        }
    }

    fn frame(&mut self, f: &Frame<M::Event>) {
        self.entity_steps += self.previous as u64;
        self.previous = f.bodies;
        self.steps += 1;
        self.last_step = f.step;
        self.hash = f.hash;
        self.entities = f.bodies;
        self.count(&f.events);
    }

    fn report(
        mut self,
        options: &RunOptions,
        wall: f64,
        initial_events: &[Event<M::Event>],
        kernel: Option<KernelReport>,
        trace: Option<crate::kernel::RunTrace>,
    ) -> ModelReport {
        self.count(initial_events);
        ModelReport {
            executor: options.executor.name().into(),
            steps: self.steps,
            stopped_at: self.stopped.then_some(self.last_step),
            wall_seconds: wall,
            steps_per_second: self.steps as f64 / wall.max(1e-9),
            entity_steps_per_second: self.entity_steps as f64 / wall.max(1e-9),
            hash: hex(self.hash),
            entities: self.entities,
            events: self.events,
            kernel,
            trace,
        }
    }
}

fn kernel_report(
    options: &RunOptions,
    threads: usize,
    schedule: Option<String>,
    counters: Counters,
    thread_times: Option<ThreadTimes>,
    balance_rounds: Vec<RoundRecord>,
) -> KernelReport {
    KernelReport {
        worlds: counters.worlds.len(),
        threads,
        mode: options.kernel.mode,
        window: options.kernel.window,
        window_auto: options.kernel.window_auto,
        partition: options.kernel.partition.clone(),
        schedule,
        efficiency: counters.total.efficiency(),
        counters,
        thread_times,
        balance: options.kernel.balance.clone(),
        balance_rounds,
        mpi: None,
    }
}

/// What an executor arm of [`Runner::run`] yields: the kernel's report, the initial events
/// and the trace.
type Ran<E> = (
    Option<KernelReport>,
    Vec<Event<E>>,
    Option<crate::kernel::RunTrace>,
);

/// A frame sink of [`Runner::run`], as the executors take it.
type FrameSink<'a, M> = dyn FnMut(
        &Frame<<M as CellModel>::Event>,
        Option<&[&<M as CellModel>::State]>,
        &mut RunControl<'_, <M as CellModel>::State>,
    ) + 'a;

/// What the MPI executor's arm of [`Runner::run`] starts from (the same on every rank).
/// Without the `mpi` feature the arm only reports that it is not built, reading none of it.
#[cfg_attr(not(feature = "mpi"), allow(dead_code))]
struct MpiStart<M: CellModel> {
    model: M,
    grid: Grid,
    initial: Vec<M::State>,
    inputs: Vec<(Step, Input<M::State>)>,
}

/// The MPI executor's arm of [`Runner::run`] (rank 0's sink sees the frames; the other ranks'
/// reports count none).
#[cfg(feature = "mpi")]
fn run_on_mpi<M: CellModel>(
    start: MpiStart<M>,
    options: &RunOptions,
    steps: u64,
    wanted: StatesWanted,
    sink: &mut FrameSink<'_, M>,
) -> Result<Ran<M::Event>, ExecError> {
    use crate::exec::mpi::{run_mpi_controlled, MpiOptions, MpiSetup};
    let mut mpi_options = MpiOptions::new(&options.kernel, steps);
    mpi_options.wanted = wanted;
    mpi_options.threads = options.threads.max(1);
    let report = run_mpi_controlled(
        MpiSetup {
            model: start.model,
            grid: start.grid,
            initial: start.initial,
            inputs: start.inputs,
        },
        &mpi_options,
        sink,
    )?;
    let mut kernel = kernel_report(
        options,
        mpi_options.threads,
        None,
        report.counters,
        None,
        report.balance,
    );
    kernel.mpi = Some(report.stats);
    Ok((Some(kernel), report.initial_events, None))
}

/// Without the `mpi` feature: the error that says to rebuild with it.
#[cfg(not(feature = "mpi"))]
fn run_on_mpi<M: CellModel>(
    _start: MpiStart<M>,
    _options: &RunOptions,
    _steps: u64,
    _wanted: StatesWanted,
    _sink: &mut FrameSink<'_, M>,
) -> Result<Ran<M::Event>, ExecError> {
    Err(crate::exec::error::MpiError::NotBuilt.into())
}
