//! The protocol in one process, over real sockets on localhost: identical
//! bytes to the local executor (maps, slabs, simulated animations), a
//! worker lost mid-animation replaced by the survivors with the same
//! pictures, a worker of another version refused, malformed messages
//! answered with an error while the worker lives on.

mod common;

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use cluster::pb::worker_client::WorkerClient;
use cluster::{DrawAt, Options, RemoteExecutor, pb, protocol};
use engine::{Drawing, EngineError, Executor, LocalExecutor, Scene, Sequence};
use glam::Vec3;
use shadow::{DensityMap, Fiber, Light, LightFrame};
use strands::{Style, StyleParams, WispModel};

/// Starts a worker on a free port in a background runtime.
fn start_worker() -> SocketAddr {
    start_stoppable_worker().0
}

/// A worker, and a switch that stops it.
fn start_stoppable_worker() -> (SocketAddr, tokio::sync::oneshot::Sender<()>) {
    common::start_worker_with(cluster::Listen::default())
}

use common::{DANCE, greeted_client, local_frames};

/// How tests run workers: drawing where `draw` says, deadline `secs`.
fn options(draw: DrawAt, secs: u64) -> Options {
    Options {
        deadline: Duration::from_secs(secs),
        connect_timeout: Duration::from_secs(5),
        tls: None,
        token: None,
        draw,
    }
}

/// `scene`'s frames rendered through `remote`, each the same bytes as
/// `want`'s, with the frames said to follow (as `render --frames` says).
fn assert_frames(scene: &Scene, remote: RemoteExecutor, want: &[image::RgbImage]) {
    let mut seq = Sequence::new(scene).unwrap();
    seq.set_executor(Box::new(remote)).unwrap();
    seq.expect_frames(want.len() as u64);
    for (i, w) in want.iter().enumerate() {
        assert!(
            seq.next_frame().unwrap().0 == w,
            "frame {i} differs from one process"
        );
    }
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
    // Drawing on the coordinator: the strands are sent, as for any hair.
    let mut remote =
        RemoteExecutor::connect(&addrs, &Scene::default(), &options(DrawAt::Coordinator, 20))
            .unwrap();
    let (mut a, mut b) = (DensityMap::new(frame), DensityMap::new(frame));
    let sa = local
        .density(
            0,
            &mut a,
            engine::Strands::Here {
                hair: &hair,
                posed: None,
            },
            &fiber,
        )
        .unwrap();
    let sb = remote
        .density(
            0,
            &mut b,
            engine::Strands::Here {
                hair: &hair,
                posed: None,
            },
            &fiber,
        )
        .unwrap();
    assert_eq!(sa, sb);
    for col in 0..frame.columns() {
        assert_eq!(a.meta(col), b.meta(col), "column {col}");
        if let Some((lo, hi)) = a.span(col) {
            assert_eq!(a.column(col, lo..hi + 1), b.column(col, lo..hi + 1));
        }
    }
    let ta = local.transmittance(0, &a).unwrap();
    let tb = remote.transmittance(0, &b).unwrap();
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
        let chunk = pb::DensityChunk::default();
        let e = c
            .density(tokio_stream::iter(vec![chunk]))
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::FailedPrecondition);
        assert!(e.message().contains("Hello"), "{}", e.message());
        assert!(e.message().contains("session"), "{}", e.message());
        let e = c
            .hello(pb::HelloRequest {
                protocol_version: protocol::PROTOCOL_VERSION + 1,
                fiber_width: 0.1,
                fiber_opacity: 0.5,
                ..Default::default()
            })
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::FailedPrecondition);
        assert!(e.message().contains("protocol version"), "{}", e.message());
    });
    // A coordinator of this version is served.
    let ok = RemoteExecutor::connect(
        &[addr.to_string()],
        &Scene::default(),
        &options(DrawAt::SortLast, 5),
    );
    assert!(ok.is_ok());
}

