//! `wisplight view`: the browser viewer.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene file (TOML); the built-in scene without one.
    #[arg(value_name = "SCENE.toml")]
    scene: Option<PathBuf>,
    /// Address to serve the page on; port 0 picks a free port. The first
    /// line on stdout names the page: `viewing on http://127.0.0.1:8080/`.
    /// Beyond loopback the page needs a token, printed in that line.
    #[arg(long, default_value = "127.0.0.1:8080", value_name = "ADDR")]
    listen: SocketAddr,
    /// Render through cluster workers, as `coordinator` does:
    /// `127.0.0.1:43125,10.0.0.2:7000`. Changing an effect or the shadow
    /// settings on the page connects to them anew.
    #[arg(long, value_delimiter = ',', value_name = "ADDR,ADDR,...")]
    workers: Vec<String>,
    /// Seconds any one call to a worker may take.
    #[arg(long, default_value_t = 30.0, value_name = "SECONDS")]
    deadline: f64,
    /// Seconds to connect to a worker and hear its Hello.
    #[arg(long, default_value_t = 5.0, value_name = "SECONDS")]
    connect_timeout: f64,
    #[command(flatten)]
    tls: super::cluster::ClientTlsArgs,
    #[command(flatten)]
    token: super::cluster::TokenArg,
    #[command(flatten)]
    pub threads: super::Threads,
}

/// Serves the page until SIGTERM or Ctrl-C.
pub fn run(args: Args) -> anyhow::Result<()> {
    let scene = super::load_scene(args.scene.as_deref())?;
    let connect: Option<viewer::Connect> = if args.workers.is_empty() {
        None
    } else {
        for (flag, v) in [
            ("--deadline", args.deadline),
            ("--connect-timeout", args.connect_timeout),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= 86_400.0) {
                return Err(super::usage(format!(
                    "{flag} {v}: must be in (0, 86400] seconds"
                )));
            }
        }
        let options = cluster::Options {
            deadline: Duration::from_secs_f64(args.deadline),
            connect_timeout: Duration::from_secs_f64(args.connect_timeout),
            tls: args.tls.load()?,
            token: args.token.load()?,
            draw: cluster::DrawAt::default(),
        };
        let workers = args.workers.clone();
        Some(Box::new(move |scene: &engine::Scene| {
            let ex = cluster::RemoteExecutor::connect(&workers, scene, &options)
                .map_err(|e| engine::EngineError::Executor(Box::new(e)))?;
            Ok(Box::new(ex) as Box<dyn engine::Executor>)
        }))
    };
    if !args.listen.ip().is_loopback() {
        tracing::warn!(
            listen = %args.listen,
            "serving the viewer beyond loopback, in plain HTTP: pages need the token printed \
             on stdout, but anyone who sees the traffic sees it"
        );
    }
    let options = viewer::Options {
        listen: args.listen,
        workers: args.workers.len(),
    };
    let shutdown = async {
        use tokio::signal::unix::{SignalKind, signal};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = term.recv() => {}
                    _ = tokio::signal::ctrl_c() => {}
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    };
    viewer::run(
        &scene,
        connect,
        &options,
        |b| {
            use std::io::Write;
            let mut out = std::io::stdout().lock();
            let _ = writeln!(out, "viewing on {}", b.url()).and_then(|()| out.flush());
        },
        shutdown,
    )
    .context("the viewer failed")
}
