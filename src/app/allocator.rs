//! The allocator settings a binary running worlds on several threads wants: mimalloc (the
//! `soda` binary's global allocator, and a good choice for your own) told to keep the
//! memory it frees instead of handing it back to the OS after a second.
//!
//! Why: in a threaded run a state is allocated by the worker that computes it and often
//! freed by another thread (the worker finishing a committed frame drops the last
//! reference of another world's states, fossil collection runs wherever its world runs
//! next). mimalloc collects those frees lazily, so the allocating thread keeps taking
//! fresh pages while the freed ones sit
//! idle, and with its default purge delay (1 s) it returns them to the OS and soon faults
//! them back in, each one zeroed by the kernel. On 8,000 falling cubes on two threads that
//! was 2,717 page faults in 600 steps against 296 with purging off (docs/performance.md,
//! "Round nine"). The reference executor, one thread, faults 278 times.
//!
//! The price is resident memory: memory freed stays mapped for reuse, so a run's resident
//! set stays at its peak (which is what a simulation that keeps stepping needs again).
//! `MIMALLOC_PURGE_DELAY` (or its old name `MIMALLOC_RESET_DELAY`, in any case, as mimalloc
//! reads them) in the environment still decides, if set.
//!
//! ```
//! // First thing in `main`, before any thread starts:
//! soda::app::allocator::configure();
//! ```

use libmimalloc_sys::{mi_option_set, mi_option_t};

/// mimalloc's `mi_option_purge_delay` (`mi_option_e` in mimalloc.h, which libmimalloc-sys
/// does not name). mimalloc keeps that enum's numbering stable across releases: an option
/// it drops stays in place as `deprecated_*`. A test checks the number against the name
/// mimalloc itself prints.
const PURGE_DELAY: mi_option_t = 15;

/// The environment variables mimalloc reads for [`PURGE_DELAY`] (the second is its old
/// name; mimalloc ignores their case); if one is set it wins.
const PURGE_DELAY_VARIABLES: [&str; 2] = ["MIMALLOC_PURGE_DELAY", "MIMALLOC_RESET_DELAY"];

/// Whether the environment sets mimalloc's purge delay (mimalloc then read it when the
/// process started).
fn purge_delay_in_environment() -> bool {
    in_environment(&PURGE_DELAY_VARIABLES)
}

/// Turns transparent huge pages off for the whole process from now on (Linux; elsewhere
/// nothing: a hint, whose failure changes nothing but the resident set).
fn disable_transparent_huge_pages() {
    #[cfg(target_os = "linux")]
    // SAFETY: `prctl(PR_SET_THP_DISABLE, 1, 0, 0, 0)` takes integers only and sets a flag
    // of this process's address space that the kernel checks before it backs a fault with
    // a huge page; it reads or writes no memory of ours. A failure (an old kernel) returns
    // -1 and changes nothing.
    unsafe {
        libc::prctl(libc::PR_SET_THP_DISABLE, 1, 0, 0, 0);
    }
}

/// The environment variable mimalloc reads for its use of transparent huge pages; if set,
/// it wins over [`configure`]'s choice.
const ALLOW_THP_VARIABLE: &str = "MIMALLOC_ALLOW_THP";

/// Whether the environment sets any of `names` (in any case, as mimalloc reads them).
fn in_environment(names: &[&str]) -> bool {
    std::env::vars_os().any(|(name, _)| {
        let name = name.to_string_lossy();
        names.iter().any(|v| name.eq_ignore_ascii_case(v))
    })
}

/// Tells mimalloc never to return freed memory to the OS (unless `MIMALLOC_PURGE_DELAY`
/// says otherwise), and on Linux turns transparent huge pages off for this process (unless
/// `MIMALLOC_ALLOW_THP` says otherwise). Call it first thing in `main`, before any other
/// thread starts; the purge setting does nothing harmful if mimalloc is not the global
/// allocator (its options then govern no allocation). [`main_with`](super::main_with)
/// calls it.
///
/// Why no huge pages: mimalloc asks for them on the memory it maps, and the kernel then
/// backs each 2 MB region it touches at all with a whole zeroed huge page. Its blocks are
/// spread over many such regions (a page of 64 KiB per size class and thread), so a run's
/// resident set was about twice the memory it uses, with no speed gained in any case
/// measured (docs/performance.md, "Round ten": 8,000 cubes on two threads 58 → 24 MB and
/// 1.016× faster, the reference 23 → 11 MB, 100,000 bodies of sparse gas 67 → 54 MB).
pub fn configure() {
    if !in_environment(&[ALLOW_THP_VARIABLE]) {
        disable_transparent_huge_pages();
    }
    if purge_delay_in_environment() {
        return;
    }
    // SAFETY: `mi_option_set` takes two integers and stores one into an entry of
    // mimalloc's static option table (a `long` and its "initialised" flag, options.c); it
    // reads or writes no memory of ours, and the index is in range (the test below checks
    // it names `purge_delay`). mimalloc's allocation paths read that entry without a lock
    // (`mi_option_get`), so a write racing with a read on another thread is the only
    // hazard; `configure` is to be called first in `main`, before any other thread
    // exists, where no race is possible. Called later, the read sees the old or the new
    // value, either a valid delay that only decides when freed memory goes back to the OS.
    unsafe { mi_option_set(PURGE_DELAY, -1) };
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::{c_char, c_void, CStr};

    /// Appends one message of mimalloc's to the `String` behind `arg`.
    ///
    /// # Safety
    /// `msg` must be a NUL-terminated string and `arg` a valid `*mut String`.
    unsafe extern "C" fn collect(msg: *const c_char, arg: *mut c_void) {
        // SAFETY: mimalloc passes a NUL-terminated message, and `arg` is the `&mut String`
        // the test hands to `mi_options_print_out`, alive for the whole call.
        let text = unsafe { CStr::from_ptr(msg) }.to_string_lossy();
        unsafe { &mut *arg.cast::<String>() }.push_str(&text);
    }

    extern "C" {
        /// Prints mimalloc's version and every option's name and value through `out`.
        fn mi_options_print_out(out: libmimalloc_sys::mi_output_fun, arg: *mut c_void);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn configure_turns_transparent_huge_pages_off_for_the_process() {
        if in_environment(&[ALLOW_THP_VARIABLE]) {
            // The environment decides; `configure` rightly leaves it alone.
            return;
        }
        configure();
        // SAFETY: `prctl(PR_GET_THP_DISABLE, 0, 0, 0, 0)` takes integers and returns the
        // process's flag; no memory of ours is touched.
        let flag = unsafe { libc::prctl(libc::PR_GET_THP_DISABLE, 0, 0, 0, 0) };
        assert_eq!(flag, 1, "transparent huge pages are still allowed");
    }

    #[test]
    fn configure_turns_off_mimallocs_purge_delay_by_its_own_name() {
        if purge_delay_in_environment() {
            // The environment decides; `configure` rightly leaves it alone.
            return;
        }
        configure();
        let mut printed = String::new();
        // SAFETY: `collect` matches `mi_output_fun` and expects `arg` to be a `*mut String`;
        // `printed` outlives the call, which prints synchronously.
        unsafe { mi_options_print_out(Some(collect), (&mut printed as *mut String).cast()) };
        assert!(
            printed.contains("option 'purge_delay': -1 "),
            "option {PURGE_DELAY} is not mimalloc's purge delay, or it was not set:\n{printed}"
        );
    }
}
