//! Expression text -> compile -> evaluate over f64, Dual64 and Dual2_64: never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    progmo::fuzzing::expr(data);
});
