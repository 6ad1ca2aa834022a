//! Executors: ways of running a cell model over the grid. Each yields the same committed
//! frames; the reference is the oracle.

pub mod clock;
pub mod contract;
pub mod control;
pub mod error;
pub mod live;
mod load;
#[cfg(feature = "mpi")]
pub mod mpi;
pub mod reference;
mod schedule;
pub mod sync;
pub mod threaded;
pub mod virtual_exec;

use crate::frame::{Event, Frame};
use crate::grid::Grid;
use crate::kernel::trace::{GvtSample, RunTrace};
use crate::kernel::{Balancer, KernelConfig, Partition, World, WorldId};
use crate::model::{CellModel, Step};
use crate::state::{canonical_hash, sorted_by_id, CellStates};
use std::sync::Arc;

/// Checks an input against the rules every executor applies: not at step 0, not before
/// `floor` (the earliest step still open), every added entity inside the grid.
pub(crate) fn check_input<M: CellModel>(
    grid: &Grid,
    floor: Step,
    step: Step,
    input: &crate::kernel::Input<M::State>,
) -> Result<(), error::InputError> {
    use crate::kernel::Input;
    if step == 0 {
        return Err(error::InputError::StepZero);
    }
    if step < floor {
        return Err(error::InputError::TooLate {
            step,
            earliest: floor,
        });
    }
    if let Input::Spawn(s) | Input::Replace(s) = input {
        if grid.cell_of(M::position(s)).is_none() {
            return Err(error::InputError::OutsideGrid {
                step,
                id: M::id(s),
                position: M::position(s),
            });
        }
    }
    Ok(())
}

/// The input message of number `seq` at `step` (destination world 0; copies go to every
/// world).
pub(crate) fn input_message<M: CellModel>(
    grid: &Grid,
    step: Step,
    input: crate::kernel::Input<M::State>,
    seq: u32,
) -> crate::kernel::Message<M::State> {
    let mut edits = Vec::new();
    let (removes, adds) = match input {
        crate::kernel::Input::Spawn(s) => (Vec::new(), vec![s]),
        crate::kernel::Input::Remove(id) => (vec![id], Vec::new()),
        crate::kernel::Input::Replace(s) => (vec![M::id(&s)], vec![s]),
        crate::kernel::Input::Edit(id, edit) => {
            edits.push(crate::kernel::message::EntityEdit { id, edit });
            (Vec::new(), Vec::new())
        }
    };
    let bodies: Vec<crate::kernel::Homed<M::State>> = adds
        .into_iter()
        .map(|state| {
            let c = grid
                .cell_of(M::position(&state))
                .expect("checked inside the grid");
            crate::kernel::Homed {
                cell: grid.index(c) as u32,
                state,
            }
        })
        .collect();
    crate::kernel::Message {
        step,
        kind: crate::kernel::MessageKind::Input,
        sign: crate::kernel::Sign::Positive,
        src_world: WorldId::MAX,
        dst_world: 0,
        src_cell: u32::MAX,
        seq,
        bodies: bodies.into(),
        removes,
        edits,
        follows: false,
        view: None,
    }
}

/// Copies of the input message `msg`, one addressed to each of `worlds` worlds (an input is
/// broadcast: every world applies the part that concerns its cells).
pub(crate) fn to_every_world<S: Clone>(
    msg: &crate::kernel::Message<S>,
    worlds: usize,
) -> impl Iterator<Item = crate::kernel::Message<S>> + '_ {
    (0..worlds).map(move |w| crate::kernel::Message {
        dst_world: w as WorldId,
        ..msg.clone()
    })
}

/// The committed frame of step `t` from every world's states (any order) and events: the
/// states sorted by id and hashed as the reference hashes them, the events sorted. Returns
/// the sorted states too ([`sorted_by_id`]).
pub(crate) fn whole_frame<'a, M: CellModel>(
    t: Step,
    states: impl IntoIterator<Item = &'a M::State>,
    mut events: Vec<Event<M::Event>>,
) -> (Frame<M::Event>, Vec<&'a M::State>) {
    let sorted = sorted_by_id::<M>(states);
    events.sort();
    let frame = Frame {
        step: t,
        hash: canonical_hash::<M>(sorted.iter().copied()),
        bodies: sorted.len(),
        events,
    };
    (frame, sorted)
}

