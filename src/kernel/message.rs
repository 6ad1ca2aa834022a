//! Messages between worlds and their total order.
//!
//! Every message is about the state of cells at one step (`step`): a *ghost* carries the
//! whole state of a border cell at `step` to a world that owns one of its neighbours; a
//! *migrate* carries the bodies that the computation of cell `src_cell` at `step − 1` homes,
//! at `step`, in cells of the destination world. A positive message is identified by
//! (kind, step, source cell, destination world, sequence number); its anti-message carries
//! the same identity and no bodies. Inputs are not messages between worlds here (see
//! SPEC.md §Inputs).

use super::partition::WorldId;
use crate::model::{BodyId, Step};
use std::sync::Arc;

/// A message's bodies with their home cells, shared (not copied) between the sender's log of
/// what it sent, the copies for several destination worlds and the receivers' logs.
pub type Bodies<S> = Arc<Vec<Homed<S>>>;

/// One body a message carries and the cell that homes it at the message's step.
#[derive(Clone, Debug, PartialEq)]
pub struct Homed<S> {
    /// Linear index of the body's home cell at the message's step.
    pub cell: u32,
    /// The body's state.
    pub state: S,
}

/// What a message is about. Inputs sort first so that, at a given step, a world has applied
/// them before anything can make a state of that step known (conservative mode).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum MessageKind {
    /// An external input changing the states at `step` (spawn, remove, replace).
    Input,
    /// The state of a border cell at `step`.
    Ghost,
    /// Bodies arriving at `step` in the destination world's cells.
    Migrate,
}

/// Positive message or anti-message. Anti sorts first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Sign {
    /// Cancels the positive message with the same identity.
    Anti,
    /// Carries bodies.
    Positive,
}

/// The total order in which a world applies the messages it has received: by step, then
/// kind, source cell, sequence number and sign — the order of the fields, which the derived
/// `Ord` compares in turn (do not reorder them: the order of application is part of
/// determinism). Together with the destination world this identifies a message uniquely;
/// arrival order never matters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct MessageKey {
    /// The message's step.
    pub step: Step,
    /// Its kind.
    pub kind: MessageKind,
    /// The cell it comes from.
    pub src_cell: u32,
    /// The sequence number of its version.
    pub seq: u32,
    /// Positive or anti.
    pub sign: Sign,
}

impl MessageKey {
    /// The smallest key of kind `kind` at step `step`: where the messages of that kind and
    /// step start in the total order.
    pub fn first_of(step: Step, kind: MessageKind) -> Self {
        MessageKey {
            step,
            kind,
            src_cell: 0,
            seq: 0,
            sign: Sign::Anti,
        }
    }
}

/// A timestamped message from one world to another.
#[derive(Clone, Debug)]
pub struct Message<S> {
    /// The step of the states it describes.
    pub step: Step,
    /// Ghost or migrate.
    pub kind: MessageKind,
    /// Positive or anti.
    pub sign: Sign,
    /// Sending world.
    pub src_world: WorldId,
    /// Receiving world.
    pub dst_world: WorldId,
    /// Linear index of the cell the message comes from (the ghosted cell, or the cell whose
    /// computation produced the migrating bodies).
    pub src_cell: u32,
    /// Sequence number of this version of the (kind, step, src cell, dst world) content.
    pub seq: u32,
    /// The bodies with their home cells at `step`, sorted by (cell, id); empty for
    /// anti-messages and null messages. For an input: the states it adds.
    pub bodies: Bodies<S>,
    /// For an input: the ids of the bodies it removes (empty otherwise).
    pub removes: Vec<BodyId>,
    /// For an input: the edits it applies, each with its entity's id (empty otherwise).
    pub edits: Vec<EntityEdit<S>>,
    /// Delta ghosts (SPEC.md §K4): the sender's state of the cell at `step` differs from its
    /// state at `step − 1`, so a ghost of `step + 1` follows. False for everything else.
    pub follows: bool,
    /// A non-empty ghost within one process: the sender's logged state of the cell — the
    /// states of `bodies`, one shared allocation that the receiver keeps as its view instead
    /// of a copy (SPEC.md §K3). `None` otherwise (and after crossing processes: the
    /// receiver copies `bodies`). Not part of the message's identity or content: equality
    /// ignores it.
    pub view: Option<crate::kernel::SharedStates<S>>,
}

impl<S: PartialEq> PartialEq for Message<S> {
    fn eq(&self, o: &Self) -> bool {
        self.step == o.step
            && self.kind == o.kind
            && self.sign == o.sign
            && self.src_world == o.src_world
            && self.dst_world == o.dst_world
            && self.src_cell == o.src_cell
            && self.seq == o.seq
            && self.bodies == o.bodies
            && self.removes == o.removes
            && self.edits == o.edits
            && self.follows == o.follows
    }
}

/// A pure change of one entity's state — an impulse, a new velocity — applied at an input's
/// step to whatever state the entity has then (SPEC.md §8, "Inputs on every executor"). It
/// must keep the entity in its home cell (an edit that moves it is an error); it may be
/// applied more than once to the same state (rollbacks), so it must be a function of the
/// state alone.
#[derive(Clone)]
pub struct Edit<S>(Arc<dyn Fn(&S) -> S + Send + Sync>);

impl<S> Edit<S> {
    /// The edit `change` (a pure function of the state).
    pub fn new(change: impl Fn(&S) -> S + Send + Sync + 'static) -> Self {
        Edit(Arc::new(change))
    }

    /// The edited state.
    pub fn apply(&self, state: &S) -> S {
        (self.0)(state)
    }
}

/// Two edits are equal when they are the same edit (one allocation), as copies of one input
/// are.
impl<S> PartialEq for Edit<S> {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

impl<S> std::fmt::Debug for Edit<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Edit(..)")
    }
}

/// An [`Edit`] of the entity with id `id`: what an input message carries for
/// [`Input::Edit`].
#[derive(Clone, Debug, PartialEq)]
pub struct EntityEdit<S> {
    /// The entity edited.
    pub id: BodyId,
    /// The change.
    pub edit: Edit<S>,
}

/// An external event at a step, applied to the states at that step (before they are used).
#[derive(Clone, Debug, PartialEq)]
pub enum Input<S> {
    /// Adds an entity (its id must not be in use).
    Spawn(S),
    /// Removes the entity with this id, wherever it is.
    Remove(BodyId),
    /// Replaces the state of the entity with the same id; it is re-homed by its new position.
    Replace(S),
    /// Changes the state the entity with this id has at the step (e.g. applies an impulse or
    /// sets its velocity from its current state); nothing if it is not there.
    Edit(BodyId, Edit<S>),
}

impl<S> Message<S> {
    /// The key of the total application order.
    pub fn key(&self) -> MessageKey {
        MessageKey {
            step: self.step,
            kind: self.kind,
            src_cell: self.src_cell,
            seq: self.seq,
            sign: self.sign,
        }
    }

    /// The earliest step whose state this message may still change: a ghost of step `t`
    /// changes computations at `t`, hence states at `t + 1`; a migrate of step `t` changes
    /// states at `t`. GVT is bounded by this value while the message is in flight or
    /// unprocessed.
    pub fn affects(&self) -> Step {
        match self.kind {
            MessageKind::Ghost => self.step + 1,
            MessageKind::Migrate | MessageKind::Input => self.step,
        }
    }

    /// Whether this is an anti-message.
    pub fn is_anti(&self) -> bool {
        self.sign == Sign::Anti
    }
}
