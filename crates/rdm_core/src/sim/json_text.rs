//! The non-float pieces of a flat JSON log record as Python's `json.dumps` writes them
//! (`ensure_ascii=True`, compact separators): object keys restricted to characters
//! `json.dumps` copies as they are, and string values escaped as `encode_basestring_ascii`
//! does. With [`super::python_float_repr`] the run logger writes its 100 Hz records in one
//! call, byte-equal with `json.dumps` (`rdm.sim.mcap_log`, tests/test_json_record.py).

use std::fmt::Write;

/// True when `key` holds only `[A-Za-z0-9_ ./:+-]` (the logger's plain keys, written between
/// quotes with no escape).
pub fn is_plain_key(key: &str) -> bool {
    key.bytes().all(|b| {
        b.is_ascii_alphanumeric() || matches!(b, b'_' | b' ' | b'.' | b'/' | b':' | b'+' | b'-')
    })
}

/// Append `value` as a quoted JSON string the way `json.encoder.encode_basestring_ascii`
/// writes it: printable ASCII as is, `"` `\` and `\b \f \n \r \t` with a backslash, every
/// other character as `\uXXXX` (lowercase hex; UTF-16 surrogate pairs above U+FFFF).
pub fn push_ascii_json_string(value: &str, out: &mut String) {
    out.push('"');
    for c in value.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            '\u{8}' => out.push_str("\\b"),
            '\u{c}' => out.push_str("\\f"),
            ' '..='~' => out.push(c),
            _ => {
                let mut units = [0u16; 2];
                for unit in c.encode_utf16(&mut units) {
                    // Writing into a String cannot fail.
                    let _ = write!(out, "\\u{unit:04x}");
                }
            }
        }
    }
    out.push('"');
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quoted(s: &str) -> String {
        let mut out = String::new();
        push_ascii_json_string(s, &mut out);
        out
    }

    #[test]
    fn escapes_like_python() {
        // Expected texts: CPython 3.11 json.dumps of the same strings.
        assert_eq!(quoted("hover"), "\"hover\"");
        assert_eq!(quoted("a\"b\\c"), "\"a\\\"b\\\\c\"");
        assert_eq!(
            quoted("\n\r\t\u{8}\u{c}\u{1}"),
            "\"\\n\\r\\t\\b\\f\\u0001\""
        );
        assert_eq!(quoted("\u{7f}é"), "\"\\u007f\\u00e9\"");
        assert_eq!(quoted("\u{1F600}"), "\"\\ud83d\\ude00\"");
    }

    #[test]
    fn plain_keys() {
        assert!(is_plain_key("base_position"));
        assert!(is_plain_key("a/b.c:d+e-f g"));
        assert!(is_plain_key(""));
        assert!(!is_plain_key("a\"b"));
        assert!(!is_plain_key("é"));
    }
}
