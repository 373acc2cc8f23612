//! cargo-fuzz target: [`rdm_fuzz::neuron_frame::check`] on every input.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| rdm_fuzz::neuron_frame::check(data));