#[test]
fn malformed_messages_get_an_error_and_the_worker_lives_on() {
    let addr = start_worker();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let frame = LightFrame::centered(&light, Vec3::ZERO, 2.0, 8).unwrap();
    rt.block_on(async {
        let mut c = greeted_client(addr).await;
        let good = protocol::frame_to_pb(&frame);
        let cases: Vec<pb::DensityChunk> = vec![
            // No frame.
            pb::DensityChunk::default(),
            // Lengths that do not match the points.
            pb::DensityChunk {
                map: Some(good.clone()),
                strand_lengths: vec![3],
                points: vec![0.0; 6],
                ..Default::default()
            },
            // A NaN point.
            pb::DensityChunk {
                map: Some(good.clone()),
                strand_lengths: vec![2],
                points: vec![0.0, 0.0, 0.0, f32::NAN, 0.0, 0.0],
                ..Default::default()
            },
            // An absurd map.
            pb::DensityChunk {
                map: Some(pb::MapFrame {
                    n_cells: 100_000,
                    ..good.clone()
                }),
                ..Default::default()
            },
            pb::DensityChunk {
                map: Some(pb::MapFrame {
                    ds: f32::INFINITY,
                    ..good.clone()
                }),
                ..Default::default()
            },
            pb::DensityChunk {
                map: Some(pb::MapFrame {
                    axes: vec![1.0; 2],
                    ..good.clone()
                }),
                ..Default::default()
            },
        ];
        for chunk in cases {
            let e = c
                .density(tokio_stream::iter(vec![chunk.clone()]))
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
                column_steps: vec![3],
                lo: vec![1],
                hi: vec![4],
                front: vec![1.0],
                cells: protocol::pack(&[1, 2]),
                ..Default::default()
            },
            // A column outside the map.
            pb::ColumnChunk {
                map: Some(good.clone()),
                end_column: 64,
                column_steps: vec![640],
                lo: vec![1],
                hi: vec![1],
                front: vec![1.0],
                cells: protocol::pack(&[1]),
                ..Default::default()
            },
            pb::ColumnChunk {
                map: Some(good.clone()),
                end_column: 64,
                column_steps: vec![3],
                lo: vec![1],
                hi: vec![9],
                front: vec![1.0],
                cells: protocol::pack(&[1; 9]),
                ..Default::default()
            },
        ];
        for chunk in sweeps {
            let e = c
                .transmittance(tokio_stream::iter(vec![chunk.clone()]))
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
        let ok = pb::DensityChunk {
            map: Some(good),
            strand_lengths: vec![2],
            points: vec![0.0, 0.5, -0.5, 0.0, 0.5, 0.5],
            ..Default::default()
        };
        let mut s = c
            .density(tokio_stream::iter(vec![ok]))
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

/// Sends `bytes` as the request of unary call `path`, as they are.
async fn raw_call(addr: SocketAddr, path: &'static str, bytes: Vec<u8>) -> tonic::Status {
    let channel = tonic::transport::Endpoint::from_shared(format!("http://{addr}"))
        .unwrap()
        .connect()
        .await
        .unwrap();
    let mut grpc = tonic::client::Grpc::new(channel);
    grpc.ready().await.unwrap();
    let codec = RawBytes::<pb::HelloReply>::default();
    grpc.unary(
        tonic::Request::new(bytes),
        tonic::codegen::http::uri::PathAndQuery::from_static(path),
        codec,
    )
    .await
    .unwrap_err()
}

/// Encodes raw bytes, decodes replies as `U`.
#[derive(Debug, Default)]
struct RawBytes<U>(std::marker::PhantomData<U>);

#[derive(Debug, Default)]
struct RawEncoder;

impl tonic::codec::Encoder for RawEncoder {
    type Item = Vec<u8>;
    type Error = tonic::Status;
    fn encode(
        &mut self,
        item: Vec<u8>,
        buf: &mut tonic::codec::EncodeBuf<'_>,
    ) -> Result<(), tonic::Status> {
        use prost::bytes::BufMut;
        buf.put_slice(&item);
        Ok(())
    }
}

impl<U: prost::Message + Default + Send + 'static> tonic::codec::Codec for RawBytes<U> {
    type Encode = Vec<u8>;
    type Decode = U;
    type Encoder = RawEncoder;
    type Decoder = tonic_prost::ProstDecoder<U>;
    fn encoder(&mut self) -> RawEncoder {
        RawEncoder
    }
    fn decoder(&mut self) -> Self::Decoder {
        tonic_prost::ProstDecoder::default()
    }
}

#[test]
fn undecodable_bytes_and_unphysical_fibers_are_invalid_arguments() {
    let addr = start_worker();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        // A field tag of 0 and a truncated varint: not a protobuf message.
        for bytes in [vec![0u8, 1], vec![0x08, 0xff]] {
            let e = raw_call(addr, "/wisplight.v1.Worker/Hello", bytes.clone()).await;
            assert_eq!(
                e.code(),
                tonic::Code::InvalidArgument,
                "{bytes:?}: {}",
                e.message()
            );
            assert!(e.message().contains("HelloRequest"), "{}", e.message());
        }
        let mut c = WorkerClient::connect(format!("http://{addr}"))
            .await
            .unwrap();
        for (width, opacity) in [
            (0.0, 0.5),
            (-0.1, 0.5),
            (f32::NAN, 0.5),
            (f32::INFINITY, 0.5),
            (0.1, 1.5),
            (0.1, -0.5),
            (0.1, f32::NAN),
        ] {
            let e = c
                .hello(pb::HelloRequest {
                    protocol_version: protocol::PROTOCOL_VERSION,
                    fiber_width: width,
                    fiber_opacity: opacity,
                    ..Default::default()
                })
                .await
                .unwrap_err();
            assert_eq!(e.code(), tonic::Code::InvalidArgument, "{width} {opacity}");
            assert!(e.message().contains("fiber"), "{}", e.message());
        }
        // The worker lives on: a physical Hello opens a session.
        let ok = c
            .hello(pb::HelloRequest {
                protocol_version: protocol::PROTOCOL_VERSION,
                fiber_width: 0.1,
                fiber_opacity: 0.0,
                ..Default::default()
            })
            .await
            .unwrap();
        assert_eq!(ok.into_inner().session.len(), 32);
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

#[test]
fn three_workers_give_the_local_animation_byte_for_byte_drawing_anywhere() {
    let scene = Scene::from_toml_str(DANCE, std::path::Path::new("dance.toml")).unwrap();
    let want = local_frames(&scene, 4);
    for draw in [DrawAt::SortLast, DrawAt::SortMiddle, DrawAt::Coordinator] {
        let addrs: Vec<String> = (0..3).map(|_| start_worker().to_string()).collect();
        let remote = RemoteExecutor::connect(&addrs, &scene, &options(draw, 20)).unwrap();
        let (traffic, timing) = (remote.traffic(), remote.timing());
        let mut seq = Sequence::new(&scene).unwrap();
        seq.set_executor(Box::new(remote)).unwrap();
        // Each frame runs the next one's stages up to its drawing while
        // its own picture is composited.
        seq.expect_frames(want.len() as u64);
        let mut after_first = None;
        for (i, w) in want.iter().enumerate() {
            let (img, _) = seq.next_frame().unwrap();
            assert!(img == w, "{draw:?}: frame {i} differs from one process");
            if i == 0 {
                after_first = Some(*traffic.lock().unwrap());
            }
        }
        let first = after_first.unwrap();
        let t = traffic.lock().unwrap().since(&first);
        // Later frames: the wisps are stepped on the workers, and the
        // density filled from the strands they posed: the Density requests
        // carry a map frame (about 70 bytes) and, drawing on the workers,
        // the column plan (addresses, sessions, the head: about 300), no
        // strand (a strand is 200+ bytes).
        assert!(t.step_sent > 0 && t.wisps_received > 0, "{t:?}");
        assert!(t.strands_sent <= 3 * 3 * 400, "{t:?}");
        assert_eq!(t.assign_sent, 0, "assigned once: {t:?}");
        // Drawing on the workers, they composite among themselves: their
        // stripes (partial pictures or segments) go to each other and
        // finished bands come back, no partial picture.
        let on_workers = draw != DrawAt::Coordinator;
        assert_eq!(t.layers_received, 0, "{t:?}");
        assert_eq!(t.stripes_between_workers > 0, on_workers, "{t:?}");
        assert_eq!(t.bands_received > 0, on_workers, "{t:?}");
        // They sum and sweep the maps among themselves too: their density
        // and swept columns go to each other, and the coordinator sends
        // no column, receives no slab.
        assert_eq!(t.density_between_workers > 0, on_workers, "{t:?}");
        assert_eq!(t.swept_between_workers > 0, on_workers, "{t:?}");
        assert_eq!(
            t.density_sent == 0 && t.slabs_received == 0,
            on_workers,
            "{t:?}"
        );
        assert!(
            t.draw_sent < 3 * 3 * 1000 || !on_workers,
            "no columns drawn with: {t:?}"
        );
        let timing = timing.lock().unwrap();
        assert_eq!(timing.composite_fallbacks, 0);
        assert_eq!(timing.exchange_fallbacks, 0);
    }
}

#[test]
fn one_worker_steps_and_fills_while_the_coordinator_sweeps_and_draws_to_the_same_bytes() {
    let scene = Scene::from_toml_str(DANCE, std::path::Path::new("dance.toml")).unwrap();
    let want = local_frames(&scene, 4);
    let addrs = [start_worker().to_string()];
    let remote = RemoteExecutor::connect(&addrs, &scene, &options(DrawAt::SortLast, 20)).unwrap();
    let traffic = remote.traffic();
    // The coordinator rasterizes each frame while the worker steps and
    // fills the next one.
    assert_frames(&scene, remote, &want);
    // The worker steps the wisps and fills the map; the coordinator sweeps
    // it and draws: no column goes out, no swept slab or picture comes in.
    let t = *traffic.lock().unwrap();
    assert!(t.step_sent > 0 && t.wisps_received > 0, "{t:?}");
    assert!(t.density_received > 0, "{t:?}");
    assert_eq!(t.density_sent, 0, "{t:?}");
    assert_eq!(t.slabs_received, 0, "{t:?}");
    assert_eq!(t.layers_received + t.bands_received, 0, "{t:?}");
}

#[test]
fn another_shadow_method_draws_on_the_coordinator_with_the_same_bytes() {
    // The peer methods need all the hair in one place: the coordinator
    // poses and draws it, the workers still simulate and fill the
    // self-collisions' map.
    let text = format!("{DANCE}\n[shadow]\nmethod = \"opacity-shadow-map\"\n");
    let scene = Scene::from_toml_str(&text, std::path::Path::new("osm.toml")).unwrap();
    let want = local_frames(&scene, 3);
    let addrs: Vec<String> = (0..2).map(|_| start_worker().to_string()).collect();
    let remote = RemoteExecutor::connect(&addrs, &scene, &options(DrawAt::SortLast, 20)).unwrap();
    assert_frames(&scene, remote, &want);
}

#[test]
fn contact_shadows_draw_on_the_coordinator_with_the_same_bytes() {
    // Contact shadows test every strand near a drawn point: the
    // coordinator poses and draws, the workers fill and sweep the map.
    let text = format!("{DANCE}\n[shadow]\ncontact = 2.0\n");
    let scene = Scene::from_toml_str(&text, std::path::Path::new("contact.toml")).unwrap();
    let want = local_frames(&scene, 3);
    let plain = local_frames(
        &Scene::from_toml_str(DANCE, std::path::Path::new("dance.toml")).unwrap(),
        3,
    );
    assert_ne!(want, plain, "contact shadows change the picture");
    let addrs: Vec<String> = (0..2).map(|_| start_worker().to_string()).collect();
    let remote = RemoteExecutor::connect(&addrs, &scene, &options(DrawAt::SortLast, 20)).unwrap();
    let traffic = remote.traffic();
    assert_frames(&scene, remote, &want);
    let t = *traffic.lock().unwrap();
    assert!(t.density_received > 0, "filled there: {t:?}");
}

#[test]
fn simplified_thin_hair_drawn_on_three_workers_is_the_local_animation() {
    // Strands about a tenth of a pixel wide, every other one drawn: each
    // worker draws the strands of its share that one process draws.
    let thin = |simplify: &str| {
        let text = DANCE.replace(
            "height = 90\n",
            &format!("height = 90\nsimplify = {simplify}\n"),
        ) + "\n[fiber]\nwidth = 0.05\n";
        Scene::from_toml_str(&text, std::path::Path::new("thin.toml")).unwrap()
    };
    let scene = thin("0.5");
    let want = local_frames(&scene, 3);
    assert!(
        want[2] != local_frames(&thin("0"), 3)[2],
        "simplified, the picture changes"
    );
    for draw in [DrawAt::SortLast, DrawAt::SortMiddle] {
        let addrs: Vec<String> = (0..3).map(|_| start_worker().to_string()).collect();
        let remote = RemoteExecutor::connect(&addrs, &scene, &options(draw, 20)).unwrap();
        assert_frames(&scene, remote, &want);
    }
}

#[test]
fn a_mesh_head_under_hair_drawn_on_three_workers_is_the_local_animation() {
    // Each band's owner draws the head in its own bands alone with
    // sort-middle, and the head's mesh hides the hair behind it there.
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    let text = format!("{DANCE}\n[head]\nmesh = \"head.obj\"\n");
    let scene = Scene::from_toml_str(&text, &dir.join("mesh_head.toml")).unwrap();
    let want = local_frames(&scene, 3);
    for draw in [DrawAt::SortMiddle, DrawAt::SortLast] {
        let addrs: Vec<String> = (0..3).map(|_| start_worker().to_string()).collect();
        let remote = RemoteExecutor::connect(&addrs, &scene, &options(draw, 20)).unwrap();
        let timing = remote.timing();
        assert_frames(&scene, remote, &want);
        let t = *timing.lock().unwrap();
        assert_eq!(t.composite_fallbacks, 0, "{draw:?}");
        assert_eq!(t.frames[2], 0, "{draw:?}: every frame on the workers");
        assert_eq!(t.frames.iter().sum::<u32>(), 3, "{draw:?}");
    }
}

#[test]
fn rigid_hair_drawn_on_workers_is_the_local_animation() {
    let text = format!("{DANCE}\n[effects]\ndynamics = false\n");
    let scene = Scene::from_toml_str(&text, std::path::Path::new("rigid.toml")).unwrap();
    let want = local_frames(&scene, 3);
    let addrs: Vec<String> = (0..2).map(|_| start_worker().to_string()).collect();
    let remote = RemoteExecutor::connect(&addrs, &scene, &options(DrawAt::SortLast, 20)).unwrap();
    let traffic = remote.traffic();
    assert_frames(&scene, remote, &want);
    let t = *traffic.lock().unwrap();
    // Three Deposits to each of two workers, of a frame and a column plan
    // (about 240 bytes each), no strand.
    assert!(t.pose > 0 && t.strands_sent < 6 * 400, "posed there: {t:?}");
    assert!(t.density_between_workers > 0, "summed there: {t:?}");
}

#[test]
fn a_worker_lost_mid_animation_hands_its_work_to_the_survivors() {
    let scene = Scene::from_toml_str(DANCE, std::path::Path::new("dance.toml")).unwrap();
    let want = local_frames(&scene, 6);
    for draw in [
        DrawAt::Auto,
        DrawAt::SortLast,
        DrawAt::SortMiddle,
        DrawAt::Coordinator,
    ] {
        let (a, _keep_a) = start_stoppable_worker();
        let (b, stop_b) = start_stoppable_worker();
        let (c, _keep_c) = start_stoppable_worker();
        let addrs = [a.to_string(), b.to_string(), c.to_string()];
        let remote = RemoteExecutor::connect(&addrs, &scene, &options(draw, 20)).unwrap();
        let timing = remote.timing();
        let mut seq = Sequence::new(&scene).unwrap();
        seq.set_executor(Box::new(remote)).unwrap();
        seq.expect_frames(want.len() as u64);
        let mut stop_b = Some(stop_b);
        for (i, w) in want.iter().enumerate() {
            if i == 3 {
                stop_b.take().unwrap().send(()).unwrap();
                // Let the server close its listener.
                std::thread::sleep(Duration::from_millis(300));
            }
            let (img, _) = seq.next_frame().unwrap();
            assert!(img == w, "{draw:?}: frame {i} differs from one process");
        }
        assert_eq!(timing.lock().unwrap().workers_lost, 1, "{draw:?}");
    }
}

#[test]
fn auto_draws_with_every_scheme_in_turn_and_every_frame_is_the_local_one() {
    // Auto measures each scheme before it chooses: frames drawn on the
    // workers (sort-middle, sort-last) and on the coordinator follow one
    // another, the hair held and posed in one place, then the other.
    let scene = Scene::from_toml_str(DANCE, std::path::Path::new("dance.toml")).unwrap();
    let want = local_frames(&scene, 8);
    let addrs: Vec<String> = (0..3).map(|_| start_worker().to_string()).collect();
    let remote = RemoteExecutor::connect(&addrs, &scene, &options(DrawAt::Auto, 20)).unwrap();
    let timing = remote.timing();
    assert_frames(&scene, remote, &want);
    let t = *timing.lock().unwrap();
    assert!(t.frames.iter().all(|&n| n > 0), "{:?}", t.frames);
    assert_eq!(t.frames.iter().sum::<u32>(), 8);
    assert_eq!(t.composite_fallbacks, 0);
}

/// The [`Executor`] methods a test's wrapper of a [`RemoteExecutor`]
/// (`self.inner`) passes on unchanged: attach, density and transmittance.
macro_rules! forward_to_inner {
    () => {
        fn attach(&mut self, anim: &engine::Animator) -> Result<(), EngineError> {
            self.inner.attach(anim)
        }
        fn density(
            &mut self,
            light: usize,
            map: &mut shadow::DensityMap,
            strands: engine::Strands<'_>,
            fiber: &shadow::Fiber,
        ) -> Result<shadow::FillStats, EngineError> {
            self.inner.density(light, map, strands, fiber)
        }
        fn transmittance(
            &mut self,
            light: usize,
            map: &shadow::DensityMap,
        ) -> Result<shadow::Transmittance, EngineError> {
            self.inner.transmittance(light, map)
        }
    };
}

/// Workers of which one is stopped in the middle of a frame: the first
/// frame from frame `at` on planned on the workers, after its plan and
/// before its Simulate call.
#[derive(Debug)]
struct StopsMidFrame {
    inner: RemoteExecutor,
    at: u64,
    planned: u64,
    armed: bool,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
}

impl Executor for StopsMidFrame {
    forward_to_inner!();
    fn simulate(
        &mut self,
        anim: &mut engine::Animator,
        plan: &engine::StepPlan,
        stats: &mut engine::FrameStats,
    ) -> Result<Option<engine::PoseReport>, EngineError> {
        if self.armed
            && let Some(stop) = self.stop.take()
        {
            stop.send(()).unwrap();
            std::thread::sleep(Duration::from_millis(300));
        }
        self.inner.simulate(anim, plan, stats)
    }
    fn runs_elsewhere(&self) -> bool {
        true
    }
    fn plan_frame(&mut self, needs: engine::FrameNeeds) -> engine::Site {
        let site = self.inner.plan_frame(needs);
        self.armed = self.planned >= self.at && site == engine::Site::Elsewhere;
        self.planned += 1;
        site
    }
    fn drawing(&mut self) -> Option<&mut dyn Drawing> {
        self.inner.drawing()
    }
}

#[test]
fn the_last_but_one_worker_lost_mid_frame_leaves_the_frame_where_it_was_planned() {
    // Two workers: a frame planned on the workers loses one before its
    // Simulate and is finished on the one left (posed, filled and drawn
    // there); the frames after are planned on the coordinator. No frame
    // fails, and each is the local one.
    let scene = Scene::from_toml_str(DANCE, std::path::Path::new("dance.toml")).unwrap();
    let want = local_frames(&scene, 6);
    for draw in [DrawAt::Auto, DrawAt::SortMiddle, DrawAt::SortLast] {
        let (a, _keep_a) = start_stoppable_worker();
        let (b, stop_b) = start_stoppable_worker();
        let addrs = [a.to_string(), b.to_string()];
        let remote = RemoteExecutor::connect(&addrs, &scene, &options(draw, 20)).unwrap();
        let timing = remote.timing();
        let mut seq = Sequence::new(&scene).unwrap();
        seq.set_executor(Box::new(StopsMidFrame {
            inner: remote,
            at: 2,
            planned: 0,
            armed: false,
            stop: Some(stop_b),
        }))
        .unwrap();
        seq.expect_frames(want.len() as u64);
        for (i, w) in want.iter().enumerate() {
            let (img, _) = seq.next_frame().unwrap();
            assert!(img == w, "{draw:?}: frame {i} differs from one process");
        }
        let t = *timing.lock().unwrap();
        assert_eq!(t.workers_lost, 1, "{draw:?}");
        // The frames after the loss on the coordinator, one worker left.
        assert!(t.frames[2] >= 2, "{draw:?}: {:?}", t.frames);
    }
}

#[test]
fn a_coordinator_with_no_worker_left_fails_naming_the_worker() {
    let scene = Scene::from_toml_str(DANCE, std::path::Path::new("dance.toml")).unwrap();
    let (a, stop) = start_stoppable_worker();
    let remote =
        RemoteExecutor::connect(&[a.to_string()], &scene, &options(DrawAt::SortLast, 5)).unwrap();
    let mut seq = Sequence::new(&scene).unwrap();
    seq.set_executor(Box::new(remote)).unwrap();
    seq.next_frame().unwrap();
    stop.send(()).unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let e = seq.next_frame().unwrap_err().to_string();
    assert!(e.contains(&a.to_string()), "{e}");
}

#[test]
fn malformed_assign_and_step_calls_get_an_error_and_the_worker_lives_on() {
    let addr = start_worker();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut c = greeted_client(addr).await;
        // Simulate before Assign.
        let e = c
            .simulate(pb::SimulateRequest::default())
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::FailedPrecondition, "{}", e.message());
        let assign = |toml: &str, first: u32, end: u32| pb::AssignChunk {
            scene_toml: toml.to_string(),
            scene_path: "dance.toml".into(),
            first_group: first,
            end_group: end,
            ..Default::default()
        };
        let bad = [
            (assign("[hair]\nstyle = \"wavy\"\n", 0, 1), "style"),
            (assign(DANCE, 0, 500), "groups 0..500"),
            (assign(DANCE, 0, 1), "no state for wisp 0"),
        ];
        for (chunk, says) in bad {
            let e = c.assign(tokio_stream::iter(vec![chunk])).await.unwrap_err();
            assert_eq!(e.code(), tonic::Code::InvalidArgument, "{}", e.message());
            assert!(e.message().contains(says), "{}", e.message());
        }
        // A good share of group 0: its wisps' rest state from the scene itself.
        let scene = Scene::from_toml_str(DANCE, std::path::Path::new("d")).unwrap();
        let anim = engine::Animator::new(&scene).unwrap();
        let wisps = anim.groups().wisp_range(0..1);
        let states = protocol::wisp_chunks(0, wisps.clone().map(|w| anim.wisp_state(w).unwrap()));
        let mut good = vec![assign(DANCE, 0, 1)];
        good.extend(states.into_iter().map(|s| pb::AssignChunk {
            state: Some(s),
            ..Default::default()
        }));
        let r = c
            .assign(tokio_stream::iter(good))
            .await
            .unwrap()
            .into_inner();
        assert_eq!(r.points_per_wisp as usize, anim.points_per_wisp());
        assert_eq!(r.first_wisp as usize..r.end_wisp as usize, wisps);
        let head = glam::Affine3A::IDENTITY.to_cols_array().to_vec();
        let pose = pb::PosePlan {
            version: 7,
            head: head.clone(),
            lights: vec![0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0],
            anchor: vec![0.0; 3],
            ..Default::default()
        };
        let step = pb::SimulateRequest {
            heads: head.clone(),
            body_counts: vec![0],
            pose: Some(pose.clone()),
            ..Default::default()
        };
        let bad_steps = [
            pb::SimulateRequest {
                heads: vec![f32::NAN; 12],
                ..step.clone()
            },
            pb::SimulateRequest {
                heads: vec![1.0; 11],
                ..step.clone()
            },
            pb::SimulateRequest {
                body_counts: vec![2],
                bodies: vec![0.0; 4],
                ..step.clone()
            },
            pb::SimulateRequest {
                body_counts: vec![1],
                bodies: vec![0.0, 0.0, 0.0, -1.0],
                ..step.clone()
            },
            pb::SimulateRequest {
                has_accel: true,
                accel_skip: vec![100_000],
                accel: vec![1.0, 0.0, 0.0],
                ..step.clone()
            },
            pb::SimulateRequest {
                has_accel: true,
                accel_skip: vec![0],
                accel: vec![f32::INFINITY, 0.0, 0.0],
                ..step.clone()
            },
            pb::SimulateRequest {
                pose: None,
                ..step.clone()
            },
            pb::SimulateRequest {
                pose: Some(pb::PosePlan {
                    lights: vec![0.0; 10],
                    ..pose.clone()
                }),
                ..step.clone()
            },
        ];
        for r in bad_steps {
            let e = c.simulate(r.clone()).await.unwrap_err();
            assert_eq!(
                e.code(),
                tonic::Code::InvalidArgument,
                "{r:?}: {}",
                e.message()
            );
        }
        // A good step, then a posed deposit of another version is refused.
        let mut s = c.simulate(step).await.unwrap().into_inner();
        let (mut got, mut report) = (0, None);
        while let Some(m) = s.message().await.unwrap() {
            got += m.pos.len();
            report = report.or(m.report);
        }
        assert_eq!(got, 3 * wisps.len() * anim.points_per_wisp());
        let report = protocol::report_from_pb(&report.unwrap(), 1).unwrap();
        assert!(!report.bounds.is_empty() && !report.extents[0].is_empty());
        let light = Light::directional(Vec3::NEG_Y).unwrap();
        let frame = LightFrame::centered(&light, Vec3::ZERO, 80.0, 8).unwrap();
        let posed = |version| pb::DensityChunk {
            map: Some(protocol::frame_to_pb(&frame)),
            posed: true,
            version,
            ..Default::default()
        };
        let e = c
            .density(tokio_stream::iter(vec![posed(6)]))
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::FailedPrecondition, "{}", e.message());
        let mut s = c
            .density(tokio_stream::iter(vec![posed(7)]))
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
fn workers_silent_or_unreachable_at_startup_are_left_out_and_the_run_carries_on() {
    let scene = Scene::from_toml_str(DANCE, std::path::Path::new("dance.toml")).unwrap();
    let want = local_frames(&scene, 3);
    // Accepts connections and never answers.
    let silent = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let silent_addr = silent.local_addr().unwrap();
    std::thread::spawn(move || {
        let mut held = Vec::new();
        for c in silent.incoming().flatten() {
            held.push(c);
        }
    });
    // Nothing listens here.
    let unreachable = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let addrs = vec![
        start_worker().to_string(),
        silent_addr.to_string(),
        unreachable.to_string(),
        start_worker().to_string(),
    ];
    let mut o = options(DrawAt::SortLast, 20);
    o.connect_timeout = Duration::from_secs(1);
    let t = std::time::Instant::now();
    let remote = RemoteExecutor::connect(&addrs, &scene, &o).unwrap();
    assert_eq!(remote.worker_count(), 2);
    assert!(t.elapsed() < Duration::from_secs(10), "{:?}", t.elapsed());
    let mut seq = Sequence::new(&scene).unwrap();
    seq.set_executor(Box::new(remote)).unwrap();
    seq.expect_frames(want.len() as u64);
    for (i, w) in want.iter().enumerate() {
        assert!(seq.next_frame().unwrap().0 == w, "frame {i}");
    }
    // None answering: the run fails, naming them.
    let none = [silent_addr.to_string(), unreachable.to_string()];
    let e = RemoteExecutor::connect(&none, &scene, &o)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(&silent_addr.to_string()) && e.contains(&unreachable.to_string()),
        "{e}"
    );
}

#[test]
fn one_worker_given_twice_is_refused() {
    let scene = Scene::default();
    let a = start_worker();
    let o = options(DrawAt::SortLast, 5);
    for twice in [
        vec![a.to_string(), a.to_string()],
        vec![a.to_string(), format!("localhost:{}", a.port())],
    ] {
        let e = RemoteExecutor::connect(&twice, &scene, &o)
            .unwrap_err()
            .to_string();
        assert!(e.contains("twice") || e.contains("same worker"), "{e}");
    }
}

/// Assigns the dance scene's first `groups` groups (all when `None`) to
/// `c`'s session, at rest: the share's guide points, the identity head
/// transform as floats, and a pose plan of version 1 with a light straight
/// down.
async fn assign_at_rest(
    c: &mut cluster::SessionClient,
    groups: Option<usize>,
) -> (usize, Vec<f32>, pb::PosePlan) {
    assign_at_rest_with_peers(c, groups, Vec::new()).await
}

/// [`assign_at_rest`], the session's workers being `peers`.
async fn assign_at_rest_with_peers(
    c: &mut cluster::SessionClient,
    groups: Option<usize>,
    peers: Vec<String>,
) -> (usize, Vec<f32>, pb::PosePlan) {
    let scene = Scene::from_toml_str(DANCE, std::path::Path::new("d")).unwrap();
    let anim = engine::Animator::new(&scene).unwrap();
    let groups = groups.unwrap_or_else(|| anim.groups().count());
    let wisps = anim.groups().wisp_range(0..groups);
    let points = wisps.len() * anim.points_per_wisp();
    let mut assign = vec![pb::AssignChunk {
        scene_toml: DANCE.to_string(),
        scene_path: "dance.toml".into(),
        first_group: 0,
        end_group: groups as u32,
        peers,
        ..Default::default()
    }];
    let states = protocol::wisp_chunks(0, wisps.map(|w| anim.wisp_state(w).unwrap()));
    assign.extend(states.into_iter().map(|s| pb::AssignChunk {
        state: Some(s),
        ..Default::default()
    }));
    c.assign(tokio_stream::iter(assign)).await.unwrap();
    let head = glam::Affine3A::IDENTITY.to_cols_array().to_vec();
    let pose = pb::PosePlan {
        version: 1,
        head: head.clone(),
        lights: vec![0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0],
        anchor: vec![0.0; 3],
        ..Default::default()
    };
    (points, head, pose)
}

#[test]
fn a_step_asking_more_work_than_the_cap_is_refused_before_any_step() {
    let addr = start_worker();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut c = greeted_client(addr).await;
        // The whole hair.
        let (points, head, pose) = assign_at_rest(&mut c, None).await;
        // Just past the cap: within MAX_STEPS, but too much work.
        let steps =
            (protocol::MAX_STEP_WORK / protocol::step_work(points as u64, 1, 0) + 1) as usize;
        assert!(
            steps <= protocol::MAX_STEPS,
            "{points} points: the cap is not what stops it"
        );
        let e = c
            .simulate(pb::SimulateRequest {
                heads: head.repeat(steps),
                body_counts: vec![0; steps],
                pose: Some(pose),
                ..Default::default()
            })
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::InvalidArgument, "{}", e.message());
        assert!(e.message().contains("MAX_STEP_WORK"), "{}", e.message());
    });
}

