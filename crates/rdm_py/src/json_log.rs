//! Bindings of `rdm_core::sim::python_float_repr` and `rdm_core::sim::json_text`: JSON text
//! written as Python's `json.dumps` writes it, for the run logger's 100 Hz records
//! (`rdm.sim.mcap_log`); and of `rdm_core::sim::mcap_chunk`: those
//! records written straight into an MCAP chunk's message records (`McapChunkBatch`).

use std::fmt::Write;

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use rdm_core::sim::json_text::{is_plain_key, push_ascii_json_string};
use rdm_core::sim::mcap_chunk::McapMessageBatch;
use rdm_core::sim::python_float_repr::PythonFloatRepr;

/// ``"v0,v1,..."``: each value as ``repr(float)``, NaN and infinities as ``null`` (the
/// logger's JSON convention); any stride.
#[pyfunction]
fn json_float_list(values: PyReadonlyArray1<'_, f64>) -> String {
    let view = values.as_array();
    // ~24 characters per value at most; one allocation for the result.
    let mut out = String::with_capacity(view.len() * 24);
    let mut writer = PythonFloatRepr::new();
    for (i, v) in view.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        writer.push_json(*v, &mut out);
    }
    out
}

/// Append one record value; false when it is outside the fast path (the caller then
/// returns None and Python takes its own path).
fn push_value(v: &Bound<'_, PyAny>, writer: &mut PythonFloatRepr, out: &mut String) -> bool {
    if v.is_none() {
        out.push_str("null");
    } else if v.is_exact_instance_of::<PyBool>() {
        out.push_str(if v.is_truthy().unwrap_or(false) {
            "true"
        } else {
            "false"
        });
    } else if let Ok(f) = v.cast::<PyFloat>() {
        // float and its subclasses (numpy.float64): the stored double, as float.__repr__.
        writer.push_json(f.value(), out);
    } else if v.is_exact_instance_of::<PyInt>() {
        let Ok(i) = v.extract::<i64>() else {
            return false; // beyond i64: Python writes it
        };
        let _ = write!(out, "{i}");
    } else if let Ok(s) = v.cast_exact::<PyString>() {
        let Ok(s) = s.to_str() else {
            return false; // lone surrogates
        };
        push_ascii_json_string(s, out);
    } else if let Ok(a) = v.cast::<PyArray1<f64>>() {
        out.push('[');
        // SAFETY: read only, and no Python runs while the view lives (untracked.rs: the
        // borrow checker's bookkeeping was most of a short array's cost); any strides.
        for (i, x) in unsafe { a.as_array() }.iter().enumerate() {
            if i > 0 {
                out.push(',');
            }
            writer.push_json(*x, out);
        }
        out.push(']');
    } else if let Ok(list) = v.cast_exact::<PyList>() {
        out.push('[');
        for (i, x) in list.iter().enumerate() {
            let Ok(x) = x.cast::<PyFloat>() else {
                return false;
            };
            if i > 0 {
                out.push(',');
            }
            writer.push_json(x.value(), out);
        }
        out.push(']');
    } else {
        return false;
    }
    true
}

/// Append `"key":` for a plain str key; false otherwise.
fn push_key(k: &Bound<'_, PyAny>, first: bool, out: &mut String) -> bool {
    let Ok(key) = k.cast_exact::<PyString>() else {
        return false;
    };
    let Ok(key) = key.to_str() else {
        return false;
    };
    if !is_plain_key(key) {
        return false;
    }
    if !first {
        out.push(',');
    }
    out.push('"');
    out.push_str(key);
    out.push_str("\":");
    true
}

/// `out` = the flat record `dict` as compact JSON; false when it holds anything else.
fn encode_record(dict: &Bound<'_, PyDict>, writer: &mut PythonFloatRepr, out: &mut String) -> bool {
    out.clear();
    out.push('{');
    for (i, (k, v)) in dict.iter().enumerate() {
        if !push_key(&k, i == 0, out) || !push_value(&v, writer, out) {
            return false;
        }
    }
    out.push('}');
    true
}

