//! `LeptrinoStream`'s sample frames against the golden force-data frames of
//! `firmware_protocol/leptrino/vectors.json` (built from the fact sheet by its own encoder,
//! `make_vectors.py`): a wrench of `raw / 10000` of a rated 1.0 per axis gives those counts.

use rdm_core::sim::leptrino_sensor::LeptrinoStream;

fn hex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect()
}

#[test]
fn stream_frames_equal_the_golden_force_data_frames() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../firmware_protocol/leptrino/vectors.json"
    );
    let text = std::fs::read_to_string(path).expect("vectors.json readable");
    let doc: serde_json::Value = serde_json::from_str(&text).expect("vectors.json is JSON");
    let entries = doc
        .get("vectors")
        .and_then(|v| v.as_array())
        .or_else(|| doc.as_array())
        .expect("a list of vectors");
    let mut checked = 0;
    for v in entries {
        if v["kind"] != "force_data" || v["fields"]["result"] != 0 {
            continue;
        }
        let f = &v["fields"];
        if f["status"] != 0 {
            continue; // the stream's frames carry status 0
        }
        let raw: Vec<f64> = f["raw"]
            .as_array()
            .expect("raw")
            .iter()
            .map(|x| x.as_f64().expect("count"))
            .collect();
        let wrench: Vec<f64> = raw.iter().map(|r| r / 10000.0).collect();
        let temperature = f["temperature"].as_i64().expect("temperature");
        let term = f["term_no"].as_i64().expect("term_no");
        let mut s = LeptrinoStream::new([1.0; 6], temperature, term).expect("fields in range");
        s.set_streaming(true);
        s.set_wrench(&wrench);
        assert!(s.stream_tick(0.0).expect("encodable"));
        let want = hex(v["frame"].as_str().expect("frame"));
        assert_eq!(s.pending().0, &want[..], "{}", v["name"]);
        checked += 1;
    }
    assert!(checked >= 1, "no status-0 force_data vector");
}
