//! Parsing the numbers of a recording: a fast path for the plain decimals loggers write
//! (`-12.345`), exact by Clinger's argument, and the standard library's parser for the rest.
//!
//! Fast path (W. D. Clinger, "How to read floating point numbers accurately", PLDI 1990): a
//! decimal with at most 15 significant digits is `m / 10^k` with the integer `m < 2^53` and
//! `k ≤ 22`; both are exact in f64, so the one IEEE division is correctly rounded and the result
//! is bit for bit what `str::parse::<f64>` returns. Anything else (exponents, more digits,
//! `inf`, `nan`, a leading `+`) goes to `str::parse`.

/// Powers of ten exact in f64.
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// Most significant digits taken by the fast path (`10^15 < 2^53`).
const MAX_FAST_DIGITS: usize = 15;

/// `text` as a finite number, or `None` when it is not one.
pub fn parse_finite(text: &str) -> Option<f64> {
    let value = match fast_decimal(text.as_bytes()) {
        Some(v) => v,
        None => text.parse::<f64>().ok()?,
    };
    value.is_finite().then_some(value)
}

/// `[-]digits[.digits]` with at most [`MAX_FAST_DIGITS`] digits in all; `None` otherwise.
fn fast_decimal(bytes: &[u8]) -> Option<f64> {
    let (negative, body) = match bytes {
        [b'-', rest @ ..] => (true, rest),
        _ => (false, bytes),
    };
    // Two tight digit loops (integer part, then fraction); the arithmetic wraps on absurdly
    // long inputs, which the digit count then sends to the standard parser.
    let mut mantissa: u64 = 0;
    let mut i = 0;
    while let Some(d) = body
        .get(i)
        .map(|b| b.wrapping_sub(b'0'))
        .filter(|d| *d <= 9)
    {
        mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(d));
        i += 1;
    }
    let integer_digits = i;
    let mut fraction_digits = 0;
    if body.get(i) == Some(&b'.') {
        i += 1;
        let start = i;
        while let Some(d) = body
            .get(i)
            .map(|b| b.wrapping_sub(b'0'))
            .filter(|d| *d <= 9)
        {
            mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(d));
            i += 1;
        }
        fraction_digits = i - start;
        // "1." style texts: leave them to the standard parser's judgement.
        if fraction_digits == 0 {
            return None;
        }
    }
    let digits = integer_digits + fraction_digits;
    if i != body.len() || digits == 0 || digits > MAX_FAST_DIGITS {
        return None;
    }
    let value = mantissa as f64 / POW10[fraction_digits];
    Some(if negative { -value } else { value })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fast_path_agrees_with_the_standard_parser_bit_for_bit() {
        let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
        for _ in 0..200_000 {
            // xorshift64: varied digit counts, signs and decimal point positions.
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let digits = 1 + (state % 15) as usize;
            let mantissa = (state >> 8) % 10u64.pow(digits as u32);
            let point = (state >> 4) as usize % (digits + 1);
            let mut text = format!("{mantissa:0digits$}");
            if point < digits {
                text.insert(digits - point, '.');
            }
            if state & 1 == 1 {
                text.insert(0, '-');
            }
            let expected: f64 = text.parse().expect("valid decimal");
            let fast = fast_decimal(text.as_bytes());
            if let Some(v) = fast {
                assert_eq!(v.to_bits(), expected.to_bits(), "{text}");
            }
            assert_eq!(
                parse_finite(&text).map(f64::to_bits),
                Some(expected.to_bits())
            );
        }
    }

    #[test]
    fn other_forms_are_left_to_the_standard_parser_and_non_finite_values_refused() {
        assert_eq!(parse_finite("1e3"), Some(1000.0));
        assert_eq!(parse_finite("+2.5"), Some(2.5));
        assert_eq!(
            parse_finite("12345678901234567890.5"),
            Some(12345678901234567890.5)
        );
        assert_eq!(parse_finite("1."), Some(1.0));
        assert_eq!(parse_finite("inf"), None);
        assert_eq!(parse_finite("NaN"), None);
        assert_eq!(parse_finite("1e400"), None);
        assert_eq!(parse_finite("-"), None);
        assert_eq!(parse_finite(""), None);
        assert_eq!(parse_finite("1.2.3"), None);
        assert_eq!(parse_finite("0x10"), None);
    }
}