/// The step, hash and body count of the last committed frame an executor finished.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LastFrame {
    /// Its step.
    pub step: Step,
    /// Its canonical hash.
    pub hash: u64,
    /// Its body count.
    pub bodies: usize,
}

/// The committed frame of step `t`, as [`whole_frame`] gives it, and its sorted states if
/// `wanted` asks for them. When `unchanged` (every world's cells hold at `t` the
/// allocations they held at `t − 1`: SPEC.md §K3, an unchanged cell shares its allocation)
/// and `last` is the frame of `t − 1`, the hash and body count are `last`'s, known without
/// sorting or hashing a state: a resting scene's frames cost O(1) each, as the reference's
/// do. `last` becomes step `t`'s.
pub(crate) fn next_frame<'a, M: CellModel>(
    t: Step,
    states: impl IntoIterator<Item = &'a M::State>,
    mut events: Vec<Event<M::Event>>,
    unchanged: bool,
    last: &mut Option<LastFrame>,
    wanted: &crate::frame::StatesWanted,
) -> (Frame<M::Event>, Option<Vec<&'a M::State>>) {
    if let Some(prev) = last.filter(|l| unchanged && l.step + 1 == t) {
        if !wanted.wants(t, prev.hash) {
            events.sort();
            *last = Some(LastFrame { step: t, ..prev });
            let frame = Frame {
                step: t,
                hash: prev.hash,
                bodies: prev.bodies,
                events,
            };
            return (frame, None);
        }
    }
    let (frame, sorted) = whole_frame::<M>(t, states, events);
    *last = Some(LastFrame {
        step: t,
        hash: frame.hash,
        bodies: frame.bodies,
    });
    let sorted = wanted.wants(t, frame.hash).then_some(sorted);
    (frame, sorted)
}

/// The worlds of a Time Warp run, as both kernel executors start them.
pub(crate) struct Worlds<M: CellModel> {
    /// The grid, shared with every world.
    pub grid: Arc<Grid>,
    /// The cell → world map (from `config.partition`, over the initial positions).
    pub partition: Arc<Partition>,
    /// One world per territory, ascending id, at step 0.
    pub worlds: Vec<World<M>>,
    /// `LeftDomain` events of initial states outside the grid (they are dropped).
    pub events: Vec<Event<M::Event>>,
}

/// Bins `initial`, partitions the grid with `config` (at least one world) and builds every
/// world at step 0.
pub(crate) fn build_worlds<M: CellModel>(
    model: M,
    grid: Grid,
    initial: Vec<M::State>,
    config: &KernelConfig,
) -> Worlds<M> {
    let positions: Vec<[f32; 3]> = initial.iter().map(M::position).collect();
    let mut events = Vec::new();
    let state = CellStates::binned::<M>(&grid, initial, 0, &mut events);
    let partition = Arc::new(Partition::build(
        &config.partition,
        &grid,
        config.worlds.max(1),
        &positions,
        config.partition_seed,
    ));
    let model = Arc::new(model);
    let grid = Arc::new(grid);
    let worlds = (0..partition.worlds() as WorldId)
        .map(|w| {
            let mut world = World::new(
                w,
                model.clone(),
                grid.clone(),
                partition.clone(),
                config,
                &state,
            );
            world.set_recording(config.trace);
            world
        })
        .collect();
    Worlds {
        grid,
        partition,
        worlds,
        events,
    }
}

/// Merges the worlds' trace parts with the executor's GVT samples into a run trace.
pub(crate) fn collect_trace<M: CellModel>(
    grid: &Grid,
    partition: &Partition,
    worlds: &mut [&mut World<M>],
    gvt: Vec<GvtSample>,
) -> RunTrace {
    let owners = (0..grid.cell_count())
        .map(|c| partition.owner(c as u32))
        .collect();
    let parts = worlds.iter_mut().map(|w| w.take_record()).collect();
    RunTrace::merge(grid.dims, owners, parts, gvt)
}

/// The whole domain's states at step `step`, gathered from the worlds (each holds its own
/// cells'); `step` must be held by every world (at GVT − 1 or later, not fossil-collected).
pub(crate) fn gather_states<'a, M: CellModel + 'a>(
    grid: &Grid,
    worlds: impl IntoIterator<Item = &'a World<M>>,
    step: Step,
) -> CellStates<M::State> {
    let all: Vec<M::State> = worlds
        .into_iter()
        .flat_map(|w| w.state_at(step).cloned())
        .collect();
    let mut outside = Vec::new();
    let states = CellStates::binned::<M>(grid, all, step, &mut outside);
    debug_assert!(outside.is_empty(), "a held state lies outside the grid");
    states
}

