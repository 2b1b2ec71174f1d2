//! The coordinator's side: an [`engine::Executor`] that runs the density
//! map's fill and sweep on workers over gRPC, with the same bytes as one
//! process.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use engine::{EngineError, Executor};
use prost::Message;
use shadow::{ColumnSlab, DensityMap, Fiber, FillStats, Transmittance};
use strands::Hair;
use tonic::transport::{Channel, Endpoint};

use crate::pb::worker_client::WorkerClient;
use crate::{ClusterError, pb, wire};

/// Bytes on the wire, by stage and direction.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Traffic {
    /// Strands sent to workers (Deposit requests).
    pub strands_sent: u64,
    /// Partial density columns received.
    pub density_received: u64,
    /// Summed density columns sent for sweeping.
    pub density_sent: u64,
    /// Transmittance slabs received.
    pub slabs_received: u64,
}

impl Traffic {
    pub fn total(&self) -> u64 {
        self.strands_sent + self.density_received + self.density_sent + self.slabs_received
    }
}

#[derive(Debug, Clone)]
struct Remote {
    addr: String,
    client: WorkerClient<Channel>,
}

/// Workers that fill and sweep the density map (see the module docs).
#[derive(Debug)]
pub struct RemoteExecutor {
    rt: tokio::runtime::Runtime,
    workers: Vec<Remote>,
    deadline: Duration,
    frame_id: u64,
    traffic: Arc<Mutex<Traffic>>,
}

impl RemoteExecutor {
    /// Connects to every worker and checks its protocol version. `deadline`
    /// bounds every call, from its first byte sent to its last received.
    pub fn connect(
        addrs: &[String],
        fiber: &Fiber,
        deadline: Duration,
    ) -> Result<RemoteExecutor, ClusterError> {
        if addrs.is_empty() {
            return Err(ClusterError::Setup("no workers given".into()));
        }
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .map_err(|e| ClusterError::Setup(format!("cannot start the network runtime: {e}")))?;
        let workers = rt.block_on(async {
            let mut out = Vec::with_capacity(addrs.len());
            for addr in addrs {
                out.push(hello(addr, fiber, deadline).await?);
            }
            Ok::<_, ClusterError>(out)
        })?;
        Ok(RemoteExecutor {
            rt,
            workers,
            deadline,
            frame_id: 0,
            traffic: Arc::new(Mutex::new(Traffic::default())),
        })
    }

    pub fn worker_count(&self) -> usize {
        self.workers.len()
    }

    /// A handle on the bytes counted so far (all stages, all frames).
    pub fn traffic(&self) -> Arc<Mutex<Traffic>> {
        self.traffic.clone()
    }

    fn count(&self, f: impl FnOnce(&mut Traffic)) {
        if let Ok(mut t) = self.traffic.lock() {
            f(&mut t);
        }
    }
}

async fn hello(addr: &str, fiber: &Fiber, deadline: Duration) -> Result<Remote, ClusterError> {
    let err = |msg: String| ClusterError::Connect {
        addr: addr.to_string(),
        msg,
    };
    let endpoint = Endpoint::from_shared(format!("http://{addr}"))
        .map_err(|e| err(e.to_string()))?
        .connect_timeout(deadline)
        .timeout(deadline)
        .tcp_nodelay(true);
    let channel = endpoint.connect().await.map_err(|e| err(root_cause(&e)))?;
    let mut client = WorkerClient::new(channel)
        .max_decoding_message_size(wire::MAX_MESSAGE_BYTES)
        .max_encoding_message_size(wire::MAX_MESSAGE_BYTES);
    let reply = client
        .hello(pb::HelloRequest {
            protocol_version: wire::PROTOCOL_VERSION,
            fiber_width: fiber.width(),
            fiber_opacity: fiber.opacity(),
        })
        .await
        .map_err(|s| match s.code() {
            tonic::Code::FailedPrecondition => ClusterError::Version {
                addr: addr.to_string(),
                msg: s.message().to_string(),
            },
            _ => err(s.message().to_string()),
        })?
        .into_inner();
    if reply.protocol_version != wire::PROTOCOL_VERSION {
        return Err(ClusterError::Version {
            addr: addr.to_string(),
            msg: format!(
                "the worker speaks protocol version {}, this coordinator {}",
                reply.protocol_version,
                wire::PROTOCOL_VERSION
            ),
        });
    }
    tracing::info!(addr, worker = reply.worker, "worker ready");
    Ok(Remote {
        addr: addr.to_string(),
        client,
    })
}

