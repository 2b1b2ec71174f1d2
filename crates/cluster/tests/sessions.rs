//! Sessions: several coordinators share workers and each gets exactly its
//! own pictures; a stray client changes nothing; calls that name no open
//! session are refused; a worker holds a bounded number of sessions and
//! ends idle ones.

mod common;

use std::net::SocketAddr;
use std::time::Duration;

use cluster::pb::worker_client::WorkerClient;
use cluster::{ClusterError, DrawAt, Options, RemoteExecutor, WorkerErrorKind, pb, protocol};
use cluster::{Listen, SessionLimits, WorkerService};
use engine::{Scene, Sequence};

use common::{DANCE, local_frames};

/// Another scene on the same workers: other hair, another fiber.
const CURLY: &str = r#"
[hair]
style = "curly"
strands_per_wisp = 3

[fiber]
width = 0.2
opacity = 0.6

[render]
width = 120
height = 80

[shadow]
cells = 48

[animation]
motion = "dance"

[dynamics]
settle = 0.1
"#;

fn scene(text: &str) -> Scene {
    Scene::from_toml_str(text, std::path::Path::new("s.toml")).unwrap()
}

fn on_workers(scene: &Scene, addrs: &[String]) -> Sequence {
    let options = Options {
        deadline: Duration::from_secs(20),
        connect_timeout: Duration::from_secs(5),
        tls: None,
        token: None,
        draw: DrawAt::SortLast,
    };
    let remote = RemoteExecutor::connect(addrs, scene, &options).unwrap();
    let mut seq = Sequence::new(scene).unwrap();
    seq.set_executor(Box::new(remote)).unwrap();
    seq
}

fn hello(fiber_width: f32) -> pb::HelloRequest {
    pb::HelloRequest {
        protocol_version: protocol::PROTOCOL_VERSION,
        fiber_width,
        fiber_opacity: 0.5,
        ..Default::default()
    }
}

/// A small map frame.
fn frame() -> shadow::LightFrame {
    let light = shadow::Light::directional(glam::Vec3::new(0.3, -0.9, 0.1)).unwrap();
    shadow::LightFrame::centered(&light, glam::Vec3::ZERO, 8.0, 16).unwrap()
}

async fn client(addr: SocketAddr) -> WorkerClient<tonic::transport::Channel> {
    WorkerClient::connect(format!("http://{addr}"))
        .await
        .unwrap()
}

#[test]
fn two_coordinators_on_the_same_workers_each_get_their_own_pictures() {
    let (a, b) = (scene(DANCE), scene(CURLY));
    let (want_a, want_b) = (local_frames(&a, 4), local_frames(&b, 4));
    assert!(
        want_a[3] != want_a[1] && want_b[3] != want_b[1],
        "the hair moves"
    );
    let addrs: Vec<String> = (0..3)
        .map(|_| common::start_worker_with(Listen::default()).0.to_string())
        .collect();
    let mut seq_a = on_workers(&a, &addrs);
    let mut seq_b = on_workers(&b, &addrs[1..]);
    seq_a.expect_frames(4);
    seq_b.expect_frames(4);
    // Frames interleaved, call after call on the shared workers.
    for f in 0..4 {
        assert!(seq_a.next_frame().unwrap().0 == &want_a[f], "A's frame {f}");
        assert!(seq_b.next_frame().unwrap().0 == &want_b[f], "B's frame {f}");
    }
}

#[test]
fn a_stray_hello_mid_render_changes_nothing() {
    let a = scene(DANCE);
    let want = local_frames(&a, 4);
    let (addr, _stop) = common::start_worker_with(Listen::default());
    let mut seq = on_workers(&a, &[addr.to_string()]);
    seq.expect_frames(want.len() as u64);
    let rt = tokio::runtime::Runtime::new().unwrap();
    for (f, w) in want.iter().enumerate() {
        if f == 1 {
            // Another client, another fiber: its own session.
            let r = rt
                .block_on(async { client(addr).await.hello(hello(3.0)).await })
                .unwrap();
            assert_eq!(r.into_inner().session.len(), 32);
        }
        assert!(seq.next_frame().unwrap().0 == w, "frame {f}");
    }
}

