//! Committed frames and the events a step can report.

use crate::model::{BodyId, Step};
use serde::{Deserialize, Serialize};

/// The kernel's own event: an entity whose home position lies outside the grid was removed
/// (SPEC.md §3, "Leaving the grid"). Every model's event type converts from it
/// ([`crate::CellModel::Event`]); a model without events of its own uses `LeftGrid` itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct LeftGrid;

/// An event raised while computing step `step` → `step + 1`: what happened (`kind`, the
/// model's own event type, [`crate::CellModel::Event`]) to which entity.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Event<K> {
    /// The step being computed.
    pub step: Step,
    /// The entity concerned.
    pub body: BodyId,
    /// What happened.
    pub kind: K,
}

/// One committed step: the canonical hash of the state at `step`, and what happened while
/// computing it from `step - 1` (events sorted by (body, kind)).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Frame<K> {
    /// The step this frame describes.
    pub step: Step,
    /// Canonical state hash at `step`.
    pub hash: u64,
    /// Number of bodies at `step`.
    pub bodies: usize,
    /// Events raised computing `step - 1` → `step`.
    pub events: Vec<Event<K>>,
}

/// Which committed steps a frame sink wants the full states of; every other step reaches
/// the sink as a [`Frame`] only (hash, body count, events), which costs nothing extra.
/// Executors clone states only for the steps asked for.
#[derive(Clone, Debug, Default)]
pub struct StatesWanted {
    /// Every step that is a multiple of this (0: none).
    pub every: u64,
    /// This one step (typically the last).
    pub step: Option<Step>,
    /// Every step whose hash differs from `expected[step - 1]` (a verifier's cheap way to
    /// capture exactly the first divergent state, even from a non-reproducible run).
    pub unexpected: Option<std::sync::Arc<Vec<u64>>>,
}

impl StatesWanted {
    /// No states at all.
    pub fn none() -> Self {
        Self::default()
    }

    /// The states of step `step` only.
    pub fn at(step: Step) -> Self {
        StatesWanted {
            step: Some(step),
            ..Self::default()
        }
    }

    /// Whether step `step`, whose canonical hash is `hash`, is wanted.
    pub fn wants(&self, step: Step, hash: u64) -> bool {
        (self.every > 0 && step % self.every == 0)
            || self.step == Some(step)
            || self
                .unexpected
                .as_ref()
                .is_some_and(|e| step >= 1 && e.get(step as usize - 1).is_some_and(|&h| h != hash))
    }
}
