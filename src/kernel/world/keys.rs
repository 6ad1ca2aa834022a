//! The keys of a slot's maps (what a world received, sent and holds migrating in at a step),
//! with named fields instead of tuples. Each derives its order from its fields in
//! declaration order, so a map iterates as the tuple it replaces did.

use crate::kernel::message::MessageKind;
use crate::kernel::partition::WorldId;
use std::ops::RangeInclusive;

/// Bodies migrating into a step from a foreign cell: the own cell they land in, then the
/// foreign cell they come from (both global). Ordered destination first, so the migrations
/// into one cell are one range ([`MigrationIn::into_cell`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct MigrationIn {
    /// The own cell the bodies land in (global).
    pub(super) dst_cell: u32,
    /// The foreign cell whose computation sent them (global).
    pub(super) src_cell: u32,
}

impl MigrationIn {
    /// Every key of migrations into own cell `dst_cell` (global), from any source.
    pub(super) fn into_cell(dst_cell: u32) -> RangeInclusive<MigrationIn> {
        MigrationIn {
            dst_cell,
            src_cell: 0,
        }..=MigrationIn {
            dst_cell,
            src_cell: u32::MAX,
        }
    }
}

/// What a world received about a step: the message kind and the cell it comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct RecvKey {
    /// Ghost or migrate.
    pub(super) kind: MessageKind,
    /// The sending cell (global).
    pub(super) src_cell: u32,
}

/// What a world sent about a step: the message kind, the own cell it is about and the world
/// it went to. One live version per key at most (lazy cancellation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct SentKey {
    /// Ghost or migrate.
    pub(super) kind: MessageKind,
    /// The own cell the message is about: the ghosted cell, or the cell whose computation
    /// produced the migrating bodies (global).
    pub(super) src_cell: u32,
    /// The receiving world.
    pub(super) dst_world: WorldId,
}
