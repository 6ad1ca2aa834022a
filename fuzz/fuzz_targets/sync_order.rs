//! Fuzzes the delivery order of the Time Warp kernel's messages: the input picks a small
//! scene and kernel configuration, and its tail drives every decision of the virtual
//! executor (which world acts, which in-flight message is delivered). Every committed frame
//! must equal the reference run's; a divergence panics with the first differing step, the
//! configuration and the schedule string that replays it.
//!
//! `SODA_PLANTED_BUG=drop-lone-anti` or `cutoff-by-ids-only` switches on a deliberate kernel
//! bug, to show the fuzzer finds it.
#![no_main]

use libfuzzer_sys::fuzz_target;
use soda::fuzzing::{check_sync_order, SyncOrderInput};
use soda::kernel::PlantedBug;
use std::sync::OnceLock;

fn planted_bug() -> PlantedBug {
    static BUG: OnceLock<PlantedBug> = OnceLock::new();
    *BUG.get_or_init(|| match std::env::var("SODA_PLANTED_BUG").as_deref() {
        Err(_) | Ok("") | Ok("none") => PlantedBug::None,
        Ok("drop-lone-anti") => PlantedBug::DropLoneAnti,
        Ok("cutoff-by-ids-only") => PlantedBug::CutoffByIdsOnly,
        Ok(other) => panic!(
            "SODA_PLANTED_BUG={other:?}: expected drop-lone-anti, cutoff-by-ids-only or none"
        ),
    })
}

fuzz_target!(|input: SyncOrderInput| {
    if let Err(e) = check_sync_order(&input, planted_bug()) {
        panic!("{e}");
    }
});
