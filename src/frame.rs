//! Committed frames and the events a step can report.

use crate::model::{BodyId, Step};
use serde::{Deserialize, Serialize};

/// Why a body's motion was altered or ended by a rule rather than by physics.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EventKind {
    /// The body's speed or per-step displacement exceeded the grid's allowance and was
    /// capped (SPEC.md §Grid).
    SpeedCapped,
    /// The body's centre left the domain; it was removed.
    LeftDomain,
}

/// An event raised while computing step `step` → `step + 1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Event {
    /// The step being computed.
    pub step: Step,
    /// The body concerned.
    pub body: BodyId,
    /// What happened.
    pub kind: EventKind,
}

/// One committed step: the canonical hash of the state at `step`, and what happened while
/// computing it from `step - 1` (events sorted by (body, kind)).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Frame {
    /// The step this frame describes.
    pub step: Step,
    /// Canonical state hash at `step`.
    pub hash: u64,
    /// Number of bodies at `step`.
    pub bodies: usize,
    /// Events raised computing `step - 1` → `step`.
    pub events: Vec<Event>,
}
