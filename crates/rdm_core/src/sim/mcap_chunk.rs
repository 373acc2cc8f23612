//! Message records of an MCAP chunk being built, written the way the `mcap` Python library's
//! `Writer.add_message` writes them into its chunk buffer, with the message-index entries it
//! keeps. The run logger (`rdm.sim.mcap_writer.McapWriter`) appends its 100 Hz records
//! here in one call each and hands the batch to the library's chunk builder (bytes, index
//! entries, time range) before the library writes anything else into that chunk or closes it,
//! so the file is byte-identical with the library's own path (tests/test_truthlog_mcap.py).
//!
//! A Message record: opcode `0x05`, record length (u64), channel id (u16), sequence (u32), log
//! time (u64), publish time (u64), then the data; little-endian, as the MCAP specification
//! lays it out. Log and publish time are the same here (the logger's simulated time).

/// The MCAP Message record's opcode.
const MESSAGE_OPCODE: u8 = 0x05;

/// Bytes of a Message record's fields before its data (channel, sequence, two times).
const MESSAGE_FIELDS: u64 = 2 + 4 + 8 + 8;

/// Bytes of a Message record before its data (opcode and record length included).
pub const MESSAGE_HEAD: usize = 1 + 8 + MESSAGE_FIELDS as usize;

/// One message-index entry: the message's channel, log time and offset in the chunk's
/// uncompressed records.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IndexEntry {
    pub channel: u16,
    pub time: u64,
    pub offset: u64,
}

/// Message records appended after `base` bytes of the chunk buffer, not yet handed over.
#[derive(Debug)]
pub struct McapMessageBatch {
    records: Vec<u8>,
    entries: Vec<IndexEntry>,
    base: u64,
    chunk_size: u64,
}

impl McapMessageBatch {
    /// A batch for a writer that closes a chunk once its buffer holds more than
    /// `chunk_size` bytes; room for `capacity_bytes` of records and `capacity_messages`
    /// entries before a vector grows.
    pub fn new(chunk_size: u64, capacity_bytes: usize, capacity_messages: usize) -> Self {
        Self {
            records: Vec::with_capacity(capacity_bytes),
            entries: Vec::with_capacity(capacity_messages),
            base: 0,
            chunk_size,
        }
    }

    /// The chunk buffer's size the next record follows (after bytes written outside the batch,
    /// or a new chunk). Call it with the batch empty.
    pub fn set_base(&mut self, base: u64) {
        self.base = base;
    }

    /// Chunk buffer offset the next record starts at.
    pub fn next_offset(&self) -> u64 {
        self.base + self.records.len() as u64
    }

    /// Append one message (log time = publish time = `time`) and its index entry.
    pub fn push(&mut self, channel: u16, sequence: u32, time: u64, data: &[u8]) {
        let offset = self.next_offset();
        let length = MESSAGE_FIELDS + data.len() as u64;
        let r = &mut self.records;
        r.push(MESSAGE_OPCODE);
        r.extend_from_slice(&length.to_le_bytes());
        r.extend_from_slice(&channel.to_le_bytes());
        r.extend_from_slice(&sequence.to_le_bytes());
        r.extend_from_slice(&time.to_le_bytes());
        r.extend_from_slice(&time.to_le_bytes());
        r.extend_from_slice(data);
        self.entries.push(IndexEntry {
            channel,
            time,
            offset,
        });
    }

    /// True when the chunk buffer (with this batch) holds more than the chunk size: the
    /// writer closes the chunk after such a message.
    pub fn over_size(&self) -> bool {
        self.next_offset() > self.chunk_size
    }

    /// Pending messages.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// No pending message.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The pending records (what the chunk buffer gets, in order).
    pub fn records(&self) -> &[u8] {
        &self.records
    }

    /// The pending index entries, in message order.
    pub fn entries(&self) -> &[IndexEntry] {
        &self.entries
    }

    /// (earliest, latest) log time of the pending messages; None when empty.
    pub fn time_range(&self) -> Option<(u64, u64)> {
        let first = self.entries.first()?.time;
        Some(self.entries.iter().fold((first, first), |(lo, hi), e| {
            (lo.min(e.time), hi.max(e.time))
        }))
    }

    /// Forget the pending messages after handing them over: the base moves past them.
    pub fn clear(&mut self) {
        self.base = self.next_offset();
        self.records.clear();
        self.entries.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_are_laid_out_as_the_specification() {
        let mut b = McapMessageBatch::new(100, 256, 4);
        b.set_base(7);
        b.push(3, 9, 0x0102, b"ab");
        let mut want = vec![0x05];
        want.extend_from_slice(&24u64.to_le_bytes());
        want.extend_from_slice(&3u16.to_le_bytes());
        want.extend_from_slice(&9u32.to_le_bytes());
        want.extend_from_slice(&0x0102u64.to_le_bytes());
        want.extend_from_slice(&0x0102u64.to_le_bytes());
        want.extend_from_slice(b"ab");
        assert_eq!(b.records(), &want[..]);
        assert_eq!(
            b.entries(),
            &[IndexEntry {
                channel: 3,
                time: 0x0102,
                offset: 7
            }]
        );
        assert_eq!(b.next_offset(), 7 + MESSAGE_HEAD as u64 + 2);
        assert!(!b.over_size());
        b.push(1, 0, 5, &[0; 60]);
        assert_eq!(b.entries()[1].offset, 7 + 33);
        assert!(b.over_size());
        assert_eq!(b.time_range(), Some((5, 0x0102)));
        b.clear();
        assert!(b.is_empty() && b.time_range().is_none());
        assert_eq!(b.next_offset(), 7 + 33 + 31 + 60);
    }
}
