//! One rank of an MPI run: its worlds, its sends and receives, the GVT rounds, committing at
//! rank 0 and balancing rounds ([module docs](super)).

use super::parallel::{Pool, Turn};
use super::wire;
use super::{PlantedTransportBug, Session};
use crate::exec::control::RunControl;
use crate::exec::error::{ExecError, InputError, MpiError};
use crate::exec::live::{LiveStatus, WorldStatus};
use crate::exec::load::LoadMeter;
use crate::exec::sync::panic_message;
use crate::frame::{Event, Frame, StatesWanted};
use crate::grid::Grid;
use crate::kernel::balance::{imbalance, Balancer, RoundRecord};
use crate::kernel::config::{KernelConfig, LoadSource};
use crate::kernel::counters::{Counters, WorldCounters};
use crate::kernel::message::{Input, Message, Sign};
use crate::kernel::partition::Partition;
use crate::kernel::world::World;
use crate::model::{CellModel, Step, Wire};
use crate::sim::MpiStats;
use crate::state::CellStates;
use mpi::collective::{CommunicatorCollectives, Root};
use mpi::datatype::PartitionMut;
use mpi::point_to_point::{Destination, MatchedReceiveVec, Source};
use mpi::request::{Request, StaticScope};
use mpi::topology::{Communicator, Rank as MpiRank, SimpleCommunicator};
use mpi::Count;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The tag of batches of kernel messages.
const TAG_BATCH: i32 = 17;

/// Exit code of a rank that aborts the job.
const ABORT_CODE: i32 = 70;

/// Rank 0's frame sink: each committed frame, the states asked for, the run's control.
pub type Sink<'a, S, E> = dyn FnMut(&Frame<E>, Option<&[&S]>, &mut RunControl<'_, S>) + 'a;

/// What an MPI run starts from (the same on every rank).
pub struct MpiSetup<M: CellModel> {
    /// The model.
    pub model: M,
    /// The grid.
    pub grid: Grid,
    /// The states at step 0.
    pub initial: Vec<M::State>,
    /// Inputs scheduled before the run starts (every rank must be given the same).
    pub inputs: Vec<(Step, Input<M::State>)>,
}

/// How an MPI run runs (the same on every rank).
#[derive(Clone, Debug)]
pub struct MpiOptions {
    /// Worlds, mode, window, ghosts, partition, balancing (the schedule is unused).
    pub kernel: KernelConfig,
    /// Steps to commit.
    pub steps: u64,
    /// The committed steps whose states rank 0's sink receives.
    pub wanted: StatesWanted,
    /// Actions a rank takes between two GVT rounds; a rank with nothing to do joins the
    /// round at once. 0: 8 per world of the rank.
    pub round_actions: usize,
    /// Threads of each rank (SPEC.md §14): the rank's worlds run on this many threads between
    /// GVT rounds, and only the rank's main thread calls MPI. 1: one thread.
    pub threads: usize,
    /// Seconds a GVT round may wait for messages sent between ranks (every rank has stopped
    /// sending, so they only have to arrive) before the run stops with an error naming what
    /// was lost. Default 30 (`SODA_MPI_ROUND_TIMEOUT` overrides it).
    pub round_timeout_seconds: f64,
}

impl MpiOptions {
    /// `kernel` for `steps` steps, no states wanted, 8 actions per local world between
    /// rounds, one thread per rank, rounds that wait at most 30 s for messages in transit.
    pub fn new(kernel: &KernelConfig, steps: u64) -> Self {
        MpiOptions {
            kernel: kernel.clone(),
            steps,
            wanted: StatesWanted::none(),
            round_actions: 0,
            threads: 1,
            round_timeout_seconds: std::env::var("SODA_MPI_ROUND_TIMEOUT")
                .ok()
                .and_then(|v| v.parse::<f64>().ok())
                .filter(|s| s.is_finite() && *s > 0.0)
                .unwrap_or(30.0),
        }
    }
}

