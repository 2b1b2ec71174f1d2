//! The coordinator's connections to its workers: dialling and the
//! protocol check, calls fanned out to every worker under a deadline, and
//! the accounting of bytes and time.

use std::time::Duration;

use shadow::Fiber;
use tonic::transport::{Channel, Endpoint};

use crate::error::{WorkerError, WorkerErrorKind, root_cause};
use crate::pb::worker_client::WorkerClient;
use crate::token::{self, Purpose, Token};
use crate::{ClusterError, Tls, pb, tls, wire};

/// The gRPC metadata key that names a call's session.
pub(crate) const SESSION_KEY: &str = "wisplight-session";

/// Bytes on the wire, by stage and direction (protobuf message bytes;
/// HTTP/2 framing adds a little).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Traffic {
    /// Wisp shares and their state sent (Assign), at the start and after
    /// a worker is lost.
    pub assign_sent: u64,
    /// Simulate requests (head transforms, bodies, accelerations).
    pub step_sent: u64,
    /// Wisp states received (Simulate replies).
    pub wisps_received: u64,
    /// Strands sent to workers (Density requests).
    pub strands_sent: u64,
    /// Partial density columns received.
    pub density_received: u64,
    /// Summed density columns sent for sweeping.
    pub density_sent: u64,
    /// Transmittance slabs received.
    pub slabs_received: u64,
    /// Pose requests and reports (hair posed on the workers without steps).
    pub pose: u64,
    /// Draw requests: the jobs and the swept columns each worker reads.
    pub draw_sent: u64,
    /// Partial pictures received.
    pub layers_received: u64,
    /// Compositing on the workers: the stripes they sent each other, and
    /// the finished bands received.
    pub stripes_between_workers: u64,
    /// See `stripes_between_workers`.
    pub bands_received: u64,
    /// Summing and sweeping on the workers: the density they sent each
    /// other's columns, and the swept columns they sent each other.
    pub density_between_workers: u64,
    /// See `density_between_workers`.
    pub swept_between_workers: u64,
}

impl Traffic {
    /// Every byte counted.
    pub fn total(&self) -> u64 {
        self.assign_sent
            + self.step_sent
            + self.wisps_received
            + self.strands_sent
            + self.density_received
            + self.density_sent
            + self.slabs_received
            + self.pose
            + self.draw_sent
            + self.layers_received
            + self.stripes_between_workers
            + self.bands_received
            + self.density_between_workers
            + self.swept_between_workers
    }

    /// The bytes counted since `earlier`.
    pub fn since(&self, earlier: &Traffic) -> Traffic {
        Traffic {
            assign_sent: self.assign_sent - earlier.assign_sent,
            step_sent: self.step_sent - earlier.step_sent,
            wisps_received: self.wisps_received - earlier.wisps_received,
            strands_sent: self.strands_sent - earlier.strands_sent,
            density_received: self.density_received - earlier.density_received,
            density_sent: self.density_sent - earlier.density_sent,
            slabs_received: self.slabs_received - earlier.slabs_received,
            pose: self.pose - earlier.pose,
            draw_sent: self.draw_sent - earlier.draw_sent,
            layers_received: self.layers_received - earlier.layers_received,
            stripes_between_workers: self.stripes_between_workers - earlier.stripes_between_workers,
            bands_received: self.bands_received - earlier.bands_received,
            density_between_workers: self.density_between_workers - earlier.density_between_workers,
            swept_between_workers: self.swept_between_workers - earlier.swept_between_workers,
        }
    }

    /// One line: the total and each part, in MB.
    pub fn summary(&self) -> String {
        let mb = |b: u64| b as f64 / 1e6;
        format!(
            "{:.3} MB (wisps: assign {:.3}, steps {:.3}, states in {:.3}; strands out {:.3}; density in {:.3}, out {:.3}, between workers {:.3}; slabs in {:.3}, swept between workers {:.3}; pose {:.3}; draw out {:.3}, pictures in {:.3}; stripes between workers {:.3}, bands in {:.3})",
            mb(self.total()),
            mb(self.assign_sent),
            mb(self.step_sent),
            mb(self.wisps_received),
            mb(self.strands_sent),
            mb(self.density_received),
            mb(self.density_sent),
            mb(self.density_between_workers),
            mb(self.slabs_received),
            mb(self.swept_between_workers),
            mb(self.pose),
            mb(self.draw_sent),
            mb(self.layers_received),
            mb(self.stripes_between_workers),
            mb(self.bands_received),
        )
    }
}

