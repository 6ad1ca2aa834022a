//! Example models besides rigid bodies, built only on the public [`crate::CellModel`] seam:
//! an agent-based epidemic ([`epidemic`]: flocking agents that infect, recover, are born and
//! die) and a PHOLD-like synthetic workload ([`phold`]) with the knobs PDES researchers use
//! to dial load and coupling. Both run on every executor, through `verify` and the CLI
//! (`soda run --model epidemic`).

pub mod epidemic;
pub mod phold;
mod random;
