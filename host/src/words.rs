//! Counts in words for messages: `1 pose`, `2 poses`.

/// `n` and `noun`, the noun in the plural (an `s` added) unless `n` is 1.
pub fn counted(n: usize, noun: &str) -> String {
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_is_singular_and_every_other_count_plural() {
        assert_eq!(counted(1, "pose"), "1 pose");
        assert_eq!(counted(0, "pose"), "0 poses");
        assert_eq!(
            counted(12, "distinct gravity direction"),
            "12 distinct gravity directions"
        );
    }
}