/// Where the time of the remote stages went, summed over frames (for the
/// scaling benchmark's critical path).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Timing {
    /// Wall time of Simulate calls, as the coordinator waited for them.
    pub step_wall_ms: f64,
    /// The slowest worker's own compute time in each Simulate, summed.
    pub step_compute_ms: f64,
    /// Wall time of Density calls plus merging their partial densities.
    pub density_ms: f64,
    /// Wall time of Transmittance calls plus assembling their slabs.
    pub transmittance_ms: f64,
    /// Wall time of Pose calls (hair posed without steps).
    pub pose_ms: f64,
    /// Wall time of Draw calls plus decoding their partial pictures.
    pub draw_ms: f64,
    /// The slowest worker's own compute time in each Draw (filter, shade,
    /// rasterize), summed.
    pub draw_compute_ms: f64,
    /// Compositing on the workers, per Draw the slowest worker's: waiting
    /// for the others' stripes, and resolving its band; summed.
    pub band_wait_ms: f64,
    /// See `band_wait_ms`.
    pub band_composite_ms: f64,
    /// Draw rounds whose compositing on the workers failed and was done
    /// on the coordinator instead.
    pub composite_fallbacks: u32,
    /// Density rounds whose summing and sweeping on the workers failed and
    /// were done through the coordinator instead.
    pub exchange_fallbacks: u32,
    /// Workers lost and their work handed to the survivors.
    pub workers_lost: u32,
    /// Frames planned with each scheme, in the order of
    /// [`crate::Scheme::ALL`]: sort-middle, sort-last, the coordinator's
    /// draw.
    pub frames: [u32; 3],
    /// With `--draw auto`, what a frame of each scheme (same order) was
    /// last estimated to cost, ms (the least of its last measured frames;
    /// 0 until measured).
    pub estimate_ms: [f64; 3],
}

/// Names a session in the metadata of every call (see the
/// `wisplight-session` key).
#[derive(Debug, Clone)]
pub struct SessionHeader {
    session: Option<tonic::metadata::AsciiMetadataValue>,
}

impl SessionHeader {
    /// The header of session `id`, as a worker's Hello reply named it.
    pub fn new(id: &str) -> Option<SessionHeader> {
        id.parse().ok().map(|v| SessionHeader { session: Some(v) })
    }

    /// The header of the calls before a session: none.
    pub(crate) fn none() -> SessionHeader {
        SessionHeader { session: None }
    }
}

impl tonic::service::Interceptor for SessionHeader {
    fn call(&mut self, mut req: tonic::Request<()>) -> Result<tonic::Request<()>, tonic::Status> {
        if let Some(s) = &self.session {
            req.metadata_mut().insert(SESSION_KEY, s.clone());
        }
        Ok(req)
    }
}

/// A worker client whose calls name its session.
pub type SessionClient =
    WorkerClient<tonic::service::interceptor::InterceptedService<Channel, SessionHeader>>;

#[derive(Debug, Clone)]
pub(crate) struct Remote {
    pub(crate) addr: String,
    /// The session the worker opened for this coordinator.
    pub(crate) session: String,
    pub(crate) client: SessionClient,
}

/// How to reach the worker at `addr`: connect and call timeouts of
/// `deadline`, and with `tls` a handshake that checks the worker's
/// certificate (its CA, the name dialled and the worker's role) before
/// any byte of a call.
pub(crate) struct Dial {
    endpoint: Endpoint,
    tls: Option<tls::Connector>,
}

impl Dial {
    pub(crate) fn new(
        addr: &str,
        deadline: Duration,
        tls: Option<&Tls>,
    ) -> Result<Dial, ClusterError> {
        let endpoint = Endpoint::from_shared(format!("http://{addr}"))
            .map_err(|e| ClusterError::Connect {
                addr: addr.to_string(),
                msg: e.to_string(),
            })?
            .connect_timeout(deadline)
            .timeout(deadline)
            .tcp_nodelay(true);
        let tls = tls.map(|t| tls::connector(t, addr)).transpose()?;
        Ok(Dial { endpoint, tls })
    }

    /// A channel, connected now.
    pub(crate) async fn connect(self) -> Result<Channel, tonic::transport::Error> {
        match self.tls {
            Some(c) => self.endpoint.connect_with_connector(c).await,
            None => self.endpoint.connect().await,
        }
    }

    /// A channel that connects on its first call.
    pub(crate) fn connect_lazy(self) -> Channel {
        match self.tls {
            Some(c) => self.endpoint.connect_with_connector_lazy(c),
            None => self.endpoint.connect_lazy(),
        }
    }
}

