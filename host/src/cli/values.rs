//! Parsers of option values shared by the commands' arguments: each refuses a value in the
//! option's own words rather than the standard parser's.

/// A count or seed: a whole number of 0 or more, refused with the option's own words (the
/// standard parser says "invalid digit found in string" for `-1`).
pub fn whole_number<T>(text: &str) -> Result<T, String>
where
    T: std::str::FromStr + std::fmt::Display + Bounded,
{
    let trimmed = text.trim();
    if let Ok(value) = trimmed.parse::<T>() {
        return Ok(value);
    }
    let digits = trimmed.strip_prefix('+').unwrap_or(trimmed);
    if !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()) {
        return Err(format!(
            "`{text}` is larger than the largest value allowed ({})",
            T::MAX_VALUE
        ));
    }
    Err(format!("`{text}` is not a whole number of 0 or more"))
}

/// The largest value of an unsigned integer type, for [`whole_number`]'s message.
pub trait Bounded {
    /// The type's largest value.
    const MAX_VALUE: Self;
}

impl Bounded for usize {
    const MAX_VALUE: Self = usize::MAX;
}

impl Bounded for u64 {
    const MAX_VALUE: Self = u64::MAX;
}