#[test]
fn a_step_past_its_deadline_stops_and_frees_the_worker_for_the_next_call() {
    let addr = start_worker();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut c = greeted_client(addr).await;
        // A share of group 0.
        let (_, head, pose) = assign_at_rest(&mut c, Some(1)).await;
        // The most steps a call may ask for: seconds of work, far past
        // this call's deadline.
        let steps = protocol::MAX_STEPS;
        let mut long = tonic::Request::new(pb::SimulateRequest {
            heads: head.repeat(steps),
            body_counts: vec![0; steps],
            pose: Some(pose.clone()),
            ..Default::default()
        });
        long.set_timeout(Duration::from_millis(300));
        assert!(c.simulate(long).await.is_err());
        // Served at once: had the steps gone on, this call's two seconds
        // would pass while they held the share.
        let mut next = tonic::Request::new(pose);
        next.set_timeout(Duration::from_secs(2));
        let r = c.pose(next).await;
        assert!(r.is_ok(), "{r:?}");
    });
}

#[test]
fn an_assign_past_the_limits_is_refused_saying_which() {
    let addr = start_worker();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut c = greeted_client(addr).await;
        // Scene text in pieces of 1 MiB, one byte past the limit in all.
        let text = "#".repeat(protocol::MAX_SCENE_TEXT + 1);
        let huge: Vec<pb::AssignChunk> = protocol::text_pieces(&text, protocol::TEXT_PIECE_BYTES)
            .map(|t| pb::AssignChunk {
                scene_toml: t.to_string(),
                scene_path: "big.toml".into(),
                end_group: 1,
                ..Default::default()
            })
            .collect();
        assert_eq!(huge.len(), 17);
        let e = c.assign(tokio_stream::iter(huge)).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::ResourceExhausted, "{}", e.message());
        assert!(e.message().contains("MAX_SCENE_TEXT"), "{}", e.message());
        // Data files: chunk after chunk, refused once past the limit.
        let first = pb::AssignChunk {
            scene_toml: DANCE.into(),
            scene_path: "dance.toml".into(),
            first_group: 0,
            end_group: 1,
            file_path: "groom.tfx".into(),
            ..Default::default()
        };
        let piece = pb::AssignChunk {
            file_data: vec![7; 8 << 20],
            ..Default::default()
        };
        let n = protocol::MAX_FILE_BYTES / (8 << 20) + 1;
        let chunks = std::iter::once(first).chain(std::iter::repeat_n(piece, n));
        let e = c.assign(tokio_stream::iter(chunks)).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::ResourceExhausted, "{}", e.message());
        assert!(e.message().contains("MAX_FILE_BYTES"), "{}", e.message());
        // The worker lives on.
        let ok = c
            .simulate(pb::SimulateRequest::default())
            .await
            .unwrap_err();
        assert_eq!(
            ok.code(),
            tonic::Code::FailedPrecondition,
            "{}",
            ok.message()
        );
    });
}

