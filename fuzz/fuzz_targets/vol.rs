//! Fuzzes `lucent::fuzzing::Target::Vol` (see src/fuzzing.rs).
#![no_main]

use libfuzzer_sys::fuzz_target;
use lucent::fuzzing::{Target, run};

fuzz_target!(|data: &[u8]| {
    let _ = run(Target::Vol, data);
});
