//! `verify`: evidence that a model commits the same bits on every executor, for any
//! [`CellModel`](crate::CellModel).
//!
//! [`verify`] runs the reference twice (a model that is not reproducible — hidden state,
//! unseeded randomness — shows there), once more under the contract checker
//! ([`crate::exec::contract`]), then the virtual executor under several seeded schedules and
//! the threaded executor several times, per rollback mode; it compares every committed
//! step's hash with the reference's and, at the first mismatch of a run, names the step,
//! entity, cell and field that differ with their exact bits. [`VerifyReport::diagnosis`]
//! says what the failures point at.
//!
//! ```
//! use soda::kernel::synthetic::Particles;
//! use soda::verify::{verify, VerifyOptions, VerifySetup};
//!
//! let (model, grid, initial) = Particles::scene(30, [4, 2, 2], false, 1);
//! let options = VerifyOptions { steps: 15, schedules: 2, repeats: 1, ..VerifyOptions::default() };
//! let report = verify(&VerifySetup::new(model, grid, initial), &options);
//! assert!(report.passed(), "{}", report.summary());
//! ```

mod diagnosis;
mod report;
mod runs;

pub use diagnosis::Diagnosis;
pub use report::{Mismatch, RunCheck, RunOutcome, VerifyReport};
pub use runs::{verify, verify_with_progress, VerifyOptions, VerifySetup};