/// What an MPI run returns, on every rank.
#[derive(Clone, Debug)]
pub struct MpiReport<E> {
    /// Whether this is rank 0 (the only one whose counters cover every world and whose
    /// sink saw the frames).
    pub root: bool,
    /// Counters: of every world on rank 0, of this rank's worlds elsewhere.
    pub counters: Counters,
    /// Transport and GVT statistics of this rank (rank 0: summed over ranks).
    pub stats: MpiStats,
    /// `LeftDomain` events of initial states outside the grid.
    pub initial_events: Vec<Event<E>>,
    /// The load balancing rounds (empty when balancing is off).
    pub balance: Vec<RoundRecord>,
    /// Wall time of the run, s.
    pub wall_seconds: f64,
}

/// A send in progress: the request and the words it reads, leaked until it completes.
struct PendingSend {
    request: Request<'static, [u64], StaticScope>,
    words: *mut [u64],
}

/// Runs `setup` across the ranks of the MPI job (every rank calls it with the same setup and
/// options), handing rank 0's sink every committed frame in step order with the states
/// `options.wanted` asks for and a [`RunControl`] that can stop the run (inputs during the
/// run are refused: [`InputError::DuringMpiRun`]). Joins the process's [`Session`] or starts
/// one for the run.
///
/// A fault on any rank — a world's panic, a message that does not decode — prints an error
/// naming the rank, the world and the step, and aborts every rank (`MPI_Abort`): this
/// function does not return then.
pub fn run_mpi_controlled<M: CellModel>(
    setup: MpiSetup<M>,
    options: &MpiOptions,
    sink: &mut Sink<'_, M::State, M::Event>,
) -> Result<MpiReport<M::Event>, ExecError> {
    let wire = M::wire().ok_or(MpiError::NoWire)?;
    if options.kernel.trace {
        return Err(MpiError::Unsupported("a run trace (--trace)").into());
    }
    let session = Session::init()?;
    let threads = options.threads.max(1);
    if threads > 1 && !super::threads_allowed() {
        return Err(MpiError::NoThreads(threads).into());
    }
    let started = Instant::now();
    let MpiSetup {
        model,
        grid,
        initial,
        inputs,
    } = setup;
    let config = &options.kernel;
    let crate::exec::Worlds {
        grid,
        partition,
        mut worlds,
        events,
    } = crate::exec::build_worlds(model, grid, initial, config);
    let mut balancer = Balancer::new(&config.balance, grid.cell_count());
    let mut partition = partition;
    if balancer.opens() {
        // Every rank holds every world at step 0: the same round everywhere.
        if let Some(p) =
            crate::exec::opening_round(&mut balancer, &grid, &partition, worlds.iter_mut())
        {
            partition = p;
        }
    }
    let ranks = session.size();
    let me = session.rank();
    let count = worlds.len();
    let owner: Vec<usize> = (0..count).map(|w| w * ranks / count).collect();
    let mut local = vec![None; count];
    let mine: Vec<World<M>> = worlds
        .into_iter()
        .filter(|w| owner[w.id() as usize] == me)
        .collect();
    for (i, w) in mine.iter().enumerate() {
        local[w.id() as usize] = Some(i);
    }
    let round_actions = if options.round_actions > 0 {
        options.round_actions
    } else {
        8 * mine.len().max(1)
    };
    let mut rank = Rank {
        comm: SimpleCommunicator::world(),
        me,
        ranks,
        wire,
        grid,
        partition,
        meters: vec![LoadMeter::default(); mine.len()],
        worlds: mine,
        local,
        owner,
        outbox: vec![Vec::new(); ranks],
        pending: Vec::new(),
        sent: 0,
        received: 0,
        stats: MpiStats {
            ranks,
            ..MpiStats::default()
        },
        planted: PlantedTransportBug::from_env(),
        gvt: 1,
        committed: 0,
        target: options.steps,
        end: options.steps,
        stopped: false,
        stop_requested: false,
        gvt_advances: 0,
        balancer,
        next_round: Step::MAX,
        last_round: 0,
        inputs_posted: Vec::new(),
        round_actions,
        threads,
        round_timeout: Duration::from_secs_f64(options.round_timeout_seconds),
    };
    rank.next_round = rank.balancer.next_round_after(0);
    rank.set_end();
    // Inputs: every rank posts the same ones, each to its own worlds.
    for (seq, (step, input)) in inputs.into_iter().enumerate() {
        crate::exec::check_input::<M>(&rank.grid, 1, step, &input)?;
        let msg = crate::exec::input_message::<M>(&rank.grid, step, input, seq as u32 + 1);
        rank.post_input(&msg);
        rank.inputs_posted.push(msg);
    }
    for i in 0..rank.worlds.len() {
        let msgs = rank.worlds[i].start();
        rank.route(msgs);
    }
    rank.flush();
    rank.run(&options.wanted, sink);
    rank.finish_sends();
    let counters = rank.gather_counters();
    let stats = rank.gather_stats();
    let balance = rank.balancer.history().to_vec();
    Ok(MpiReport {
        root: me == 0,
        counters,
        stats,
        initial_events: events,
        balance,
        wall_seconds: started.elapsed().as_secs_f64(),
    })
}

