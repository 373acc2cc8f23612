//! Readers of `firmware_protocol/neuron/vectors.json`, shared by the Neuron-side and the
//! Spinal-side golden-vector tests.

use serde_json::Value;

pub fn vectors() -> Vec<Value> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../firmware_protocol/neuron/vectors.json"
    );
    let text = std::fs::read_to_string(path).expect("vectors.json readable");
    let doc: Value = serde_json::from_str(&text).expect("valid JSON");
    doc["vectors"].as_array().expect("vectors array").clone()
}

pub fn id_of(v: &Value) -> u32 {
    let s = v["id"].as_str().expect("id string");
    u32::from_str_radix(s.trim_start_matches("0x"), 16).expect("hex id")
}

pub fn data_of(v: &Value) -> Vec<u8> {
    let s = v["data"].as_str().expect("data string");
    (0..s.len() / 2)
        .map(|k| u8::from_str_radix(&s[2 * k..2 * k + 2], 16).expect("hex byte"))
        .collect()
}

pub fn int(v: &Value, key: &str) -> i64 {
    let f = &v["fields"][key];
    f.as_i64()
        .or_else(|| f.as_bool().map(i64::from))
        .unwrap_or_else(|| panic!("{}: field {key}", v["name"]))
}
