//! The `wisplight-bench` program (also run as `wisplight bench`): stage
//! timings, the shadow methods' accuracy and cluster scaling.

use std::process::ExitCode;

use clap::Parser;
use wisplight_cli::{app, bench};

/// Measures wisplight: stage timings, the shadow methods' accuracy, cluster scaling.
#[derive(Debug, Parser)]
#[command(
    name = "wisplight-bench",
    bin_name = "wisplight bench",
    version,
    about = "Measures wisplight: stage timings, the shadow methods' accuracy, cluster scaling"
)]
struct Cli {
    /// More log detail on stderr (-v info, -vv debug).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    verbose: u8,
    /// Only errors on stderr.
    #[arg(short, long, global = true, conflicts_with = "verbose")]
    quiet: bool,
    #[command(subcommand)]
    bench: bench::Bench,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    app::start(cli.quiet, cli.verbose);
    let result = app::init_threads(cli.bench.threads()).and_then(|()| bench::run(cli.bench));
    app::finish(result)
}
