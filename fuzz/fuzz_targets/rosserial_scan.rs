//! cargo-fuzz target: [`rdm_fuzz::rosserial_scan::check`] on every input.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| rdm_fuzz::rosserial_scan::check(data));
