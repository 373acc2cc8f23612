//! Python's `repr(float)` text, written without Python: the ground-truth and status records of
//! a simulated run are logged as JSON at 100 Hz, and Python's `json.dumps` spends most of its
//! time in `float.__repr__`. This writes the same characters, so a log is byte-equal with
//! either encoder (`rdm.sim.mcap_log`, tested against `json.dumps` on random bit patterns).
//!
//! Python's repr is the shortest decimal that reads back as the same double (David Gay's
//! mode 0); Rust's `{:e}` gives the same shortest digits. Only the layout differs: Python
//! writes fixed notation for decimal exponents -4..=15 (`0.0001`, `1000000000000000.0`) and
//! otherwise `d.ddde+XX` with at least two exponent digits (`1e-05`, `1.5e+16`).

use std::fmt::Write;

/// Longest text `{:e}` writes for an f64 (17 digits, point, sign, `e-324`): a bound for the
/// scratch buffer, which then never reallocates.
const SCRATCH_CAPACITY: usize = 32;

/// Reusable writer of Python float reprs.
#[derive(Debug)]
pub struct PythonFloatRepr {
    scratch: String,
    digits: String,
}

impl Default for PythonFloatRepr {
    fn default() -> Self {
        Self::new()
    }
}

impl PythonFloatRepr {
    /// A writer with its scratch buffers allocated.
    pub fn new() -> Self {
        Self {
            scratch: String::with_capacity(SCRATCH_CAPACITY),
            digits: String::with_capacity(SCRATCH_CAPACITY),
        }
    }

    /// Fill `digits` with the shortest round-trip digits of `magnitude` (> 0, finite) that
    /// Python picks, and return the decimal exponent of the first digit.
    ///
    /// Ryu gives the shortest digits that read back as the same double, the closest to the
    /// exact value among them, and breaks an exact tie to the even digit: Python's dtoa mode
    /// 0 choice (tested against `repr` on random bit patterns, tests/test_truth_record.py).
    fn shortest_digits(&mut self, magnitude: f64) -> i32 {
        let mut buffer = ryu::Buffer::new();
        let text = buffer.format_finite(magnitude);
        normalise_digits(text, &mut self.digits)
    }

    /// The reference form of [`Self::shortest_digits`] (std's `{:e}`, then the half-even tie
    /// check through `{:.N$e}` and a parse): kept to test the Ryu path against.
    fn shortest_digits_std(&mut self, magnitude: f64) -> i32 {
        self.scratch.clear();
        // Writing into a String cannot fail.
        let _ = write!(self.scratch, "{magnitude:e}");
        let mut exponent = split_exponent(&self.scratch, &mut self.digits);
        let odd_last = self.digits.as_bytes().last().is_some_and(|d| d % 2 == 1); // ASCII "0" is even: byte parity = digit parity
        if odd_last {
            let precision = self.digits.len() - 1;
            self.scratch.clear();
            let _ = write!(self.scratch, "{magnitude:.precision$e}");
            if self.scratch.parse::<f64>() == Ok(magnitude) {
                exponent = split_exponent(&self.scratch, &mut self.digits);
            }
        }
        exponent
    }

    /// `repr(value)` through the std reference digits ([`Self::shortest_digits_std`]), for
    /// tests of the Ryu path.
    pub fn push_repr_std(&mut self, value: f64, out: &mut String) {
        self.push_repr_with(value, out, Self::shortest_digits_std);
    }

    /// Append `repr(value)` for a finite value, `null` (JSON) for NaN and infinities (the
    /// logger's convention: JSON has no NaN).
    pub fn push_json(&mut self, value: f64, out: &mut String) {
        if value.is_finite() {
            self.push_repr(value, out);
        } else {
            out.push_str("null");
        }
    }

