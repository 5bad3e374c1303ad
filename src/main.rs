//! The `fogsmith` command line.

use std::process::ExitCode;

fn main() -> ExitCode {
    fogsmith::cli::ensure_runtime_dir();
    match fogsmith::cli::run(std::env::args_os().collect()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("fogsmith: {e:#}");
            ExitCode::FAILURE
        }
    }
}
