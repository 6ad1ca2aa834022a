//! The synchronisation facade of the threaded executor: every lock, atomic, thread spawn and
//! yield it performs goes through a [`Facade`], so tests can run the executor's own
//! coordination under shuttle's schedulers (a test crate implements [`Facade`] with
//! shuttle's primitives). [`StdFacade`] is the production implementation.
//! crossbeam-deque's operations stay opaque: to a model checker each is one atomic step.

use std::ops::DerefMut;

/// A mutual-exclusion lock.
pub trait FacadeMutex<T>: Send + Sync {
    /// The guard type.
    type Guard<'a>: DerefMut<Target = T>
    where
        Self: 'a;
    /// A new lock holding `v`.
    fn new(v: T) -> Self;
    /// Locks, ignoring poisoning (a panicking world ends the run anyway).
    fn lock(&self) -> Self::Guard<'_>;
    /// Locks if the lock is free now (ignoring poisoning); `None` only if another thread
    /// holds it, never spuriously (the threaded executor's frame finishing relies on it).
    fn try_lock(&self) -> Option<Self::Guard<'_>>;
}

/// An atomic `u64` (all operations sequentially consistent).
pub trait FacadeAtomic: Send + Sync {
    /// A new atomic.
    fn new(v: u64) -> Self;
    /// Reads.
    fn load(&self) -> u64;
    /// Writes.
    fn store(&self, v: u64);
    /// Swaps, returning the old value.
    fn swap(&self, v: u64) -> u64;
    /// Adds, returning the old value.
    fn fetch_add(&self, v: u64) -> u64;
}

/// A thread that panicked, with its panic message ([`Facade::join`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ThreadPanicked(pub String);

/// The primitives the threaded executor is written against.
pub trait Facade: Send + Sync + 'static {
    /// Lock type.
    type Mutex<T: Send + 'static>: FacadeMutex<T>;
    /// Atomic type.
    type Atomic: FacadeAtomic;
    /// Join handle of a spawned thread.
    type Handle: Send;
    /// Starts a thread.
    fn spawn(f: impl FnOnce() + Send + 'static) -> Self::Handle;
    /// Waits for a thread; `Err` if it panicked.
    fn join(h: Self::Handle) -> Result<(), ThreadPanicked>;
    /// Gives the processor to another thread; `spins` counts consecutive idle calls so an
    /// implementation may back off (`u32::MAX`: a poller nobody waits for, which may sleep
    /// longest; [`SOON_POLL_SPINS`]: one that others will wait for soon).
    fn pause(spins: u32);
    /// Gives the processor away for about `d` when nobody waits for the caller: the
    /// output stage's slow poll once it knows steps take longer than [`SLOW_POLL`].
    /// Without a clock of its own an implementation pauses as for `spins == u32::MAX`.
    fn pause_for(d: std::time::Duration) {
        let _ = d;
        Self::pause(u32::MAX);
    }
}

/// The standard library's primitives.
pub struct StdFacade;

impl<T: Send> FacadeMutex<T> for std::sync::Mutex<T> {
    type Guard<'a>
        = std::sync::MutexGuard<'a, T>
    where
        T: 'a;
    fn new(v: T) -> Self {
        std::sync::Mutex::new(v)
    }
    fn lock(&self) -> Self::Guard<'_> {
        std::sync::Mutex::lock(self).unwrap_or_else(|e| e.into_inner())
    }
    fn try_lock(&self) -> Option<Self::Guard<'_>> {
        match std::sync::Mutex::try_lock(self) {
            Ok(g) => Some(g),
            Err(std::sync::TryLockError::Poisoned(e)) => Some(e.into_inner()),
            Err(std::sync::TryLockError::WouldBlock) => None,
        }
    }
}

impl FacadeAtomic for std::sync::atomic::AtomicU64 {
    fn new(v: u64) -> Self {
        std::sync::atomic::AtomicU64::new(v)
    }
    fn load(&self) -> u64 {
        self.load(std::sync::atomic::Ordering::SeqCst)
    }
    fn store(&self, v: u64) {
        self.store(v, std::sync::atomic::Ordering::SeqCst)
    }
    fn swap(&self, v: u64) -> u64 {
        self.swap(v, std::sync::atomic::Ordering::SeqCst)
    }
    fn fetch_add(&self, v: u64) -> u64 {
        self.fetch_add(v, std::sync::atomic::Ordering::SeqCst)
    }
}

impl Facade for StdFacade {
    type Mutex<T: Send + 'static> = std::sync::Mutex<T>;
    type Atomic = std::sync::atomic::AtomicU64;
    type Handle = std::thread::JoinHandle<()>;

    fn spawn(f: impl FnOnce() + Send + 'static) -> Self::Handle {
        std::thread::spawn(f)
    }

    fn join(h: Self::Handle) -> Result<(), ThreadPanicked> {
        h.join().map_err(|e| ThreadPanicked(panic_message(&*e)))
    }

    fn pause(spins: u32) {
        match spins {
            0..64 => std::thread::yield_now(),
            u32::MAX => std::thread::sleep(SLOW_POLL),
            SOON_POLL_SPINS => std::thread::sleep(SLOW_POLL / 4),
            _ => std::thread::sleep(std::time::Duration::from_micros(50)),
        }
    }

    fn pause_for(d: std::time::Duration) {
        std::thread::sleep(d);
    }
}

/// How long [`StdFacade`] sleeps for `spins == u32::MAX`: the pace of a poller nobody
/// waits for (the threaded executor's output stage between frames).
pub const SLOW_POLL: std::time::Duration = std::time::Duration::from_millis(2);

/// The longest the threaded executor's output stage sleeps between polls: when a step
/// takes longer than [`SLOW_POLL`] it polls once per step's time, up to this (a frame then
/// reaches the sink at most this late, and a stop request is seen this soon).
pub const LONGEST_POLL: std::time::Duration = std::time::Duration::from_millis(16);

/// The `spins` of a poller that others will wait for soon, but not yet: [`StdFacade`]
/// sleeps a quarter of [`SLOW_POLL`].
pub const SOON_POLL_SPINS: u32 = u32::MAX - 1;

/// The text of a panic payload.
pub fn panic_message(e: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = e.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = e.downcast_ref::<String>() {
        s.clone()
    } else {
        "non-string panic payload".to_string()
    }
}