/// A balancing round at committed step `step` (SPEC.md §K13): hands `loads` (per world, per
/// committed step since the last round), `leads` (each world's mean LVT − GVT meanwhile) and
/// the body count of every cell to the balancer; if cells move, every world takes its new territory at `step` with its final
/// states ([`World::reterritory`]) and the new partition is returned. The caller must
/// discard every message in transit and let the worlds [`World::start`] again.
pub(crate) fn balance_round<'a, M: CellModel + 'a>(
    balancer: &mut Balancer,
    grid: &Grid,
    partition: &Partition,
    worlds: impl IntoIterator<Item = &'a mut World<M>>,
    loads: &[f64],
    leads: &[f64],
    step: Step,
) -> Option<Arc<Partition>> {
    let mut worlds: Vec<&mut World<M>> = worlds.into_iter().collect();
    let bodies = body_counts(grid, &worlds, step);
    let new = balancer.round(grid, partition, loads, leads, &bodies, step)?;
    Some(take_territories(grid, &mut worlds, new, step))
}

/// What the worlds send when they start again after a balancing round moved cells at
/// committed step `step` (every message in transit was discarded): each world's
/// [`World::start`] messages, in world order, and the inputs posted for steps after `step`,
/// which must be delivered again to every world. The same on every executor.
pub(crate) struct Restart<S> {
    /// The worlds' start messages, world by world.
    pub started: Vec<crate::kernel::Message<S>>,
    /// The inputs still ahead of `step`, in the order they were posted.
    pub pending_inputs: Vec<crate::kernel::Message<S>>,
}

/// Starts `worlds` again after a balancing round that moved cells at `step` (see
/// [`Restart`]); `posted` is every input message posted so far, in posting order.
pub(crate) fn restart_worlds<'a, M: CellModel + 'a>(
    worlds: impl IntoIterator<Item = &'a mut World<M>>,
    posted: &[crate::kernel::Message<M::State>],
    step: Step,
) -> Restart<M::State> {
    Restart {
        started: worlds.into_iter().flat_map(|w| w.start()).collect(),
        pending_inputs: posted.iter().filter(|m| m.step > step).cloned().collect(),
    }
}

/// The opening balancing round at step 0 ([`Balancer::opening_round`]): loads estimated from
/// the bodies, nothing computed yet. Returns the new partition if cells moved; the caller
/// then lets the worlds [`World::start`] (again).
pub(crate) fn opening_round<'a, M: CellModel + 'a>(
    balancer: &mut Balancer,
    grid: &Grid,
    partition: &Partition,
    worlds: impl IntoIterator<Item = &'a mut World<M>>,
) -> Option<Arc<Partition>> {
    let mut worlds: Vec<&mut World<M>> = worlds.into_iter().collect();
    let bodies = body_counts(grid, &worlds, 0);
    let new = balancer.opening_round(grid, partition, &bodies)?;
    Some(take_territories(grid, &mut worlds, new, 0))
}

/// The bodies in every cell at `step`, counted in the worlds' logs (nothing is copied: a
/// round that moves no cell needs only these).
fn body_counts<M: CellModel>(grid: &Grid, worlds: &[&mut World<M>], step: Step) -> Vec<u32> {
    let mut bodies = vec![0u32; grid.cell_count()];
    for w in worlds {
        for &c in w.cells() {
            bodies[c as usize] = w.cell_state(c, step).map_or(0, |s| s.len() as u32);
        }
    }
    bodies
}

/// Every world takes its territory in `new` at `step`, with the final states gathered from
/// the worlds' logs ([`World::reterritory`]).
fn take_territories<M: CellModel>(
    grid: &Grid,
    worlds: &mut [&mut World<M>],
    new: Partition,
    step: Step,
) -> Arc<Partition> {
    let states = gather_states(grid, worlds.iter().map(|w| &**w), step);
    let new = Arc::new(new);
    for w in worlds.iter_mut() {
        w.reterritory(new.clone(), &states, step);
    }
    new
}
