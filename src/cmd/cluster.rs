//! `wisplight worker` and `wisplight coordinator`: cluster mode.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;

use crate::output::AtomicFile;

#[derive(Debug, clap::Args)]
pub struct WorkerArgs {
    /// Address to listen on; port 0 picks a free port. The first line on
    /// stdout names the bound address: `listening on 127.0.0.1:43125`.
    #[arg(long, default_value = "127.0.0.1:0", value_name = "ADDR")]
    listen: SocketAddr,
    #[command(flatten)]
    tls: TlsArgs,
    #[command(flatten)]
    token: TokenArg,
    /// Also serve grpc.health.v1 alone, in plain gRPC, on this address: for
    /// probes that cannot present a certificate when TLS is on.
    #[arg(long, value_name = "ADDR")]
    health_listen: Option<SocketAddr>,
    /// The most coordinators served at once: each Hello opens a session
    /// (its own scene, hair and maps); more get RESOURCE_EXHAUSTED.
    #[arg(long, default_value_t = 4, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..=256))]
    max_sessions: u32,
    /// Seconds after which a session no call used ends (a coordinator
    /// that died without ending it). A session whose coordinator's
    /// connection has closed ends after 10 s unused.
    #[arg(long, default_value_t = 600, value_name = "SECS",
          value_parser = clap::value_parser!(u64).range(1..=86_400))]
    session_idle: u64,
    /// The worker's memory budget, MiB: the density maps its calls hold,
    /// the strands they receive, each session's scene, files, states and
    /// share of the hair. A map waits for room; received data past it gets
    /// RESOURCE_EXHAUSTED. Resident memory stays under this plus
    /// `--max-sessions` x 86 MiB of kept maps, 16 MiB per call in flight
    /// and the program itself (see proto/README.md).
    #[arg(long, default_value_t = 2048, value_name = "MIB",
          value_parser = clap::value_parser!(u64).range(64..=1 << 30))]
    max_memory_mib: u64,
    /// Each session's memory budget, MiB (the most one coordinator's
    /// scene, share and calls may hold); `--max-memory-mib` when not given.
    #[arg(long, value_name = "MIB",
          value_parser = clap::value_parser!(u64).range(16..=1 << 30))]
    max_session_memory_mib: Option<u64>,
    #[command(flatten)]
    pub threads: super::Threads,
}

/// `--token`: the cluster's shared secret.
#[derive(Debug, clap::Args)]
pub struct TokenArg {
    /// The cluster's token (at least 16 printable characters, e.g. from
    /// `openssl rand -hex 16`): a worker given one opens a session only for
    /// a coordinator that proves it knows the token, and sends a fellow
    /// worker nothing before it proves it too; the token itself never
    /// crosses the wire. Best given in the environment, where `ps` does not
    /// show it.
    #[arg(
        long,
        env = "WISPLIGHT_TOKEN",
        hide_env_values = true,
        value_name = "TOKEN"
    )]
    token: Option<String>,
}

impl TokenArg {
    /// The token, checked, when given.
    pub fn load(&self) -> anyhow::Result<Option<cluster::Token>> {
        self.token
            .as_deref()
            .map(cluster::Token::new)
            .transpose()
            .context("--token")
    }
}

/// Mutual TLS (all three files, or none: plain gRPC, for loopback and
/// private networks only).
#[derive(Debug, clap::Args)]
pub struct TlsArgs {
    /// Mutual TLS: the CA certificate (PEM) that signed the other side's
    /// certificates. A worker then serves only clients presenting one.
    #[arg(long, value_name = "PEM", requires_all = ["tls_cert", "tls_key"])]
    tls_ca: Option<PathBuf>,
    /// Mutual TLS: this side's certificate chain (PEM).
    #[arg(long, value_name = "PEM", requires = "tls_ca")]
    tls_cert: Option<PathBuf>,
    /// Mutual TLS: this side's private key (PEM, PKCS#8, PKCS#1 or SEC1).
    #[arg(long, value_name = "PEM", requires = "tls_ca")]
    tls_key: Option<PathBuf>,
}

impl TlsArgs {
    /// The credentials, when TLS is on.
    pub fn load(&self) -> anyhow::Result<Option<cluster::Tls>> {
        match (&self.tls_ca, &self.tls_cert, &self.tls_key) {
            (Some(ca), Some(cert), Some(key)) => Ok(Some(cluster::Tls::load(ca, cert, key)?)),
            _ => Ok(None),
        }
    }
}

