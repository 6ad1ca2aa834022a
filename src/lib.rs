//! SODA: deterministic, optimistic (Time Warp) parallel simulation on a uniform spatial
//! grid, with rigid bodies as its built-in model.
//!
//! Space is a grid of cells; groups of cells (territories) belong to *worlds*, logical
//! processes that run ahead optimistically, exchange timestamped messages about entities
//! near their borders and roll back only the cells a late message affects. Every committed
//! step is bit-identical to a single-threaded reference run, under any thread count,
//! partition, rollback mode and interleaving. SPEC.md is the precise contract.
//!
//! # Bring your own model
//!
//! SODA is a framework: implement [`CellModel`] for your entities and every executor,
//! [`verify`](mod@verify), the fuzzing checks ([`fuzzing::check_model_sync_order`]), the
//! kernel's counters and traces work for it. A model says what an entity is ([`CellModel::State`]),
//! its id and position, and how one cell's entities step from their 27-cell neighbourhood:
//!
//! ```
//! use soda::prelude::*;
//!
//! /// Walkers drifting along x, slowed by every neighbour within 0.5 m.
//! #[derive(Clone)]
//! struct Drift;
//!
//! #[derive(Clone, Debug, PartialEq)]
//! struct Walker { id: u64, pos: [f32; 3], speed: f32 }
//!
//! impl CellModel for Drift {
//!     type State = Walker;
//!     type Event = LeftGrid; // no events of its own
//!     fn id(w: &Walker) -> BodyId { w.id }
//!     fn position(w: &Walker) -> [f32; 3] { w.pos }
//!     fn step_cell(&self, _step: Step, _grid: &Grid, nb: &Neighbourhood<'_, Walker>,
//!                  out: &mut Vec<Walker>, _events: &mut Vec<Event<LeftGrid>>) {
//!         for w in nb.own() {
//!             let crowd = nb.iter().filter(|o| o.id != w.id && (o.pos[0] - w.pos[0]).abs() < 0.5).count();
//!             let speed = w.speed / (1.0 + crowd as f32);
//!             out.push(Walker { pos: [w.pos[0] + speed, w.pos[1], w.pos[2]], speed, ..w.clone() });
//!         }
//!     }
//!     fn hash_state(w: &Walker, h: &mut StateHash) {
//!         h.u64(w.id);
//!         w.pos.iter().for_each(|&v| h.f32(v));
//!         h.f32(w.speed);
//!     }
//! }
//!
//! let grid = Grid::covering(soda::math::Vec3::zeros(), soda::math::Vec3::new(8.0, 1.0, 1.0), 1.0);
//! let walkers: Vec<Walker> = (0..12).map(|i| Walker { id: i, pos: [0.3 * i as f32, 0.5, 0.5], speed: 0.2 }).collect();
//! // Any executor, the same bits:
//! let reference = Runner::new(Drift, grid.clone(), walkers.clone()).run_quiet(30)?;
//! let threaded = Runner::new(Drift, grid.clone(), walkers.clone())
//!     .options(RunOptions::threaded(KernelConfig::new(4), 2))
//!     .run_quiet(30)?;
//! assert_eq!(reference.hash, threaded.hash);
//! // Evidence, with diagnoses if it fails:
//! let options = VerifyOptions { steps: 20, schedules: 2, repeats: 1, ..VerifyOptions::default() };
//! assert!(verify(&VerifySetup::new(Drift, grid, walkers), &options).passed());
//! # Ok::<(), soda::ExecError>(())
//! ```
//!
//! The rules a model keeps are on [`CellModel`]; `examples/custom_model.rs` is a complete
//! model with inputs and the CLI, `examples/epidemic.rs` and `examples/phold.rs` run the
//! two example models of [`models`].
//!
//! # Layers
//!
//! Lowest first; a lower layer never imports a higher one:
//! - [`math`], [`grid`], [`physics`]: pure computation — vectors, the uniform grid, the
//!   rigid-body cell model;
//! - [`model`], [`state`], [`hash`], [`frame`]: the seam between a kernel and a cell model,
//!   the per-cell state of the whole domain, the canonical state hash, committed frames;
//!   [`text`]: counts written for people;
//!   [`models`]: example models built on that seam only;
//! - [`kernel`]: the pure, single-threaded Time Warp protocol (worlds, messages, GVT,
//!   balancing);
//! - [`exec`]: executors, each with its own options beside the kernel's configuration — the
//!   single-threaded reference, the virtual executor (one thread, a seeded replayable
//!   schedule) and the threaded one (the only module that starts
//!   threads), the contract checker, run control and errors;
//! - [`sim`], [`verify`](mod@verify), [`fuzzing`], [`divergence`], [`scaling`]: running a
//!   model and checking it;
//! - [`scene`]: scene description, builder, built-in scenes and scene files (with the
//!   binary's CLI, behind the default `cli` feature, the only I/O).

#![warn(missing_docs)]

#[cfg(feature = "cli")]
pub mod app;
pub mod checkpoint;
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
pub mod text;
pub mod verify;

/// The generic path in one import: implement [`CellModel`], run it with [`Runner`] on any
/// executor, check it with [`verify`](mod@crate::verify).
pub mod prelude {
    pub use crate::exec::control::RunControl;
    pub use crate::exec::error::{ContractRule, ContractViolation, ExecError, InputError};
    pub use crate::exec::virtual_exec::{ScheduleSpec, VirtualOptions};
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
