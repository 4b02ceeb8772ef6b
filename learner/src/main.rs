//! `learner`: the command line ([`learner::cli`]).

use std::process::ExitCode;

/// A failed command prints one line, `learner: error: ` and the cause chain, without a stack
/// backtrace even where `RUST_BACKTRACE` is set; `RUST_LIB_BACKTRACE=1` asks for one.
fn main() -> ExitCode {
    match learner::cli::main() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!(
                "learner: error: {}",
                ur5_shared::report::error_line(e.chain())
            );
            if std::env::var_os("RUST_LIB_BACKTRACE").is_some_and(|v| v != "0") {
                eprintln!("{}", e.backtrace());
            }
            ExitCode::FAILURE
        }
    }
}
