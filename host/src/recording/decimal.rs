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

/// Powers of ten as integers, to join runs of up to eight digits.
const POW10_INT: [u64; 9] = [
    1,
    10,
    100,
    1_000,
    10_000,
    100_000,
    1_000_000,
    10_000_000,
    100_000_000,
];

/// The number field of a row that starts at `bytes[at]`, read by the rules of the fast path
/// (`[-]digits[.digits]`, at most [`MAX_FAST_DIGITS`] digits): its value, bit for bit what
/// `str::parse` gives, and the index of the byte after it. `None` when the field does not start
/// with such a number; the caller checks the byte that follows it.
///
/// The digits are taken eight at a time from one 64-bit word (the "SWAR" technique): a mask
/// finds where the run of digits ends and three multiplications join them, with no branch per
/// digit. The byte found after the number is never part of it, so the result is the value of
/// the same text [`fast_decimal`] reads.
#[inline]
pub fn fast_field(bytes: &[u8], at: usize) -> Option<(f64, usize)> {
    let negative = bytes.get(at) == Some(&b'-');
    let mut i = at + usize::from(negative);
    // The usual field ends within one word: read it from that word alone.
    if let Some((mantissa, fraction_digits, len)) = short_field(bytes, i) {
        let value = mantissa as i64 as f64 / POW10.get(fraction_digits)?;
        let sign = u64::from(negative) << 63;
        return Some((f64::from_bits(value.to_bits() | sign), i + len));
    }
    let (integer_digits, mut mantissa) = digit_run(bytes, i, 0);
    i += integer_digits;
    let mut fraction_digits = 0;
    if bytes.get(i) == Some(&b'.') {
        i += 1;
        let (n, m) = digit_run(bytes, i, mantissa);
        // "1." style texts: leave them to the standard parser's judgement.
        if n == 0 {
            return None;
        }
        fraction_digits = n;
        mantissa = m;
        i += n;
    }
    let digits = integer_digits + fraction_digits;
    if digits == 0 || digits > MAX_FAST_DIGITS {
        return None;
    }
    // Below 2^53, the mantissa converts exactly (as a signed integer: one instruction).
    let value = mantissa as i64 as f64 / POW10.get(fraction_digits)?;
    // The sign set without a branch (signs of sensor values are as good as random): `value` is
    // not negative, so setting its sign bit is negating it, `-0` included.
    let sign = u64::from(negative) << 63;
    Some((f64::from_bits(value.to_bits() | sign), i))
}

/// A field `digits[.digits]` at `bytes[at..]` that ends within the eight bytes from `at` or
/// right after them (a byte that is neither a digit nor its one point follows it): its digits as an
/// integer, the number of digits after the point and the field's length. `None` when the
/// field runs past the word (the caller reads it run by run) or has no digit before its end,
/// or no digit after its point (those are not numbers of the fast path).
///
/// The mask of [`eight_digits`] judges every byte up to the field's end: neither a point nor
/// the byte that ends the field carries out of its byte, so the bytes after the point are
/// judged as if they came first. The digits after the point are moved down one byte, over it,
/// and the joined run is converted as one.
#[inline]
fn short_field(bytes: &[u8], at: usize) -> Option<(u64, usize, usize)> {
    let word = load8(bytes, at) ^ 0x3030_3030_3030_3030;
    let not_digit = (word.wrapping_add(0x7676_7676_7676_7676) | word) & 0x8080_8080_8080_8080;
    // A field that fills the word ends there when the byte after it is not a digit.
    let ends_at_word_end = || !bytes.get(at + 8).is_some_and(u8::is_ascii_digit);
    let first = (not_digit.trailing_zeros() / 8) as usize;
    if first >= 8 && !(ends_at_word_end() && bytes.get(at + 8) != Some(&b'.')) {
        return None;
    }
    let (digits, fraction_digits, len, run) = if bytes.get(at + first) == Some(&b'.') {
        let after = not_digit & !(0x80u64 << (8 * first));
        let end = (after.trailing_zeros() / 8) as usize;
        if (end >= 8 && !ends_at_word_end()) || end == first + 1 {
            return None;
        }
        // Bytes below the point as they are; those after it one byte down.
        let below = word & ((1u64 << (8 * first)) - 1);
        let above = (word >> 8) & !((1u64 << (8 * first)) - 1);
        (end - 1, end - first - 1, end, below | above)
    } else {
        (first, 0, first, word)
    };
    if digits == 0 {
        return None;
    }
    Some((join_digits(run, digits), fraction_digits, len))
}

/// The run of digits at `bytes[at..]` appended to `mantissa`: its length and the new mantissa.
/// Stops once the run is longer than [`MAX_FAST_DIGITS`] (the mantissa then wraps, and the
/// caller refuses the number for its digit count).
#[inline]
fn digit_run(bytes: &[u8], at: usize, mut mantissa: u64) -> (usize, u64) {
    let mut count = 0;
    loop {
        let (n, value) = eight_digits(bytes, at + count);
        mantissa = mantissa.wrapping_mul(POW10_INT[n]).wrapping_add(value);
        count += n;
        if n < 8 || count > MAX_FAST_DIGITS {
            return (count, mantissa);
        }
    }
}