/// A Density call of `strands` two-point strands across a map of `cells` a
/// side and out beyond it on both sides: each cut into `4 * cells` pieces,
/// the most a segment is.
fn crossing_deposit(cells: u32, strands: usize) -> Vec<pb::DensityChunk> {
    let light = Light::directional(Vec3::X).unwrap();
    let frame = LightFrame::centered(&light, Vec3::ZERO, 2.0, cells).unwrap();
    let mut hair = strands::Hair::new();
    for s in 0..strands {
        let t = s as f32 / strands as f32 * 1.8 - 0.9;
        hair.push_strand(&[Vec3::new(-4.0, t, -0.9), Vec3::new(4.0, -t, 0.9)])
            .unwrap();
    }
    protocol::density_chunks(1, 0, &frame, &hair, 0..strands)
}

#[test]
fn a_deposit_past_its_deadline_stops_and_gives_its_memory_back() {
    // Room for one map of 256^3 cells (64 MiB) and the strands below.
    let map = shadow::DensityMap::bytes_for(256);
    let limits = cluster::SessionLimits {
        max_memory: map + (40 << 20),
        ..Default::default()
    };
    let service = cluster::WorkerService::new(limits);
    let (addr, _stop) = common::start_service(service, cluster::Listen::default());
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut c = greeted_client(addr).await;
        // 300,000 strands of 1024 pieces: about 5 s of work here, far past this
        // call's deadline.
        let mut long = tonic::Request::new(tokio_stream::iter(crossing_deposit(256, 300_000)));
        long.set_timeout(Duration::from_millis(500));
        let t = std::time::Instant::now();
        assert!(c.density(long).await.is_err());
        let sent = t.elapsed();
        // The next map fits only once the first is given back: at once,
        // had the deposit stopped; seconds later otherwise.
        let mut next = tonic::Request::new(tokio_stream::iter(crossing_deposit(256, 10)));
        next.set_timeout(Duration::from_secs(2));
        let r = c.density(next).await;
        assert!(r.is_ok(), "{r:?} (the first call took {sent:?})");
        // Received strands past the budget are refused, saying which limit.
        let e = c
            .density(tokio_stream::iter(crossing_deposit(8, 5_000_000)))
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::ResourceExhausted, "{}", e.message());
        assert!(e.message().contains("--max-memory-mib"), "{}", e.message());
        // A map larger than the whole budget is refused, not waited for.
        let e = c
            .density(tokio_stream::iter(crossing_deposit(512, 1)))
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::ResourceExhausted, "{}", e.message());
        assert!(e.message().contains("512^3"), "{}", e.message());
    });
}

