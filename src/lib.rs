//! SODA: deterministic, optimistic (Time Warp) parallel simulation of rigid bodies on a
//! uniform spatial grid.
//!
//! Layers, lowest first (a lower layer never imports a higher one):
//! - [`math`], [`grid`], [`physics`]: pure computation — vectors, the uniform grid, the
//!   rigid-body cell model;
//! - [`model`], [`state`], [`hash`], [`frame`]: the seam between a kernel and a cell model,
//!   the per-cell state of the whole domain, the canonical state hash, committed frames;
//! - [`exec`]: executors (the single-threaded reference run);
//! - [`scene`]: scene description, builder, built-in scenes and scene files (the only layer
//!   that reads files, besides the binary).
//!
//! SPEC.md is the precise contract.

pub mod divergence;
pub mod exec;
pub mod frame;
pub mod fuzzing;
pub mod grid;
pub mod hash;
pub mod kernel;
pub mod math;
pub mod model;
pub mod models;
pub mod physics;
pub mod scaling;
pub mod scene;
pub mod sim;
pub mod state;
pub mod verify;

/// The generic path in one import: implement [`CellModel`], run it with [`Runner`] on any
/// executor, check it with [`verify`](crate::verify).
pub mod prelude {
    pub use crate::exec::control::RunControl;
    pub use crate::exec::error::{ContractRule, ContractViolation, ExecError, InputError};
    pub use crate::frame::{Event, Frame, LeftGrid, StatesWanted};
    pub use crate::grid::{CellCoord, Grid};
    pub use crate::hash::StateHash;
    pub use crate::kernel::{GhostPolicy, Input, KernelConfig, PartitionKind, RollbackMode};
    pub use crate::model::{exact_f32, BodyId, CellModel, Neighbourhood, Step};
    pub use crate::sim::{run_model, ExecutorKind, ModelReport, RunOptions, Runner};
    pub use crate::verify::{verify, VerifyOptions, VerifyReport, VerifySetup};
}

pub use exec::control::RunControl;
pub use exec::error::{ExecError, InputError};
pub use exec::reference::ReferenceRun;
pub use frame::{Event, Frame, LeftGrid};
pub use grid::{CellCoord, Grid};
pub use hash::StateHash;
pub use model::{BodyId, CellModel, Neighbourhood, Step};
pub use physics::EventKind;
pub use physics::{Body, RigidBodyModel, Shape};
pub use scene::{Scene, SceneBuilder, SceneError};
pub use sim::{run_model, ModelReport, RunOptions, RunReport, Runner, Simulation, StateReport};
