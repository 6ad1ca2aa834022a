//! Why a run stopped early: the typed errors every executor returns.

use super::sync::ThreadPanicked;
use crate::kernel::partition::WorldId;
use crate::model::{BodyId, Step};
use thiserror::Error;

/// Why a run stopped early. All are fatal for the run; the frames committed before the error
/// were handed to the sink and stay valid.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ExecError {
    /// A world's action panicked (the model's `step_cell`, or a check of the kernel such as
    /// an entity that moved more than one cell); the other threads were stopped.
    #[error("world {world} panicked while computing from step {step}: {message}")]
    WorldPanicked {
        /// The world.
        world: WorldId,
        /// Its local virtual time when it panicked.
        step: Step,
        /// The panic message.
        message: String,
    },
    /// The model panicked computing one cell in the reference executor.
    #[error("the model panicked computing cell ({}, {}, {}) at step {step}: {message}", cell[0], cell[1], cell[2])]
    CellPanicked {
        /// The step being computed.
        step: Step,
        /// The cell's coordinates.
        cell: [i32; 3],
        /// The panic message.
        message: String,
    },
    /// A model broke a rule of the [`crate::CellModel`] contract (found by the contract
    /// checker, [`crate::exec::contract`]).
    #[error("{0}")]
    Contract(#[from] ContractViolation),
    /// An input could not be scheduled.
    #[error("{0}")]
    Input(#[from] InputError),
    /// No world could act, no message was pending and GVT could not advance (a kernel bug).
    #[error("kernel stalled at GVT {gvt}: no world can act and no message is pending")]
    Stalled {
        /// GVT at the stall.
        gvt: Step,
    },
    /// A thread of the executor failed outside a world's step (a worker died, or a
    /// committed frame's hashing panicked: the message names the step).
    #[error("an executor thread failed: {0}")]
    Thread(#[from] ThreadPanicked),
    /// The MPI executor cannot run this (SPEC.md §14).
    #[error("{0}")]
    Mpi(#[from] MpiError),
}

/// Why the MPI executor cannot run (SPEC.md §14). Faults during an MPI run (a panic, a
/// message that does not decode) stop every rank with `MPI_Abort` instead: the others could
/// not go on.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum MpiError {
    /// This build has no MPI executor.
    #[error(
        "this soda was built without the MPI executor: rebuild with `cargo build --release \
         --features mpi` (after scripts/install-mpi-deps.sh) and start it under `mpirun`"
    )]
    NotBuilt,
    /// The model has no [`Wire`](crate::model::Wire) to send its states between processes.
    #[error(
        "this model cannot run across processes: its CellModel::wire is None (give it one, \
         e.g. with soda::checkpoint::exact_wire)"
    )]
    NoWire,
    /// MPI could not be initialised (or was finalised already: one MPI run per process).
    #[error("MPI could not be initialised (it was already finalised in this process)")]
    Init,
    /// Several threads per rank, but the MPI library offers no `MPI_THREAD_FUNNELED`.
    #[error(
        "--threads {0} per rank needs an MPI library with MPI_THREAD_FUNNELED support, and this \
         one has none: run one thread per rank (more ranks instead)"
    )]
    NoThreads(usize),
    /// A kernel option the MPI executor does not support.
    #[error("{0} is not supported by the MPI executor")]
    Unsupported(&'static str),
}

/// Why a schedule string ([`parse_schedule`]) does not parse.
///
/// [`parse_schedule`]: super::virtual_exec::parse_schedule
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum ScheduleParseError {
    /// The string does not start with the format's prefix.
    #[error("a schedule string starts with {prefix:?}")]
    MissingPrefix {
        /// The prefix expected.
        prefix: &'static str,
    },
    /// A decision is not a number.
    #[error("bad decision {token:?}: {source}")]
    BadDecision {
        /// The text of the decision.
        token: String,
        /// Why it is not a number.
        source: std::num::ParseIntError,
    },
}

/// Why an input (spawn, remove, replace at a step) was refused.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum InputError {
    /// Step 0 is the initial state: inputs apply from step 1 on.
    #[error("an input at step 0 is refused: step 0 is the initial state, inputs apply from step 1 on (add the entity to the initial states instead)")]
    StepZero,
    /// The step is already committed (or, in conservative mode, made known to a neighbour).
    #[error("an input at step {step} is too late: the earliest step still open is {earliest}")]
    TooLate {
        /// The input's step.
        step: Step,
        /// The earliest step an input may still name.
        earliest: Step,
    },
    /// An edit moved its entity out of its home cell (edits change a state in place; use a
    /// replacement to move an entity).
    #[error("an input at step {step} edits entity {id} out of its home cell: an edit must keep the entity in its cell (replace the state to move it)")]
    EditLeftCell {
        /// The input's step.
        step: Step,
        /// The entity.
        id: BodyId,
    },
    /// An input posted while an MPI run is going (the MPI executor takes only the inputs
    /// scheduled before the run: every rank must post the same).
    #[error("an input at step {step} posted during an MPI run is refused: schedule inputs before the run (an input script)")]
    DuringMpiRun {
        /// The input's step.
        step: Step,
    },
    /// An added entity's home position lies outside the grid.
    #[error("an input at step {step} adds entity {id} at {position:?}, outside the grid")]
    OutsideGrid {
        /// The input's step.
        step: Step,
        /// The entity.
        id: BodyId,
        /// Its position.
        position: [f32; 3],
    },
}

/// One broken rule of the [`crate::CellModel`] contract: which rule, which entity, where and
/// when.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
#[error("contract violation at step {step}, cell ({}, {}, {}), entity {entity}: {rule}: {detail}", cell[0], cell[1], cell[2])]
pub struct ContractViolation {
    /// The rule broken.
    pub rule: ContractRule,
    /// The step being computed (outputs are states at `step + 1`).
    pub step: Step,
    /// The cell whose computation broke it.
    pub cell: [i32; 3],
    /// The entity concerned.
    pub entity: BodyId,
    /// What was seen.
    pub detail: String,
}

/// The rules of the [`crate::CellModel`] contract the checker enforces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ContractRule {
    /// Entity ids are unique in every state.
    UniqueIds,
    /// An entity moves at most one cell per step (its new home is in the 27-neighbourhood
    /// of the cell that computed it).
    OneCellMove,
    /// `step_cell` appends its outputs in strictly ascending id order.
    SortedOutputs,
    /// `step_cell` is a pure function of its neighbourhood: computing the same cell again,
    /// in another order, gives the same bits.
    PureStep,
    /// A neighbourhood whose entities are all at rest ([`crate::CellModel::at_rest`]) steps
    /// to exactly the centre cell's states, with no event.
    AtRest,
}

impl std::fmt::Display for ContractRule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ContractRule::UniqueIds => "duplicate id (entity ids must be unique)",
            ContractRule::OneCellMove => {
                "an entity moved more than one cell (outputs must land in the 27-cell neighbourhood)"
            }
            ContractRule::SortedOutputs => {
                "outputs not sorted by id (step_cell must append them in ascending id order)"
            }
            ContractRule::PureStep => {
                "step_cell is not a pure function of its neighbourhood (hidden state or randomness)"
            }
            ContractRule::AtRest => {
                "a neighbourhood at rest changed (at_rest promised that step_cell keeps the centre cell's states)"
            }
        })
    }
}
