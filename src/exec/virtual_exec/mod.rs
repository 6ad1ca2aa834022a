//! The virtual executor: one thread runs N worlds under a scheduler that chooses, at every
//! decision, either a world to act or an in-flight message to deliver — so deliveries are
//! delayed and reordered at will, and an anti-message may overtake its positive twin.
//!
//! The scheduler ([`VirtualOptions::schedule`], an executor setting beside the kernel's
//! [`KernelConfig`]) is a ChaCha8 generator ([`ScheduleSpec::Seeded`]), fuzz bytes
//! ([`ScheduleSpec::Bytes`]), a recorded decision list ([`ScheduleSpec::Replay`]) or the
//! deterministic FIFO fallback. Every decision is an index into the list of enabled actions
//! (the worlds that want to act, ascending, then the in-flight messages in send order); the
//! recorded list prints as a string ([`VirtualRun::schedule_string`]) that replays the run
//! exactly ([`parse_schedule`]).
//!
//! After every decision GVT is recomputed exactly (minimum of the worlds' bounds and of the
//! in-flight messages' `affects` steps); when it advances, the steps below it are committed
//! — every world's states at that step merged and hashed as the reference hashes them —
//! handed to the sink in step order, and the worlds fossil-collect.
//!
//! ```
//! use soda::exec::virtual_exec::{parse_schedule, VirtualOptions, VirtualRun};
//! use soda::kernel::synthetic::Particles;
//! use soda::kernel::{KernelConfig, PartitionKind, RollbackMode};
//!
//! let (model, grid, bodies) = Particles::scene(50, [4, 2, 2], false, 1);
//! let config = KernelConfig::new(4)
//!     .mode(RollbackMode::Cell)
//!     .window(8)
//!     .partition(PartitionKind::Blocks);
//! let options = VirtualOptions::seeded(7);
//! let (mut run, _left_domain) =
//!     VirtualRun::new(model.clone(), grid.clone(), bodies.clone(), &config, &options);
//! let frames = run.run(20); // committed frames 1..=20, hashed like the reference's
//! let counters = run.counters();
//! assert_eq!(frames.len(), 20);
//! assert!(counters.total.efficiency() <= 1.0);
//!
//! // The printed schedule replays the run exactly.
//! let replay = options.schedule(parse_schedule(&run.schedule_string()).unwrap());
//! let (mut again, _) = VirtualRun::new(model, grid, bodies, &config, &replay);
//! assert_eq!(again.run(20), frames);
//! ```

mod chooser;
mod options;

pub use options::{parse_schedule, ScheduleSpec, VirtualOptions};

use chooser::Chooser;

use super::control::RunControl;
use super::error::{ExecError, InputError};
use super::live::{LiveStatus, WorldStatus};
use super::load::LoadMeter;
use super::sync::panic_message;
use super::LastFrame;
use crate::frame::{Event, Frame, StatesWanted};
use crate::grid::Grid;
use crate::kernel::balance::{imbalance, Balancer, RoundRecord};
use crate::kernel::config::KernelConfig;
use crate::kernel::config::{LoadSource, RollbackMode};
use crate::kernel::counters::Counters;
use crate::kernel::gvt::global_virtual_time;
use crate::kernel::message::{Input, Message};
use crate::kernel::partition::{Partition, WorldId};
use crate::kernel::trace::{GvtSample, RunTrace};
use crate::kernel::world::World;
use crate::model::{CellModel, Step};
use std::collections::{BTreeMap, VecDeque};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;

/// Prefix of schedule strings.
const SCHEDULE_PREFIX: &str = "v1:";

