//! The `fogsmith` command line.

use std::process::ExitCode;

fn main() -> ExitCode {
    fogsmith::cli::ensure_runtime_dir();
    match fogsmith::cli::run(std::env::args_os().collect()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.is::<fogsmith::cli::progress::Cancelled>() => {
            eprintln!("fogsmith: {e}");
            ExitCode::from(fogsmith::cli::progress::CANCELLED_EXIT)
        }
        Err(e) => {
            eprintln!("fogsmith: {e:#}");
            ExitCode::FAILURE
        }
    }
}
