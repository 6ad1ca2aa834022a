//! A command line for any model: register your models and your own binary gets `run`
//! (with `--trace`), `verify`, `experiment granularity`, `plot` and `models` for them (the
//! `cli` feature).
//!
//! ```no_run
//! use soda::app::{main_with, ModelSize, Registry};
//! use soda::kernel::synthetic::Particles;
//!
//! fn main() -> std::process::ExitCode {
//!     main_with(Registry::new().register("particles", "soft particles in a box", |s: &ModelSize| {
//!         Particles::scene(s.entities.unwrap_or(500), [8, 8, 8], false, s.seed)
//!     }))
//! }
//! ```
//!
//! `my-binary run --model particles --executor threaded --worlds 8`, `my-binary verify
//! --model particles`, `my-binary experiment granularity --model particles --windows 4,16,64`.
//! The `soda` binary registers the example models ([`Registry::examples`]) besides its
//! rigid-body scenes: `soda run --model epidemic`, `soda verify --model phold`.

pub mod allocator;
pub mod atomic;
pub mod charts;
pub mod checkpoint;
pub mod commands;
pub mod interrupt;
mod main;
pub mod numbers;
pub mod output;
pub mod plan;
mod registry;
pub mod usage;

pub use main::{
    check_checkpoint_has_a_step, check_executor_options, check_partition_seed, main_with, run_with,
    worlds_beyond_cells_warning, ModelCli,
};
pub use registry::{ModelSize, RegisteredModel, Registry};
pub use usage::{usage, UsageError};
