//! The examples the README points users to run to the end (an example that panics is the
//! first thing a new user meets: `custom_model` once stamped its live input at a fixed step
//! that the threaded executor's GVT had often already passed).

#[path = "../examples/custom_model.rs"]
mod custom_model;

#[test]
fn the_custom_model_example_runs_to_the_end_with_its_hashes_equal() {
    for _ in 0..5 {
        custom_model::main().unwrap();
    }
}
