//! `host-sim`: the elevator plant closed around the drive core, and the
//! commands that analyse it. `host-sim --help` lists the commands.

use std::process::ExitCode;

use clap::Parser;
use host_sim::cli::{run, Cli};

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
