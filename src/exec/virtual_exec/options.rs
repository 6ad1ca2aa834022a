//! The virtual executor's own settings: who decides the interleaving ([`ScheduleSpec`]) and
//! whether the decisions are recorded for a replay string ([`VirtualOptions`]). They are the
//! executor's, not the kernel's: the committed bits never depend on them.

use super::SCHEDULE_PREFIX;
use crate::exec::error::ScheduleParseError;
use serde::{Deserialize, Serialize};

/// Who decides, in the virtual executor, which world acts next and which in-flight message
/// is delivered next.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ScheduleSpec {
    /// A ChaCha8 generator with this seed. Replays exactly from the seed.
    Seeded(u64),
    /// The recorded decisions of an earlier run (see `VirtualRun::schedule_string`), then the
    /// deterministic fallback.
    Replay(Vec<u32>),
    /// Fuzz bytes: each decision consumes one or two bytes, then the deterministic fallback.
    Bytes(Vec<u8>),
    /// The deterministic fallback only: deliver the oldest in-flight message first, else let
    /// a world with a non-empty inbox apply it, else let the world with the smallest LVT
    /// compute (lowest id on ties). Worlds then advance in lockstep with no straggler: the
    /// overhead of the kernel alone.
    Fifo,
}

impl Default for ScheduleSpec {
    fn default() -> Self {
        ScheduleSpec::Seeded(0)
    }
}

/// How the virtual executor runs a kernel configuration: its schedule and whether it records
/// its decisions (SPEC.md §K8).
///
/// ```
/// use soda::exec::virtual_exec::{ScheduleSpec, VirtualOptions};
///
/// let options = VirtualOptions::new(ScheduleSpec::Fifo).record_schedule(false);
/// assert_eq!(VirtualOptions::default(), VirtualOptions::seeded(0));
/// assert!(!options.record_schedule);
/// ```
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct VirtualOptions {
    /// Who decides which world acts and which message is delivered next.
    pub schedule: ScheduleSpec,
    /// Record the decisions so the run can print a replay string
    /// (`VirtualRun::schedule_string`; costs four bytes per decision).
    pub record_schedule: bool,
    /// After each action, let the world compute ahead the interior of its head step
    /// (`World::compute_interior_ahead`, as the threaded executor does while a world is
    /// held back), so that stragglers meet outputs computed ahead. Off by default; the
    /// committed bits never depend on it.
    #[serde(default)]
    pub compute_ahead: bool,
}

impl Default for VirtualOptions {
    /// Seed 0, decisions recorded.
    fn default() -> Self {
        VirtualOptions::new(ScheduleSpec::default())
    }
}

impl VirtualOptions {
    /// The schedule `schedule`, decisions recorded.
    pub fn new(schedule: ScheduleSpec) -> Self {
        VirtualOptions {
            schedule,
            record_schedule: true,
            compute_ahead: false,
        }
    }

    /// A ChaCha8 schedule seeded with `seed` ([`ScheduleSpec::Seeded`]), decisions recorded.
    pub fn seeded(seed: u64) -> Self {
        Self::new(ScheduleSpec::Seeded(seed))
    }

    /// The same options with the schedule `schedule`.
    pub fn schedule(mut self, schedule: ScheduleSpec) -> Self {
        self.schedule = schedule;
        self
    }

    /// The same options with decision recording on or off.
    pub fn record_schedule(mut self, on: bool) -> Self {
        self.record_schedule = on;
        self
    }

    /// The same options with computing ahead on or off ([`VirtualOptions::compute_ahead`]).
    pub fn compute_ahead(mut self, on: bool) -> Self {
        self.compute_ahead = on;
        self
    }
}

/// Parses a string printed by `VirtualRun::schedule_string` into a replay schedule.
pub fn parse_schedule(s: &str) -> Result<ScheduleSpec, ScheduleParseError> {
    let body = s
        .trim()
        .strip_prefix(SCHEDULE_PREFIX)
        .ok_or(ScheduleParseError::MissingPrefix {
            prefix: SCHEDULE_PREFIX,
        })?;
    if body.is_empty() {
        return Ok(ScheduleSpec::Replay(Vec::new()));
    }
    body.split('.')
        .map(|t| {
            t.parse::<u32>()
                .map_err(|source| ScheduleParseError::BadDecision {
                    token: t.to_string(),
                    source,
                })
        })
        .collect::<Result<Vec<_>, _>>()
        .map(ScheduleSpec::Replay)
}