/// One rank's part of a run.
struct Rank<M: CellModel> {
    comm: SimpleCommunicator,
    me: usize,
    ranks: usize,
    wire: Wire<M::State, M::Event>,
    grid: Arc<Grid>,
    partition: Arc<Partition>,
    /// This rank's worlds, ascending id.
    worlds: Vec<World<M>>,
    /// Per local world, what the next balancing round measures.
    meters: Vec<LoadMeter>,
    /// World id → index in `worlds`, for this rank's worlds.
    local: Vec<Option<usize>>,
    /// World id → rank.
    owner: Vec<usize>,
    /// Messages for each rank, sent at the next flush.
    outbox: Vec<Vec<Message<M::State>>>,
    pending: Vec<PendingSend>,
    /// Messages sent to and received from other ranks (GVT's counts).
    sent: u64,
    received: u64,
    stats: MpiStats,
    planted: PlantedTransportBug,
    gvt: Step,
    committed: Step,
    target: Step,
    end: Step,
    /// Whether every rank knows the run stops (from a GVT round: all ranks alike).
    stopped: bool,
    /// Rank 0: whether its sink asked to stop (told to every rank at the next round).
    stop_requested: bool,
    gvt_advances: u64,
    balancer: Balancer,
    next_round: Step,
    last_round: Step,
    /// One copy of every input (re-posted after a balancing round moves cells).
    inputs_posted: Vec<Message<M::State>>,
    round_actions: usize,
    /// Threads acting on this rank's worlds between GVT rounds.
    threads: usize,
    /// How long a GVT round may wait for messages in transit before the run stops.
    round_timeout: Duration,
}

impl<M: CellModel> Rank<M> {
    /// Prints why this rank cannot go on and aborts every rank of the job.
    ///
    /// The line goes to stderr in one `write` (stderr is unbuffered, and `eprintln!` writes
    /// each piece of its format separately), so Open MPI's abort banner, forwarded from
    /// another process, cannot land in the middle of it.
    fn fatal(&self, what: &str) -> ! {
        use std::io::Write as _;
        let line = format!(
            "error: MPI rank {} of {}: {what} (GVT {}, committed step {}); aborting every rank\n",
            self.me, self.ranks, self.gvt, self.committed
        );
        // Nothing is left to do if stderr is gone: the abort below still stops every rank.
        let _ = std::io::stderr().lock().write_all(line.as_bytes());
        self.comm.abort(ABORT_CODE)
    }

    /// The worlds compute up to the run's end, but never past the next balancing round.
    fn set_end(&mut self) {
        let end = self.end.min(self.next_round);
        for w in &mut self.worlds {
            w.set_end(end);
        }
    }

    /// Puts an input's copies in this rank's worlds' inboxes.
    fn post_input(&mut self, msg: &Message<M::State>) {
        let all = crate::exec::to_every_world(msg, self.owner.len());
        for m in all {
            if let Some(i) = self.local[m.dst_world as usize] {
                self.worlds[i].receive(m);
            }
        }
    }

    /// Delivers messages to this rank's worlds or queues them for their ranks.
    fn route(&mut self, msgs: Vec<Message<M::State>>) {
        for m in msgs {
            let w = m.dst_world as usize;
            match self.local[w] {
                Some(i) => self.worlds[i].receive(m),
                None => self.outbox[self.owner[w]].push(m),
            }
        }
    }

