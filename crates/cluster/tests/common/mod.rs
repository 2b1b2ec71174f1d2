//! What the in-process protocol tests share.

use std::net::SocketAddr;
use std::time::Duration;

use cluster::worker::Listen;

/// A worker on a free localhost port in a background runtime, listening as
/// `listen` says, and a switch that stops it (the server closes; calls in
/// flight finish, new ones find no server). A dropped switch never stops
/// the worker.
pub fn start_worker_with(listen: Listen) -> (SocketAddr, tokio::sync::oneshot::Sender<()>) {
    start_service(cluster::worker::WorkerService::default(), listen)
}

/// [`start_worker_with`] for `service`.
#[allow(dead_code)]
pub fn start_service(
    service: cluster::worker::WorkerService,
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
        rt.block_on(cluster::worker::serve(
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
