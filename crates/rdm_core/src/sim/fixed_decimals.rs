//! `{:.6}` of an `f64` (Python's `"%.6f"`, the same text) without the formatting machinery.
//!
//! Why: the candump capture writes one stamp per CAN frame (2-3 a simulated ms), and the
//! formatter's exact mode (Grisu with a Dragon fallback, then `fmt::write`) cost ~1,000
//! instructions a stamp. A stamp is a finite, moderate number, and its correctly rounded six
//! decimals follow from integer arithmetic on its bits: |x| = m 2^e exactly, so
//! x 10^6 = m 10^6 / 2^-e, a u128 quotient and remainder, rounded half to even (the
//! formatter's and Python's tie rule: 0.0078125 -> "0.007812"). Anything else (|x| >= 1e12,
//! infinities, NaN) goes through the formatter.

use std::fmt::Write;

/// Magnitudes from here on go through the formatter (x 10^6 must stay far inside u64).
const FAST_LIMIT: f64 = 1e12;
const SCALE: u128 = 1_000_000;

/// Append `format!("{x:.6}")` to `out`.
pub fn push_fixed6(out: &mut String, x: f64) {
    if !x.is_finite() || x.abs() >= FAST_LIMIT {
        let _ = write!(out, "{x:.6}");
        return;
    }
    let bits = x.to_bits();
    let biased = ((bits >> 52) & 0x7FF) as i32;
    let fraction = bits & ((1_u64 << 52) - 1);
    // |x| = m 2^e; subnormals have no hidden bit and the smallest exponent
    let (m, e) = if biased == 0 {
        (fraction, -1074)
    } else {
        (fraction | (1_u64 << 52), biased - 1075)
    };
    // m 10^6 < 2^73; |x| < 1e12 < 2^40 with m >= 2^52 (or a subnormal) gives e <= -13,
    // so the scaling by 2^e is a right shift
    let scaled = u128::from(m) * SCALE;
    let shift = -e as u32;
    let micros = if shift >= 128 {
        0 // scaled < 2^73 is far below half of 2^shift: rounds to zero
    } else {
        let quotient = scaled >> shift;
        let remainder = scaled & ((1_u128 << shift) - 1);
        let half = 1_u128 << (shift - 1);
        if remainder > half || (remainder == half && quotient & 1 == 1) {
            quotient + 1
        } else {
            quotient
        }
    };
    // laid out from the end in one buffer: six decimals, the point, the integer digits
    let micros = micros as u64; // < 1e18
    let mut buf = [b'0'; 24];
    let mut i = buf.len();
    let mut frac = micros % 1_000_000;
    for _ in 0..6 {
        i -= 1;
        buf[i] = b'0' + (frac % 10) as u8;
        frac /= 10;
    }
    i -= 1;
    buf[i] = b'.';
    let mut whole = micros / 1_000_000;
    loop {
        i -= 1;
        buf[i] = b'0' + (whole % 10) as u8;
        whole /= 10;
        if whole == 0 {
            break;
        }
    }
    if x.is_sign_negative() {
        i -= 1;
        buf[i] = b'-';
    }
    // ASCII digits, a point and a sign: always UTF-8
    out.push_str(std::str::from_utf8(&buf[i..]).unwrap_or_default());
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fixed6(x: f64) -> String {
        let mut s = String::new();
        push_fixed6(&mut s, x);
        s
    }

    #[test]
    fn ties_round_half_to_even_as_the_formatter() {
        // k / 128 is exact and a tie at the 7th decimal for odd k (2^-7 = 0.0078125)
        for k in 0..20_000_u32 {
            let x = f64::from(k) / 128.0;
            assert_eq!(fixed6(x), format!("{x:.6}"), "{x}");
            assert_eq!(fixed6(-x), format!("{:.6}", -x), "{}", -x);
        }
        assert_eq!(fixed6(0.0078125), "0.007812");
        assert_eq!(fixed6(0.0234375), "0.023438");
    }

    #[test]
    fn equals_the_formatter_on_stamps_and_random_bits() {
        let mut seed = 0x9E37_79B9_7F4A_7C15_u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for k in 0..200_000_u64 {
            // channel-clock stamps (ms steps, accumulated and products) and random bit patterns
            let stamps = [
                k as f64 * 0.001,
                k as f64 * 0.000_5 + 1.0 / 3.0,
                1.7e9 + k as f64 * 0.001,
                f64::from_bits(next()),
                f64::from_bits(next() >> 12 | 0x3FF0_0000_0000_0000) * 1e3,
                f64::from_bits(next() >> 2),
            ];
            for x in stamps {
                assert_eq!(fixed6(x), format!("{x:.6}"), "{x:e} ({:#x})", x.to_bits());
            }
        }
    }

    #[test]
    fn edges_equal_the_formatter() {
        let edges = [
            0.0,
            -0.0,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
            f64::from_bits(1),
            5e-7,
            4.999_999_999_999_999e-7,
            5.000_000_000_000_001e-7,
            0.999_999_5,
            0.999_999_499_999_999_9,
            999_999_999_999.999_9,
            FAST_LIMIT,
            -FAST_LIMIT,
            1e300,
            f64::MAX,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        for x in edges {
            assert_eq!(fixed6(x), format!("{x:.6}"), "{x:e}");
        }
    }
}
