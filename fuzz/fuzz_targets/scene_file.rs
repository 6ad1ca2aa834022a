//! Fuzzes the scene file parser and validator: arbitrary bytes are read as a TOML and as a
//! JSON scene. Nothing may panic, an accepted scene must survive a write/read round trip,
//! and a small accepted scene is stepped twice in the reference executor.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|bytes: &[u8]| {
    soda::fuzzing::check_scene_file(bytes);
});
