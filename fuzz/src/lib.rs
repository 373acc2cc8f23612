//! What every fuzz target checks beyond "no crash, no hang" (docs/fuzzing.md). Each
//! `check(data)` runs one parser of `rdm_core` on a fuzzer input and panics when the
//! parser breaks a rule: the panic message starts with the finding's class
//! (`bad frame accepted`, `wrong rejection`, `not canonical`, `non-finite`), which the
//! campaign script counts. The same functions replay the committed corpus in
//! `tests/replay.rs`.

pub mod description;
pub mod leptrino_ok_run;
pub mod neuron_frame;
pub mod rosserial_scan;