/// Workers whose picture left to finish at the first frame drawn ahead
/// from hair version `at` on is given up as failed (once its real bands
/// came): the coordinator draws that frame again after the next frame's
/// stages ran.
#[derive(Debug)]
struct GivesUp {
    inner: RemoteExecutor,
    at: u64,
    gave_up: Arc<AtomicBool>,
}

impl Executor for GivesUp {
    forward_to_inner!();
    fn simulate(
        &mut self,
        anim: &mut engine::Animator,
        plan: &engine::StepPlan,
        stats: &mut engine::FrameStats,
    ) -> Result<Option<engine::PoseReport>, EngineError> {
        self.inner.simulate(anim, plan, stats)
    }
    fn plan_frame(&mut self, needs: engine::FrameNeeds) -> engine::Site {
        self.inner.plan_frame(needs)
    }
    fn drawing(&mut self) -> Option<&mut dyn Drawing> {
        Some(self)
    }
}

impl Drawing for GivesUp {
    fn composites(&self) -> bool {
        Drawing::composites(&self.inner)
    }
    fn pose(&mut self, plan: &engine::PosePlan) -> Result<engine::PoseReport, EngineError> {
        Drawing::pose(&mut self.inner, plan)
    }
    fn draw(&mut self, job: &engine::DrawJob) -> Result<engine::DrawReport, EngineError> {
        Drawing::draw(&mut self.inner, job)
    }
    fn draw_ahead(&mut self, job: &engine::DrawJob) -> Result<engine::DrawReport, EngineError> {
        let mut r = self.inner.draw_ahead(job)?;
        if job.version >= self.at && !self.gave_up.load(Ordering::Relaxed) {
            let engine::Drawn::Pending(real) = std::mem::take(&mut r.drawn) else {
                panic!("composited on the workers");
            };
            real.wait()?;
            self.gave_up.store(true, Ordering::Relaxed);
            r.drawn = engine::Drawn::Pending(engine::PendingPicture::new(|| {
                Err(EngineError::executor("given up"))
            }));
        }
        Ok(r)
    }
    fn redraw(&mut self, job: &engine::DrawJob) -> Result<engine::DrawReport, EngineError> {
        self.inner.redraw(job)
    }
}

