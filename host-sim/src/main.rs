//! `host-sim`: the elevator plant closed around the drive core, and the
//! commands that analyse it. `host-sim --help` lists the commands.

use std::process::ExitCode;

use clap::Parser;
use host_sim::cli::{error_message, run, Cli};

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = run(cli);
    // A closed standard output (`| head`) is not an error: the command has
    // done its work and printed what the reader took.
    let stdout_error = host_sim::output::stdout_error();
    match (result, stdout_error) {
        (Ok(()), None) => ExitCode::SUCCESS,
        (Ok(()), Some(e)) => {
            eprintln!("error: cannot write to standard output: {e}");
            ExitCode::FAILURE
        }
        (Err(error), _) => {
            eprintln!("error: {}", host_sim::output::public_paths(&error_message(&error)));
            ExitCode::FAILURE
        }
    }
}
