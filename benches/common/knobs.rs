//! Shared by the benches that take their sizes from the environment: whether the run is the
//! tiny `--test` version, numeric knobs, and medians of repeated wall times and of their
//! pairwise ratios.

/// Whether this is the tiny version (`cargo test --benches`, or `-- --test`).
pub fn quick() -> bool {
    let args: Vec<String> = std::env::args().collect();
    !args.iter().any(|a| a == "--bench") || args.iter().any(|a| a == "--test")
}

/// The numeric knob `name` from the environment (`default` if unset or unreadable), or
/// `quick_value` in the tiny version.
pub fn env(name: &str, default: u64, quick_value: u64) -> u64 {
    if quick() {
        return quick_value;
    }
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// The comma-separated, lower-cased list in the environment variable `name`, if it is set
/// (empty items dropped): which cases or engines a bench runs. Not every bench that includes
/// this file filters.
#[allow(dead_code)]
pub fn list(name: &str) -> Option<Vec<String>> {
    std::env::var(name).ok().map(|v| {
        v.split(',')
            .map(|s| s.trim().to_lowercase())
            .filter(|s| !s.is_empty())
            .collect()
    })
}

/// The median of `v` (the mean of the middle two for an even count).
pub fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let m = s.len() / 2;
    if s.len() % 2 == 1 {
        s[m]
    } else {
        (s[m - 1] + s[m]) / 2.0
    }
}

/// The median of `a[k] / b[k]` over pairs of runs taken back to back: robust when the
/// machine's speed drifts between pairs, as the ratio of the medians is not.
pub fn median_ratio(a: &[f64], b: &[f64]) -> f64 {
    median(&a.iter().zip(b).map(|(x, y)| x / y).collect::<Vec<f64>>())
}