#[test]
fn a_picture_given_up_after_the_next_frames_stages_is_drawn_again_with_the_same_bytes() {
    let scene = Scene::from_toml_str(DANCE, std::path::Path::new("dance.toml")).unwrap();
    let want = local_frames(&scene, 5);
    let addrs: Vec<String> = (0..3).map(|_| start_worker().to_string()).collect();
    let remote = RemoteExecutor::connect(&addrs, &scene, &options(DrawAt::SortLast, 20)).unwrap();
    let timing = remote.timing();
    let gave_up = Arc::new(AtomicBool::new(false));
    let mut seq = Sequence::new(&scene).unwrap();
    seq.set_executor(Box::new(GivesUp {
        inner: remote,
        at: 3,
        gave_up: gave_up.clone(),
    }))
    .unwrap();
    seq.expect_frames(want.len() as u64);
    for (i, w) in want.iter().enumerate() {
        let (img, _) = seq.next_frame().unwrap();
        assert!(img == w, "frame {i} differs from one process");
    }
    assert!(gave_up.load(Ordering::Relaxed), "a picture was given up");
    let t = *timing.lock().unwrap();
    assert_eq!((t.workers_lost, t.composite_fallbacks), (0, 0), "{t:?}");
}

#[test]
fn a_physically_based_fiber_draws_the_same_bytes_on_workers() {
    // The fiber's settings travel with the draw job (protocol 12), with
    // multiple scattering and without.
    let addrs: Vec<String> = (0..2).map(|_| start_worker().to_string()).collect();
    let fiber =
        format!("{DANCE}\n[shading]\nmodel = \"marschner\"\neumelanin = 0.6\nbeta_n = 0.4\n");
    let mut firsts = Vec::new();
    for text in [
        fiber.clone(),
        format!("{fiber}[effects]\nmultiple_scattering = true\n"),
    ] {
        let scene = Scene::from_toml_str(&text, std::path::Path::new("fiber.toml")).unwrap();
        let want = local_frames(&scene, 2);
        let remote =
            RemoteExecutor::connect(&addrs, &scene, &options(DrawAt::SortLast, 20)).unwrap();
        let mut seq = Sequence::new(&scene).unwrap();
        seq.set_executor(Box::new(remote)).unwrap();
        seq.expect_frames(want.len() as u64);
        for (i, w) in want.iter().enumerate() {
            assert!(seq.next_frame().unwrap().0 == w, "{text}: frame {i}");
        }
        firsts.push(want[0].clone());
    }
    // With multiple scattering the head lights the hair (a sphere, and a
    // mesh whose surface the workers find as one process does), from
    // the maps the workers hold: the same bytes with every scheme.
    let mesh = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/head.obj");
    for head in [
        String::new(),
        format!(
            "[head]\nmesh = {:?}\ncolor = [0.7, 0.3, 0.2]\n",
            mesh.display().to_string()
        ),
    ] {
        let text = format!("{fiber}[effects]\nmultiple_scattering = true\n{head}");
        let mut scene = Scene::from_toml_str(&text, std::path::Path::new("fiber.toml")).unwrap();
        scene.read_data_files().unwrap();
        let want = local_frames(&scene, 2);
        for draw in [DrawAt::SortMiddle, DrawAt::SortLast, DrawAt::Coordinator] {
            let remote = RemoteExecutor::connect(&addrs, &scene, &options(draw, 20)).unwrap();
            assert_frames(&scene, remote, &want);
        }
    }
    // Multiple scattering changes the picture; the fiber differs from
    // Kajiya-Kay's.
    assert!(firsts[0] != firsts[1]);
    let kk = Scene::from_toml_str(DANCE, std::path::Path::new("kk.toml")).unwrap();
    assert!(local_frames(&kk, 1)[0] != firsts[0]);
}

