//! The protocol in one process, over real sockets on localhost: identical
//! bytes to the local executor, a worker of another version refused,
//! malformed messages answered with an error while the worker lives on.

use std::net::SocketAddr;
use std::time::Duration;

use cluster::pb::worker_client::WorkerClient;
use cluster::{RemoteExecutor, pb, wire};
use engine::{Executor, LocalExecutor};
use glam::Vec3;
use shadow::{DensityMap, Fiber, Light, LightFrame};
use strands::{Style, StyleParams, WispModel};

/// Starts a worker on a free port in a background runtime.
fn start_worker() -> SocketAddr {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(cluster::worker::serve(
            "127.0.0.1:0".parse().unwrap(),
            move |a| tx.send(a).unwrap(),
            std::future::pending(),
        ))
        .unwrap();
    });
    rx.recv_timeout(Duration::from_secs(10)).unwrap()
}

fn hair() -> strands::Hair {
    let mut p = StyleParams::new(Style::Curly);
    p.strands_per_wisp = 3;
    WispModel::generate(&p).interpolate()
}

#[test]
fn three_workers_give_the_local_map_and_transmittance_bit_for_bit() {
    let addrs: Vec<String> = (0..3).map(|_| start_worker().to_string()).collect();
    let hair = hair();
    let fiber = Fiber::new(0.1, 0.5).unwrap();
    let light = Light::directional(Vec3::new(0.9, -0.35, -0.25)).unwrap();
    let frame = LightFrame::fit(&light, hair.points(), 96).unwrap();
    let mut local = LocalExecutor;
    let mut remote = RemoteExecutor::connect(&addrs, &fiber, Duration::from_secs(20)).unwrap();
    let (mut a, mut b) = (DensityMap::new(frame), DensityMap::new(frame));
    let sa = local.fill(0, &mut a, &hair, &fiber).unwrap();
    let sb = remote.fill(0, &mut b, &hair, &fiber).unwrap();
    assert_eq!(sa, sb);
    for col in 0..frame.columns() {
        assert_eq!(a.meta(col), b.meta(col), "column {col}");
        if let Some((lo, hi)) = a.span(col) {
            assert_eq!(a.column(col, lo..hi + 1), b.column(col, lo..hi + 1));
        }
    }
    let ta = local.sweep(0, &a).unwrap();
    let tb = remote.sweep(0, &b).unwrap();
    for p in hair.points().iter().step_by(13) {
        assert_eq!(
            ta.optical_depth(*p, true).to_bits(),
            tb.optical_depth(*p, true).to_bits()
        );
    }
    let t = *remote.traffic().lock().unwrap();
    assert!(
        t.strands_sent > 0 && t.density_received > 0 && t.density_sent > 0 && t.slabs_received > 0
    );
}

#[test]
fn a_worker_refuses_another_protocol_version_and_calls_before_hello() {
    let addr = start_worker();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut c = WorkerClient::connect(format!("http://{addr}"))
            .await
            .unwrap();
        let chunk = pb::DepositChunk::default();
        let e = c
            .deposit(tokio_stream::iter(vec![chunk]))
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::FailedPrecondition);
        assert!(e.message().contains("Hello"), "{}", e.message());
        let e = c
            .hello(pb::HelloRequest {
                protocol_version: wire::PROTOCOL_VERSION + 1,
                fiber_width: 0.1,
                fiber_opacity: 0.5,
            })
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::FailedPrecondition);
        assert!(e.message().contains("protocol version"), "{}", e.message());
    });
    // And the coordinator says so, naming the worker.
    let fiber = Fiber::new(0.1, 0.5).unwrap();
    let ok = RemoteExecutor::connect(&[addr.to_string()], &fiber, Duration::from_secs(5));
    assert!(ok.is_ok());
}