    /// Sends every queued batch (non-blocking) and reclaims completed sends.
    fn flush(&mut self) {
        for dest in 0..self.ranks {
            if self.outbox[dest].is_empty() {
                continue;
            }
            let mut msgs = std::mem::take(&mut self.outbox[dest]);
            // Counted as sent before anything can lose them (the planted fault below).
            self.sent += msgs.len() as u64;
            if self.planted == PlantedTransportBug::DropAnti {
                msgs.retain(|m| m.sign != Sign::Anti);
                if msgs.is_empty() {
                    continue;
                }
            }
            let mut words = match wire::encode_batch(&self.wire, &msgs) {
                Ok(w) => w,
                Err(e) => self.fatal(&format!("cannot encode a batch for rank {dest}: {e}")),
            };
            if self.planted == PlantedTransportBug::Corrupt && self.stats.batches_sent == 0 {
                let last = words.len() / 2;
                words[last] ^= 1 << 40;
            }
            self.stats.batches_sent += 1;
            self.stats.messages_sent += msgs.len() as u64;
            self.stats.bytes_sent += 8 * words.len() as u64;
            // The words stay alive until MPI is done with them (`reclaim`).
            let words: &'static mut [u64] = Box::leak(words.into_boxed_slice());
            let raw: *mut [u64] = words;
            let request = self
                .comm
                .process_at_rank(dest as MpiRank)
                .immediate_send_with_tag(StaticScope, &*words, TAG_BATCH);
            self.pending.push(PendingSend {
                request,
                words: raw,
            });
        }
        self.reclaim();
    }

    /// Frees the words of completed sends.
    fn reclaim(&mut self) {
        let pending = std::mem::take(&mut self.pending);
        for p in pending {
            match p.request.test() {
                Ok(_) => {
                    // SAFETY: the send is complete, so MPI no longer reads the words, and
                    // `words` came from `Box::leak` in `flush` and is freed only here.
                    drop(unsafe { Box::from_raw(p.words) });
                }
                Err(request) => self.pending.push(PendingSend {
                    request,
                    words: p.words,
                }),
            }
        }
    }

    /// Waits until every send is complete (at the end of the run, when every batch sent has
    /// been received: the last GVT round counted them).
    fn finish_sends(&mut self) {
        for p in std::mem::take(&mut self.pending) {
            p.request.wait();
            // SAFETY: as in `reclaim`.
            drop(unsafe { Box::from_raw(p.words) });
        }
    }

    /// Receives every batch that has arrived and puts its messages in the inboxes.
    fn poll(&mut self) {
        let local = std::mem::take(&mut self.local);
        let got = self.receive_batches(&local);
        self.local = local;
        for (i, m) in got {
            self.worlds[i].receive(m);
        }
    }

    /// Receives every batch that has arrived: its messages with the index of the local world
    /// (`local`: world id → index) each is for.
    fn receive_batches(&mut self, local: &[Option<usize>]) -> Vec<(usize, Message<M::State>)> {
        let mut got = Vec::new();
        while let Some(probed) = self
            .comm
            .any_process()
            .immediate_matched_probe_with_tag(TAG_BATCH)
        {
            let from = probed.1.source_rank();
            let (words, _) = probed.matched_receive_vec::<u64>();
            let msgs = match wire::decode_batch(&self.wire, &words) {
                Ok(m) => m,
                Err(e) => self.fatal(&format!("a batch from rank {from} does not decode: {e}")),
            };
            self.received += msgs.len() as u64;
            for m in msgs {
                match local.get(m.dst_world as usize).copied().flatten() {
                    Some(i) => got.push((i, m)),
                    None => self.fatal(&format!(
                        "a batch from rank {from} holds a message for world {}, which is not \
                         on this rank",
                        m.dst_world
                    )),
                }
            }
        }
        self.reclaim();
        got
    }

    /// The local world to act next: one with messages first, then the smallest LVT.
    fn pick(&self) -> Option<usize> {
        (0..self.worlds.len())
            .filter(|&i| self.worlds[i].wants_to_act(self.gvt))
            .min_by_key(|&i| {
                let w = &self.worlds[i];
                (!w.has_inbox(), w.lvt(), i)
            })
    }

