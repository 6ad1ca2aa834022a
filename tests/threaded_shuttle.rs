//! The threaded executor's own coordination (world locks, inboxes, the scheduled flags, the
//! GVT cut, the output stage, shutdown) explored under shuttle's randomized and PCT
//! schedulers: over thousands of interleavings it never deadlocks and always commits the
//! reference's hashes. The executor is written against `soda::exec::sync::Facade`; this file
//! implements that facade with shuttle's primitives (crossbeam-deque's operations stay
//! opaque: each is one atomic step to shuttle).
//!
//! A failing schedule prints a shuttle replay string; `SHUTTLE_ITERATIONS` raises the count.

use soda::exec::sync::{Facade, FacadeAtomic, FacadeMutex, ThreadPanicked};
use soda::exec::threaded::{run_threaded_with, ThreadedOptions, ThreadedSetup};
use soda::kernel::synthetic::Particles;
use soda::kernel::{BalanceConfig, KernelConfig, LoadSource, PartitionKind, RollbackMode};
use soda::ReferenceRun;
use std::sync::Arc;

struct ShuttleFacade;

struct Mutex<T>(shuttle::sync::Mutex<T>);

impl<T: Send> FacadeMutex<T> for Mutex<T> {
    type Guard<'a>
        = shuttle::sync::MutexGuard<'a, T>
    where
        T: 'a;
    fn new(v: T) -> Self {
        Mutex(shuttle::sync::Mutex::new(v))
    }
    fn lock(&self) -> Self::Guard<'_> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }
    fn try_lock(&self) -> Option<Self::Guard<'_>> {
        match self.0.try_lock() {
            Ok(g) => Some(g),
            Err(std::sync::TryLockError::Poisoned(e)) => Some(e.into_inner()),
            Err(std::sync::TryLockError::WouldBlock) => None,
        }
    }
}

struct Atomic(shuttle::sync::atomic::AtomicU64);

impl FacadeAtomic for Atomic {
    fn new(v: u64) -> Self {
        Atomic(shuttle::sync::atomic::AtomicU64::new(v))
    }
    fn load(&self) -> u64 {
        self.0.load(std::sync::atomic::Ordering::SeqCst)
    }
    fn store(&self, v: u64) {
        self.0.store(v, std::sync::atomic::Ordering::SeqCst)
    }
    fn swap(&self, v: u64) -> u64 {
        self.0.swap(v, std::sync::atomic::Ordering::SeqCst)
    }
    fn fetch_add(&self, v: u64) -> u64 {
        self.0.fetch_add(v, std::sync::atomic::Ordering::SeqCst)
    }
}

impl Facade for ShuttleFacade {
    type Mutex<T: Send + 'static> = Mutex<T>;
    type Atomic = Atomic;
    type Handle = shuttle::thread::JoinHandle<()>;
    fn spawn(f: impl FnOnce() + Send + 'static) -> Self::Handle {
        shuttle::thread::spawn(f)
    }
    fn join(h: Self::Handle) -> Result<(), ThreadPanicked> {
        h.join()
            .map_err(|_| ThreadPanicked("a shuttle thread panicked".to_string()))
    }
    fn pause(_spins: u32) {
        shuttle::thread::yield_now();
    }
}

const STEPS: u64 = 6;

fn iterations() -> usize {
    std::env::var("SHUTTLE_ITERATIONS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1000)
}

/// A small particle scene, its reference hashes, and a kernel configuration per mode.
fn case(mode: RollbackMode) -> impl Fn() + Send + Sync + 'static {
    case_with(mode, BalanceConfig::default())
}

/// [`case`] with load balancing `balance`.
fn case_with(mode: RollbackMode, balance: BalanceConfig) -> impl Fn() + Send + Sync + 'static {
    let (model, grid, bodies) = Particles::scene(24, [4, 2, 2], false, 5);
    let (mut reference, _) = ReferenceRun::new(model.clone(), grid.clone(), bodies.clone());
    let expected: Arc<Vec<u64>> = Arc::new((0..STEPS).map(|_| reference.advance().hash).collect());
    let config = KernelConfig::new(3)
        .mode(mode)
        .window(3)
        .partition(PartitionKind::Random)
        .partition_seed(2)
        .balance(balance);
    move || {
        let mut got = Vec::new();
        let report = run_threaded_with::<Particles, ShuttleFacade>(
            ThreadedSetup::new(model.clone(), grid.clone(), bodies.clone()),
            &ThreadedOptions::new(&config, 2, STEPS),
            |f, _| got.push(f.hash),
        )
        .expect("the threaded run succeeds");
        assert_eq!(got, *expected, "committed hashes differ from the reference");
        assert_eq!(report.frames.len() as u64, STEPS);
        if config.mode == RollbackMode::Conservative {
            assert_eq!(report.counters.total.steps_rolled_back, 0);
        }
    }
}

#[test]
fn threaded_coordination_commits_reference_hashes_under_random_schedules() {
    for mode in [
        RollbackMode::Cell,
        RollbackMode::World,
        RollbackMode::Conservative,
    ] {
        shuttle::check_random(case(mode), iterations());
    }
}

#[test]
fn threaded_coordination_commits_reference_hashes_under_pct_schedules() {
    for mode in [
        RollbackMode::Cell,
        RollbackMode::World,
        RollbackMode::Conservative,
    ] {
        shuttle::check_pct(case(mode), iterations(), 3);
    }
}

#[test]
fn balancing_handovers_between_epochs_commit_reference_hashes_under_random_schedules() {
    // Seeded loads: cells move at steps 2 and 4 whatever the timing.
    let balance = BalanceConfig {
        period: 2,
        load: LoadSource::Seeded(7),
        ..BalanceConfig::on()
    };
    for mode in [
        RollbackMode::Cell,
        RollbackMode::World,
        RollbackMode::Conservative,
    ] {
        shuttle::check_random(case_with(mode, balance.clone()), iterations() / 4);
    }
}
