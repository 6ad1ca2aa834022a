//! Value parsers for whole-number options, with messages that say what to give: clap's own
//! say "invalid digit found in string" for `-1` and "0 is not in 1..18446744073709551615"
//! for a zero. Commands taking these options allow values that look like negative numbers
//! (`allow_negative_numbers`), so `--steps -1` reaches the parser instead of being taken
//! for an unknown argument.

/// A parser for a whole number from `min` to `max` inclusive.
pub fn whole(
    min: u64,
    max: u64,
) -> impl Fn(&str) -> Result<u64, String> + Clone + Send + Sync + 'static {
    move |s: &str| {
        let range = if max == u64::MAX {
            format!("a whole number {min} or more")
        } else {
            format!("a whole number from {min} to {max}")
        };
        let t = s.trim();
        if t.starts_with('-') && t[1..].bytes().all(|b| b.is_ascii_digit()) && t.len() > 1 {
            return Err(format!("negative numbers are not allowed: give {range}"));
        }
        let n: u64 = t.parse().map_err(|_| {
            if !t.is_empty() && t.bytes().all(|b| b.is_ascii_digit()) {
                format!("too large: give {range}")
            } else {
                format!("not a whole number: give {range}")
            }
        })?;
        if n < min || n > max {
            return Err(format!("out of range: give {range}"));
        }
        Ok(n)
    }
}

/// A parser for a count of things from `min` up (`--threads`, `--entities`), as a `usize`.
pub fn count_from(
    min: usize,
) -> impl Fn(&str) -> Result<usize, String> + Clone + Send + Sync + 'static {
    move |s: &str| {
        let n = whole(min as u64, u64::MAX)(s)?;
        usize::try_from(n).map_err(|_| "too large for this machine".to_string())
    }
}

/// A parser for a count of things, 0 included (`--objects`; a zero is left for the scene
/// builder to refuse, naming the scene).
pub fn count(s: &str) -> Result<usize, String> {
    count_from(0)(s)
}

/// The most entities a registered model may be asked for (`--entities`): ten times
/// `--objects`' cap. Unbounded, a billion entities aborted on a 56 GB allocation and
/// `u64::MAX` divided by zero in the grid.
pub const MAX_ENTITIES: u64 = 10_000_000;

/// A parser for `--entities`: a whole number from 1 to [`MAX_ENTITIES`].
pub fn entity_count(s: &str) -> Result<usize, String> {
    let n = whole(1, MAX_ENTITIES)(s)?;
    usize::try_from(n).map_err(|_| "too large for this machine".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_say_what_to_give() {
        let p = whole(1, u64::MAX);
        assert_eq!(p("3"), Ok(3));
        assert!(p("-1").unwrap_err().contains("negative"));
        assert!(p("0").unwrap_err().contains("1 or more"));
        assert!(p("x").unwrap_err().contains("not a whole number"));
        assert!(p("99999999999999999999999")
            .unwrap_err()
            .contains("too large"));
        let q = whole(1, 4096);
        assert!(q("5000").unwrap_err().contains("from 1 to 4096"));
        assert_eq!(whole(0, u64::MAX)("0"), Ok(0));
        assert_eq!(count("0"), Ok(0));
        assert!(count_from(1)("0").unwrap_err().contains("1 or more"));
        assert_eq!(count_from(1)("4"), Ok(4));
    }
}
