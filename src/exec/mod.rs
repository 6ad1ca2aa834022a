//! Executors: ways of running a cell model over the grid. Each yields the same committed
//! frames; the reference is the oracle.

pub mod reference;
pub mod sync;
pub mod threaded;
pub mod virtual_exec;