/// The leading decimal digits of `bytes[at..]`, at most eight: how many, and their value.
#[inline]
fn eight_digits(bytes: &[u8], at: usize) -> (usize, u64) {
    // '0'..'9' become 0..9; a byte is a digit when it is then below 10, that is when neither it
    // nor it plus 0x76 has its top bit set. The addition carries only out of a byte that is not
    // a digit, so every byte up to the first one that is not a digit is judged right.
    let word = load8(bytes, at) ^ 0x3030_3030_3030_3030;
    let not_digit = (word.wrapping_add(0x7676_7676_7676_7676) | word) & 0x8080_8080_8080_8080;
    let n = (not_digit.trailing_zeros() / 8) as usize;
    (n, join_digits(word, n))
}

/// The value of the `n` digits (0..9 per byte, the first and most significant lowest) in the
/// low bytes of `run`: they go to the top bytes, zeros below as leading zeros, then pairs,
/// fours and eights of digits are joined.
#[inline]
fn join_digits(run: u64, n: usize) -> u64 {
    let mut v = run.checked_shl(8 * (8 - n) as u32).unwrap_or(0);
    v = v.wrapping_mul(10).wrapping_add(v >> 8) & 0x00FF_00FF_00FF_00FF;
    v = v.wrapping_mul(100).wrapping_add(v >> 16) & 0x0000_FFFF_0000_FFFF;
    v.wrapping_mul(10_000).wrapping_add(v >> 32) & 0xFFFF_FFFF
}

/// Eight bytes of `bytes` from `at` as a little-endian word, zeros past the end (a zero byte is
/// not a digit).
#[inline]
fn load8(bytes: &[u8], at: usize) -> u64 {
    if let Some(word) = bytes
        .get(at..at.saturating_add(8))
        .and_then(|s| <[u8; 8]>::try_from(s).ok())
    {
        return u64::from_le_bytes(word);
    }
    let mut word = [0u8; 8];
    for (to, from) in word.iter_mut().zip(bytes.get(at..).unwrap_or_default()) {
        *to = *from;
    }
    u64::from_le_bytes(word)
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

    /// What [`fast_field`] must give for `text` followed by `rest`: a number it reads is the
    /// fast path's value of the bytes it read; when `rest` starts with what ends a field (or is
    /// empty), it reads all of `text` exactly when the fast path takes `text`, to that value.
    fn check_field(text: &str, rest: &str) {
        let row = format!("{text}{rest}");
        for (at, row) in [(0, row.clone()), (5, format!("12.5,{row}"))] {
            let got = fast_field(row.as_bytes(), at);
            if let Some((v, end)) = got {
                let read = &row.as_bytes()[at..end];
                assert_eq!(
                    fast_decimal(read).map(f64::to_bits),
                    Some(v.to_bits()),
                    "{row:?}"
                );
                let parsed: f64 = row[at..end].parse().expect("valid decimal");
                assert_eq!(v.to_bits(), parsed.to_bits(), "{row:?}");
            }
            if rest.is_empty() || rest.starts_with([',', '\n', '\r']) {
                let want = fast_decimal(text.as_bytes()).map(|v| (v.to_bits(), at + text.len()));
                let whole = got
                    .map(|(v, end)| (v.to_bits(), end))
                    .filter(|(_, end)| *end == at + text.len());
                assert_eq!(whole, want, "{row:?}");
            }
        }
    }

    #[test]
    fn fields_read_eight_digits_at_a_time_agree_with_the_fast_path_and_the_standard_parser() {
        let mut state: u64 = 0x2545_F491_4F6C_DD1D;
        for _ in 0..200_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            // Up to 20 digits: runs longer than eight, and numbers too long for the fast path.
            let digits = 1 + (state % 20) as usize;
            let mantissa = (state >> 8) % 10u64.pow(digits.min(19) as u32);
            let point = (state >> 4) as usize % (digits + 1);
            let mut text = format!("{mantissa:0digits$}");
            if point < digits {
                text.insert(digits - point, '.');
            }
            if state & 1 == 1 {
                text.insert(0, '-');
            }
            // Fields that end within one word (read from it alone) and those that do not, ended
            // by every kind of byte, a multi-byte character included.
            let rest = [
                ",", "\n", "\r\n", "", ",-3.25,7", " ,1", "e3,", "x", "\u{e9},1", ".5,",
            ][(state >> 40) as usize % 10];
            check_field(&text, rest);
        }
    }

    #[test]
    fn fields_of_other_forms_are_left_to_the_standard_parser() {
        for text in [
            "",
            "-",
            ".",
            "-.",
            "1.",
            "-1.",
            ".5",
            "-.5",
            "+1",
            "1e3",
            "inf",
            "nan",
            "1.2.3",
            "0x10",
            "00000000000000001",
            "123456789012345",
            "1234567890123456",
            "12345678.1234567",
            "12345678.12345678",
            "99999999",
            "999999999",
            "-0.0",
            "0",
            "\u{e9}",
        ] {
            for rest in ["", ",", "\n", "\r\n,5"] {
                check_field(text, rest);
            }
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
