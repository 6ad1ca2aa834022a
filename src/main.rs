//! The `soda` command-line tool: runs scenes in the reference executor, lists and dumps the
//! built-in scenes. README.md, "The `soda` command", documents every command and option.

mod cli;

/// mimalloc instead of the system allocator: worlds on several threads allocate message
/// bodies and states that other threads free, which glibc's per-thread arenas pay for
/// (docs/performance.md, Load balancing: the balanced run's action CPU fell by 4-19 % in two measurements).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> std::process::ExitCode {
    // Before any thread starts: freed memory is kept for reuse (`soda::app::allocator`).
    soda::app::allocator::configure();
    cli::main()
}
