//! Global virtual time (SPEC.md §GVT).
//!
//! GVT is the smallest step whose state may still change. It is the minimum of
//! - for every world, its local bound: `min(LVT, earliest dirty step) + 1` (optimistic
//!   modes; LVT = the next step it will compute) or `min over its cells of the next step to
//!   compute + 1` (conservative), and the `affects` step of every message in its inbox;
//! - the `affects` step of every message in flight (sent, not yet in an inbox).
//!
//! States at steps below GVT are final: no world can recompute them and no message can
//! change them. They are committed and fossil-collected.
//!
//! In the virtual executor everything is visible, so GVT is computed exactly after every
//! action. A threaded executor uses the same local bounds with the Fujimoto–Hybinette
//! shared-memory scheme: sending is an atomic push into the receiver's inbox (so no
//! message is ever "in the network"), and a GVT round asks every world for its local bound
//! *after* a flag is raised, each world also reporting the smallest `affects` of messages
//! it sent since the flag; the minimum of the reports is a lower bound of the true GVT.

use crate::model::Step;

/// The minimum of local bounds and in-flight message bounds; `None` if both are empty.
pub fn global_virtual_time(
    local_bounds: impl IntoIterator<Item = Step>,
    in_flight: impl IntoIterator<Item = Step>,
) -> Option<Step> {
    local_bounds.into_iter().chain(in_flight).min()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gvt_is_the_minimum_of_worlds_and_messages() {
        assert_eq!(global_virtual_time([5, 7], [6]), Some(5));
        assert_eq!(global_virtual_time([5, 7], [3]), Some(3));
        assert_eq!(global_virtual_time([], []), None);
    }
}
