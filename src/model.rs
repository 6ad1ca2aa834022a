//! The seam between a kernel and a cell model: the kernel moves opaque entity states
//! between cells and asks the model to step one cell from its 27-cell neighbourhood.
//! The kernel never knows it is running physics.

use crate::frame::{Event, LeftGrid};
use crate::grid::{CellCoord, Grid};
use crate::hash::StateHash;
use std::fmt::Debug;

/// Virtual time: a step number. Step `t` is followed by step `t + 1`, `dt` seconds later.
pub type Step = u64;

/// The identity of an entity (a body). Canonical order everywhere is ascending id.
pub type BodyId = u64;

/// Four words a model computes from one entity's state ([`CellModel::hint`]) that its
/// `step_cell` may read instead of computing them again, once per neighbourhood.
pub type Hint = [f32; 4];

/// The states of the entities homed in the 27 cells around a centre cell at one step.
///
/// Slot `k` holds cell `centre + offset(k)` with offsets in lexicographic `(dz, dy, dx)`
/// order, each in `-1..=1`; slot 13 is the centre. Every slot is sorted by id. Cells
/// outside the grid are empty slots.
pub struct Neighbourhood<'a, S> {
    /// The centre cell.
    pub centre: CellCoord,
    /// The 27 slots, see the type's doc.
    pub cells: [&'a [S]; 27],
    /// Per row of three slots along x (row `r` holds slots `3r`, `3r + 1` and `3r + 2`),
    /// either the [`CellModel::hint`] of each of the row's entities, in slot order (as
    /// long as the three slots together), or nothing (an empty slice): an executor may
    /// give hints for some rows, all or none.
    pub hints: [&'a [Hint]; 9],
}

impl<'a, S> Neighbourhood<'a, S> {
    /// Index of the centre slot.
    pub const CENTRE: usize = 13;

    /// The neighbourhood of `centre` with these slots and no hints.
    pub fn new(centre: CellCoord, cells: [&'a [S]; 27]) -> Self {
        Neighbourhood {
            centre,
            cells,
            hints: [&[]; 9],
        }
    }

    /// The hints of row `r`'s entities (slots `3r..3r + 3`), if the executor gave them.
    pub fn row_hints(&self, r: usize) -> Option<&'a [Hint]> {
        let hints = self.hints[r];
        let len: usize = self.cells[3 * r..3 * r + 3].iter().map(|c| c.len()).sum();
        (hints.len() == len && len > 0).then_some(hints)
    }

    /// The offset `(dx, dy, dz)` of slot `k`.
    pub fn offset(k: usize) -> [i32; 3] {
        let k = k as i32;
        [k % 3 - 1, (k / 3) % 3 - 1, k / 9 - 1]
    }

    /// The entities homed in the centre cell.
    pub fn own(&self) -> &'a [S] {
        self.cells[Self::CENTRE]
    }

    /// All entities of the neighbourhood, slot by slot (not globally id-sorted).
    pub fn iter(&self) -> impl Iterator<Item = &'a S> + '_ {
        self.cells.iter().flat_map(|c| c.iter())
    }
}

/// A deterministic cell model: stepping a cell is a pure function of the step-`t` states of
/// its 27-cell neighbourhood and the model's static data (SPEC.md §4). Implement it for your
/// own entities and every executor, `verify`, the fuzzing checks and the CLI run it.
///
/// # The rules a model keeps
///
/// The kernel's guarantee — every executor commits the reference's bits — holds exactly when
/// these do. The contract checker ([`crate::exec::contract`], always run by `verify`) finds
/// the breaches it can and names the rule, entity, cell and step.
///
/// 1. **Pure steps.** [`step_cell`](Self::step_cell) reads only its arguments (`step`,
///    `grid`, the neighbourhood) and the model's own fields, which never change during a
///    run: no interior mutability, no global or thread-local state, no clock, no
///    `std::collections::HashMap`/`HashSet` iteration order, no unseeded randomness (seed a
///    `rand_chacha` generator from the entity, the step and a seed of the model). The same
///    cell may be computed many times (rollbacks, other worlds, the checker).
/// 2. **Unique ids.** Every entity of a state has its own [`id`](Self::id); the canonical
///    order everywhere is ascending id. A model that creates entities must give them ids no
///    other entity can get, whichever cell computes them (e.g. derived from the parent's id
///    range, never from a shared counter).
/// 3. **One cell per step.** An output's [`position`](Self::position) lies in the
///    27-cell neighbourhood of the cell that computed it (its home cell at step `t + 1` is at
///    most one cell away on each axis), or outside the grid — then the kernel removes it with
///    a [`LeftGrid`] event. The cell edge must be at least the distance over which entities
///    interact, and an entity may not move farther than one cell edge per step.
/// 4. **Sorted outputs.** `step_cell` appends the next states of the centre cell's
///    entities, and of any entity it creates, to `out` in ascending id order. It may drop
///    entities (deaths) and create entities (births); everything it appends is homed by
///    its new position. On entry, `out` may already hold other cells' outputs: append, never
///    clear or read it; the same holds for `events`.
/// 5. **Honest `may_affect`.** If [`may_affect`](Self::may_affect) is overridden, `false`
///    must mean the reader's step cannot read that neighbour.
/// 6. **Every bit hashed.** [`hash_state`](Self::hash_state) feeds every bit that a step can
///    read (else two different states could commit the same hash).
/// 7. **Honest `at_rest`.** If [`at_rest`](Self::at_rest) is overridden, a neighbourhood
///    whose entities are all at rest must step to exactly the centre cell's states.
pub trait CellModel: Send + Sync {
    /// The state of one entity, moved between cells and worlds by the kernel.
    type State: Clone + PartialEq + Debug + Send + Sync + 'static;