#[test]
fn calls_naming_no_open_session_are_refused_and_change_nothing() {
    let (addr, _stop) = common::start_worker_with(Listen::default());
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let channel = tonic::transport::Endpoint::from_shared(format!("http://{addr}"))
            .unwrap()
            .connect()
            .await
            .unwrap();
        let id = WorkerClient::new(channel.clone())
            .hello(hello(0.1))
            .await
            .unwrap()
            .into_inner()
            .session;
        let named = |id: &str| {
            WorkerClient::with_interceptor(
                channel.clone(),
                cluster::SessionHeader::new(id).unwrap(),
            )
        };
        // An open session is served (a Simulate call before Assign: refused for
        // that reason, not for the session).
        let e = named(&id)
            .simulate(pb::SimulateRequest::default())
            .await
            .unwrap_err();
        assert!(e.message().contains("Assign"), "{}", e.message());
        // No session, a made-up one, a guessed prefix.
        let e = client(addr)
            .await
            .simulate(pb::SimulateRequest::default())
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::FailedPrecondition);
        assert!(e.message().contains("names no session"), "{}", e.message());
        for other in ["0123456789abcdef0123456789abcdef", &id[..16]] {
            let e = named(other)
                .simulate(pb::SimulateRequest::default())
                .await
                .unwrap_err();
            assert_eq!(e.code(), tonic::Code::FailedPrecondition);
            assert!(e.message().contains("not open"), "{}", e.message());
        }
        // Another worker's stripes: refused without the session, and as
        // an absurd picture within it; taken when well formed.
        let stripes = |w: u32, h: u32| {
            tokio_stream::iter(vec![pb::LayerChunk {
                width: w,
                height: h,
                round: 1,
                from: 1,
                ..Default::default()
            }])
        };
        let e = client(addr)
            .await
            .composite(stripes(8, 8))
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::FailedPrecondition);
        let e = named(&id)
            .composite(stripes(100_000, 100_000))
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::InvalidArgument);
        assert!(e.message().contains("pixels"), "{}", e.message());
        named(&id).composite(stripes(8, 8)).await.unwrap();
        // The same worker's stripes of the same round again: refused.
        let e = named(&id).composite(stripes(8, 8)).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::InvalidArgument);
        assert!(e.message().contains("twice"), "{}", e.message());
        // Another worker's columns: refused without the session, from an
        // absurd worker, or carrying what the call does not; taken once
        // when well formed.
        let columns = |from: u32, swept: bool, density: bool| {
            tokio_stream::iter(vec![pb::ExchangeChunk {
                round: 3,
                from,
                swept,
                map: (!swept).then(|| protocol::frame_to_pb(&frame())),
                density: density.then(pb::ColumnChunk::default),
                ..Default::default()
            }])
        };
        let e = client(addr)
            .await
            .exchange(columns(1, false, true))
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::FailedPrecondition);
        let e = named(&id)
            .exchange(columns(100_000, false, true))
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::InvalidArgument);
        assert!(e.message().contains("worker 100000"), "{}", e.message());
        let e = named(&id)
            .exchange(columns(1, true, true))
            .await
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::InvalidArgument);
        assert!(e.message().contains("does not"), "{}", e.message());
        named(&id).exchange(columns(1, false, true)).await.unwrap();
        let e = named(&id)
            .exchange(columns(1, false, true))
            .await
            .unwrap_err();
        assert!(e.message().contains("twice"), "{}", e.message());
        // Ended: refused from then on, the End itself too.
        named(&id).end(pb::EndRequest {}).await.unwrap();
        for _ in 0..2 {
            let e = named(&id).end(pb::EndRequest {}).await.unwrap_err();
            assert_eq!(e.code(), tonic::Code::FailedPrecondition);
        }
        let e = named(&id)
            .simulate(pb::SimulateRequest::default())
            .await
            .unwrap_err();
        assert!(e.message().contains("not open"), "{}", e.message());
    });
}