/// `--tls-*` for a client (coordinator, health), with the name to expect
/// in the workers' certificates.
#[derive(Debug, clap::Args)]
pub struct ClientTlsArgs {
    #[command(flatten)]
    files: TlsArgs,
    /// Mutual TLS: the name the workers' certificates must carry, when it
    /// is not the host part of their addresses.
    #[arg(long, value_name = "NAME", requires = "tls_ca")]
    tls_domain: Option<String>,
}

impl ClientTlsArgs {
    pub fn load(&self) -> anyhow::Result<Option<cluster::Tls>> {
        let tls = self.files.load()?;
        Ok(match (tls, &self.tls_domain) {
            (Some(t), Some(d)) => Some(t.with_domain(d)),
            (t, _) => t,
        })
    }
}

/// Serves until SIGTERM or Ctrl-C.
pub fn worker(args: WorkerArgs) -> anyhow::Result<()> {
    let service = cluster::WorkerService::new(cluster::SessionLimits {
        max_sessions: args.max_sessions as usize,
        idle: std::time::Duration::from_secs(args.session_idle),
        max_memory: args.max_memory_mib << 20,
        max_session_memory: args.max_session_memory_mib.unwrap_or(args.max_memory_mib) << 20,
        ..cluster::SessionLimits::default()
    });
    let tls = args.tls.load()?;
    let token = args.token.load()?;
    if !args.listen.ip().is_loopback() {
        match (&tls, &token) {
            (None, None) => tracing::warn!(
                listen = %args.listen,
                "serving plain gRPC beyond loopback without a token: anyone who reaches this \
                 port can open sessions and send work; give --token (or WISPLIGHT_TOKEN), and \
                 use --tls-ca/--tls-cert/--tls-key on untrusted networks"
            ),
            (Some(_), None) => tracing::warn!(
                listen = %args.listen,
                "no --token: any holder of a certificate from this CA (a worker's included) \
                 can open sessions; give --token (or WISPLIGHT_TOKEN)"
            ),
            (None, Some(_)) => tracing::warn!(
                listen = %args.listen,
                "plain gRPC beyond loopback: the token and the work travel unencrypted; use \
                 --tls-ca/--tls-cert/--tls-key on untrusted networks"
            ),
            (Some(_), Some(_)) => {}
        }
    }
    let listen = cluster::Listen {
        tls,
        health: args.health_listen,
        token,
    };
    cluster::run_worker(service, args.listen, &listen, |b| {
        // Each line flushed at once, even into a pipe; a reader that has
        // gone (one that wanted the first line alone) stops nothing.
        use std::io::Write;
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "listening on {}", b.addr).and_then(|()| out.flush());
        if let Some(h) = b.health {
            let _ = writeln!(out, "health on {h}").and_then(|()| out.flush());
        }
    })
    .context("worker failed")
}

/// `--draw`: where the drawn hair is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Draw {
    /// Sort-middle, sort-last or the coordinator's draw, chosen frame by
    /// frame by what each cost the frames before; with one worker, the
    /// coordinator draws.
    Auto,
    /// Each worker rasterizes its own strands; the workers composite
    /// their partial pictures, each its own bands of rows.
    #[value(alias = "workers")]
    SortLast,
    /// Each worker shades its own strands and sends their segments to the
    /// worker that owns their rows, which rasterizes all of them.
    SortMiddle,
    /// The paper's scheme: the coordinator draws every strand.
    Coordinator,
}

impl From<Draw> for cluster::DrawAt {
    fn from(d: Draw) -> cluster::DrawAt {
        match d {
            Draw::Auto => cluster::DrawAt::Auto,
            Draw::SortLast => cluster::DrawAt::SortLast,
            Draw::SortMiddle => cluster::DrawAt::SortMiddle,
            Draw::Coordinator => cluster::DrawAt::Coordinator,
        }
    }
}

