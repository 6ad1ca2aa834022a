//! Fuzzes the synchronisation order for a model that is not rigid bodies: the example SIR
//! epidemic (births, deaths, model events). Six header bytes pick the kernel configuration
//! (`soda::fuzzing::fuzz_case`), the rest drive every decision of the virtual executor;
//! every committed frame must equal the reference run's. The template for your own model.
#![no_main]

use libfuzzer_sys::fuzz_target;
use soda::fuzzing::{check_model_sync_order, fuzz_case};
use soda::models::epidemic::Epidemic;

fuzz_target!(|data: &[u8]| {
    let Some(case) = fuzz_case(data, 30) else {
        return;
    };
    let seed = data.get(6).copied().unwrap_or(0);
    let (model, grid, initial) = Epidemic::default().scene(50, 5, [4, 2, 3], u64::from(seed));
    if let Err(e) = check_model_sync_order(model, grid, initial, &case) {
        panic!("{e}");
    }
});
