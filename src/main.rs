//! The `wisplight` program: renders, serves and coordinates workers,
//! views and exports; `wisplight bench ...` runs `wisplight-bench`.

use std::process::ExitCode;

use clap::Parser;
use wisplight_cli::cli::{Cli, run};

fn main() -> ExitCode {
    run(Cli::parse())
}