/// The innermost cause: "Connection refused (os error 111)" rather than
/// three layers of "transport error".
fn root_cause(e: &dyn std::error::Error) -> String {
    let mut last = e.to_string();
    let mut s = e.source();
    while let Some(x) = s {
        last = x.to_string();
        s = x.source();
    }
    last
}

/// Cuts `0..len` into `parts` contiguous ranges whose `weight` sums are
/// about equal (a range may be empty).
fn split_by(
    len: usize,
    parts: usize,
    weight: impl Fn(usize) -> u64,
) -> Vec<std::ops::Range<usize>> {
    let total: u64 = (0..len).map(&weight).sum();
    let mut out = Vec::with_capacity(parts);
    let (mut start, mut acc, mut i) = (0, 0u64, 0);
    for p in 1..=parts {
        let goal = total * p as u64 / parts as u64;
        while i < len && (acc < goal || p == parts) {
            acc += weight(i);
            i += 1;
        }
        out.push(start..i);
        start = i;
    }
    out
}

/// Runs `call` on every worker at once, each bounded by `deadline`, and
/// returns the results in worker order: the first error, if any, names
/// its worker.
fn fan_out<R, T, F, Fut>(
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
    rt.block_on(async {
        let tasks: Vec<_> = requests
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
            .collect();
        let mut out = Vec::with_capacity(tasks.len());
        for t in tasks {
            out.push(t.await.map_err(|e| ClusterError::Setup(e.to_string()))??);
        }
        Ok(out)
    })
}

fn call_error(addr: &str, stage: &'static str, s: tonic::Status) -> ClusterError {
    ClusterError::Call {
        addr: addr.to_string(),
        stage,
        msg: format!("{:?}: {}", s.code(), s.message()),
    }
}

impl RemoteExecutor {
    fn fill_remote(
        &mut self,
        light: usize,
        map: &mut DensityMap,
        hair: &Hair,
    ) -> Result<FillStats, ClusterError> {
        self.frame_id += 1;
        let frame = *map.frame();
        let offsets = hair.offsets();
        let shares = split_by(hair.strand_count(), self.workers.len(), |s| {
            u64::from(offsets[s + 1] - offsets[s]) + 1
        });
        let deadline = self.deadline;
        let mut requests = Vec::with_capacity(shares.len());
        let mut sent = 0u64;
        for (w, share) in self.workers.iter().zip(shares) {
            let chunks = wire::deposit_chunks(self.frame_id, light as u32, &frame, hair, share);
            sent += chunks.iter().map(|c| c.encoded_len() as u64).sum::<u64>();
            requests.push((w.clone(), chunks));
        }
        let replies = fan_out(
            &self.rt,
            requests,
            "deposit",
            deadline,
            |mut w, chunks| async move {
                let mut s = w
                    .client
                    .deposit(tokio_stream::iter(chunks))
                    .await
                    .map_err(|s| call_error(&w.addr, "deposit", s))?
                    .into_inner();
                let mut got = Vec::new();
                while let Some(c) = s
                    .message()
                    .await
                    .map_err(|s| call_error(&w.addr, "deposit", s))?
                {
                    got.push(c);
                }
                Ok((w.addr, got))
            },
        )?;
        // Merge in worker order (integer sums: any order gives the same map).
        let mut stats = FillStats::default();
        let mut received = 0u64;
        for (addr, chunks) in replies {
            for c in &chunks {
                received += c.encoded_len() as u64;
                wire::merge_columns(map, c).map_err(|e| ClusterError::Malformed {
                    addr: addr.clone(),
                    msg: e.to_string(),
                })?;
                stats.samples += c.samples;
                stats.out_of_map += c.out_of_map;
            }
        }
        self.count(|t| {
            t.strands_sent += sent;
            t.density_received += received;
        });
        Ok(stats)
    }

