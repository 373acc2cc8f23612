//! cargo-fuzz target: [`rdm_fuzz::leptrino_ok_run::check`] on every input.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| rdm_fuzz::leptrino_ok_run::check(data));