/// A Time Warp run of a cell model on the virtual executor.
pub struct VirtualRun<M: CellModel> {
    config: KernelConfig,
    inputs: u32,
    grid: Arc<Grid>,
    partition: Arc<Partition>,
    worlds: Vec<World<M>>,
    /// Each world's GVT bound ([`World::bound`]) as of its last change; `None` when it
    /// acted or received since (recomputed at the next GVT update, not after every turn).
    bounds: Vec<Option<Step>>,
    /// Messages in flight, oldest first. A deque: FIFO and the seeded schedules take
    /// messages mostly from the front, which a `Vec` paid for by shifting the whole pool.
    pool: VecDeque<Message<M::State>>,
    /// Scratch for `decide`: the worlds that may act this turn.
    acts: Vec<usize>,
    in_flight: BTreeMap<Step, usize>,
    chooser: Chooser,
    record: bool,
    /// Worlds compute their interior ahead after each action ([`VirtualOptions::compute_ahead`]).
    compute_ahead: bool,
    decisions: Vec<u32>,
    turn: u64,
    gvt: Step,
    committed: Step,
    /// The last committed frame (a step no cell changed at keeps its hash).
    last_frame: Option<LastFrame>,
    limit: Step,
    end: Step,
    gvt_advances: u64,
    started: std::time::Instant,
    gvt_samples: Vec<GvtSample>,
    /// Load balancing: the balancer, the next round's step and the last round's step.
    balancer: Balancer,
    next_round: Step,
    last_round: Step,
    /// Per world, what the next balancing round measures (cell computations, the
    /// deterministic load proxy, and the lead over GVT).
    meters: Vec<LoadMeter>,
    /// One copy of every input posted (re-posted to the worlds after a balancing round).
    inputs_posted: Vec<Message<M::State>>,
    /// A world's action that panicked (the run cannot go on).
    failure: Option<ExecError>,
    /// Whether a controlled run's sink stopped the run.
    stopped: bool,
}

impl<M: CellModel> VirtualRun<M> {
    /// A run of `config.worlds` worlds starting at step 0 from `initial`, scheduled as
    /// `options` say. Entities outside the grid are dropped and reported as `LeftDomain`
    /// events (as by the reference).
    ///
    /// # Panics
    /// If `config.worlds` is 0 or an explicit partition does not fit the grid.
    pub fn new(
        model: M,
        grid: Grid,
        initial: Vec<M::State>,
        config: &KernelConfig,
        options: &VirtualOptions,
    ) -> (Self, Vec<Event<M::Event>>) {
        assert!(config.worlds >= 1, "at least one world");
        let super::Worlds {
            grid,
            partition,
            mut worlds,
            events,
        } = super::build_worlds(model, grid, initial, config);
        let mut balancer = Balancer::new(&config.balance, grid.cell_count());
        let mut partition = partition;
        if balancer.opens() {
            if let Some(p) =
                super::opening_round(&mut balancer, &grid, &partition, worlds.iter_mut())
            {
                partition = p;
            }
        }
        let mut run = VirtualRun {
            config: config.clone(),
            inputs: 0,
            grid,
            partition,
            worlds: Vec::new(),
            bounds: vec![None; worlds.len()],
            pool: VecDeque::new(),
            acts: Vec::new(),
            in_flight: BTreeMap::new(),
            chooser: Chooser::new(&options.schedule),
            record: options.record_schedule,
            compute_ahead: options.compute_ahead,
            decisions: Vec::new(),
            turn: 0,
            gvt: 1,
            committed: 0,
            last_frame: None,
            limit: 0,
            end: 0,
            gvt_advances: 0,
            started: std::time::Instant::now(),
            gvt_samples: Vec::new(),
            balancer,
            next_round: Step::MAX,
            last_round: 0,
            meters: vec![LoadMeter::default(); worlds.len()],
            inputs_posted: Vec::new(),
            failure: None,
            stopped: false,
        };
        run.next_round = run.balancer.next_round_after(0);
        for w in &mut worlds {
            let msgs = w.start();
            run.post(msgs);
        }
        run.worlds = worlds;
        (run, events)
    }

    /// The same run with its schedule driven by `bytes` (for fuzzing), decisions recorded.
    pub fn from_bytes(
        model: M,
        grid: Grid,
        initial: Vec<M::State>,
        config: &KernelConfig,
        bytes: &[u8],
    ) -> (Self, Vec<Event<M::Event>>) {
        let options = VirtualOptions::new(ScheduleSpec::Bytes(bytes.to_vec()));
        Self::new(model, grid, initial, config, &options)
    }

    fn post(&mut self, msgs: Vec<Message<M::State>>) {
        for m in msgs {
            *self.in_flight.entry(m.affects()).or_default() += 1;
            self.pool.push_back(m);
        }
    }