    /// Append Python's `repr(value)` (finite values; NaN and infinities as Python writes
    /// them: `nan`, `inf`, `-inf`).
    pub fn push_repr(&mut self, value: f64, out: &mut String) {
        if value.is_finite() && value != 0.0 {
            // Ryu writes fixed notation for decimal exponents -5..=15, Python for -4..=15,
            // both with the same digits and `.0` for whole numbers: inside the common range
            // Ryu's text is Python's (tested against the digit path below).
            let mut buffer = ryu::Buffer::new();
            let text = buffer.format_finite(value);
            let body = text.strip_prefix('-').unwrap_or(text);
            if let Some(at) = body.bytes().position(|c| c == b'e' || c == b'E') {
                // Ryu's exponent notation (decimal exponents below -5 or above 15, where
                // Python writes it too, with the same mantissa text): only the exponent's
                // text differs, Ryu's `e-7` / `e16` against Python's `e-07` / `e+16`.
                let at = at + (text.len() - body.len());
                out.push_str(&text[..at]);
                push_python_exponent(parse_exponent(&text.as_bytes()[at + 1..]), out);
                return;
            }
            if !body.starts_with("0.0000") {
                out.push_str(text);
                return;
            }
            // Outside it, the same digits in Python's layout (Ryu's text of -x is `-` and its
            // text of x: what `shortest_digits` would format again).
            if value.is_sign_negative() {
                out.push('-');
            }
            let exponent = normalise_digits(body, &mut self.digits);
            self.push_layout(exponent, out);
            return;
        }
        self.push_repr_with(value, out, Self::shortest_digits);
    }

    /// `repr(value)` always through the digit path (Ryu digits, Python's layout rules): the
    /// reference of [`Self::push_repr`]'s direct copy of Ryu's fixed-notation text.
    pub fn push_repr_digits(&mut self, value: f64, out: &mut String) {
        self.push_repr_with(value, out, Self::shortest_digits);
    }

    fn push_repr_with(
        &mut self,
        value: f64,
        out: &mut String,
        shortest: fn(&mut Self, f64) -> i32,
    ) {
        if value.is_nan() {
            out.push_str("nan");
            return;
        }
        if value.is_sign_negative() {
            out.push('-');
        }
        let magnitude = value.abs();
        if magnitude.is_infinite() {
            out.push_str("inf");
            return;
        }
        if magnitude == 0.0 {
            out.push_str("0.0");
            return;
        }
        let exponent = shortest(self, magnitude);
        self.push_layout(exponent, out);
    }

    /// Python's layout of `self.digits` (significant digits, first one at decimal
    /// `exponent`) after the sign.
    fn push_layout(&self, exponent: i32, out: &mut String) {
        let digits = self.digits.as_str();
        let n = digits.len() as i32;
        if (-4..16).contains(&exponent) {
            if exponent >= 0 {
                let whole = (exponent + 1) as usize;
                if n as usize <= whole {
                    out.push_str(digits);
                    for _ in 0..(whole - n as usize) {
                        out.push('0');
                    }
                    out.push_str(".0");
                } else {
                    out.push_str(&digits[..whole]);
                    out.push('.');
                    out.push_str(&digits[whole..]);
                }
            } else {
                out.push_str("0.");
                for _ in 0..(-exponent - 1) {
                    out.push('0');
                }
                out.push_str(digits);
            }
        } else {
            out.push_str(&digits[..1]);
            if n > 1 {
                out.push('.');
                out.push_str(&digits[1..]);
            }
            push_python_exponent(exponent, out);
        }
    }
}

/// Python's exponent text: `e`, the sign, at least two digits (`e-05`, `e+16`, `e-324`; a
/// double's decimal exponent has at most three).
fn push_python_exponent(exponent: i32, out: &mut String) {
    out.push('e');
    out.push(if exponent < 0 { '-' } else { '+' });
    let e = exponent.unsigned_abs();
    if e >= 100 {
        out.push(char::from(b'0' + (e / 100 % 10) as u8));
    }
    out.push(char::from(b'0' + (e / 10 % 10) as u8));
    out.push(char::from(b'0' + (e % 10) as u8));
}

/// Ryu's text of a positive finite value (`1.0`, `0.00123`, `1.5e-7`, `1e16`) as its
/// significant digits (into `digits`, no leading or trailing zeros) and the decimal exponent
/// of the first digit.
fn normalise_digits(text: &str, digits: &mut String) -> i32 {
    // bytes, not `split_once`/`parse`: this runs for every float outside -4..=15 of a log
    let bytes = text.as_bytes();
    let (mantissa, exp10) = match bytes.iter().position(|&c| c == b'e' || c == b'E') {
        Some(i) => (&bytes[..i], parse_exponent(&bytes[i + 1..])),
        None => (bytes, 0),
    };
    digits.clear();
    let (mut whole, mut in_whole, mut leading_zeros) = (0i32, true, 0i32);
    for &c in mantissa {
        if c == b'.' {
            in_whole = false;
            continue;
        }
        whole += i32::from(in_whole);
        if digits.is_empty() && c == b'0' {
            leading_zeros += 1;
        } else {
            digits.push(char::from(c));
        }
    }
    let kept = digits.trim_end_matches('0').len();
    digits.truncate(kept);
    whole - 1 - leading_zeros + exp10
}