    fn sweep_remote(
        &mut self,
        light: usize,
        map: &DensityMap,
    ) -> Result<Transmittance, ClusterError> {
        let frame = *map.frame();
        let n = frame.columns();
        let shares = split_by(n, self.workers.len(), |c| {
            let m = map.meta(c);
            if m.is_empty() {
                1
            } else {
                u64::from(m.hi - m.lo) + 2
            }
        });
        let deadline = self.deadline;
        let mut requests = Vec::with_capacity(shares.len());
        let mut sent = 0u64;
        for (w, share) in self.workers.iter().zip(&shares) {
            let mut chunks = wire::column_chunks(map, share.clone());
            let first = &mut chunks[0];
            first.frame_id = self.frame_id;
            first.light = light as u32;
            first.map = Some(wire::frame_to_pb(&frame));
            first.first_column = share.start as u32;
            first.end_column = share.end as u32;
            sent += chunks.iter().map(|c| c.encoded_len() as u64).sum::<u64>();
            requests.push((w.clone(), (chunks, share.clone())));
        }
        let n_cells = frame.n_cells;
        let replies = fan_out(
            &self.rt,
            requests,
            "sweep",
            deadline,
            move |mut w, (chunks, share)| async move {
                let mut s = w
                    .client
                    .sweep(tokio_stream::iter(chunks))
                    .await
                    .map_err(|s| call_error(&w.addr, "sweep", s))?
                    .into_inner();
                let start = share.start as u32;
                let mut slab = ColumnSlab {
                    columns: start..start,
                    spans: Vec::new(),
                    depth: Vec::new(),
                };
                let mut bytes = 0u64;
                let malformed = |msg: String| ClusterError::Malformed {
                    addr: w.addr.clone(),
                    msg,
                };
                while let Some(c) = s
                    .message()
                    .await
                    .map_err(|s| call_error(&w.addr, "sweep", s))?
                {
                    bytes += c.encoded_len() as u64;
                    wire::add_slab_chunk(&mut slab, &c, n_cells)
                        .map_err(|e| malformed(e.to_string()))?;
                }
                if slab.columns.end as usize != share.end {
                    return Err(malformed(format!(
                        "slab ends at column {}, expected {}",
                        slab.columns.end, share.end
                    )));
                }
                Ok((slab, bytes))
            },
        )?;
        let received: u64 = replies.iter().map(|(_, b)| b).sum();
        self.count(|t| {
            t.density_sent += sent;
            t.slabs_received += received;
        });
        Transmittance::assemble(frame, replies.into_iter().map(|(s, _)| s)).map_err(|e| {
            ClusterError::Malformed {
                addr: "workers".into(),
                msg: e.to_string(),
            }
        })
    }
}

impl Executor for RemoteExecutor {
    fn fill(
        &mut self,
        light: usize,
        map: &mut DensityMap,
        hair: &Hair,
        _fiber: &Fiber,
    ) -> Result<FillStats, EngineError> {
        self.fill_remote(light, map, hair)
            .map_err(|e| EngineError::Executor(e.to_string()))
    }

    fn sweep(&mut self, light: usize, map: &DensityMap) -> Result<Transmittance, EngineError> {
        self.sweep_remote(light, map)
            .map_err(|e| EngineError::Executor(e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::split_by;

    #[test]
    fn splits_cover_everything_in_order_and_balance_weight() {
        for (len, parts) in [(0, 3), (1, 3), (10, 3), (100, 1), (7, 7)] {
            let s = split_by(len, parts, |i| (i % 5) as u64 + 1);
            assert_eq!(s.len(), parts);
            assert_eq!(s[0].start, 0);
            assert_eq!(s[parts - 1].end, len);
            assert!(s.windows(2).all(|w| w[0].end == w[1].start));
        }
        let s = split_by(90, 3, |_| 1);
        assert_eq!(s, vec![0..30, 30..60, 60..90]);
    }
}