    /// The earliest step an input may name now: GVT in the optimistic modes; in
    /// conservative mode the step after every state already made known to another world
    /// ([`World::frontier`]).
    pub fn input_floor(&self) -> Step {
        if self.config.mode == RollbackMode::Conservative {
            1 + self.worlds.iter().map(|w| w.frontier()).max().unwrap_or(0)
        } else {
            self.gvt
        }
    }

    /// Schedules an external input at step `step` ([`try_add_input`](Self::try_add_input)).
    ///
    /// # Panics
    /// If the input is refused.
    pub fn add_input(&mut self, step: Step, input: Input<M::State>) {
        if let Err(e) = self.try_add_input(step, input) {
            panic!("{e}");
        }
    }

    /// Schedules an external input at step `step`: it is broadcast to every world as an input
    /// message (in the optimistic modes through the in-flight pool, so it may arrive late and
    /// cause rollbacks; in conservative mode straight into the inboxes). Refused if `step` is
    /// 0 or below [`input_floor`](Self::input_floor), or if an added entity lies outside the
    /// grid.
    pub fn try_add_input(&mut self, step: Step, input: Input<M::State>) -> Result<(), InputError> {
        super::check_input::<M>(&self.grid, self.input_floor(), step, &input)?;
        self.post_input(step, input);
        Ok(())
    }

    /// Posts a checked input.
    fn post_input(&mut self, step: Step, input: Input<M::State>) {
        self.inputs += 1;
        let msg = super::input_message::<M>(&self.grid, step, input, self.inputs);
        let msgs = super::to_every_world(&msg, self.worlds.len()).collect();
        self.inputs_posted.push(msg);
        self.deliver_inputs(msgs);
    }

    /// Inputs go through the in-flight pool (optimistic modes) or straight into the inboxes
    /// (conservative).
    fn deliver_inputs(&mut self, msgs: Vec<Message<M::State>>) {
        if self.config.mode == RollbackMode::Conservative {
            for m in msgs {
                self.changing(m.dst_world as usize).receive(m);
            }
        } else {
            self.post(msgs);
        }
    }

    /// The furthest step the worlds may compute to: `end`, but never past the next
    /// balancing round (where every state must be final before cells move).
    fn world_end(&self, end: Step) -> Step {
        end.min(self.next_round)
    }

    /// The balancing rounds held so far (empty when balancing is off).
    pub fn balance_history(&self) -> &[RoundRecord] {
        self.balancer.history()
    }

    /// A balancing round, if one is due at the committed step (then GVT = committed + 1:
    /// every state at it is final). Loads are cell computations per committed step since
    /// the last round (or seeded), so decisions replay with the schedule. If cells move, the
    /// worlds take their new territories, the messages in transit are dropped, the worlds
    /// send their ghosts again and pending inputs are re-posted.
    fn balance_if_due(&mut self) {
        if self.committed != self.next_round {
            return;
        }
        let step = self.committed;
        debug_assert_eq!(self.gvt, step + 1, "balancing below GVT");
        let steps = (step - self.last_round).max(1) as f64;
        let computed: Vec<u64> = self
            .worlds
            .iter()
            .map(|w| w.counters().cells_computed)
            .collect();
        let loads: Vec<f64> = self
            .meters
            .iter()
            .zip(&computed)
            .map(|(m, &now)| m.load(LoadSource::CellsComputed, now, steps))
            .collect();
        let leads: Vec<f64> = self.meters.iter().map(LoadMeter::mean_lead).collect();
        for (meter, &now) in self.meters.iter_mut().zip(&computed) {
            meter.restart(now);
        }
        let moved = super::balance_round(
            &mut self.balancer,
            &self.grid,
            &self.partition,
            self.worlds.iter_mut(),
            &loads,
            &leads,
            step,
        );
        if let Some(p) = moved {
            self.partition = p;
            self.bounds.iter_mut().for_each(|b| *b = None);
            self.pool.clear();
            self.in_flight.clear();
            let restart = super::restart_worlds(&mut self.worlds, &self.inputs_posted, step);
            self.post(restart.started);
            for m in restart.pending_inputs {
                let copies = super::to_every_world(&m, self.worlds.len()).collect();
                self.deliver_inputs(copies);
            }
        }
        self.last_round = step;
        self.next_round = self.balancer.next_round_after(step);
        let end = self.world_end(self.end);
        for w in &mut self.worlds {
            w.set_end(end);
        }
    }

