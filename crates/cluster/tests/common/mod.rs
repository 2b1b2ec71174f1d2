//! What the in-process protocol tests share.

use std::net::SocketAddr;
use std::time::Duration;

use cluster::Listen;
use engine::{Scene, Sequence};

/// A small simulated scene: the smooth style, thinned, on a dancing head.
#[allow(dead_code)]
pub(crate) const DANCE: &str = r#"
[hair]
style = "smooth"
strands_per_wisp = 4

[render]
width = 160
height = 90

[animation]
motion = "dance"
fps = 30

[dynamics]
settle = 0.1
"#;

/// `frames` pictures of `scene` in one process, as `render --frames` makes them.
#[allow(dead_code)]
pub(crate) fn local_frames(scene: &Scene, frames: usize) -> Vec<image::RgbImage> {
    let mut seq = Sequence::new(scene).unwrap();
    // As `render --frames` does: the camera frames all of them.
    seq.expect_frames(frames as u64);
    (0..frames)
        .map(|_| seq.next_frame().unwrap().0.clone())
        .collect()
}

/// A worker on a free localhost port in a background runtime, listening as
/// `listen` says, and a switch that stops it (the server closes; calls in
/// flight finish, new ones find no server). A dropped switch never stops
/// the worker.
pub(crate) fn start_worker_with(listen: Listen) -> (SocketAddr, tokio::sync::oneshot::Sender<()>) {
    start_service(cluster::WorkerService::default(), listen)
}

/// [`start_worker_with`] for `service`.
#[allow(dead_code)]
pub(crate) fn start_service(
    service: cluster::WorkerService,
    listen: Listen,
) -> (SocketAddr, tokio::sync::oneshot::Sender<()>) {
    let (tx, rx) = std::sync::mpsc::channel();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(cluster::serve_worker(
            service,
            "127.0.0.1:0".parse().unwrap(),
            &listen,
            move |b| tx.send(b.addr).unwrap(),
            async {
                if stopped.await.is_err() {
                    std::future::pending::<()>().await;
                }
            },
        ))
        .unwrap();
    });
    (rx.recv_timeout(Duration::from_secs(10)).unwrap(), stop)
}

/// A client of the worker at `addr` that has said Hello, naming the
/// session it opened in every call.
#[allow(dead_code)]
pub(crate) async fn greeted_client(addr: SocketAddr) -> cluster::SessionClient {
    let channel = tonic::transport::Endpoint::from_shared(format!("http://{addr}"))
        .unwrap()
        .connect()
        .await
        .unwrap();
    let id = cluster::pb::worker_client::WorkerClient::new(channel.clone())
        .hello(cluster::pb::HelloRequest {
            protocol_version: cluster::protocol::PROTOCOL_VERSION,
            fiber_width: 0.1,
            fiber_opacity: 0.5,
        })
        .await
        .unwrap()
        .into_inner()
        .session;
    cluster::pb::worker_client::WorkerClient::with_interceptor(
        channel,
        cluster::SessionHeader::new(&id).unwrap(),
    )
}