#[test]
fn point_and_spot_lights_draw_the_same_bytes_on_workers() {
    // The lights and their maps' partition from the source travel with
    // the pose plan, the deposits and the draw job (protocol 12); the
    // workers sum and sweep the fans among themselves.
    let text = format!(
        "{DANCE}\n[[light]]\nposition = [25, 30, 20]\n\
         [[light]]\nposition = [-20, 35, 25]\ndirection = [0.5, -0.8, -0.4]\ncone_deg = 25\nfalloff_deg = 6\n"
    );
    let scene = Scene::from_toml_str(&text, std::path::Path::new("point.toml")).unwrap();
    let want = local_frames(&scene, 2);
    let addrs: Vec<String> = (0..3).map(|_| start_worker().to_string()).collect();
    let remote = RemoteExecutor::connect(&addrs, &scene, &options(DrawAt::SortLast, 20)).unwrap();
    let timing = remote.timing();
    let mut seq = Sequence::new(&scene).unwrap();
    seq.set_executor(Box::new(remote)).unwrap();
    seq.expect_frames(want.len() as u64);
    for (i, w) in want.iter().enumerate() {
        assert!(seq.next_frame().unwrap().0 == w, "frame {i}");
    }
    let t = *timing.lock().unwrap();
    assert_eq!((t.workers_lost, t.exchange_fallbacks), (0, 0), "{t:?}");
    // And the lights matter: the directional default draws otherwise.
    let sun = Scene::from_toml_str(DANCE, std::path::Path::new("sun.toml")).unwrap();
    assert!(local_frames(&sun, 1)[0] != want[0]);
}

/// A Density round of hair version 1 in a map of a light straight down,
/// its columns cut in two between worker 0 and `peers[1]`, waiting 500 ms.
fn two_worker_round(peers: Vec<String>) -> pb::DensityChunk {
    let light = Light::directional(Vec3::NEG_Y).unwrap();
    let frame = LightFrame::centered(&light, Vec3::ZERO, 80.0, 8).unwrap();
    let columns = frame.columns() as u32;
    pb::DensityChunk {
        map: Some(protocol::frame_to_pb(&frame)),
        posed: true,
        version: 1,
        columns: Some(pb::ColumnPlan {
            round: 1,
            cuts: vec![0, columns / 2, columns],
            own: 0,
            peers,
            sessions: vec!["a".repeat(32), "b".repeat(32)],
            wait_ms: 500,
            ..Default::default()
        }),
        ..Default::default()
    }
}

/// Every byte each connection to a listener sent in its first `secs`
/// seconds: the listener accepts and reads, and never answers.
fn recording_listener(secs: u64) -> (String, std::thread::JoinHandle<Vec<Vec<u8>>>) {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap().to_string();
    l.set_nonblocking(true).unwrap();
    let seen = std::thread::spawn(move || {
        use std::io::Read;
        let until = std::time::Instant::now() + Duration::from_secs(secs);
        let mut conns: Vec<(std::net::TcpStream, Vec<u8>)> = Vec::new();
        while std::time::Instant::now() < until {
            if let Ok((s, _)) = l.accept() {
                s.set_read_timeout(Some(Duration::from_millis(10))).unwrap();
                conns.push((s, Vec::new()));
            }
            for (s, got) in &mut conns {
                let mut buf = [0u8; 65536];
                if let Ok(n) = s.read(&mut buf) {
                    got.extend_from_slice(&buf[..n]);
                }
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        conns.into_iter().map(|(_, got)| got).collect()
    });
    (addr, seen)
}

#[test]
fn a_listener_named_as_a_peer_sees_no_hair_and_no_token() {
    // A listener that is no worker is named as a peer by the session's
    // own Assign (so the plan passes the session's check). Before the
    // worker sends it anything it asks it to prove it belongs to the
    // cluster (Prove): the listener sees that question alone, a few
    // hundred bytes with neither the token nor any hair. Sending the
    // round's density straight away would show it some 64 KiB of it (the
    // HTTP/2 window), as this map's half of the columns holds more.
    //
    // With mutual TLS the listener holds a certificate of the cluster's
    // CA for the address dialled, but not a worker's (it does not name
    // `wisplight-worker`): the worker ends the handshake, and the
    // listener reads not one byte of a call.
    const TOKEN: &str = "peer-test-token-0123456789";
    let ca = common::TestCa::new();
    use rcgen::ExtendedKeyUsagePurpose::{ClientAuth, ServerAuth};
    let worker = ca.leaf(
        &["127.0.0.1", "localhost", cluster::WORKER_NAME],
        &[ServerAuth, ClientAuth],
    );
    let coordinator = ca.leaf(&[cluster::COORDINATOR_NAME], &[ClientAuth]);
    let stranger = ca.leaf(&["127.0.0.1", "localhost"], &[ServerAuth]);
    for (token, tls) in [(None, false), (Some(TOKEN), false), (None, true)] {
        let case = format!("token {token:?}, TLS {tls}");
        let (addr, _stop) = common::start_worker_with(cluster::Listen {
            token: token.map(|t| cluster::Token::new(t).unwrap()),
            tls: tls.then(|| ca.tls(&worker)),
            ..cluster::Listen::default()
        });
        let (stray, seen) = if tls {
            let (stray, seen) = common::recording_tls_listener(3, &stranger.0, &stranger.1);
            (
                stray,
                std::thread::spawn(move || vec![seen.join().unwrap()]),
            )
        } else {
            let (stray, seen) = recording_listener(3);
            let seen = std::thread::spawn(move || {
                let conns = seen.join().unwrap();
                vec![(conns.len(), conns.concat())]
            });
            (stray, seen)
        };
        let rt = tokio::runtime::Runtime::new().unwrap();
        let e = rt.block_on(async {
            let mut c = match token {
                Some(t) => common::proved_client(addr, t).await,
                None if tls => {
                    common::greeted_tls_client(addr, &ca.pem, (&coordinator.0, &coordinator.1))
                        .await
                }
                None => greeted_client(addr).await,
            };
            let peers = vec![addr.to_string(), stray.clone()];
            let (_, _, pose) = assign_at_rest_with_peers(&mut c, None, peers.clone()).await;
            c.pose(pose).await.unwrap();
            // A map fitted to the hair, 64 cells a side.
            let scene = Scene::from_toml_str(DANCE, std::path::Path::new("d")).unwrap();
            let hair = engine::Animator::new(&scene).unwrap();
            let b = hair.hair().bounds();
            let light = Light::directional(Vec3::NEG_Y).unwrap();
            let size = (b.max - b.min).max_element() * 1.2;
            let frame = LightFrame::centered(&light, (b.min + b.max) / 2.0, size, 64).unwrap();
            let mut round = two_worker_round(peers);
            round.map = Some(protocol::frame_to_pb(&frame));
            let columns = frame.columns() as u32;
            if let Some(p) = &mut round.columns {
                p.cuts = vec![0, columns / 2, columns];
            }
            match c.density(tokio_stream::iter(vec![round])).await {
                Ok(r) => {
                    let mut s = r.into_inner();
                    loop {
                        match s.message().await {
                            Ok(Some(_)) => continue,
                            Ok(None) => break "the round ended".to_string(),
                            Err(e) => break e.message().to_string(),
                        }
                    }
                }
                Err(e) => e.message().to_string(),
            }
        });
        assert!(e.contains("took no part"), "{case}: {e}");
        let (conns, all) = seen.join().unwrap().remove(0);
        assert!(conns > 0, "{case}: the worker dialled the listener");
        if tls {
            // The handshake failed on the worker's side: nothing of a
            // call, not even HTTP/2's preface, reached the listener.
            assert!(all.is_empty(), "{case}: the listener read {all:?}");
        } else {
            assert!(
                !all.is_empty(),
                "{case}: the worker asked the listener to prove itself"
            );
            assert!(
                all.len() < 2048,
                "{case}: the listener saw {} bytes",
                all.len()
            );
        }
        assert!(
            !all.windows(TOKEN.len()).any(|w| w == TOKEN.as_bytes()),
            "{case}: the token crossed the wire"
        );
    }
}

#[test]
fn a_plan_naming_a_worker_outside_the_session_is_refused_and_never_dialled() {
    // The stray address: a listener that would see any connection.
    let stray = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    stray.set_nonblocking(true).unwrap();
    let stray_addr = stray.local_addr().unwrap().to_string();
    // A second worker, which the session does name.
    let addr = start_worker();
    let other = start_worker().to_string();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut c = greeted_client(addr).await;
        let peers = vec![addr.to_string(), other.clone()];
        let (_, _, pose) = assign_at_rest_with_peers(&mut c, None, peers).await;
        c.pose(pose).await.unwrap();
        let round = |peer: &str| two_worker_round(vec![addr.to_string(), peer.to_string()]);
        let refused = |r: Result<_, tonic::Status>| match r {
            Err(e) => e,
            Ok(_) => panic!("a plan naming {stray_addr} was taken"),
        };
        let e = refused(
            c.density(tokio_stream::iter(vec![round(&stray_addr)]))
                .await,
        );
        assert_eq!(e.code(), tonic::Code::InvalidArgument, "{}", e.message());
        assert!(e.message().contains("peer 1"), "{}", e.message());
        // The refusal says nothing of the address or whether it listens.
        let port = stray_addr.rsplit(':').next().unwrap();
        assert!(!e.message().contains(port), "{}", e.message());
        // A closed port gets the same answer.
        let closed = {
            let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
            l.local_addr().unwrap().to_string()
        };
        let e2 = refused(c.density(tokio_stream::iter(vec![round(&closed)])).await);
        assert_eq!(
            (e2.code(), e2.message().replace(&closed, "")),
            (e.code(), e.message().to_string())
        );
    });
    // Nothing ever connected to the stray listener.
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!(
        stray.accept().map(|_| ()).map_err(|e| e.kind()),
        Err(std::io::ErrorKind::WouldBlock)
    );
}