impl CoordinatorArgs {
    /// The `--threads` of the run (those of the render it makes).
    pub fn threads(&self) -> Option<u16> {
        self.render.threads.threads
    }
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
    /// Seconds to connect to a worker and hear its Hello; a worker that
    /// does not answer in time is left out (with a warning) and the run
    /// carries on over the others.
    #[arg(long, default_value_t = 5.0, value_name = "SECONDS")]
    connect_timeout: f64,
    /// How the picture is drawn. On the workers (with two or more; they
    /// must reach each other at the addresses given), each finishing its
    /// own bands of rows from what the others send it: `sort-middle`
    /// (their shaded segments there), `sort-last` (their partial
    /// pictures), or `auto`, the cheaper of the two as measured frame by
    /// frame; or `coordinator` (the paper's scheme: workers simulate, fill
    /// and sweep, the coordinator draws every strand). With one worker the
    /// coordinator draws. The pictures are the same bytes whichever.
    #[arg(long, value_enum, default_value_t = Draw::Auto, value_name = "SCHEME")]
    draw: Draw,
    #[command(flatten)]
    tls: ClientTlsArgs,
    #[command(flatten)]
    token: TokenArg,
    #[command(flatten)]
    render: super::render::Args,
}

/// `render` with the density map filled and swept by the workers: the same
/// bytes as one process.
pub fn coordinator(args: CoordinatorArgs) -> anyhow::Result<()> {
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
    let remote = super::render::Remote {
        workers: args.workers,
        options: cluster::Options {
            deadline: Duration::from_secs_f64(args.deadline),
            connect_timeout: Duration::from_secs_f64(args.connect_timeout),
            tls: args.tls.load()?,
            token: args.token.load()?,
            draw: args.draw.into(),
        },
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
    #[command(flatten)]
    tls: ClientTlsArgs,
}

/// Exits 0 when the worker at ADDR answers SERVING (container health checks).
pub fn health(args: HealthArgs) -> anyhow::Result<()> {
    if !(args.deadline.is_finite() && args.deadline > 0.0 && args.deadline <= 3600.0) {
        return Err(super::usage(format!(
            "--deadline {}: must be in (0, 3600] seconds",
            args.deadline
        )));
    }
    let tls = args.tls.load()?;
    let serving = cluster::check_health(
        &args.addr,
        Duration::from_secs_f64(args.deadline),
        tls.as_ref(),
    )
    .context("health check failed")?;
    if !serving {
        anyhow::bail!("worker {} is not serving", args.addr);
    }
    println!("{} SERVING", args.addr);
    Ok(())
}

#[derive(Debug, clap::Args)]
pub struct CertsArgs {
    /// Directory to write ca.pem, ca.key, worker.pem, worker.key,
    /// coordinator.pem and coordinator.key into (created if missing; no
    /// file in it is overwritten).
    #[arg(value_name = "DIR")]
    dir: PathBuf,
    /// The DNS names and IP addresses the workers are dialled by,
    /// comma-separated: every worker gets the same certificate, valid for
    /// all of them.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "localhost,127.0.0.1,::1",
        value_name = "NAME,..."
    )]
    names: Vec<String>,
}

/// Writes a fresh CA and the worker and coordinator credentials.
pub fn certs(args: CertsArgs) -> anyhow::Result<()> {
    use std::io::Write;

    let pki = cluster::Pki::generate(&args.names)?;
    std::fs::create_dir_all(&args.dir)
        .with_context(|| format!("cannot create the directory {}", args.dir.display()))?;
    let files = pki.files();
    if let Some((name, _, _)) = files.iter().find(|(n, _, _)| args.dir.join(n).exists()) {
        anyhow::bail!(
            "{} already exists; not overwriting credentials (choose another directory)",
            args.dir.join(name).display()
        );
    }
    // Each file appears whole: written beside its name, then renamed;
    // keys readable by their owner alone from the start.
    for (name, pem, secret) in files {
        let path = args.dir.join(name);
        let mut file = if secret {
            AtomicFile::private(&path)?
        } else {
            AtomicFile::create(&path)?
        };
        file.write_all(pem.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
        file.commit()?;
    }
    println!(
        "wrote {} (workers: --tls-ca ca.pem --tls-cert worker.pem --tls-key worker.key; \
         coordinator: --tls-ca ca.pem --tls-cert coordinator.pem --tls-key coordinator.key); \
         workers are valid for: {}",
        args.dir.display(),
        args.names.join(", ")
    );
    Ok(())
}
