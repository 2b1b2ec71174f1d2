//! A worker process's resident memory stays under its documented bound
//! (`--max-memory-mib`, plus each session's kept maps, a message per call
//! in flight and the program itself) whatever it is sent: the worst cases
//! of strands of no points, data files and scene text past the limits, a
//! scene of absurd hair, and concurrent deposits of large maps.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use cluster::pb::worker_client::WorkerClient;
use cluster::{SessionClient, SessionHeader, pb, protocol};
use glam::Vec3;
use shadow::{Light, LightFrame};

const BUDGET_MIB: u64 = 256;
const SESSIONS: u64 = 2;

struct Worker {
    child: Child,
    addr: String,
}

impl Drop for Worker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn start() -> Worker {
    let mut child = Command::new(env!("CARGO_BIN_EXE_wisplight"))
        .args(["worker", "--listen", "127.0.0.1:0", "-q"])
        .args(["--max-memory-mib", &BUDGET_MIB.to_string()])
        .args(["--max-sessions", &SESSIONS.to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line
        .trim()
        .strip_prefix("listening on ")
        .unwrap()
        .to_string();
    Worker { child, addr }
}

/// A field of `/proc/PID/status`, bytes.
fn status_bytes(pid: u32, field: &str) -> u64 {
    let text = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let line = text.lines().find(|l| l.starts_with(field)).unwrap();
    let kb: u64 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
    kb << 10
}

async fn session(addr: &str) -> SessionClient {
    let channel = tonic::transport::Endpoint::from_shared(format!("http://{addr}"))
        .unwrap()
        .connect()
        .await
        .unwrap();
    let id = WorkerClient::new(channel.clone())
        .hello(pb::HelloRequest {
            protocol_version: protocol::PROTOCOL_VERSION,
            fiber_width: 0.1,
            fiber_opacity: 0.5,
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner()
        .session;
    WorkerClient::with_interceptor(channel, SessionHeader::new(&id).unwrap())
        .max_encoding_message_size(protocol::MAX_MESSAGE_BYTES)
}

fn frame(cells: u32) -> pb::MapFrame {
    let light = Light::directional(Vec3::X).unwrap();
    protocol::frame_to_pb(&LightFrame::centered(&light, Vec3::ZERO, 2.0, cells).unwrap())
}

fn assign(text: &str) -> pb::AssignChunk {
    pb::AssignChunk {
        scene_toml: text.into(),
        scene_path: "s.toml".into(),
        end_group: 1,
        ..Default::default()
    }
}

#[test]
fn a_worker_stays_under_its_memory_bound_whatever_it_is_sent() {
    if !std::path::Path::new("/proc/self/status").exists() {
        eprintln!("no /proc: resident memory cannot be read here");
        return;
    }
    let w = start();
    let pid = w.child.id();
    let idle = status_bytes(pid, "VmRSS");
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut c = session(&w.addr).await;

        // Strands of no points, a million a chunk, far past the budget.
        let nothing = (0..40).map(|i| pb::DensityChunk {
            map: (i == 0).then(|| frame(64)),
            strand_lengths: vec![0; 1 << 20],
            ..Default::default()
        });
        let m = exhausted(
            c.density(tokio_stream(nothing)).await,
            "zero-length strands",
        );
        assert!(m.contains("memory-mib"), "{m}");

        // Data files of 8 MiB a chunk past the budget (320 MiB in all).
        let files = std::iter::once(pb::AssignChunk {
            file_path: "big.tfx".into(),
            ..assign("")
        })
        .chain((0..40).map(|_| pb::AssignChunk {
            file_data: vec![7; 8 << 20],
            ..Default::default()
        }));
        exhausted(c.assign(tokio_stream(files)).await, "data files");

        // Scene text past its limit, in 1 MiB pieces.
        let text = "#".repeat(protocol::MAX_SCENE_TEXT + 1);
        let pieces: Vec<_> = protocol::text_pieces(&text, protocol::TEXT_PIECE_BYTES)
            .map(assign)
            .collect();
        let m = exhausted(c.assign(tokio_stream(pieces)).await, "scene text");
        assert!(m.contains("MAX_SCENE_TEXT"), "{m}");

        // A scene of 42 bytes asking for four million drawn segments: refused
        // before any is made.
        let absurd = "[hair]\nstyle = \"smooth\"\nstrands_per_wisp = 1000\n";
        let m = exhausted(
            c.assign(tokio_stream([assign(absurd)])).await,
            "absurd hair",
        );
        assert!(m.contains("hair"), "{m}");

        // Four concurrent deposits of 256^3 maps (64 MiB each) from two
        // sessions: they take turns within the budget and all finish.
        let d = session(&w.addr).await;
        let calls = (0..4).map(|i| {
            let mut c = if i % 2 == 0 { c.clone() } else { d.clone() };
            async move {
                let chunk = pb::DensityChunk {
                    map: Some(frame(256)),
                    strand_lengths: vec![2; 1000],
                    points: (0..1000)
                        .flat_map(|s| {
                            let t = s as f32 / 1000.0 * 1.8 - 0.9;
                            [-0.9, t, -0.9, 0.9, -t, 0.9]
                        })
                        .collect(),
                    ..Default::default()
                };
                let mut r = tonic::Request::new(tokio_stream([chunk]));
                r.set_timeout(Duration::from_secs(60));
                let mut s = c.density(r).await.unwrap().into_inner();
                let mut samples = 0;
                while let Some(m) = s.message().await.unwrap() {
                    samples += m.samples;
                }
                samples
            }
        });
        let samples: Vec<u64> = futures_join(calls).await;
        assert!(
            samples.iter().all(|&s| s > 0 && s == samples[0]),
            "{samples:?}"
        );
    });
    let peak = status_bytes(pid, "VmHWM");
    // The documented bound: the budget, each session's pool of kept maps,
    // a message for each call in flight (four here), and the idle program
    // with 32 MiB for the allocator's and threads' own.
    let bound = (BUDGET_MIB << 20)
        + SESSIONS * cluster::POOL_BYTES
        + 4 * protocol::MAX_MESSAGE_BYTES as u64
        + idle
        + (32 << 20);
    eprintln!(
        "peak resident {} MiB (idle {} MiB), bound {} MiB",
        peak >> 20,
        idle >> 20,
        bound >> 20
    );
    assert!(peak < bound, "peak {peak} B past the bound {bound} B");
}

/// The message of a call refused with RESOURCE_EXHAUSTED.
fn exhausted<T>(r: Result<T, tonic::Status>, what: &str) -> String {
    let e = r.err().unwrap_or_else(|| panic!("{what}: served"));
    assert_eq!(
        e.code(),
        tonic::Code::ResourceExhausted,
        "{what}: {}",
        e.message()
    );
    e.message().to_string()
}

fn tokio_stream<T: Send + 'static>(
    items: impl IntoIterator<Item = T, IntoIter: Send + 'static>,
) -> impl tonic::codegen::tokio_stream::Stream<Item = T> + Send + 'static {
    tonic::codegen::tokio_stream::iter(items)
}

/// Runs `calls` at once, their results in order.
async fn futures_join<F>(calls: impl Iterator<Item = F>) -> Vec<F::Output>
where
    F: std::future::Future + Send + 'static,
    F::Output: Send + 'static,
{
    let handles: Vec<_> = calls.map(tokio::spawn).collect();
    let mut out = Vec::new();
    for h in handles {
        out.push(h.await.unwrap());
    }
    out
}
