//! The optimism window as command lines take it: `W` steps, or `auto` / `auto:W`, a window
//! each world adapts by its rollbacks up to `W` (SPEC.md §K14).

use super::KernelConfig;
use std::fmt;
use std::str::FromStr;

/// A fixed or an adaptive optimism window.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WindowSpec {
    /// Every world computes at most this many steps past GVT.
    Fixed(u64),
    /// Each world adapts its own window within `1..=` this many steps.
    Auto(u64),
}

impl WindowSpec {
    /// The ceiling of a plain `auto`: the widest window of the experiments.
    pub const AUTO_CEILING: u64 = 64;

    /// The window, or the ceiling of an adaptive one.
    pub fn steps(self) -> u64 {
        match self {
            WindowSpec::Fixed(w) | WindowSpec::Auto(w) => w,
        }
    }

    /// `config` with this window.
    pub fn apply(self, config: KernelConfig) -> KernelConfig {
        config
            .window(self.steps())
            .window_auto(matches!(self, WindowSpec::Auto(_)))
    }

    /// The window `window` (steps; the ceiling if `auto`), adaptive or fixed.
    pub fn new(window: u64, auto: bool) -> WindowSpec {
        if auto {
            WindowSpec::Auto(window)
        } else {
            WindowSpec::Fixed(window)
        }
    }

    /// The window of `config`.
    pub fn of(config: &KernelConfig) -> WindowSpec {
        WindowSpec::new(config.window, config.window_auto)
    }
}

impl fmt::Display for WindowSpec {
    /// `16`, or `auto:64`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            WindowSpec::Fixed(w) => write!(f, "{w}"),
            WindowSpec::Auto(w) => write!(f, "auto:{w}"),
        }
    }
}

impl FromStr for WindowSpec {
    type Err = String;

    /// `W` (1 to 1,000,000), `auto` (up to [`WindowSpec::AUTO_CEILING`]) or `auto:W`.
    fn from_str(s: &str) -> Result<Self, String> {
        let steps = |t: &str| -> Result<u64, String> {
            match t.parse::<u64>() {
                Ok(w) if (1..=1_000_000).contains(&w) => Ok(w),
                _ => Err(format!(
                    "`{t}` is not a window: give a whole number of steps from 1 to 1000000, or \
                     `auto` (or `auto:W`) for a window each world adapts by its rollbacks"
                )),
            }
        };
        let t = s.trim();
        if t == "auto" {
            return Ok(WindowSpec::Auto(Self::AUTO_CEILING));
        }
        match t.strip_prefix("auto:") {
            Some(ceiling) => steps(ceiling).map(WindowSpec::Auto),
            None => steps(t).map(WindowSpec::Fixed),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_parse_print_and_apply_round_trip() {
        for (text, spec) in [
            ("16", WindowSpec::Fixed(16)),
            ("auto", WindowSpec::Auto(64)),
            ("auto:8", WindowSpec::Auto(8)),
        ] {
            let parsed: WindowSpec = text.parse().unwrap();
            assert_eq!(parsed, spec);
            assert_eq!(WindowSpec::of(&spec.apply(KernelConfig::new(2))), spec);
            assert_eq!(parsed.to_string().parse::<WindowSpec>().unwrap(), spec);
        }
        for bad in ["0", "auto:0", "-3", "fast", "auto:", "1000001"] {
            let e = bad.parse::<WindowSpec>().unwrap_err();
            assert!(e.contains("auto"), "{bad}: {e}");
        }
    }
}
