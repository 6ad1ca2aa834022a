//! Ctrl-C (SIGINT) and SIGTERM during a run (`soda run`, `run --model NAME`): the first one
//! asks the run to stop at its next committed frame (the frame sink polls [`requested`]), a
//! second one gives up at once.
//!
//! The signal handler only stores a flag and writes one byte to a pipe (both async-signal
//! safe). A watcher thread reads the pipe: on the second signal it removes every uncommitted
//! temporary output file ([`super::atomic::discard_all`]) and exits with 128 + the signal
//! number, for a run stuck in a long step.

use std::sync::atomic::{AtomicBool, AtomicI32, AtomicUsize, Ordering};

/// Set by the first SIGINT or SIGTERM.
static REQUESTED: AtomicBool = AtomicBool::new(false);
/// Signals received so far.
static COUNT: AtomicUsize = AtomicUsize::new(0);
/// The last signal's number.
static SIGNAL: AtomicI32 = AtomicI32::new(0);
/// The write end of the watcher's pipe (-1 before [`install`]).
static PIPE: AtomicI32 = AtomicI32::new(-1);

/// The exit status of a run stopped by a signal (130 for Ctrl-C, 143 for SIGTERM).
pub fn exit_status() -> u8 {
    let signal = SIGNAL.load(Ordering::SeqCst);
    (128 + signal.clamp(1, 127)) as u8
}

/// Whether a stop was requested.
pub fn requested() -> bool {
    REQUESTED.load(Ordering::Relaxed)
}

extern "C" fn on_signal(signal: libc::c_int) {
    SIGNAL.store(signal, Ordering::SeqCst);
    REQUESTED.store(true, Ordering::SeqCst);
    COUNT.fetch_add(1, Ordering::SeqCst);
    let fd = PIPE.load(Ordering::SeqCst);
    if fd >= 0 {
        let byte = 1u8;
        // SAFETY: write(2) is async-signal safe; the buffer is a live local byte.
        unsafe {
            libc::write(fd, (&byte as *const u8).cast(), 1);
        }
    }
}

/// Why the graceful stop could not be installed (the run then proceeds without it).
#[derive(Debug, thiserror::Error)]
pub enum InstallError {
    /// The watcher's pipe could not be created.
    #[error("pipe: {0}")]
    Pipe(std::io::Error),
    /// The watcher thread could not be started.
    #[error("cannot start the signal watcher: {0}")]
    Watcher(std::io::Error),
    /// A signal handler could not be installed.
    #[error("sigaction: {0}")]
    Sigaction(std::io::Error),
}

/// Installs the handlers for SIGINT and SIGTERM and starts the watcher thread. Returns an
/// error if the system refuses (the run then proceeds without the graceful stop).
pub fn install() -> Result<(), InstallError> {
    let mut fds = [0 as libc::c_int; 2];
    // SAFETY: `fds` has room for the two descriptors pipe(2) writes.
    if unsafe { libc::pipe(fds.as_mut_ptr()) } != 0 {
        return Err(InstallError::Pipe(std::io::Error::last_os_error()));
    }
    let [read_end, write_end] = fds;
    PIPE.store(write_end, Ordering::SeqCst);
    std::thread::Builder::new()
        .name("soda-signals".into())
        .spawn(move || watch(read_end))
        .map_err(InstallError::Watcher)?;
    for signal in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: a zeroed sigaction with a handler that only touches atomics and write(2);
        // SA_RESTART keeps interrupted system calls of the run going.
        let ok = unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
            action.sa_flags = libc::SA_RESTART;
            libc::sigemptyset(&mut action.sa_mask);
            libc::sigaction(signal, &action, std::ptr::null_mut()) == 0
        };
        if !ok {
            return Err(InstallError::Sigaction(std::io::Error::last_os_error()));
        }
    }
    Ok(())
}

/// The watcher thread: on the second signal, discard the temporary files and exit.
fn watch(read_end: libc::c_int) {
    let mut byte = 0u8;
    loop {
        // SAFETY: reads at most one byte into a live local.
        let n = unsafe { libc::read(read_end, (&mut byte as *mut u8).cast(), 1) };
        if n < 0 && std::io::Error::last_os_error().kind() == std::io::ErrorKind::Interrupted {
            continue;
        }
        if n <= 0 {
            return;
        }
        if COUNT.load(Ordering::SeqCst) >= 2 {
            super::atomic::discard_all();
            eprintln!(
                "interrupted again: stopped at once; the files being written were discarded \
                 (outputs already whole, such as an earlier checkpoint, are kept)"
            );
            std::process::exit(i32::from(exit_status()));
        }
    }
}
