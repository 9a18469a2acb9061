//! `meshdeco` command line: parses arguments into validated configs and hands them to the
//! library; errors are printed with their whole context chain and a non-zero exit code.
//!
//! Exit status: 0 on success, 1 on an error, 2 on a command-line mistake (clap), and 141
//! (128 + SIGPIPE, [`cli::out::BROKEN_PIPE_STATUS`]) when the command finished but its standard
//! output was a closed pipe (`meshdeco inspect --json DIR | head -1`): whatever it wrote to
//! files is complete, and nothing is printed about the pipe.

mod cli;

use std::io::Write;
use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    let result = cli::run(args);
    // Written with `writeln!` (errors ignored), so a closed stderr cannot panic here either.
    let mut stderr = std::io::stderr().lock();
    match result {
        Ok(()) => match cli::out::status() {
            cli::out::Status::Written => ExitCode::SUCCESS,
            cli::out::Status::Closed => ExitCode::from(cli::out::BROKEN_PIPE_STATUS),
            cli::out::Status::Failed(e) => {
                let _ = writeln!(stderr, "error: writing to standard output: {e}");
                ExitCode::FAILURE
            }
        },
        Err(e) => {
            let _ = writeln!(stderr, "error: {e}");
            for cause in e.chain().skip(1) {
                let _ = writeln!(stderr, "  caused by: {cause}");
            }
            ExitCode::FAILURE
        }
    }
}