#[test]
fn a_worker_holds_at_most_its_sessions_and_ends_idle_ones() {
    let limits = SessionLimits {
        max_sessions: 2,
        idle: Duration::from_millis(400),
        ..SessionLimits::default()
    };
    let (addr, _stop) = common::start_service(WorkerService::new(limits), Listen::default());
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut c = client(addr).await;
        let first = c.hello(hello(0.1)).await.unwrap().into_inner().session;
        let second = c.hello(hello(0.1)).await.unwrap().into_inner().session;
        assert_ne!(first, second);
        // A fiber that is not physical opens nothing.
        for width in [-1.0, f32::NAN, f32::INFINITY] {
            let e = c.hello(hello(width)).await.unwrap_err();
            assert_eq!(e.code(), tonic::Code::InvalidArgument, "{width}");
        }
        let e = c.hello(hello(0.1)).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::ResourceExhausted);
        assert!(e.message().contains("--max-sessions"), "{}", e.message());
        // A coordinator refused this way says which limit.
        let refused = tokio::task::spawn_blocking(move || {
            RemoteExecutor::connect(
                &[addr.to_string()],
                &scene(DANCE),
                &Options {
                    deadline: Duration::from_secs(5),
                    connect_timeout: Duration::from_secs(5),
                    tls: None,
                    token: None,
                    draw: DrawAt::SortLast,
                },
            )
            .unwrap_err()
            .to_string()
        })
        .await
        .unwrap();
        assert!(refused.contains("--max-sessions"), "{refused}");
        // Beside a worker with room, a full one is left out and the run
        // goes on over the other, as for a worker that does not answer.
        let (free, _stop_free) = common::start_worker_with(Listen::default());
        let pictures = tokio::task::spawn_blocking(move || {
            let s = scene(DANCE);
            let mut seq = on_workers(&s, &[addr.to_string(), free.to_string()]);
            seq.expect_frames(2);
            let mine: Vec<_> = (0..2)
                .map(|_| seq.next_frame().unwrap().0.clone())
                .collect();
            (mine, local_frames(&s, 2))
        })
        .await
        .unwrap();
        assert!(
            pictures.0 == pictures.1,
            "the pictures differ from one process's"
        );
        // Unused, both end; new ones open.
        tokio::time::sleep(Duration::from_millis(900)).await;
        let named = WorkerClient::with_interceptor(
            tonic::transport::Endpoint::from_shared(format!("http://{addr}"))
                .unwrap()
                .connect()
                .await
                .unwrap(),
            cluster::SessionHeader::new(&first).unwrap(),
        )
        .simulate(pb::SimulateRequest::default())
        .await
        .unwrap_err();
        // Said as expired, with why, and marked for the coordinator.
        assert_eq!(named.code(), tonic::Code::FailedPrecondition);
        assert!(
            named.message().contains("expired on this worker")
                && named.message().contains("--session-idle"),
            "{}",
            named.message()
        );
        assert!(cluster::WorkerError::from(named).expired);
        c.hello(hello(0.1)).await.unwrap();
        c.hello(hello(0.1)).await.unwrap();
    });
}

#[test]
fn a_coordinator_stalled_past_the_idle_limit_says_its_session_expired_and_drops_no_worker() {
    let limits = SessionLimits {
        idle: Duration::from_millis(400),
        ..SessionLimits::default()
    };
    let a = common::start_service(WorkerService::new(limits), Listen::default());
    let b = common::start_service(WorkerService::new(limits), Listen::default());
    let s = scene(DANCE);
    let mut seq = on_workers(&s, &[a.0.to_string(), b.0.to_string()]);
    seq.next_frame().unwrap();
    // The coordinator stalls (stopped, a laptop asleep): both sessions end.
    std::thread::sleep(Duration::from_millis(1200));
    let e = seq.next_frame().unwrap_err().to_string();
    assert!(
        e.contains("ended this coordinator's session")
            && e.contains("expired on this worker")
            && e.contains("--session-idle"),
        "{e}"
    );
    assert!(!e.contains("lost"), "{e}");
}

