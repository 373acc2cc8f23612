//! Replays the committed corpus (`fuzz/corpus/<target>/`) through every Rust target's
//! checks on the stable toolchain: `cargo test --manifest-path fuzz/Cargo.toml`.

use std::fs;
use std::path::Path;

fn replay(target: &str, check: fn(&[u8])) -> usize {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("corpus")
        .join(target);
    let mut n = 0;
    for entry in fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let path = entry.expect("corpus entry").path();
        let data = fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        check(&data);
        n += 1;
    }
    assert!(n > 0, "{}: empty corpus", dir.display());
    n
}

#[test]
fn rosserial_scan_corpus() {
    replay("rosserial_scan", rdm_fuzz::rosserial_scan::check);
}

#[test]
fn neuron_frame_corpus() {
    replay("neuron_frame", rdm_fuzz::neuron_frame::check);
}

#[test]
fn leptrino_ok_run_corpus() {
    replay("leptrino_ok_run", rdm_fuzz::leptrino_ok_run::check);
}

#[test]
fn description_corpus() {
    replay("description", rdm_fuzz::description::check);
}

/// A URDF nested `depth` elements deep, as the macro of `description::expand` writes it.
fn deep_urdf(depth: u16) -> Vec<u8> {
    let mut data = b"<robot name=\"deep\"><a>".to_vec();
    data.extend([0, (depth >> 8) as u8, depth as u8, 3]);
    data
}

#[test]
fn macro_expands_to_deep_nesting() {
    let (urdf, toml) = rdm_fuzz::description::split(&deep_urdf(999));
    assert_eq!(urdf.matches("<a>").count(), 1000);
    assert!(urdf.starts_with("<robot name=\"deep\"><a><a>"));
    assert!(toml.is_empty());
}
