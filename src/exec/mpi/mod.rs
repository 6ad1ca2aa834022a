//! The MPI executor (cargo feature `mpi`; SPEC.md §14): the worlds of one Time Warp run spread
//! over the ranks of an MPI job, each rank one process driving its worlds on one thread or,
//! with `threads > 1`, on several (only the rank's main thread calls MPI).
//!
//! - **Worlds to ranks**: world `w` of `W` runs on rank `w · R / W` (contiguous blocks of
//!   world ids, so neighbouring territories of the blocks partitioner share a rank). Every
//!   rank builds the same partition from the same scene; a rank with no world takes part in
//!   the reductions only.
//! - **Messages**: ghosts, migrations and their anti-messages (and conservative mode's null
//!   messages) between worlds of one rank go straight into the inbox; to another rank they
//!   travel as one batch per destination per action, encoded as exact words ([`wire`]) and
//!   sent with non-blocking `MPI_Isend`, received by `MPI_Improbe`/`MPI_Mrecv`. A batch that
//!   does not decode is fatal. Inputs are never sent: every rank posts the run's scheduled
//!   inputs to its own worlds.
//! - **GVT**: ROSS-style synchronous rounds (SPEC.md §14, with its proof): each rank stops
//!   sending, then every rank repeatedly receives what has arrived and all-gathers (messages
//!   sent to other ranks, messages received from them, the minimum of its worlds' GVT
//!   bounds, a stop flag) until the sums of sent and received messages are equal; GVT is
//!   then the minimum of the bounds. A round that waits too long for messages in transit
//!   (they were lost) stops the run.
//! - **Committing**: steps below GVT are final; every rank sends its worlds' states and events
//!   of those steps to rank 0 (`MPI_Gatherv` of their words), which merges, sorts by id and
//!   hashes them exactly as the reference does and hands the frames to the sink. Every rank
//!   then fossil-collects its worlds.
//! - **Load balancing** (`BalanceConfig::enabled`): at a balancing round every rank holds the
//!   same loads and the whole domain's final states (all-gathered), so every rank takes the
//!   same decision; cells move between worlds on any ranks.
//! - **Faults**: a world's panic or a batch that does not decode makes its rank print an error
//!   naming the rank, the world and the step, and call `MPI_Abort`, which stops every rank.

mod rank;
pub mod wire;

mod parallel;

pub use rank::{run_mpi_controlled, MpiOptions, MpiReport, MpiSetup, Sink};

use super::error::MpiError;
use mpi::environment::Universe;
use mpi::topology::{Communicator, SimpleCommunicator};
use std::sync::Mutex;

/// The MPI environment of this process, while a [`Session`] holds it.
static UNIVERSE: Mutex<Option<Universe>> = Mutex::new(None);

/// Whether the MPI library granted `MPI_THREAD_FUNNELED` (worker threads beside the one
/// that calls MPI) when this process initialised it.
static FUNNELED: Mutex<bool> = Mutex::new(false);

/// Whether a rank may run its worlds on several threads (the MPI library granted
/// `MPI_THREAD_FUNNELED`).
pub(crate) fn threads_allowed() -> bool {
    *FUNNELED.lock().unwrap_or_else(|e| e.into_inner())
}

/// MPI initialised for this process: `MPI_Init` when the first session starts,
/// `MPI_Finalize` when it ends. MPI can be initialised once per process, so a process runs
/// its MPI runs within one session (the `soda` binary starts one before anything else in an
/// MPI run, to know its rank; [`run_mpi_controlled`] starts one itself if none is held).
pub struct Session {
    rank: usize,
    size: usize,
    /// Whether this session initialised MPI (and finalises it when dropped).
    owner: bool,
}

impl Session {
    /// Initialises MPI, or joins the session already open in this process.
    pub fn init() -> Result<Self, MpiError> {
        let mut universe = UNIVERSE.lock().unwrap_or_else(|e| e.into_inner());
        let owner = universe.is_none();
        if owner {
            if mpi::environment::is_initialized() {
                return Err(MpiError::Init);
            }
            // Funneled: a rank's worker threads compute, only its main thread calls MPI.
            let (u, level) =
                mpi::initialize_with_threading(mpi::Threading::Funneled).ok_or(MpiError::Init)?;
            *universe = Some(u);
            *FUNNELED.lock().unwrap_or_else(|e| e.into_inner()) = level >= mpi::Threading::Funneled;
        }
        let world = SimpleCommunicator::world();
        Ok(Session {
            rank: world.rank() as usize,
            size: world.size() as usize,
            owner,
        })
    }

    /// This process's rank if a session is open in it (`None`: no session, and none is
    /// started, so no MPI call is made).
    pub fn open_rank() -> Option<usize> {
        let universe = UNIVERSE.lock().unwrap_or_else(|e| e.into_inner());
        universe
            .as_ref()
            .map(|_| SimpleCommunicator::world().rank() as usize)
    }

    /// This process's rank (0 writes the run's outputs).
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// The number of ranks.
    pub fn size(&self) -> usize {
        self.size
    }

    /// Whether this is rank 0, the one that commits frames and writes outputs.
    pub fn is_root(&self) -> bool {
        self.rank == 0
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        if self.owner {
            // Dropping the universe calls MPI_Finalize.
            drop(UNIVERSE.lock().unwrap_or_else(|e| e.into_inner()).take());
        }
    }
}

/// Test-only faults planted in the transport (`SODA_MPI_PLANTED_BUG`, read once per run),
/// to prove the checks catch them: `drop-anti` (anti-messages to other ranks are counted as
/// sent but never sent, so the next GVT round finds them missing),
/// `corrupt` (the first batch a rank sends has a flipped bit), `panic:R:S` (rank R panics in
/// a world's action from step S on). Never for real runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum PlantedTransportBug {
    /// No fault.
    None,
    /// Anti-messages bound for another rank are dropped.
    DropAnti,
    /// The first batch sent by each rank is damaged after sealing.
    Corrupt,
    /// Rank `.0` panics when one of its worlds acts at step `.1` or later.
    Panic(usize, u64),
}

impl PlantedTransportBug {
    /// The fault the environment asks for.
    pub(crate) fn from_env() -> Self {
        let Ok(v) = std::env::var("SODA_MPI_PLANTED_BUG") else {
            return Self::None;
        };
        match v.as_str() {
            "drop-anti" => Self::DropAnti,
            "corrupt" => Self::Corrupt,
            other => {
                let mut parts = other.strip_prefix("panic:").unwrap_or("").split(':');
                match (
                    parts.next().and_then(|r| r.parse().ok()),
                    parts.next().and_then(|s| s.parse().ok()),
                ) {
                    (Some(r), Some(s)) => Self::Panic(r, s),
                    _ => Self::None,
                }
            }
        }
    }
}
