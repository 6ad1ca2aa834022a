//! The Time Warp kernel: territories, messages, worlds (logical processes with per-cell
//! checkpoint logs), the GVT rule and counters. Pure and single-threaded: no threads, no
//! I/O, no clocks. Executors (`crate::exec`) drive worlds and carry messages between them.
//!
//! The contract is in SPEC.md §9: the state of a cell at a
//! step is the unit of logs, ghosts and comparison; messages are applied in a total order
//! (never arrival order); committed steps are bit-identical to the reference run whatever
//! the partition, rollback mode, window and delivery order.
//!
//! Modules, lowest first:
//! - [`config`]: the worlds' configuration (worlds, mode, window, partition, ghosts,
//!   balancing);
//! - [`partition`]: cell → world maps (blocks, equal-size k-means, random, explicit);
//! - [`message`]: ghost / migrate / anti-messages and their total order;
//! - [`counters`]: per-world and total statistics and their formulas;
//! - [`gvt`]: the global virtual time rule;
//! - [`balance`]: load balancing by cell cession (load levels, cession, famine);
//! - [`world`]: one logical process (receive, act, fossil-collect);
//! - [`synthetic`]: a tiny non-physics cell model for tests, benches and fuzzing.

pub mod balance;
pub mod config;
pub mod counters;
pub mod gvt;
pub mod message;
pub mod partition;
pub mod shared_states;
pub mod synthetic;
pub mod trace;
pub mod world;

pub use balance::{Balancer, LoadLevel, RoundRecord};
pub use config::{
    BalanceConfig, GhostPolicy, KernelConfig, LoadSource, PartitionKind, PlantedBug, RollbackMode,
    WindowSpec,
};
pub use counters::{BalanceCounters, Counters, WorldCounters};
pub use message::{Edit, EntityEdit, Homed, Input, Message, MessageKey, MessageKind, Sign};
pub use partition::{Partition, WorldId};
pub use shared_states::SharedStates;
pub use trace::{RunTrace, TraceError, WorldTrace};
pub use world::{LogBytes, World};