pub(crate) async fn hello(
    addr: &str,
    fiber: &Fiber,
    deadline: Duration,
    tls: Option<&Tls>,
    token: Option<&Token>,
) -> Result<Remote, ClusterError> {
    let err = |msg: String| ClusterError::Connect {
        addr: addr.to_string(),
        msg: tls::explain(tls, msg),
    };
    let channel = Dial::new(addr, deadline, tls)?
        .connect()
        .await
        .map_err(|e| err(root_cause(&e)))?;
    let mut client = WorkerClient::with_interceptor(channel.clone(), SessionHeader::none())
        .max_decoding_message_size(wire::MAX_MESSAGE_BYTES)
        .max_encoding_message_size(wire::MAX_MESSAGE_BYTES);
    let refused = |msg: String| ClusterError::Refused {
        addr: addr.to_string(),
        msg,
    };
    // With a token: the worker's challenge, and a nonce of this side's
    // for the worker to prove the token back over.
    let mut request = pb::HelloRequest {
        protocol_version: wire::PROTOCOL_VERSION,
        fiber_width: fiber.width(),
        fiber_opacity: fiber.opacity(),
        ..Default::default()
    };
    if let Some(token) = token {
        let challenge = client
            .challenge(pb::ChallengeRequest {})
            .await
            .map_err(|s| match s.code() {
                tonic::Code::Unimplemented => refused(
                    "the worker gives no challenge: it speaks an older wisplight protocol, or \
                     this address serves no wisplight worker"
                        .into(),
                ),
                _ => err(WorkerError::from(s).message),
            })?
            .into_inner()
            .nonce;
        let mine = crate::token::nonce().map_err(|e| ClusterError::Setup(e.to_string()))?;
        request.proof = token::prove(token.key(), Purpose::Hello, &[&challenge, &mine]);
        request.challenge = challenge;
        request.client_nonce = mine.to_vec();
    }
    let reply = client
        .hello(request.clone())
        .await
        .map_err(|s| {
            let e = WorkerError::from(s);
            match e.kind {
                // Full: left out, as a worker that does not answer is.
                WorkerErrorKind::Exhausted => ClusterError::Connect {
                    addr: addr.to_string(),
                    msg: format!("full: {}", e.message),
                },
                WorkerErrorKind::Precondition
                | WorkerErrorKind::Other(
                    tonic::Code::Unauthenticated | tonic::Code::PermissionDenied,
                ) => ClusterError::Refused {
                    addr: addr.to_string(),
                    msg: e.message,
                },
                WorkerErrorKind::Other(tonic::Code::Unimplemented) => ClusterError::Connect {
                    addr: addr.to_string(),
                    msg: "this address serves no wisplight worker (unimplemented: a health port?)"
                        .into(),
                },
                _ => err(e.message),
            }
        })?
        .into_inner();
    if reply.protocol_version != wire::PROTOCOL_VERSION {
        return Err(ClusterError::Refused {
            addr: addr.to_string(),
            msg: format!(
                "the worker speaks protocol version {}, this coordinator {}",
                reply.protocol_version,
                wire::PROTOCOL_VERSION
            ),
        });
    }
    let Some(header) = SessionHeader::new(&reply.session).filter(|_| !reply.session.is_empty())
    else {
        return Err(err(format!(
            "the worker opened no usable session ({:?})",
            reply.session
        )));
    };
    // The worker proves the token back before anything is sent to it.
    if let Some(token) = token {
        let parts: [&[u8]; 2] = [&request.client_nonce, reply.session.as_bytes()];
        if reply.proof.is_empty() {
            return Err(refused(
                "the worker has no cluster token while this coordinator has one: start \
                 both with the same --token (or WISPLIGHT_TOKEN)"
                    .into(),
            ));
        }
        if !token::proves(token.key(), Purpose::Worker, &parts, &reply.proof) {
            return Err(refused(
                "the worker did not prove the cluster's token: its token is another".into(),
            ));
        }
    }
    tracing::info!(addr, worker = reply.worker, "worker ready");
    Ok(Remote {
        addr: addr.to_string(),
        session: reply.session.clone(),
        client: WorkerClient::with_interceptor(channel, header)
            .max_decoding_message_size(wire::MAX_MESSAGE_BYTES)
            .max_encoding_message_size(wire::MAX_MESSAGE_BYTES),
    })
}

/// Starts `call` on every worker at once, each bounded by `deadline`.
fn spawn_calls<R, T, F, Fut>(
    requests: Vec<(Remote, R)>,
    stage: &'static str,
    deadline: Duration,
    call: F,
) -> Vec<tokio::task::JoinHandle<Result<T, ClusterError>>>
where
    R: Send + 'static,
    T: Send + 'static,
    F: Fn(Remote, R) -> Fut,
    Fut: std::future::Future<Output = Result<T, ClusterError>> + Send + 'static,
{
    requests
        .into_iter()
        .map(|(w, r)| {
            let addr = w.addr.clone();
            let fut = call(w, r);
            tokio::spawn(async move {
                match tokio::time::timeout(deadline, fut).await {
                    Ok(r) => r,
                    Err(_) => Err(ClusterError::Deadline {
                        addr,
                        stage,
                        secs: deadline.as_secs_f64(),
                    }),
                }
            })
        })
        .collect()
}