#[test]
fn a_draw_of_another_size_than_the_sessions_scene_is_refused_before_anything_is_kept() {
    let addr = start_worker();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let scene = Scene::from_toml_str(DANCE, std::path::Path::new("dance.toml")).unwrap();
        let anim = engine::Animator::new(&scene).unwrap();
        let mut r = engine::Renderer::new(&scene).unwrap();
        r.frame_on(anim.hair().bounds()).unwrap();
        let job = r.draw_job(1, false).unwrap();
        let (w, h) = (scene.render.width, scene.render.height);
        let sized = |width: u32, height: u32| {
            let c = &job.camera;
            let mut j = job.clone();
            j.camera =
                raster::Camera::new(c.position, c.look_at(), c.fov_deg(), width, height).unwrap();
            vec![pb::DrawChunk {
                job: Some(protocol::job_to_pb(&j)),
                ..Default::default()
            }]
        };
        let mut c = greeted_client(addr).await;
        // Before any Assign: no scene, no size.
        let e = match c.draw(tokio_stream::iter(sized(w, h))).await {
            Err(e) => e,
            Ok(_) => panic!("a Draw before any Assign was taken"),
        };
        assert_eq!(e.code(), tonic::Code::FailedPrecondition, "{}", e.message());
        let (_, _, pose) = assign_at_rest(&mut c, None).await;
        c.pose(pose).await.unwrap();
        // The largest picture the protocol allows, for a scene of 96x64.
        let e = match c.draw(tokio_stream::iter(sized(6324, 6324))).await {
            Err(e) => e,
            Ok(_) => panic!("a Draw of another size was taken"),
        };
        assert_eq!(e.code(), tonic::Code::InvalidArgument, "{}", e.message());
        assert!(
            e.message()
                .contains(&format!("6324x6324 picture for a scene of {w}x{h}")),
            "{}",
            e.message()
        );
        // The scene's own size is drawn.
        let drawn = c.draw(tokio_stream::iter(sized(w, h))).await;
        assert!(drawn.is_ok(), "{:?}", drawn.err());
    });
}

#[test]
fn the_peers_of_a_refused_assign_are_not_kept_nor_those_before_it() {
    // The stray address: a listener that would see any connection.
    let stray = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    stray.set_nonblocking(true).unwrap();
    let stray_addr = stray.local_addr().unwrap().to_string();
    let addr = start_worker();
    let other = start_worker().to_string();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut c = greeted_client(addr).await;
        let peers = vec![addr.to_string(), other.clone()];
        let (_, _, pose) = assign_at_rest_with_peers(&mut c, None, peers).await;
        c.pose(pose).await.unwrap();
        // An Assign naming the stray peer, refused on its second chunk
        // (file data before any file's path): the share stays.
        let refused = c
            .assign(tokio_stream::iter(vec![
                pb::AssignChunk {
                    scene_toml: DANCE.to_string(),
                    scene_path: "dance.toml".into(),
                    first_group: 0,
                    end_group: 6,
                    peers: vec![addr.to_string(), stray_addr.clone()],
                    ..Default::default()
                },
                pb::AssignChunk {
                    file_data: vec![1, 2, 3],
                    ..Default::default()
                },
            ]))
            .await;
        assert_eq!(refused.unwrap_err().code(), tonic::Code::InvalidArgument);
        // A plan naming either peer is refused now, and none is dialled.
        for peer in [&stray_addr, &other] {
            let plan = two_worker_round(vec![addr.to_string(), peer.clone()]);
            let e = match c.density(tokio_stream::iter(vec![plan])).await {
                Err(e) => e,
                Ok(_) => panic!("a plan naming {peer} was taken"),
            };
            assert_eq!(
                e.code(),
                tonic::Code::InvalidArgument,
                "{peer}: {}",
                e.message()
            );
            assert!(e.message().contains("peer 1"), "{peer}: {}", e.message());
        }
    });
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!(
        stray.accept().map(|_| ()).map_err(|e| e.kind()),
        Err(std::io::ErrorKind::WouldBlock),
        "the stray peer was dialled"
    );
}

#[test]
fn a_failed_dial_answers_one_message_whatever_the_cause() {
    // Three peers that are not workers: a closed port, a listener that
    // stays silent, and an HTTP/1.1 server.
    let closed = {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        l.local_addr().unwrap().to_string()
    };
    let silent = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let http = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let http_addr = http.local_addr().unwrap().to_string();
    std::thread::spawn(move || {
        use std::io::{Read, Write};
        for s in http.incoming().flatten() {
            let mut s = s;
            let mut buf = [0u8; 1024];
            let _ = s.read(&mut buf);
            let _ = s.write_all(b"HTTP/1.1 404 Not Found\r\ncontent-length: 0\r\n\r\n");
        }
    });
    let strays = [closed, silent.local_addr().unwrap().to_string(), http_addr];
    let addr = start_worker();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let answers: Vec<(tonic::Code, String)> = strays
        .iter()
        .map(|stray| {
            rt.block_on(async {
                let mut c = greeted_client(addr).await;
                let peers = vec![addr.to_string(), stray.clone()];
                let (_, _, pose) = assign_at_rest_with_peers(&mut c, None, peers.clone()).await;
                c.pose(pose).await.unwrap();
                let plan = two_worker_round(peers);
                let e = match c.density(tokio_stream::iter(vec![plan])).await {
                    Err(e) => e,
                    Ok(r) => match r.into_inner().message().await {
                        Err(e) => e,
                        Ok(m) => {
                            panic!("{stray}: a round with a peer that is no worker gave {m:?}")
                        }
                    },
                };
                (e.code(), e.message().to_string())
            })
        })
        .collect();
    for (stray, a) in strays.iter().zip(&answers) {
        assert_eq!(
            *a, answers[0],
            "{stray} answered otherwise than {}",
            strays[0]
        );
        assert!(
            !a.1.contains(stray.rsplit(':').next().unwrap()),
            "{stray}: {a:?}"
        );
    }
    assert_eq!(answers[0].1, "worker 1 of the round took no part in it");
}
