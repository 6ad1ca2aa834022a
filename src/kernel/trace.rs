//! Run traces for analysis (SPEC.md §K9, "Traces"): each world's LVT over time, every
//! rollback (start step, length, cells recomputed, cause), GVT advances and messages per step.
//!
//! A world records its own part ([`WorldTrace`]) without reading a clock: the executor passes
//! the time (seconds since the run started) in. Tracing only observes; it never changes what
//! a world computes, so a traced run commits the same bits as an untraced one.

use super::partition::WorldId;
use crate::grid::Grid;
use crate::model::Step;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// What made a world roll back (SPEC.md §K5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RollbackCause {
    /// At least one positive message of the batch was late (a primary rollback).
    Straggler,
    /// Only anti-messages caused it (a secondary rollback).
    AntiMessage,
}

/// One rollback of one world.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RollbackRecord {
    /// The world that rolled back.
    pub world: WorldId,
    /// When (seconds since the run started).
    pub time: f64,
    /// The earliest step made dirty.
    pub start: Step,
    /// `head − start`, in steps.
    pub length: Step,
    /// Cell computations the repair re-executed (attributed to the latest rollback until the
    /// world has no dirty step left).
    pub cells_recomputed: u64,
    /// Straggler or anti-message.
    pub cause: RollbackCause,
}

/// A world's LVT at a time.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LvtSample {
    /// The world.
    pub world: WorldId,
    /// Seconds since the run started.
    pub time: f64,
    /// Its LVT after an action.
    pub lvt: Step,
}

/// A GVT advance.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GvtSample {
    /// Seconds since the run started.
    pub time: f64,
    /// The new GVT.
    pub gvt: Step,
}

/// Messages sent, stamped with one step, summed over worlds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StepMessages {
    /// The step the messages are stamped with.
    pub step: Step,
    /// Positive messages (ghosts, migrations, null messages).
    pub positive: u64,
    /// Anti-messages.
    pub anti: u64,
}

/// One world's trace buffer.
#[derive(Clone, Debug, Default)]
pub struct WorldTrace {
    now: f64,
    lvt: Vec<LvtSample>,
    rollbacks: Vec<RollbackRecord>,
    open: Option<usize>,
    messages: BTreeMap<Step, (u64, u64)>,
    recomputations: Vec<(Step, u32)>,
}

impl WorldTrace {
    /// Sets the time of what is recorded next (the executor calls this before an action).
    pub fn set_time(&mut self, now: f64) {
        self.now = now;
    }

    /// Records `lvt` for `world` if it changed since the last sample.
    pub fn sample_lvt(&mut self, world: WorldId, lvt: Step) {
        if self.lvt.last().map(|s| s.lvt) != Some(lvt) {
            self.lvt.push(LvtSample {
                world,
                time: self.now,
                lvt,
            });
        }
    }

    pub(crate) fn rollback(&mut self, world: WorldId, start: Step, length: Step, primary: bool) {
        self.open = Some(self.rollbacks.len());
        self.rollbacks.push(RollbackRecord {
            world,
            time: self.now,
            start,
            length,
            cells_recomputed: 0,
            cause: if primary {
                RollbackCause::Straggler
            } else {
                RollbackCause::AntiMessage
            },
        });
    }

    pub(crate) fn recomputed(&mut self, step: Step, cell: u32) {
        if let Some(i) = self.open {
            self.rollbacks[i].cells_recomputed += 1;
        }
        self.recomputations.push((step, cell));
    }

    /// Every re-executed cell computation as (step, cell), in the order they ran.
    pub fn recomputations(&self) -> &[(Step, u32)] {
        &self.recomputations
    }

    pub(crate) fn repaired(&mut self) {
        self.open = None;
    }

    pub(crate) fn sent(&mut self, step: Step, anti: bool) {
        let e = self.messages.entry(step).or_default();
        if anti {
            e.1 += 1;
        } else {
            e.0 += 1;
        }
    }
}

/// The trace of a whole run: the worlds' parts merged (each list sorted by time, then world).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunTrace {
    /// Number of worlds.
    pub worlds: usize,
    /// Grid dimensions (cells along x, y, z).
    pub grid: [i32; 3],
    /// Owner world of every cell, in cell index order (x fastest, then y, then z is the
    /// grid's own index order, SPEC.md §3).
    pub owners: Vec<WorldId>,
    /// Each world's LVT whenever it changed.
    pub lvt: Vec<LvtSample>,
    /// GVT advances.
    pub gvt: Vec<GvtSample>,
    /// Every rollback.
    pub rollbacks: Vec<RollbackRecord>,
    /// Messages sent per stamped step.
    pub messages: Vec<StepMessages>,
    /// Re-executions per cell (index, count), ascending cell index.
    pub recomputed_cells: Vec<(u32, u64)>,
}