/// `out` = the record `{key: attributes[key] for key in keys}` as compact JSON; false when
/// a key is missing or a key or value is outside the flat record.
fn encode_fields(
    attributes: &Bound<'_, PyDict>,
    keys: &Bound<'_, PyTuple>,
    writer: &mut PythonFloatRepr,
    out: &mut String,
) -> bool {
    out.clear();
    out.push('{');
    for (i, k) in keys.iter().enumerate() {
        let Ok(Some(v)) = attributes.get_item(&k) else {
            return false;
        };
        if !push_key(&k, i == 0, out) || !push_value(&v, writer, out) {
            return false;
        }
    }
    out.push('}');
    true
}

/// A flat record (a dict of plain str keys to None, bool, float, int, str, 1-D float64
/// arrays, lists of floats) as compact ``json.dumps`` text (NaN and infinities as
/// ``null``); None when the record holds anything else.
#[pyfunction]
fn json_record(values: &Bound<'_, PyAny>) -> Option<String> {
    let dict = values.cast_exact::<PyDict>().ok()?;
    let mut out = String::with_capacity(64 + dict.len() * 64);
    let mut writer = PythonFloatRepr::new();
    encode_record(dict, &mut writer, &mut out).then_some(out)
}

/// What an ``McapChunkBatch`` add method did: nothing (the caller takes the library's path),
/// the message was added, or it was added and the chunk is now over its size.
const DECLINED: u8 = 0;
const ADDED: u8 = 1;
const CHUNK_FULL: u8 = 2;

/// A Message record's channel id, sequence and time as the record's integer types; None
/// when one is not an int in range (``struct.pack`` would fail: the library's path decides).
fn record_ids(
    channel: &Bound<'_, PyAny>,
    sequence: &Bound<'_, PyAny>,
    time: &Bound<'_, PyAny>,
) -> Option<(u16, u32, u64)> {
    Some((
        channel.extract().ok()?,
        sequence.extract().ok()?,
        time.extract().ok()?,
    ))
}

/// The message records of one MCAP chunk in the making, for ``rdm.sim.mcap_writer.
/// McapWriter``: each add appends one Message record (log time = publish time) and its
/// index entry in one call, the JSON ones encoding the record straight into it; ``take``
/// hands the batch to the ``mcap`` library's chunk builder. The add methods return 0 when
/// they decline (nothing added: an id out of range, data that is not bytes, a record outside
/// the flat JSON form), 1 when added, 2 when added and the chunk buffer is now over
/// ``chunk_size`` bytes (the writer closes the chunk).
#[pyclass(module = "rdm._rdm")]
struct McapChunkBatch {
    inner: McapMessageBatch,
    writer: PythonFloatRepr,
    text: String,
}

impl McapChunkBatch {
    fn push(&mut self, ids: (u16, u32, u64), data: &[u8]) -> u8 {
        self.inner.push(ids.0, ids.1, ids.2, data);
        if self.inner.over_size() {
            CHUNK_FULL
        } else {
            ADDED
        }
    }

    fn push_text(&mut self, ids: (u16, u32, u64), encoded: bool) -> u8 {
        if !encoded {
            return DECLINED;
        }
        let text = std::mem::take(&mut self.text);
        let code = self.push(ids, text.as_bytes());
        self.text = text;
        code
    }
}

#[pymethods]
impl McapChunkBatch {
    /// An empty batch for a writer whose chunks close past ``chunk_size`` bytes.
    #[new]
    fn new(chunk_size: u64) -> Self {
        let room = usize::try_from(chunk_size.min(1 << 22)).unwrap_or(1 << 22) + (1 << 16);
        Self {
            inner: McapMessageBatch::new(chunk_size, room, 1024),
            writer: PythonFloatRepr::new(),
            text: String::with_capacity(1 << 14),
        }
    }

