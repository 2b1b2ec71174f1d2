//! The `wisplight` program's command line: what it accepts, and running
//! it.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

use crate::{app, cmd};

/// Renders hair with light-oriented density-map self-shadowing.
#[derive(Debug, Parser)]
#[command(name = "wisplight", version, about, propagate_version = true)]
pub struct Cli {
    #[command(flatten)]
    pub log: cmd::Log,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Renders a self-shadowed picture of a scene (the built-in one without a file), or frames of its animation.
    Render(cmd::render::Args),
    /// Simulates a scene's wisps and writes their state after each frame, one file a frame: a cache from which `render --cache` renders any chunk of frames alone.
    Simulate(cmd::simulate::Args),
    /// Prints how much light reaches given points: CSV `x,y,z` in, `x,y,z,transmittance` out.
    Probe(cmd::probe::Args),
    /// Serves a coordinator (cluster mode): simulates a share of the wisps, fills their density, sweeps a share of the map's columns.
    Worker(cmd::cluster::WorkerArgs),
    /// Renders like `render` with workers simulating the wisps and filling and sweeping the density map: the same bytes as one process.
    Coordinator(cmd::cluster::CoordinatorArgs),
    /// Checks that a worker answers SERVING to a gRPC health check (exit 0), for container health checks.
    Health(cmd::cluster::HealthArgs),
    /// Makes a certificate authority and certificates for mutual TLS between a coordinator and its workers.
    Certs(cmd::cluster::CertsArgs),
    /// Writes a frame of a scene for Blender Cycles: the strands as posed, head, camera, lights, fiber, and a script that renders it.
    Export(cmd::export::Args),
    /// Serves a page that shows the animation as it renders and steers it: camera, lights, effects, shadow method.
    View(cmd::view::Args),
    /// Measures the speed of pipeline stages, the shadow methods' accuracy and cluster scaling: runs `wisplight-bench` (`wisplight bench --help`).
    #[command(disable_help_flag = true)]
    Bench {
        /// What `wisplight-bench` gets: `shadow`, `frame`, `accuracy` or `scaling`, and their options.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, num_args = 0..)]
        args: Vec<std::ffi::OsString>,
    },
}

/// Runs the command `cli` names: its exit code.
pub fn run(cli: Cli) -> ExitCode {
    app::start(cli.log);
    // Commands that write pictures leave no partial file when stopped.
    if matches!(
        cli.command,
        Command::Render(_) | Command::Coordinator(_) | Command::Simulate(_)
    ) {
        app::exit_cleanly_on_signals();
    }
    let threads = match &cli.command {
        Command::Render(a) => a.threads.threads,
        Command::Probe(a) => a.threads.threads,
        Command::Simulate(a) => a.threads.threads,
        Command::Worker(a) => a.threads.threads,
        Command::Coordinator(a) => a.threads(),
        Command::View(a) => a.threads.threads,
        Command::Export(a) => a.threads.threads,
        Command::Health(_) | Command::Certs(_) | Command::Bench { .. } => None,
    };
    let result = app::init_threads(threads).and_then(|()| match cli.command {
        Command::Render(args) => cmd::render::run(args),
        Command::Probe(args) => cmd::probe::run(args),
        Command::Simulate(args) => cmd::simulate::run(args),
        Command::Worker(args) => cmd::cluster::worker(args),
        Command::Coordinator(args) => cmd::cluster::coordinator(args),
        Command::Health(args) => cmd::cluster::health(args),
        Command::Certs(args) => cmd::cluster::certs(args),
        Command::View(args) => cmd::view::run(args),
        Command::Export(args) => cmd::export::run(args),
        // The flags given before `bench` go along.
        Command::Bench { args } => cmd::run_bench(cli.log, args),
    });
    app::finish(result)
}