    /// What the model reports happened to an entity during a step (e.g. an infection, a
    /// birth, a capped speed), collected into committed frames in (step, entity, kind)
    /// order. It converts from the kernel's own [`LeftGrid`] event, raised when an entity's
    /// home position lies outside the grid; a model without events of its own uses
    /// `type Event = LeftGrid;`.
    type Event: From<LeftGrid> + Clone + Ord + Debug + Send + Sync + 'static;

    /// The entity's id.
    fn id(state: &Self::State) -> BodyId;

    /// The point that decides the entity's home cell.
    fn position(state: &Self::State) -> [f32; 3];

    /// Computes the step-`t + 1` states of the entities homed in `nb.centre` at step `t`,
    /// appending them to `out` in ascending id order, and any events to `events`.
    /// Must read nothing but `nb`, `grid` and the model's static data.
    fn step_cell(
        &self,
        step: Step,
        grid: &Grid,
        nb: &Neighbourhood<'_, Self::State>,
        out: &mut Vec<Self::State>,
        events: &mut Vec<Event<Self::Event>>,
    );

    /// Four words about `state` that [`step_cell`](Self::step_cell) may read from the
    /// neighbourhood ([`Neighbourhood::hints`]) instead of computing them itself: a pure
    /// function of the state and the model's static data, which an executor may compute
    /// once per entity and step rather than once per neighbourhood that holds it. Whether
    /// hints are given must not change any output (`step_cell` computes what is missing;
    /// the contract checker computes every cell a second time without hints). `None`, the
    /// default: the model reads none, and executors compute none.
    fn hint(&self, state: &Self::State) -> Option<Hint> {
        let _ = state;
        None
    }

    /// Whether computing the cell that homes `reader` may read `other`, the state of an
    /// entity homed in a neighbouring cell at the same step. `false` is a promise: a cell's
    /// output is unchanged when every neighbour entity that no entity of the cell may read is
    /// removed from its neighbourhood (SPEC.md §K4, dirty propagation). `true` is always
    /// sound (the default).
    fn may_affect(&self, reader: &Self::State, other: &Self::State) -> bool {
        let _ = (reader, other);
        true
    }

    /// Whether `state` is at rest: `true` is a promise that whenever every entity of a
    /// cell's 27-cell neighbourhood is at rest, [`step_cell`](Self::step_cell) appends
    /// exactly the centre cell's states — the same entities, the same bits
    /// ([`same_bits`](Self::same_bits)), in the same order — and raises no event, at every
    /// step. Executors may then skip the computation and keep the cell's state (and, when no
    /// cell changed, the frame's hash) as it is: a pile asleep costs nearly nothing per step
    /// (SPEC.md §4.1, rule 7). The contract checker checks the promise on every cell it
    /// covers. `false`, the default, is always sound.
    fn at_rest(&self, state: &Self::State) -> bool {
        let _ = state;
        false
    }

    /// Feeds every bit of the state that matters into the canonical hash.
    fn hash_state(state: &Self::State, hasher: &mut StateHash);

    /// Whether two states are the same bits: equal, and equal in every hashed bit (so `0.0`
    /// and `-0.0`, which compare equal, differ). The kernel's lazy cancellation, early
    /// cut-off and delta ghosts call it for every compared entity; a model may answer it
    /// faster than the default (equality, then both hashes); `true` must mean that neither
    /// the hash nor any computation can tell the two apart.
    fn same_bits(a: &Self::State, b: &Self::State) -> bool {
        if a != b {
            return false;
        }
        let (mut ha, mut hb) = (StateHash::new(), StateHash::new());
        Self::hash_state(a, &mut ha);
        Self::hash_state(b, &mut hb);
        ha.finish() == hb.finish()
    }

    /// The state's hashed fields as (name, value) pairs, in hash order, for divergence
    /// reports (the first field whose value differs is named). Values should show the exact
    /// bits. The default is the whole state as one field.
    fn fields(state: &Self::State) -> Vec<(String, String)> {
        vec![("state".to_string(), format!("{state:?}"))]
    }

    /// The name an event kind is counted under in reports (`RunReport::events`). The
    /// default is its `Debug` form.
    fn event_name(kind: &Self::Event) -> String {
        format!("{kind:?}")
    }

    /// How states and events travel between processes as exact 64-bit words (the MPI
    /// executor, SPEC.md §14): `None`, the default, means the model cannot be run across
    /// processes. A model whose state is [`ExactState`](crate::checkpoint::ExactState)
    /// builds it with [`exact_wire`](crate::checkpoint::exact_wire).
    fn wire() -> Option<Wire<Self::State, Self::Event>> {
        None
    }
}

/// A model's states and events as exact 64-bit words, for the MPI executor's messages and
/// committed frames ([`CellModel::wire`]). Decoding what encoding wrote must give back the
/// same bits; decoding anything else must fail (an `Err`, a `None`), never give another
/// state.
pub struct Wire<S, E> {
    /// Appends a state's words.
    pub state_to_words: fn(&S, &mut Vec<u64>),
    /// Reads a state back from exactly the words `state_to_words` wrote, or says what is wrong.
    pub state_from_words: fn(&[u64]) -> Result<S, String>,
    /// An event kind as one word.
    pub event_to_word: fn(&E) -> u64,
    /// The event kind of a word `event_to_word` wrote (`None` for any other word).
    pub event_from_word: fn(u64) -> Option<E>,
}

impl<S, E> Clone for Wire<S, E> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<S, E> Copy for Wire<S, E> {}

/// An `f32` written so two different bit patterns never look alike: shortest decimal and
/// the raw bits.
pub fn exact_f32(v: f32) -> String {
    format!("{v:?} (0x{:08x})", v.to_bits())
}
