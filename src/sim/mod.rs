//! Running a model: [`Runner`] runs any [`crate::CellModel`] on any executor and returns one
//! [`ModelReport`] (or one [`crate::ExecError`]); [`verify`](crate::verify) builds on it. The
//! rigid-body model has thin wrappers: [`run_scene`], [`Simulation`], and physics
//! measurements of a state ([`StateReport`]).

mod offset;
mod options;
mod report;
mod rigid;
mod runner;

pub use options::{ExecutorKind, RunOptions, UnknownExecutor};
pub use report::{KernelReport, ModelReport, MpiStats};
pub use rigid::{
    measure, measure_state, run_scene, run_scene_controlled, run_scene_from, ResumeFrom, RunReport,
    Simulation, StateReport,
};
pub use runner::{run_model, Runner};