    /// The last committed step (0 before any).
    pub fn committed_step(&self) -> Step {
        self.committed
    }

    /// Current GVT: the smallest step whose state may still change.
    pub fn gvt(&self) -> Step {
        self.gvt
    }

    /// The partition in use.
    pub fn partition(&self) -> &Partition {
        &self.partition
    }

    /// The grid.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// Counters per world and in total.
    pub fn counters(&self) -> Counters {
        let mut c = Counters::from_worlds(
            self.worlds.iter().map(|w| w.counters().clone()).collect(),
            self.gvt_advances,
            self.gvt,
        );
        c.decisions = self.turn;
        let computed: Vec<f64> = c.worlds.iter().map(|w| w.cells_computed as f64).collect();
        c.balance = self.balancer.counters(imbalance(&computed));
        c
    }

    /// Bytes held by all worlds' logs now.
    pub fn log_bytes(&self) -> u64 {
        self.worlds.iter().map(|w| w.log_bytes()).sum()
    }

    /// Bytes held by all worlds' logs now, by part.
    pub fn log_breakdown(&self) -> crate::kernel::LogBytes {
        let mut b = crate::kernel::LogBytes::default();
        for w in &self.worlds {
            b += w.log_breakdown();
        }
        b
    }

    /// Steps held by the logs now, summed over worlds.
    pub fn steps_held(&self) -> u64 {
        self.worlds.iter().map(|w| w.steps_held()).sum()
    }

    /// The run trace recorded so far (`config.trace`; empty lists otherwise): LVT samples,
    /// rollbacks, GVT advances, messages per step. Times are wall-clock seconds since the
    /// run was built.
    pub fn take_trace(&mut self) -> RunTrace {
        let gvt = std::mem::take(&mut self.gvt_samples);
        let mut worlds: Vec<&mut World<M>> = self.worlds.iter_mut().collect();
        super::collect_trace(&self.grid, &self.partition, &mut worlds, gvt)
    }

    /// The decisions taken so far, as a string [`parse_schedule`] turns back into a schedule
    /// that replays this run exactly (no decisions unless
    /// [`VirtualOptions::record_schedule`]).
    pub fn schedule_string(&self) -> String {
        let d: Vec<String> = self.decisions.iter().map(|d| d.to_string()).collect();
        format!("{SCHEDULE_PREFIX}{}", d.join("."))
    }

    /// Lets the worlds compute up to step `end` even if the current `run` stops committing
    /// earlier (to observe a run in the middle of its speculation).
    pub fn set_horizon(&mut self, end: Step) {
        self.end = self.end.max(end);
        let end = self.world_end(self.end);
        for w in &mut self.worlds {
            w.set_end(end);
        }
    }

    /// Runs until exactly `steps` more steps are committed, returning their frames in step order.
    pub fn run(&mut self, steps: u64) -> Vec<Frame<M::Event>> {
        let mut frames = Vec::new();
        self.run_with(steps, |f| frames.push(f));
        frames
    }

    /// Runs until exactly `steps` more steps are committed, handing each committed frame to `sink`
    /// in step order.
    pub fn run_with(&mut self, steps: u64, mut sink: impl FnMut(Frame<M::Event>)) {
        self.run_with_states(steps, &StatesWanted::none(), |f, _| sink(f));
    }

    /// [`run_with`](Self::run_with), also handing the sink the committed states (sorted by
    /// id) of the steps `wanted` asks for.
    ///
    /// # Panics
    /// If a world's action panics (with its message; see
    /// [`run_controlled`](Self::run_controlled) for the error instead).
    pub fn run_with_states(
        &mut self,
        steps: u64,
        wanted: &StatesWanted,
        mut sink: impl FnMut(Frame<M::Event>, Option<&[&M::State]>),
    ) {
        if let Err(e) = self.run_controlled(steps, wanted, |f, s, _| sink(f, s)) {
            panic!("{e}");
        }
    }

