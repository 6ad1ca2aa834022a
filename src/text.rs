//! Plain text for people: counts with the noun that goes with them, as the library's reports
//! ([`verify`](mod@crate::verify)) and the command line write them.

/// `n` and the noun that goes with it: `counted(1, "frame", "frames")` is `1 frame`,
/// `counted(3, "body", "bodies")` is `3 bodies` (and `0 bodies`).
pub fn counted<N>(n: N, one: &str, many: &str) -> String
where
    N: std::fmt::Display + PartialEq + From<u8>,
{
    let noun = if n == N::from(1) { one } else { many };
    format!("{n} {noun}")
}

#[cfg(test)]
mod tests {
    use super::counted;

    #[test]
    fn one_thing_is_singular_and_every_other_count_plural() {
        assert_eq!(counted(1u64, "frame", "frames"), "1 frame");
        assert_eq!(counted(0u32, "frame", "frames"), "0 frames");
        assert_eq!(counted(2usize, "body", "bodies"), "2 bodies");
    }
}
