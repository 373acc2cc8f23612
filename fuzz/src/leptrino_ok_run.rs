//! Leptrino host-side fast scan (`rdm_core::sim::leptrino_stream::ok_sample_run`): the
//! leading run of whole frames that each carry an OK force sample.
//!
//! Input: the bytes read from the sensor's port.
//!
//! Checks, against the framing re-read here from the bytes (fact sheet sec. 5:
//! `DLE STX | payload, DLE doubled | DLE ETX | BCC`, BCC = XOR of the unstuffed payload and
//! ETX): the run is made of back-to-back frames each with a good BCC and a 20-byte payload
//! `[20, *, 0x32, 0, ...]`; it ends at `end`; `last_start` and `last_payload` are those of
//! its last frame; and it is the longest such run (no OK-sample frame starts at `end`).

use rdm_core::sim::leptrino_stream::ok_sample_run;

const DLE: u8 = 0x10;
const STX: u8 = 0x02;
const ETX: u8 = 0x03;

/// The frame at the start of `data` if it is a whole, well-formed OK sample: its length on
/// the wire and its unstuffed payload.
fn ok_sample(data: &[u8]) -> Option<(usize, Vec<u8>)> {
    if data.len() < 2 || data[0] != DLE || data[1] != STX {
        return None;
    }
    let mut payload = Vec::new();
    let mut i = 2;
    loop {
        match (data.get(i)?, data.get(i + 1)) {
            (&DLE, Some(&DLE)) => {
                payload.push(DLE);
                i += 2;
            }
            (&DLE, Some(&ETX)) => break,
            (&DLE, _) => return None,
            (&b, _) => {
                payload.push(b);
                i += 1;
            }
        }
        if payload.len() > 20 {
            return None;
        }
    }
    let bcc = payload.iter().fold(ETX, |acc, b| acc ^ b);
    let ok = payload.len() == 20
        && payload[0] == 20
        && payload[2] == 0x32
        && payload[3] == 0
        && *data.get(i + 2)? == bcc;
    ok.then_some((i + 3, payload))
}

/// Scan `data` (see the module doc); panics on a broken rule.
pub fn check(data: &[u8]) {
    let run = ok_sample_run(data);
    let mut at = 0;
    let mut last: Option<(usize, Vec<u8>)> = None;
    for k in 0..run.count {
        let Some((len, payload)) = ok_sample(&data[at..]) else {
            panic!("bad frame accepted: frame {k} of the run at {at} is no whole OK sample");
        };
        last = Some((at, payload));
        at += len;
    }
    assert_eq!(
        at, run.end,
        "bad frame accepted: run ends at {} not {at}",
        run.end
    );
    if let Some((start, payload)) = last {
        assert_eq!(start, run.last_start, "wrong rejection: last frame start");
        assert_eq!(
            payload, run.last_payload,
            "bad frame accepted: last payload differs"
        );
    }
    assert!(
        ok_sample(&data[run.end..]).is_none(),
        "wrong rejection: an OK sample at {} left out of the run",
        run.end
    );
}
