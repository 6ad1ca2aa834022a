//! The rigid-body model's events: rules that altered or ended a body's motion.

use crate::frame::LeftGrid;
use serde::{Deserialize, Serialize};

/// Why a body's motion was altered or ended by a rule rather than by physics (the rigid-body
/// model's [`crate::CellModel::Event`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EventKind {
    /// The body's speed or per-step displacement exceeded the grid's allowance and was
    /// capped (SPEC.md §3).
    SpeedCapped,
    /// The body's centre left the domain; it was removed.
    LeftDomain,
}

impl EventKind {
    /// The kebab-case name used in reports and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            EventKind::SpeedCapped => "speed-capped",
            EventKind::LeftDomain => "left-domain",
        }
    }
}

/// A body the kernel removed for leaving the grid left the domain.
impl From<LeftGrid> for EventKind {
    fn from(_: LeftGrid) -> Self {
        EventKind::LeftDomain
    }
}
