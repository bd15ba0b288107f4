//! The `annotrace` command: parses arguments and hands them to `cli`.

mod cli;

fn main() -> std::process::ExitCode {
    cli::main()
}