    /// One world's action; a panic aborts the job.
    fn act(&mut self, i: usize) {
        let gvt = self.gvt;
        let lvt = self.worlds[i].lvt();
        let id = self.worlds[i].id();
        let planted = self.planted;
        let me = self.me;
        let acted = catch_unwind(AssertUnwindSafe(|| {
            if let PlantedTransportBug::Panic(r, s) = planted {
                if r == me && lvt >= s {
                    panic!("planted panic (SODA_MPI_PLANTED_BUG)");
                }
            }
            self.worlds[i].act(gvt)
        }));
        match acted {
            Ok(msgs) => {
                self.meters[i].note_action(self.worlds[i].lvt(), gvt);
                self.route(msgs);
            }
            Err(p) => self.fatal(&format!(
                "world {id} panicked while computing from step {lvt}: {}",
                panic_message(&*p)
            )),
        }
    }

    /// Up to `round_actions` actions of this rank's worlds (fewer if none can act), receiving
    /// and sending batches between them: on one thread, or on `threads` when the rank has
    /// several worlds.
    fn work(&mut self) {
        if self.threads > 1 && self.worlds.len() > 1 {
            self.work_on_threads();
            return;
        }
        for _ in 0..self.round_actions {
            self.poll();
            let Some(i) = self.pick() else { break };
            self.act(i);
            self.flush();
        }
    }

    /// [`Self::work`] on `threads` threads ([`parallel`](super::parallel)): the main thread
    /// takes turns like the helpers and, between its turns, receives and sends the batches.
    fn work_on_threads(&mut self) {
        let local = std::mem::take(&mut self.local);
        let owner = std::mem::take(&mut self.owner);
        let pool = Pool::new(
            std::mem::take(&mut self.worlds),
            std::mem::take(&mut self.meters),
            &local,
            &owner,
            self.ranks,
            self.gvt,
            self.round_actions,
            self.planted,
            self.me,
        );
        let helpers = (self.threads - 1).min(pool.len() - 1);
        std::thread::scope(|scope| {
            for _ in 0..helpers {
                scope.spawn(|| pool.help());
            }
            loop {
                for (i, m) in self.receive_batches(&local) {
                    pool.deliver(i, m);
                }
                self.send(pool.take_outbox());
                match pool.turn() {
                    Turn::Acted => {}
                    Turn::Wait => std::thread::yield_now(),
                    Turn::Done => break,
                }
            }
        });
        self.send(pool.take_outbox());
        let end = pool.finish();
        self.local = local;
        self.owner = owner;
        self.worlds = end.worlds;
        self.meters = end.meters;
        if let Some(failure) = end.failure {
            self.fatal(&failure);
        }
    }

    /// Queues messages for other ranks (`by_rank[r]` for rank `r`) and sends them.
    fn send(&mut self, by_rank: Vec<Vec<Message<M::State>>>) {
        for (dest, msgs) in by_rank.into_iter().enumerate() {
            self.outbox[dest].extend(msgs);
        }
        self.flush();
    }

    /// The run: work, GVT round, commit, until the last step is committed or rank 0's sink
    /// stops the run.
    fn run(&mut self, wanted: &StatesWanted, sink: &mut Sink<'_, M::State, M::Event>) {
        while self.committed < self.target && !self.stopped {
            self.balance_if_due();
            self.work();
            let new = self.gvt_round();
            if new > self.gvt {
                self.gvt = new;
                self.gvt_advances += 1;
            }
            let last = (self.gvt - 1).min(self.target);
            if last > self.committed && !self.stopped {
                self.commit(last, wanted, sink);
            }
            for w in &mut self.worlds {
                w.sample_log_bytes();
                w.fossil_collect((self.gvt - 1).min(self.committed));
            }
        }
    }

