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
    let (integer, fraction) = match memchr::memchr(b'.', body) {
        // "1." style texts: leave them to the standard parser's judgement.
        Some(at) if at + 1 == body.len() => return None,
        Some(at) => (&body[..at], &body[at + 1..]),
        None => (body, &body[body.len()..]),
    };
    let digits = integer.len() + fraction.len();
    if digits == 0 || digits > MAX_FAST_DIGITS {
        return None;
    }
    // Both parts together have at most 15 digits, so the mantissa stays below 10^15 < 2^53.
    let mantissa = digits_value(integer)? * POW10_INT[fraction.len()] + digits_value(fraction)?;
    let value = mantissa as f64 / POW10[fraction.len()];
    Some(if negative { -value } else { value })
}

/// Powers of ten as integers, for the at most 15 fraction digits of the fast path.
const POW10_INT: [u64; 16] = [
    1,
    10,
    100,
    1_000,
    10_000,
    100_000,
    1_000_000,
    10_000_000,
    100_000_000,
    1_000_000_000,
    10_000_000_000,
    100_000_000_000,
    1_000_000_000_000,
    10_000_000_000_000,
    100_000_000_000_000,
    1_000_000_000_000_000,
];

/// The value of at most 16 ASCII digits (empty: 0); `None` when a byte is not a digit.
fn digits_value(text: &[u8]) -> Option<u64> {
    if text.len() <= 8 {
        eight_digits(text)
    } else {
        let (high, low) = text.split_at(text.len() - 8);
        Some(eight_digits(high)? * 100_000_000 + eight_digits(low)?)
    }
}

/// The value of at most 8 ASCII digits, all eight converted at once in one 64-bit word (the
/// "SWAR" method of D. Lemire's fast_float, `parse_eight_digits_unrolled`): the text is padded
/// with leading `'0'`s to eight bytes, checked to be digits, then pairs, quads and the whole
/// are combined by three multiplications.
fn eight_digits(text: &[u8]) -> Option<u64> {
    let mut padded = [b'0'; 8];
    padded.get_mut(8 - text.len()..)?.copy_from_slice(text);
    let word = u64::from_le_bytes(padded);
    const ZEROS: u64 = 0x3030_3030_3030_3030;
    const HIGH_NIBBLES: u64 = 0xF0F0_F0F0_F0F0_F0F0;
    // Every byte is 0x30..=0x39: its high nibble is 3, and adding 6 does not carry into it.
    let digits = word & HIGH_NIBBLES == ZEROS
        && word.wrapping_add(0x0606_0606_0606_0606) & HIGH_NIBBLES == ZEROS;
    if !digits {
        return None;
    }
    const MASK: u64 = 0x0000_00FF_0000_00FF;
    const MUL1: u64 = 0x000F_4240_0000_0064; // 100 + (1_000_000 << 32)
    const MUL2: u64 = 0x0000_2710_0000_0001; // 1 + (10_000 << 32)
    let v = word - ZEROS;
    let v = v * 10 + (v >> 8);
    let v1 = (v & MASK).wrapping_mul(MUL1);
    let v2 = ((v >> 16) & MASK).wrapping_mul(MUL2);
    Some(u64::from(v1.wrapping_add(v2).wrapping_shr(32) as u32))
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
        assert_eq!(parse_finite(".5"), Some(0.5));
        assert_eq!(parse_finite("-.5"), Some(-0.5));
        assert_eq!(parse_finite("1:5"), None);
        assert_eq!(parse_finite("12/4"), None);
        assert_eq!(parse_finite("-0").map(f64::to_bits), Some((-0.0f64).to_bits()));
        assert_eq!(parse_finite("00000000000012.5"), Some(12.5));
    }
}
