//! The `soda` command-line tool: runs scenes in the reference executor, lists and dumps the
//! built-in scenes. README.md §CLI documents every command and option.

mod cli;

fn main() -> std::process::ExitCode {
    cli::main()
}