    /// A GVT round (SPEC.md §14): this rank sends nothing more until it ends; receive what
    /// has arrived, all-gather (sent, received, bound, stop) and repeat until every batch
    /// sent was received. Returns the new GVT; sets `stopped` if rank 0 stopped the run.
    fn gvt_round(&mut self) -> Step {
        self.stats.gvt_rounds += 1;
        let started = Instant::now();
        loop {
            self.poll();
            let bound = self
                .worlds
                .iter()
                .map(World::bound)
                .min()
                .unwrap_or(Step::MAX);
            let stop = self.stopped || self.stop_requested;
            let mine = [self.sent, self.received, bound, u64::from(stop)];
            let mut all = vec![0u64; 4 * self.ranks];
            self.comm.all_gather_into(&mine[..], &mut all[..]);
            self.stats.reductions += 1;
            let sum = |k: usize| all.chunks(4).map(|c| c[k]).sum::<u64>();
            let (sent, received) = (sum(0), sum(1));
            if sent == received {
                self.stopped |= all.chunks(4).any(|c| c[3] != 0);
                let min = all.chunks(4).map(|c| c[2]).min().unwrap_or(Step::MAX);
                self.stats.gvt_seconds += started.elapsed().as_secs_f64();
                let end = self.end.min(self.next_round);
                return min.min(end + 1).max(self.gvt);
            }
            // Every rank stopped sending: what has not arrived by now never will.
            if started.elapsed() > self.round_timeout {
                self.fatal(&format!(
                    "a GVT round waited {:.0} s: {sent} messages were sent between ranks but \
                     {received} received (lost in transit)",
                    started.elapsed().as_secs_f64()
                ));
            }
        }
    }

    /// Commits steps `committed + 1 ..= last`: every rank's states and events go to rank 0,
    /// which builds the frames and hands them to the sink.
    fn commit(
        &mut self,
        last: Step,
        wanted: &StatesWanted,
        sink: &mut Sink<'_, M::State, M::Event>,
    ) {
        let first = self.committed + 1;
        let root = self.comm.process_at_rank(0);
        // Rank 0 reads its own worlds directly; the others send their words.
        let words = if self.me == 0 {
            vec![]
        } else {
            let parts: Vec<_> = (first..=last)
                .map(|t| {
                    let states: Vec<&M::State> =
                        self.worlds.iter().flat_map(|w| w.state_at(t)).collect();
                    let events: Vec<&Event<M::Event>> = self
                        .worlds
                        .iter()
                        .flat_map(|w| w.events_at(t - 1))
                        .collect();
                    (states, events)
                })
                .collect();
            wire::encode_frames(&self.wire, first, parts.into_iter())
        };
        self.stats.commit_bytes += 8 * words.len() as u64;
        let count = words.len() as Count;
        if self.me != 0 {
            root.gather_into(&count);
            root.gather_varcount_into(&words[..]);
        } else {
            let mut counts = vec![0 as Count; self.ranks];
            root.gather_into_root(&count, &mut counts[..]);
            let displs = displacements(&counts);
            let mut all = vec![0u64; counts.iter().map(|&c| c as usize).sum()];
            {
                let mut part = PartitionMut::new(&mut all[..], &counts[..], &displs[..]);
                root.gather_varcount_into_root(&words[..], &mut part);
            }
            let mut others = Vec::with_capacity(self.ranks);
            for r in 1..self.ranks {
                let at = displs[r] as usize;
                let slice = &all[at..at + counts[r] as usize];
                match wire::decode_frames(&self.wire, slice) {
                    Ok((f, parts)) if f == first && parts.len() as u64 == last - first + 1 => {
                        others.push(parts)
                    }
                    Ok(_) => self.fatal(&format!(
                        "rank {r} sent the committed states of other steps than {first}..={last}"
                    )),
                    Err(e) => {
                        self.fatal(&format!("rank {r}'s committed states do not decode: {e}"))
                    }
                }
            }
            // Notes every step it hands over as committed (stopping where the sink stops).
            self.deliver_frames(first, last, &others, wanted, sink);
            return;
        }
        for t in first..=last {
            self.note_committed(t);
        }
    }

    /// Every local world notes step `t` as committed (in step order, as the frames go).
    fn note_committed(&mut self, t: Step) {
        for w in &mut self.worlds {
            w.note_committed(t);
        }
        self.committed = t;
    }

