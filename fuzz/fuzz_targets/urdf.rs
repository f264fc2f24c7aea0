//! URDF bytes -> the scene loader (`model.kind = "urdf"`): never a panic; every error in the file
//! located, and none quoting a file that is not XML (`progmo::fuzzing::robot`).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    progmo::fuzzing::urdf(data);
});
