//! `wisplight worker` and `wisplight coordinator`: cluster mode.

use std::net::SocketAddr;
use std::time::Duration;

use anyhow::Context;

#[derive(Debug, clap::Args)]
pub struct WorkerArgs {
    /// Address to listen on; port 0 picks a free port. The first line on
    /// stdout names the bound address: `listening on 127.0.0.1:43125`.
    #[arg(long, default_value = "127.0.0.1:0", value_name = "ADDR")]
    listen: SocketAddr,
    /// Fault injection for tests: exit, as if killed, when the N-th Step
    /// call arrives.
    #[arg(long, hide = true, value_name = "N")]
    exit_after_steps: Option<u64>,
}

/// Serves until SIGTERM or Ctrl-C.
pub fn worker(args: WorkerArgs) -> anyhow::Result<()> {
    let service = match args.exit_after_steps {
        Some(n) => cluster::worker::WorkerService::exiting_after_steps(n),
        None => cluster::worker::WorkerService::default(),
    };
    cluster::worker::run(service, args.listen, |addr| {
        // println! flushes at the newline, even into a pipe.
        println!("listening on {addr}");
    })
    .context("worker failed")
}

#[derive(Debug, clap::Args)]
pub struct CoordinatorArgs {
    /// Worker addresses, comma-separated: `127.0.0.1:43125,10.0.0.2:7000`.
    #[arg(
        long,
        required = true,
        value_delimiter = ',',
        value_name = "ADDR,ADDR,..."
    )]
    workers: Vec<String>,
    /// Seconds any one call to a worker may take, from the first byte sent
    /// to the last received.
    #[arg(long, default_value_t = 30.0, value_name = "SECONDS")]
    deadline: f64,
    #[command(flatten)]
    render: super::render::Args,
}

/// `render` with the density map filled and swept by the workers: the same
/// bytes as one process.
pub fn coordinator(args: CoordinatorArgs) -> anyhow::Result<()> {
    if !(args.deadline.is_finite() && args.deadline > 0.0 && args.deadline <= 86_400.0) {
        return Err(super::usage(format!(
            "--deadline {}: must be in (0, 86400] seconds",
            args.deadline
        )));
    }
    let remote = super::render::Remote {
        workers: args.workers,
        deadline: Duration::from_secs_f64(args.deadline),
    };
    super::render::run_with(args.render, Some(remote))
}

#[derive(Debug, clap::Args)]
pub struct HealthArgs {
    /// The worker's address, e.g. `127.0.0.1:7000`.
    #[arg(value_name = "ADDR")]
    addr: String,
    /// Seconds to wait for the answer.
    #[arg(long, default_value_t = 5.0, value_name = "SECONDS")]
    deadline: f64,
}

/// Exits 0 when the worker at ADDR answers SERVING (container health checks).
pub fn health(args: HealthArgs) -> anyhow::Result<()> {
    if !(args.deadline.is_finite() && args.deadline > 0.0 && args.deadline <= 3600.0) {
        return Err(super::usage(format!(
            "--deadline {}: must be in (0, 3600] seconds",
            args.deadline
        )));
    }
    let serving = cluster::check_health(&args.addr, Duration::from_secs_f64(args.deadline))
        .context("health check failed")?;
    if !serving {
        anyhow::bail!("worker {} is not serving", args.addr);
    }
    println!("{} SERVING", args.addr);
    Ok(())
}