    /// The chunk buffer's size the next record follows (call with the batch empty).
    fn set_base(&mut self, base: u64) {
        self.inner.set_base(base);
    }

    /// Chunk buffer offset the next record starts at.
    fn next_offset(&self) -> u64 {
        self.inner.next_offset()
    }

    /// Pending messages.
    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// One message with ``data`` (bytes) as its payload (0 / 1 / 2: see the class).
    fn add(
        &mut self,
        channel: &Bound<'_, PyAny>,
        sequence: &Bound<'_, PyAny>,
        time: &Bound<'_, PyAny>,
        data: &Bound<'_, PyAny>,
    ) -> u8 {
        let (Some(ids), Ok(data)) = (record_ids(channel, sequence, time), data.cast::<PyBytes>())
        else {
            return DECLINED;
        };
        self.push(ids, data.as_bytes())
    }

    /// One message whose payload is the flat record ``values`` (a dict) as ``json_record``
    /// writes it (0 / 1 / 2: see the class).
    fn add_record(
        &mut self,
        channel: &Bound<'_, PyAny>,
        sequence: &Bound<'_, PyAny>,
        time: &Bound<'_, PyAny>,
        values: &Bound<'_, PyAny>,
    ) -> u8 {
        let (Some(ids), Ok(dict)) = (
            record_ids(channel, sequence, time),
            values.cast_exact::<PyDict>(),
        ) else {
            return DECLINED;
        };
        let encoded = encode_record(dict, &mut self.writer, &mut self.text);
        self.push_text(ids, encoded)
    }

    /// One message whose payload is the record ``{k: attributes[k] for k in keys}`` (an
    /// instance ``__dict__`` and its field names, a tuple) as ``json_record`` writes it
    /// (0 / 1 / 2: see the class; a missing key declines).
    fn add_fields(
        &mut self,
        channel: &Bound<'_, PyAny>,
        sequence: &Bound<'_, PyAny>,
        time: &Bound<'_, PyAny>,
        attributes: &Bound<'_, PyAny>,
        keys: &Bound<'_, PyAny>,
    ) -> u8 {
        let (Some(ids), Ok(dict), Ok(keys)) = (
            record_ids(channel, sequence, time),
            attributes.cast_exact::<PyDict>(),
            keys.cast_exact::<PyTuple>(),
        ) else {
            return DECLINED;
        };
        let encoded = encode_fields(dict, keys, &mut self.writer, &mut self.text);
        self.push_text(ids, encoded)
    }

    /// Hand the pending messages over and empty the batch: ``(records, count, first time,
    /// last time, [(channel, [(time, offset), ...]), ...])`` with the channels in the order of
    /// their first pending message and times the earliest / latest; None when empty.
    fn take<'py>(&mut self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyTuple>>> {
        let Some((first, last)) = self.inner.time_range() else {
            return Ok(None);
        };
        let mut channels: Vec<(u16, Vec<(u64, u64)>)> = Vec::new();
        for e in self.inner.entries() {
            match channels.iter_mut().find(|(c, _)| *c == e.channel) {
                Some((_, list)) => list.push((e.time, e.offset)),
                None => channels.push((e.channel, vec![(e.time, e.offset)])),
            }
        }
        let records = PyBytes::new(py, self.inner.records());
        let count = self.inner.len();
        self.inner.clear();
        let groups = channels
            .into_iter()
            .map(|(c, list)| (c, PyList::new(py, list)?).into_pyobject(py))
            .collect::<PyResult<Vec<_>>>()?;
        Ok(Some(
            (records, count, first, last, PyList::new(py, groups)?).into_pyobject(py)?,
        ))
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(json_float_list, m)?)?;
    m.add_function(wrap_pyfunction!(json_record, m)?)?;
    m.add_class::<McapChunkBatch>()?;
    Ok(())
}