#[test]
fn a_coordinator_ends_its_sessions_when_it_is_done() {
    let limits = SessionLimits {
        max_sessions: 1,
        idle: Duration::from_secs(600),
        ..SessionLimits::default()
    };
    let (addr, _stop) = common::start_service(WorkerService::new(limits), Listen::default());
    let a = scene(DANCE);
    for _ in 0..3 {
        // Each run's session is ended when its executor goes: the next
        // coordinator finds room on a worker that holds one session.
        let mut seq = on_workers(&a, &[addr.to_string()]);
        seq.next_frame().unwrap();
    }
}

#[test]
fn a_session_past_its_own_memory_is_refused_and_the_others_are_served() {
    let limits = SessionLimits {
        max_session_memory: 32 << 20,
        ..SessionLimits::default()
    };
    let (addr, _stop) = common::start_service(WorkerService::new(limits), Listen::default());
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let (mut a, mut b) = (
            common::greeted_client(addr).await,
            common::greeted_client(addr).await,
        );
        let light = shadow::Light::directional(glam::Vec3::X).unwrap();
        let frame = shadow::LightFrame::centered(&light, glam::Vec3::ZERO, 2.0, 32).unwrap();
        // `strands` two-point strands: 60 bytes each received.
        let deposit = |strands: usize| {
            let mut hair = strands::Hair::new();
            for s in 0..strands {
                let t = s as f32 / strands as f32 - 0.5;
                hair.push_strand(&[glam::Vec3::new(-0.5, t, 0.0), glam::Vec3::new(0.5, t, 0.1)])
                    .unwrap();
            }
            tokio_stream::iter(protocol::density_chunks(1, 0, &frame, &hair, 0..strands))
        };
        // 60 MB: past this session's 32 MiB, far within the worker's.
        let e = a.density(deposit(1_000_000)).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::ResourceExhausted, "{}", e.message());
        assert!(
            e.message().contains("--max-session-memory-mib"),
            "{}",
            e.message()
        );
        // 6 MB: served, in this session and the other.
        for c in [&mut a, &mut b] {
            let mut s = c.density(deposit(100_000)).await.unwrap().into_inner();
            let mut samples = 0;
            while let Some(m) = s.message().await.unwrap() {
                samples += m.samples;
            }
            assert!(samples > 0);
        }
    });
}

#[test]
fn a_workers_refusal_reaches_the_frame_as_its_own_type() {
    // A session allowed too little memory for the scene's hair: the
    // worker refuses it (RESOURCE_EXHAUSTED), and the frame's error is
    // that refusal, typed, not its text.
    let limits = SessionLimits {
        max_session_memory: 1 << 10,
        ..SessionLimits::default()
    };
    let (addr, _stop) = common::start_service(WorkerService::new(limits), Listen::default());
    let scene = scene(DANCE);
    let options = Options {
        deadline: Duration::from_secs(20),
        connect_timeout: Duration::from_secs(5),
        tls: None,
        token: None,
        draw: DrawAt::SortLast,
    };
    let err = match RemoteExecutor::connect(&[addr.to_string()], &scene, &options) {
        Err(e) => engine::EngineError::Executor(Box::new(e)),
        Ok(remote) => {
            let mut seq = Sequence::new(&scene).unwrap();
            match seq.set_executor(Box::new(remote)) {
                Err(e) => e,
                Ok(()) => seq.next_frame().map(|_| ()).unwrap_err(),
            }
        }
    };
    let engine::EngineError::Executor(source) = &err else {
        panic!("not the executor's error: {err}");
    };
    let cluster = source
        .downcast_ref::<ClusterError>()
        .unwrap_or_else(|| panic!("not a cluster error: {source}"));
    match cluster {
        ClusterError::Call {
            addr: at, error, ..
        } => {
            assert_eq!(at, &addr.to_string());
            assert_eq!(error.kind, WorkerErrorKind::Exhausted, "{error}");
            assert!(error.message.contains("memory"), "{error}");
        }
        other => panic!("not a worker's refusal: {other}"),
    }
}

