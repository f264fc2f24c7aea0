//! Scene text -> `Scene::from_text`: any input must give `Ok` or a located `Err`, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    progmo::fuzzing::scene(data);
});