/// Ryu's exponent text (`-7`, `16`) as a number (0 if it is not one, as `parse` gave).
fn parse_exponent(text: &[u8]) -> i32 {
    let (negative, digits) = match text.split_first() {
        Some((b'-', rest)) => (true, rest),
        Some((b'+', rest)) => (false, rest),
        _ => (false, text),
    };
    if digits.is_empty() || digits.len() > 4 || !digits.iter().all(u8::is_ascii_digit) {
        return 0;
    }
    let value = digits
        .iter()
        .fold(0i32, |v, &d| v * 10 + i32::from(d - b'0'));
    if negative {
        -value
    } else {
        value
    }
}

/// Split `d.ddde-X` into its digits (into `digits`) and its exponent.
fn split_exponent(text: &str, digits: &mut String) -> i32 {
    let (mantissa, exponent) = text.split_once('e').unwrap_or((text, "0"));
    digits.clear();
    digits.extend(mantissa.chars().filter(|c| *c != '.'));
    exponent.parse().unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn repr(v: f64) -> String {
        let mut out = String::new();
        PythonFloatRepr::new().push_repr(v, &mut out);
        out
    }

    #[test]
    fn layouts_match_python() {
        // Expected texts are what CPython 3.11 prints for these literals.
        let cases = [
            (0.0, "0.0"),
            (-0.0, "-0.0"),
            (1.0, "1.0"),
            (0.1, "0.1"),
            (-2.5, "-2.5"),
            (0.0001, "0.0001"),
            (0.00001, "1e-05"),
            (1.5e-7, "1.5e-07"),
            (123456.789, "123456.789"),
            (1e15, "1000000000000000.0"),
            (1e16, "1e+16"),
            (1.2345e16, "1.2345e+16"),
            (1e100, "1e+100"),
            (5e-324, "5e-324"),
            (f64::MAX, "1.7976931348623157e+308"),
            (9.81, "9.81"),
            // exact ties between two shortest candidates: Python takes the even digit
            (575_395_288_650_688.0 + 0.25, "575395288650688.2"),
            (161_624_357_233_039.0 + 0.625, "161624357233039.62"),
            (f64::NAN, "nan"),
            (f64::INFINITY, "inf"),
            (f64::NEG_INFINITY, "-inf"),
        ];
        for (v, want) in cases {
            assert_eq!(repr(v), want, "{v:e}");
        }
    }

    #[test]
    fn ryu_digits_match_the_std_reference() {
        // Bit patterns across the whole range (a xorshift walk), and the layout cases above.
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut writer = PythonFloatRepr::new();
        let (mut fast, mut plain) = (String::new(), String::new());
        for i in 0..200_000u64 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let v = if i % 4 == 0 {
                // short decimals and their neighbours: where ties and trailing zeros live
                let base = (state % 100_000) as f64 / 8.0_f64.powi((state >> 40) as i32 % 9);
                f64::from_bits(base.to_bits().wrapping_add((state >> 60) % 3))
            } else {
                f64::from_bits(state)
            };
            fast.clear();
            plain.clear();
            writer.push_repr(v, &mut fast);
            writer.push_repr_std(v, &mut plain);
            assert_eq!(fast, plain, "{v:e} bits {:#x}", v.to_bits());
            fast.clear();
            writer.push_repr_digits(v, &mut fast);
            assert_eq!(fast, plain, "digits {v:e} bits {:#x}", v.to_bits());
        }
    }

    #[test]
    fn json_writes_null_for_non_finite() {
        let mut writer = PythonFloatRepr::new();
        let mut out = String::new();
        for v in [1.0, f64::NAN, -f64::INFINITY, 0.25] {
            writer.push_json(v, &mut out);
            out.push(',');
        }
        assert_eq!(out, "1.0,null,null,0.25,");
    }
}
