//! The `wisplight-bench` program (also run as `wisplight bench`): stage
//! timings, the shadow methods' accuracy and cluster scaling.

use std::process::ExitCode;

use clap::Parser;
use wisplight_cli::bench::{Cli, run_cli};

fn main() -> ExitCode {
    run_cli(Cli::parse())
}
