//! The calling thread's CPU clock: time a thread actually ran, without the time other
//! processes took its core. Load measurements and benchmarks on a shared machine read it
//! beside (never instead of) wall-clock time.

use std::time::Instant;

/// CPU seconds the calling thread has run so far (`CLOCK_THREAD_CPUTIME_ID`); wall-clock
/// seconds since the thread's first call where the thread clock is unavailable.
pub fn thread_cpu_seconds() -> f64 {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `clock_gettime` writes one `timespec` through the pointer, which points to a
    // live, writable, properly aligned local; the clock id is a constant the C library
    // knows. No other memory is touched.
    let ok = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) } == 0;
    if ok {
        t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
    } else {
        thread_local!(static START: Instant = Instant::now());
        START.with(|s| s.elapsed().as_secs_f64())
    }
}

#[cfg(test)]
mod tests {
    use super::thread_cpu_seconds;

    #[test]
    fn thread_cpu_clock_advances_with_work_and_never_goes_back() {
        let a = thread_cpu_seconds();
        let mut x = 0u64;
        for i in 0..20_000_000u64 {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(i);
        }
        std::hint::black_box(x);
        let b = thread_cpu_seconds();
        assert!(
            b > a,
            "the thread clock did not advance over busy work: {a} -> {b}"
        );
    }
}