#[test]
fn malformed_messages_get_an_error_and_the_worker_lives_on() {
    let addr = start_worker();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let frame = LightFrame::centered(&light, Vec3::ZERO, 2.0, 8).unwrap();
    rt.block_on(async {
        let mut c = WorkerClient::connect(format!("http://{addr}"))
            .await
            .unwrap();
        c.hello(pb::HelloRequest {
            protocol_version: wire::PROTOCOL_VERSION,
            fiber_width: 0.1,
            fiber_opacity: 0.5,
        })
        .await
        .unwrap();
        let good = wire::frame_to_pb(&frame);
        let cases: Vec<pb::DepositChunk> = vec![
            // No frame.
            pb::DepositChunk::default(),
            // Lengths that do not match the points.
            pb::DepositChunk {
                map: Some(good.clone()),
                strand_lengths: vec![3],
                points: vec![0.0; 6],
                ..Default::default()
            },
            // A NaN point.
            pb::DepositChunk {
                map: Some(good.clone()),
                strand_lengths: vec![2],
                points: vec![0.0, 0.0, 0.0, f32::NAN, 0.0, 0.0],
                ..Default::default()
            },
            // An absurd map.
            pb::DepositChunk {
                map: Some(pb::MapFrame {
                    n_cells: 100_000,
                    ..good.clone()
                }),
                ..Default::default()
            },
            pb::DepositChunk {
                map: Some(pb::MapFrame {
                    ds: f32::INFINITY,
                    ..good.clone()
                }),
                ..Default::default()
            },
            pb::DepositChunk {
                map: Some(pb::MapFrame {
                    axes: vec![1.0; 2],
                    ..good.clone()
                }),
                ..Default::default()
            },
        ];
        for chunk in cases {
            let e = c
                .deposit(tokio_stream::iter(vec![chunk.clone()]))
                .await
                .unwrap_err();
            assert_eq!(
                e.code(),
                tonic::Code::InvalidArgument,
                "{chunk:?}: {}",
                e.message()
            );
        }
        let sweeps = vec![
            // Columns past the map.
            pb::ColumnChunk {
                map: Some(good.clone()),
                first_column: 0,
                end_column: 65,
                ..Default::default()
            },
            // A column whose cells do not match its values.
            pb::ColumnChunk {
                map: Some(good.clone()),
                end_column: 64,
                columns: vec![3],
                lo: vec![1],
                hi: vec![4],
                front: vec![1.0],
                quanta: vec![1, 2],
                ..Default::default()
            },
            // A column outside the map.
            pb::ColumnChunk {
                map: Some(good.clone()),
                end_column: 64,
                columns: vec![640],
                lo: vec![1],
                hi: vec![1],
                front: vec![1.0],
                quanta: vec![1],
                ..Default::default()
            },
            pb::ColumnChunk {
                map: Some(good.clone()),
                end_column: 64,
                columns: vec![3],
                lo: vec![1],
                hi: vec![9],
                front: vec![1.0],
                quanta: vec![1; 9],
                ..Default::default()
            },
        ];
        for chunk in sweeps {
            let e = c
                .sweep(tokio_stream::iter(vec![chunk.clone()]))
                .await
                .unwrap_err();
            assert_eq!(
                e.code(),
                tonic::Code::InvalidArgument,
                "{chunk:?}: {}",
                e.message()
            );
        }
        // Still serving: a good call works.
        let ok = pb::DepositChunk {
            map: Some(good),
            strand_lengths: vec![2],
            points: vec![0.0, 0.5, -0.5, 0.0, 0.5, 0.5],
            ..Default::default()
        };
        let mut s = c
            .deposit(tokio_stream::iter(vec![ok]))
            .await
            .unwrap()
            .into_inner();
        let mut samples = 0;
        while let Some(m) = s.message().await.unwrap() {
            samples += m.samples;
        }
        assert!(samples > 0);
    });
}

#[test]
fn a_worker_answers_health_checks_for_itself_and_the_server() {
    use tonic_health::pb::health_client::HealthClient;
    use tonic_health::pb::{HealthCheckRequest, health_check_response::ServingStatus};
    let addr = start_worker();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let channel = tonic::transport::Channel::from_shared(format!("http://{addr}"))
            .unwrap()
            .connect()
            .await
            .unwrap();
        let mut h = HealthClient::new(channel);
        for service in ["", "wisplight.v1.Worker"] {
            let r = h
                .check(HealthCheckRequest {
                    service: service.into(),
                })
                .await
                .unwrap()
                .into_inner();
            assert_eq!(r.status, ServingStatus::Serving as i32, "{service:?}");
        }
    });
}