/// The most worlds a trace may name ([`RunTrace::check`]): far more than any run has, and a
/// bound on what drawing it allocates per world.
pub const MAX_TRACE_WORLDS: usize = 1 << 20;

/// A trace read from a file that does not describe a run ([`RunTrace::check`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("field `{field}` = {value} is invalid: {allowed}")]
pub struct TraceError {
    /// The field, as a path (`owners[12]`).
    pub field: String,
    /// The value found.
    pub value: String,
    /// What it must be.
    pub allowed: String,
}

impl RunTrace {
    /// Checks that the trace describes a run the way [`RunTrace::merge`] builds one: at
    /// least one world, a grid of 1 to [`Grid::MAX_CELLS`] cells, an owner below `worlds`
    /// for every cell, worlds and cells in range wherever they are named. A hand-edited or
    /// foreign trace is refused naming the first field that is not (`soda plot` checks this
    /// before drawing).
    pub fn check(&self) -> Result<(), TraceError> {
        let bad = |field: String, value: String, allowed: String| {
            Err(TraceError {
                field,
                value,
                allowed,
            })
        };
        if self.worlds == 0 || self.worlds > MAX_TRACE_WORLDS {
            return bad(
                "worlds".into(),
                self.worlds.to_string(),
                format!("a run has 1 to {MAX_TRACE_WORLDS} worlds"),
            );
        }
        if self.grid.iter().any(|&n| n < 1) {
            return bad(
                "grid".into(),
                format!("{:?}", self.grid),
                "every dimension must be 1 or more".into(),
            );
        }
        // In u128: three i32 dimensions cannot overflow it.
        let cells: u128 = self.grid.iter().map(|&n| n as u128).product();
        if cells > Grid::MAX_CELLS as u128 {
            return bad(
                "grid".into(),
                format!("{:?}", self.grid),
                format!("at most {} cells", Grid::MAX_CELLS),
            );
        }
        let cells = cells as u64;
        if self.owners.len() as u64 != cells {
            return bad(
                "owners".into(),
                format!("{} entries", self.owners.len()),
                format!("one owner per cell of the grid: {cells}"),
            );
        }
        let world = |field: String, w: WorldId| {
            if (w as usize) < self.worlds {
                Ok(())
            } else {
                bad(
                    field,
                    w.to_string(),
                    format!("a world below `worlds` = {}", self.worlds),
                )
            }
        };
        for (i, &w) in self.owners.iter().enumerate() {
            world(format!("owners[{i}]"), w)?;
        }
        for (i, s) in self.lvt.iter().enumerate() {
            world(format!("lvt[{i}].world"), s.world)?;
        }
        for (i, r) in self.rollbacks.iter().enumerate() {
            world(format!("rollbacks[{i}].world"), r.world)?;
        }
        for (i, &(cell, _)) in self.recomputed_cells.iter().enumerate() {
            if cell as u64 >= cells {
                return bad(
                    format!("recomputed_cells[{i}]"),
                    cell.to_string(),
                    format!("a cell index below the grid's {cells} cells"),
                );
            }
        }
        Ok(())
    }

    /// Merges the worlds' traces (in world order) with the executor's GVT samples.
    pub fn merge(
        grid: [i32; 3],
        owners: Vec<WorldId>,
        parts: Vec<WorldTrace>,
        gvt: Vec<GvtSample>,
    ) -> RunTrace {
        let worlds = parts.len();
        let mut lvt = Vec::new();
        let mut rollbacks = Vec::new();
        let mut messages: BTreeMap<Step, (u64, u64)> = BTreeMap::new();
        let mut recomputed: BTreeMap<u32, u64> = BTreeMap::new();
        for p in parts {
            lvt.extend(p.lvt);
            rollbacks.extend(p.rollbacks);
            for (s, (pos, anti)) in p.messages {
                let e = messages.entry(s).or_default();
                e.0 += pos;
                e.1 += anti;
            }
            for (_, c) in p.recomputations {
                *recomputed.entry(c).or_default() += 1;
            }
        }
        lvt.sort_by(|a, b| a.time.total_cmp(&b.time).then(a.world.cmp(&b.world)));
        rollbacks.sort_by(|a, b| a.time.total_cmp(&b.time).then(a.world.cmp(&b.world)));
        RunTrace {
            worlds,
            grid,
            owners,
            lvt,
            gvt,
            rollbacks,
            messages: messages
                .into_iter()
                .map(|(step, (positive, anti))| StepMessages {
                    step,
                    positive,
                    anti,
                })
                .collect(),
            recomputed_cells: recomputed.into_iter().collect(),
        }
    }
}