#[test]
fn a_worker_with_a_token_serves_only_coordinators_that_show_it() {
    const TOKEN: &str = "s3cret-cluster-token-0123";
    let listen = || Listen {
        token: Some(cluster::Token::new(TOKEN).unwrap()),
        ..Listen::default()
    };
    // Two workers, so that they also call each other (with the token).
    let (a, _stop_a) = common::start_worker_with(listen());
    let (b, _stop_b) = common::start_worker_with(listen());
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        // A bare Hello opens nothing.
        let e = client(a).await.hello(hello(0.1)).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::Unauthenticated);
        assert!(e.message().contains("token"), "{}", e.message());
    });
    let addrs = [a.to_string(), b.to_string()];
    let connect = |token: Option<&str>| {
        RemoteExecutor::connect(
            &addrs,
            &scene(DANCE),
            &Options {
                deadline: Duration::from_secs(20),
                connect_timeout: Duration::from_secs(5),
                tls: None,
                token: token.map(|t| cluster::Token::new(t).unwrap()),
                draw: DrawAt::SortLast,
            },
        )
    };
    // No token, or another: the coordinator stops at once, saying why.
    for token in [None, Some("another-token-of-16chars")] {
        let e = connect(token).unwrap_err().to_string();
        assert!(e.contains("token"), "{token:?}: {e}");
    }
    // A coordinator with a token sends nothing to a worker that cannot
    // prove it: one without a token is refused too.
    let (open, _stop_open) = common::start_worker_with(Listen::default());
    let e = RemoteExecutor::connect(
        &[open.to_string()],
        &scene(DANCE),
        &Options {
            deadline: Duration::from_secs(20),
            connect_timeout: Duration::from_secs(5),
            tls: None,
            token: Some(cluster::Token::new(TOKEN).unwrap()),
            draw: DrawAt::SortLast,
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("has no cluster token"), "{e}");
    // A Hello may not replay a challenge: each is good once.
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut c = client(a).await;
        let proved = common::proved_hello(&mut c, TOKEN).await;
        c.hello(proved.clone()).await.unwrap();
        let e = c.hello(proved).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::Unauthenticated);
        assert!(e.message().contains("challenge"), "{}", e.message());
    });
    // The right one: the same pictures as one process.
    let s = scene(DANCE);
    let mut seq = Sequence::new(&s).unwrap();
    let remote = connect(Some(TOKEN)).unwrap();
    let timing = remote.timing();
    seq.set_executor(Box::new(remote)).unwrap();
    seq.expect_frames(3);
    let mine: Vec<_> = (0..3)
        .map(|_| seq.next_frame().unwrap().0.clone())
        .collect();
    assert!(
        mine == local_frames(&s, 3),
        "the pictures differ from one process's"
    );
    // The workers reached each other with the token: they summed, swept
    // and composited among themselves, nothing fell back.
    let t = *timing.lock().unwrap();
    assert_eq!(
        (t.composite_fallbacks, t.exchange_fallbacks),
        (0, 0),
        "{t:?}"
    );
}

#[test]
fn a_session_whose_coordinator_hung_up_ends_soon_and_a_live_one_stays() {
    let limits = SessionLimits {
        max_sessions: 2,
        idle: Duration::from_secs(600),
        orphaned: Duration::from_millis(300),
        ..SessionLimits::default()
    };
    let (addr, _stop) = common::start_service(WorkerService::new(limits), Listen::default());
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        // One client stays connected, one hangs up (as a killed
        // coordinator's connection closes).
        let mut live = client(addr).await;
        live.hello(hello(0.1)).await.unwrap();
        {
            let mut gone = client(addr).await;
            gone.hello(hello(0.1)).await.unwrap();
        }
        // Both slots are taken at once...
        let e = live.hello(hello(0.1)).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::ResourceExhausted);
        // ...and the hung-up one's is free well before the idle limit.
        tokio::time::sleep(Duration::from_millis(900)).await;
        live.hello(hello(0.1)).await.unwrap();
        // The live client's first session was kept: both slots are its.
        let e = live.hello(hello(0.1)).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::ResourceExhausted);
    });
}