    /// Rank 0: builds the frames of `first..=last` from its worlds and the other ranks' parts
    /// and hands them to the sink in step order (until it asks to stop the run).
    fn deliver_frames(
        &mut self,
        first: Step,
        last: Step,
        others: &[Vec<wire::StepPart<M::State, M::Event>>],
        wanted: &StatesWanted,
        sink: &mut Sink<'_, M::State, M::Event>,
    ) {
        for t in first..=last {
            // Every rank commits the same steps (so the next collectives match); frames after
            // a stop only reach no sink.
            if !self.stop_requested {
                self.deliver_frame(t, first, others, wanted, sink);
            }
            self.note_committed(t);
        }
    }

    /// Rank 0: builds the frame of step `t` and hands it to the sink.
    fn deliver_frame(
        &mut self,
        t: Step,
        first: Step,
        others: &[Vec<wire::StepPart<M::State, M::Event>>],
        wanted: &StatesWanted,
        sink: &mut Sink<'_, M::State, M::Event>,
    ) {
        {
            let k = (t - first) as usize;
            let mut events: Vec<Event<M::Event>> = self
                .worlds
                .iter()
                .flat_map(|w| w.events_at(t - 1))
                .cloned()
                .collect();
            events.extend(others.iter().flat_map(|p| p[k].events.iter().cloned()));
            let states = self
                .worlds
                .iter()
                .flat_map(|w| w.state_at(t))
                .chain(others.iter().flat_map(|p| p[k].states.iter()));
            let (frame, all) = crate::exec::whole_frame::<M>(t, states, events);
            let mut post = |step: Step, _input: Input<M::State>| -> Result<(), InputError> {
                Err(InputError::DuringMpiRun { step })
            };
            let gvt = self.gvt;
            let worlds = &self.worlds;
            let mut probe = || LiveStatus {
                gvt,
                worlds: worlds.iter().map(WorldStatus::of).collect(),
            };
            let mut control = RunControl::new(gvt, &mut post).with_probe(&mut probe);
            let wants = wanted.wants(t, frame.hash).then_some(&all[..]);
            sink(&frame, wants, &mut control);
            // Every rank learns of it in the next GVT round and leaves the run there.
            self.stop_requested |= control.stopped();
        }
    }

    /// A balancing round, if one is due at the committed step (SPEC.md §K13, §14): every rank
    /// all-gathers the worlds' loads and leads and the whole domain's states at the step, so
    /// every rank's balancer takes the same decision; if cells move, every rank's worlds take
    /// their new territories, send their ghosts again and get the pending inputs again.
    fn balance_if_due(&mut self) {
        if self.committed != self.next_round || self.committed >= self.target {
            return;
        }
        let step = self.committed;
        let steps = (step - self.last_round).max(1) as f64;
        // Loads and leads of every world, in world order.
        let mut mine = Vec::with_capacity(3 * self.worlds.len());
        for (w, m) in self.worlds.iter().zip(&mut self.meters) {
            let now = w.counters().cells_computed;
            mine.extend([
                u64::from(w.id()),
                m.load(LoadSource::CellsComputed, now, steps).to_bits(),
                m.mean_lead().to_bits(),
            ]);
            m.restart(now);
        }
        let gathered = self.all_gather_words(&mine);
        let n = self.owner.len();
        let (mut loads, mut leads) = (vec![0.0; n], vec![0.0; n]);
        for c in gathered.iter().flat_map(|g| g.chunks(3)) {
            loads[c[0] as usize] = f64::from_bits(c[1]);
            leads[c[0] as usize] = f64::from_bits(c[2]);
        }
        // The whole domain's final states at the step, on every rank.
        let states: Vec<&M::State> = self.worlds.iter().flat_map(|w| w.state_at(step)).collect();
        let words = wire::encode_frames(&self.wire, step, [(states, Vec::new())].into_iter());
        let gathered = self.all_gather_words(&words);
        let mut all = Vec::new();
        for (r, g) in gathered.iter().enumerate() {
            match wire::decode_frames(&self.wire, g) {
                Ok((_, parts)) => all.extend(parts.into_iter().flat_map(|p| p.states)),
                Err(e) => self.fatal(&format!(
                    "rank {r}'s states for the balancing round at step {step} do not decode: {e}"
                )),
            }
        }
        let mut outside = Vec::new();
        let states = CellStates::binned::<M>(&self.grid, all, step, &mut outside);
        let bodies: Vec<u32> = (0..self.grid.cell_count())
            .map(|c| states.cell_at(c).len() as u32)
            .collect();
        let new = self
            .balancer
            .round(&self.grid, &self.partition, &loads, &leads, &bodies, step);
        if let Some(new) = new {
            let new = Arc::new(new);
            self.partition = new.clone();
            for w in &mut self.worlds {
                w.reterritory(new.clone(), &states, step);
            }
            let restart = crate::exec::restart_worlds(&mut self.worlds, &self.inputs_posted, step);
            self.route(restart.started);
            for m in &restart.pending_inputs {
                self.post_input(m);
            }
            self.flush();
        }
        self.last_round = step;
        self.next_round = self.balancer.next_round_after(step);
        self.set_end();
    }