    /// Runs until `steps` more steps are committed (or the sink stops the run), handing each
    /// committed frame in step order to `sink` with the committed states (sorted by id) of
    /// the steps `wanted` asks for and a [`RunControl`] to schedule inputs or stop. A panic
    /// of a world's action is an [`ExecError::WorldPanicked`] naming the world and step.
    pub fn run_controlled(
        &mut self,
        steps: u64,
        wanted: &StatesWanted,
        mut sink: impl FnMut(Frame<M::Event>, Option<&[&M::State]>, &mut RunControl<'_, M::State>),
    ) -> Result<(), ExecError> {
        let target = self.committed + steps;
        self.limit = target;
        self.end = self.end.max(target);
        let end = self.world_end(target);
        for w in &mut self.worlds {
            w.set_end(end);
        }
        self.update_gvt(wanted, &mut sink);
        while self.committed < target && !self.stopped {
            self.balance_if_due();
            self.decide();
            if let Some(e) = self.failure.take() {
                return Err(e);
            }
            self.update_gvt(wanted, &mut sink);
        }
        Ok(())
    }

    /// Whether a controlled run's sink stopped the run.
    pub fn stopped(&self) -> bool {
        self.stopped
    }

    fn decide(&mut self) {
        let gvt = self.gvt;
        // The worlds that may act, in a buffer kept between decisions (one per turn).
        let mut acts = std::mem::take(&mut self.acts);
        acts.clear();
        acts.extend((0..self.worlds.len()).filter(|&w| self.worlds[w].wants_to_act(gvt)));
        assert!(
            !acts.is_empty() || !self.pool.is_empty(),
            "kernel deadlock at GVT {gvt}: no world can act and no message is in flight"
        );
        let laggard = (0..acts.len())
            .min_by_key(|&k| {
                let w = &self.worlds[acts[k]];
                (!w.has_inbox(), w.lvt(), k)
            })
            .unwrap_or(0);
        let i = self.chooser.choose(acts.len(), self.pool.len(), laggard);
        self.turn += 1;
        if self.record {
            self.decisions.push(i as u32);
        }
        if i < acts.len() {
            if self.config.trace {
                let now = self.started.elapsed().as_secs_f64();
                self.worlds[acts[i]].trace_time(now);
            }
            let w = acts[i];
            let lvt = self.worlds[w].lvt();
            let ahead = self.compute_ahead;
            let acted = catch_unwind(AssertUnwindSafe(|| {
                let world = self.changing(w);
                let msgs = world.act(gvt);
                if ahead {
                    world.compute_interior_ahead(gvt);
                }
                msgs
            }));
            let msgs = match acted {
                Ok(msgs) => msgs,
                Err(p) => {
                    self.failure = Some(ExecError::WorldPanicked {
                        world: w as WorldId,
                        step: lvt,
                        message: panic_message(&*p),
                    });
                    self.acts = acts;
                    return;
                }
            };
            self.meters[w].note_action(self.worlds[w].lvt(), gvt);
            self.post(msgs);
        } else {
            let m = self
                .pool
                .remove(i - acts.len())
                .expect("the chooser picks a message in the pool");
            let a = m.affects();
            let n = self.in_flight.get_mut(&a).expect("counted in flight");
            *n -= 1;
            if *n == 0 {
                self.in_flight.remove(&a);
            }
            let w = m.dst_world as usize;
            let lvt = self.worlds[w].lvt();
            let received = catch_unwind(AssertUnwindSafe(|| self.changing(w).receive(m)));
            if let Err(p) = received {
                self.failure = Some(ExecError::WorldPanicked {
                    world: w as WorldId,
                    step: lvt,
                    message: panic_message(&*p),
                });
            }
        }
        self.acts = acts;
    }

    /// World `w`, about to act or receive: its cached GVT bound is dropped.
    fn changing(&mut self, w: usize) -> &mut World<M> {
        self.bounds[w] = None;
        &mut self.worlds[w]
    }

    fn update_gvt(
        &mut self,
        wanted: &StatesWanted,
        sink: &mut impl FnMut(Frame<M::Event>, Option<&[&M::State]>, &mut RunControl<'_, M::State>),
    ) {
        for (b, w) in self.bounds.iter_mut().zip(&self.worlds) {
            if b.is_none() {
                *b = Some(w.bound());
            }
        }
        debug_assert!(self
            .bounds
            .iter()
            .zip(&self.worlds)
            .all(|(b, w)| *b == Some(w.bound())));
        let new = global_virtual_time(
            self.bounds.iter().flatten().copied(),
            self.in_flight.keys().next().copied(),
        )
        .unwrap_or(self.end + 1)
        .min(self.end + 1);
        debug_assert!(new >= self.gvt, "GVT went back from {} to {new}", self.gvt);
        if new > self.gvt {
            self.gvt = new;
            self.gvt_advances += 1;
            if self.config.trace {
                self.gvt_samples.push(GvtSample {
                    time: self.started.elapsed().as_secs_f64(),
                    gvt: new,
                });
            }
        } else if self.committed + 1 >= self.gvt || self.committed >= self.limit {
            return;
        }
        let floor = self.input_floor();
        let grid = self.grid.clone();
        while self.committed + 1 < new && self.committed < self.limit && !self.stopped {
            let t = self.committed + 1;
            let mut last = self.last_frame;
            let (frame, all) = self.frame(t, wanted, &mut last);
            let mut pending = Vec::new();
            let mut post = |step: Step, input: Input<M::State>| {
                super::check_input::<M>(&grid, floor, step, &input)?;
                pending.push((step, input));
                Ok(())
            };
            let gvt = self.gvt;
            let worlds = &self.worlds;
            let mut probe = || LiveStatus {
                gvt,
                worlds: worlds.iter().map(WorldStatus::of).collect(),
            };
            let mut control = RunControl::new(floor, &mut post).with_probe(&mut probe);
            sink(frame, all.as_deref(), &mut control);
            let stop = control.stopped();
            drop(all);
            self.last_frame = last;
            for w in &mut self.worlds {
                w.note_committed(t);
            }
            self.committed = t;
            for (step, input) in pending {
                self.post_input(step, input);
            }
            self.stopped |= stop;
        }
        for w in &mut self.worlds {
            w.sample_log_bytes();
            w.fossil_collect((new - 1).min(self.committed));
        }
    }

    /// The committed frame of step `t` ([`super::next_frame`]: a step no world's cells
    /// changed at keeps the previous frame's hash) and its sorted states if `wanted`.
    fn frame(
        &self,
        t: Step,
        wanted: &StatesWanted,
        last: &mut Option<LastFrame>,
    ) -> (Frame<M::Event>, Option<Vec<&M::State>>) {
        let events: Vec<Event<M::Event>> = self
            .worlds
            .iter()
            .flat_map(|w| w.events_at(t - 1))
            .cloned()
            .collect();
        let unchanged = self.worlds.iter().all(|w| w.unchanged_since_previous(t));
        super::next_frame::<M>(
            t,
            self.worlds.iter().flat_map(|w| w.state_at(t)),
            events,
            unchanged,
            last,
            wanted,
        )
    }
}

/// What [`run_virtual`] returns.
#[derive(Clone, Debug)]
pub struct VirtualReport<E> {
    /// Committed frames, steps 1..=N.
    pub frames: Vec<Frame<E>>,
    /// Counters.
    pub counters: Counters,
    /// The replay string (no decisions unless [`VirtualOptions::record_schedule`]).
    pub schedule: String,
    /// `LeftDomain` events of initial states outside the grid.
    pub initial_events: Vec<Event<E>>,
}

/// Runs `model` from `initial` for `steps` steps on the virtual executor, scheduled as
/// `options` say.
pub fn run_virtual<M: CellModel>(
    model: M,
    grid: Grid,
    initial: Vec<M::State>,
    config: &KernelConfig,
    options: &VirtualOptions,
    steps: u64,
) -> VirtualReport<M::Event> {
    let (mut run, initial_events) = VirtualRun::new(model, grid, initial, config, options);
    let frames = run.run(steps);
    VirtualReport {
        frames,
        counters: run.counters(),
        schedule: run.schedule_string(),
        initial_events,
    }
}
