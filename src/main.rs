//! The `wisplight` command-line program: the only place that touches the
//! terminal, parses arguments and turns errors into messages and exit codes.

#![recursion_limit = "256"]

mod cmd;
mod csv;
mod cycles;
mod output;
mod plot;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Renders hair with light-oriented density-map self-shadowing.
#[derive(Debug, Parser)]
#[command(name = "wisplight", version, about, propagate_version = true)]
struct Cli {
    /// More log detail on stderr (-v info, -vv debug).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    verbose: u8,
    /// Only errors on stderr.
    #[arg(short, long, global = true, conflicts_with = "verbose")]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Renders a self-shadowed picture of a scene (the built-in one without a file), or frames of its animation.
    Render(cmd::render::Args),
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
    /// Measures the speed of pipeline stages.
    #[command(subcommand)]
    Bench(cmd::bench::Bench),
}

/// On SIGINT or SIGTERM: removes the temporary file of every output still
/// being written and exits (130 or 143), so an interrupted render leaves
/// neither a partial picture nor a hidden temporary file. The signals are
/// registered before this returns.
fn exit_cleanly_on_signals() {
    use tokio::signal::unix::{SignalKind, signal};
    let Ok(rt) = tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .build()
    else {
        return;
    };
    let registered = {
        let _in = rt.enter();
        signal(SignalKind::terminate()).and_then(|t| Ok((t, signal(SignalKind::interrupt())?)))
    };
    let Ok((mut term, mut int)) = registered else {
        return;
    };
    std::thread::spawn(move || {
        let (name, code) = rt.block_on(async {
            tokio::select! {
                _ = term.recv() => ("SIGTERM", 143),
                _ = int.recv() => ("SIGINT", 130),
            }
        });
        output::remove_temporaries();
        eprintln!("error: stopped by {name}; outputs not finished were removed");
        std::process::exit(code);
    });
}

fn main() -> ExitCode {
    // A bug is still reported on one line, never as a trace.
    std::panic::set_hook(Box::new(|info| {
        let message = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_default();
        let at = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        eprintln!("error: internal error{at}: {message} (a bug in wisplight; please report it)");
    }));
    let cli = Cli::parse();
    cmd::set_quiet(cli.quiet);
    let level = match (cli.quiet, cli.verbose) {
        (true, _) => tracing::Level::ERROR,
        (_, 0) => tracing::Level::WARN,
        (_, 1) => tracing::Level::INFO,
        _ => tracing::Level::DEBUG,
    };
    tracing_subscriber::fmt()
        .with_max_level(level)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_target(false)
        .init();

    // Commands that write pictures leave no partial file when stopped.
    if matches!(cli.command, Command::Render(_) | Command::Coordinator(_)) {
        exit_cleanly_on_signals();
    }
    let threads = match &cli.command {
        Command::Render(a) => a.threads.threads,
        Command::Probe(a) => a.threads.threads,
        Command::Worker(a) => a.threads.threads,
        Command::Coordinator(a) => a.threads(),
        Command::Bench(b) => b.threads(),
        Command::View(a) => a.threads.threads,
        Command::Export(a) => a.threads.threads,
        Command::Health(_) | Command::Certs(_) => None,
    };
    let result = init_threads(threads).and_then(|()| match cli.command {
        Command::Render(args) => cmd::render::run(args),
        Command::Probe(args) => cmd::probe::run(args),
        Command::Worker(args) => cmd::cluster::worker(args),
        Command::Coordinator(args) => cmd::cluster::coordinator(args),
        Command::Health(args) => cmd::cluster::health(args),
        Command::Certs(args) => cmd::cluster::certs(args),
        Command::Bench(b) => cmd::bench::run(b),
        Command::View(args) => cmd::view::run(args),
        Command::Export(args) => cmd::export::run(args),
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line: the context chain, outermost first.
            eprintln!("error: {e:#}");
            // 2 for a mistake in the command line (as clap's own errors),
            // 1 for anything that failed while running.
            if e.chain().any(|c| c.is::<cmd::Usage>()) {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

fn init_threads(threads: Option<u16>) -> anyhow::Result<()> {
    if let Some(n) = threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n.into())
            .build_global()?;
    }
    Ok(())
}