    /// Every rank's `words`, in rank order (`MPI_Allgatherv`).
    fn all_gather_words(&self, words: &[u64]) -> Vec<Vec<u64>> {
        let count = words.len() as Count;
        let mut counts = vec![0 as Count; self.ranks];
        self.comm.all_gather_into(&count, &mut counts[..]);
        let displs = displacements(&counts);
        let mut all = vec![0u64; counts.iter().map(|&c| c as usize).sum()];
        {
            let mut part = PartitionMut::new(&mut all[..], &counts[..], &displs[..]);
            self.comm.all_gather_varcount_into(words, &mut part);
        }
        (0..self.ranks)
            .map(|r| {
                let at = displs[r] as usize;
                all[at..at + counts[r] as usize].to_vec()
            })
            .collect()
    }

    /// Every world's counters, at rank 0 (the others get their own).
    fn gather_counters(&self) -> Counters {
        let words = wire::encode_counters(self.worlds.iter().map(|w| (w.id(), w.counters())));
        let gathered = self.all_gather_words(&words);
        let mut worlds = vec![WorldCounters::default(); self.owner.len()];
        for (r, g) in gathered.iter().enumerate() {
            match wire::decode_counters(g) {
                Ok(list) => {
                    for (id, c) in list {
                        if let Some(slot) = worlds.get_mut(id as usize) {
                            *slot = c;
                        }
                    }
                }
                Err(e) => self.fatal(&format!("rank {r}'s counters do not decode: {e}")),
            }
        }
        let mut c = Counters::from_worlds(worlds, self.gvt_advances, self.gvt);
        let computed: Vec<f64> = c.worlds.iter().map(|w| w.cells_computed as f64).collect();
        c.balance = self.balancer.counters(imbalance(&computed));
        c
    }

    /// The transport statistics summed over ranks (GVT time: the slowest rank's).
    fn gather_stats(&self) -> MpiStats {
        let s = &self.stats;
        let mine = [
            s.batches_sent,
            s.messages_sent,
            s.bytes_sent,
            s.commit_bytes,
            s.gvt_seconds.to_bits(),
        ];
        let mut all = vec![0u64; 5 * self.ranks];
        self.comm.all_gather_into(&mine[..], &mut all[..]);
        let sum = |k: usize| all.chunks(5).map(|c| c[k]).sum::<u64>();
        MpiStats {
            ranks: self.ranks,
            gvt_rounds: s.gvt_rounds,
            reductions: s.reductions,
            batches_sent: sum(0),
            messages_sent: sum(1),
            bytes_sent: sum(2),
            commit_bytes: sum(3),
            gvt_seconds: all
                .chunks(5)
                .map(|c| f64::from_bits(c[4]))
                .fold(0.0, f64::max),
        }
    }
}

/// Where each rank's part starts in a gathered buffer of parts of `counts` words, in rank
/// order (the displacements of `MPI_Gatherv` / `MPI_Allgatherv`).
fn displacements(counts: &[Count]) -> Vec<Count> {
    counts
        .iter()
        .scan(0, |at, &c| {
            let d = *at;
            *at += c;
            Some(d)
        })
        .collect()
}