fn joined<T>(
    r: Result<Result<T, ClusterError>, tokio::task::JoinError>,
) -> Result<T, ClusterError> {
    r.map_err(|e| ClusterError::Setup(e.to_string()))
        .and_then(|r| r)
}

/// Runs `call` on every worker at once, each bounded by `deadline`, and
/// returns the results in worker order: the first error, if any, names
/// its worker.
///
/// It returns only when every call has ended, failed ones included. A
/// call left running after the round failed would reach its worker after
/// the coordinator's next move: a Simulate call still in flight when the
/// survivors are assigned their new shares would step their wisps once
/// more, and the frame after a loss would differ from one process's.
pub(crate) fn fan_out<R, T, F, Fut>(
    rt: &tokio::runtime::Runtime,
    requests: Vec<(Remote, R)>,
    stage: &'static str,
    deadline: Duration,
    call: F,
) -> Result<Vec<T>, ClusterError>
where
    R: Send + 'static,
    T: Send + 'static,
    F: Fn(Remote, R) -> Fut,
    Fut: std::future::Future<Output = Result<T, ClusterError>> + Send + 'static,
{
    fan_out_all(rt, requests, stage, deadline, call)
        .into_iter()
        .collect()
}

/// [`fan_out`], every call's result in worker order: the calls that
/// fail do not stop the others.
pub(crate) fn fan_out_all<R, T, F, Fut>(
    rt: &tokio::runtime::Runtime,
    requests: Vec<(Remote, R)>,
    stage: &'static str,
    deadline: Duration,
    call: F,
) -> Vec<Result<T, ClusterError>>
where
    R: Send + 'static,
    T: Send + 'static,
    F: Fn(Remote, R) -> Fut,
    Fut: std::future::Future<Output = Result<T, ClusterError>> + Send + 'static,
{
    rt.block_on(async {
        let tasks = spawn_calls(requests, stage, deadline, call);
        let mut out = Vec::with_capacity(tasks.len());
        for t in tasks {
            out.push(joined(t.await));
        }
        out
    })
}

pub(crate) fn call_error(addr: &str, stage: &'static str, s: tonic::Status) -> ClusterError {
    ClusterError::Call {
        addr: addr.to_string(),
        stage,
        error: WorkerError::from(s),
    }
}

/// Collects a server stream's messages.
pub(crate) async fn collect<T>(
    addr: &str,
    stage: &'static str,
    mut s: tonic::Streaming<T>,
) -> Result<Vec<T>, ClusterError> {
    let mut out = Vec::new();
    while let Some(c) = s.message().await.map_err(|e| call_error(addr, stage, e))? {
        out.push(c);
    }
    Ok(out)
}

pub(crate) fn malformed(addr: &str, e: impl ToString) -> ClusterError {
    ClusterError::Malformed {
        addr: addr.to_string(),
        msg: e.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};

    use super::*;

    /// A worker nobody dials: the calls below never use the client.
    fn remote(rt: &tokio::runtime::Runtime, addr: &str) -> Remote {
        let _in = rt.enter();
        let channel = Channel::from_static("http://127.0.0.1:9").connect_lazy();
        Remote {
            addr: addr.into(),
            session: "s".into(),
            client: WorkerClient::with_interceptor(channel, SessionHeader::none()),
        }
    }

    #[test]
    fn a_failed_round_returns_only_when_every_call_has_ended() {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        let ended = Arc::new(AtomicBool::new(false));
        let requests = vec![(remote(&rt, "a"), 0u64), (remote(&rt, "b"), 300)];
        let seen = ended.clone();
        let r = fan_out(
            &rt,
            requests,
            "step",
            Duration::from_secs(10),
            move |w, ms| {
                let ended = seen.clone();
                async move {
                    if ms == 0 {
                        return Err(malformed(&w.addr, "lost"));
                    }
                    tokio::time::sleep(Duration::from_millis(ms)).await;
                    ended.store(true, Ordering::SeqCst);
                    Ok(())
                }
            },
        );
        // The first worker's error, in worker order, after the second's
        // call ended (a call left running would reach its worker after
        // the survivors were assigned their new shares).
        let e = r.unwrap_err();
        assert_eq!(e.worker(), Some("a"), "{e}");
        assert!(ended.load(Ordering::SeqCst), "returned while a call ran");
    }
}
