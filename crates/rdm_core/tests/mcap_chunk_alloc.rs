//! Proves that appending MCAP message records to a batch allocates nothing once the batch is
//! set up with room for a chunk: a counting global allocator wraps the system allocator while
//! chunks' worth of records are pushed, checked and cleared.

use std::alloc::System;

use rdm_core::sim::mcap_chunk::{McapMessageBatch, MESSAGE_HEAD};
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

#[test]
fn pushing_records_allocates_nothing() {
    let chunk = 64 * 1024;
    let mut batch = McapMessageBatch::new(chunk, chunk as usize + (1 << 16), 1024);
    let payload = [b'7'; 1500];
    let region = Region::new(GLOBAL);
    let mut closed = 0;
    for k in 0..5000u64 {
        let n = (k as usize * 37) % payload.len();
        batch.push((k % 3) as u16, k as u32, k * 1_000_000, &payload[..n]);
        if batch.over_size() {
            let (lo, hi) = batch.time_range().unwrap_or((0, 0));
            assert!(lo <= hi);
            assert!(batch.records().len() >= batch.len() * MESSAGE_HEAD);
            batch.clear();
            batch.set_base(0);
            closed += 1;
        }
    }
    let stats = region.change();
    assert_eq!(stats.allocations, 0, "allocations: {stats:?}");
    assert_eq!(stats.reallocations, 0);
    assert!(closed > 10);
}
