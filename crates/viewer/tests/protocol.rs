//! The viewer's WebSocket protocol, spoken by a test page: frames and
//! their records, what each control reruns, bad messages, several pages,
//! access beyond loopback, and workers giving the same frames.

mod common;

use std::io::{Read, Write};
use std::time::Duration;

use common::{Page, scene, start};
use tokio_tungstenite::tungstenite::Message;

const ALL_STAGES: [&str; 9] = [
    "self_collide",
    "simulate",
    "body_collide",
    "pose",
    "density",
    "transmittance",
    "filter",
    "shade",
    "draw",
];

#[test]
fn frames_arrive_with_the_stats_record_and_a_jpeg() {
    let v = start(scene(), None, "127.0.0.1:0");
    assert!(v.bound.token.is_none(), "no token on loopback");
    let mut page = Page::open(&v);
    let a = page.frame();
    let b = page.frame();
    // Every stage of the --stats record, in order.
    assert_eq!(a.stage_names(), ALL_STAGES);
    let mut recorded: Vec<&String> = a.header["stats"]["stages"]
        .as_object()
        .unwrap()
        .keys()
        .collect();
    recorded.sort();
    let mut all = ALL_STAGES.to_vec();
    all.sort();
    assert_eq!(recorded, all);
    assert_eq!(a.image().dimensions(), (192, 108));
    assert!(
        b.index() > a.index(),
        "playing: {} then {}",
        a.index(),
        b.index()
    );
    assert!(b.header["seq"].as_u64() > a.header["seq"].as_u64());
    // The first frame simulated (and settled) and shadowed.
    for s in [
        "simulate",
        "pose",
        "density",
        "transmittance",
        "filter",
        "shade",
        "draw",
    ] {
        assert!(a.ran(s), "{s} in {}", a.header);
    }
    assert_eq!(a.header["playing"], true);
    assert_eq!(a.header["shadow"]["method"], "density-map");
    assert_eq!(a.header["shadow"]["cells"], 64);
    assert_eq!(a.header["lights"][0]["kind"], "directional");
    // Hair is drawn: the picture is not the background alone.
    assert!(a.mean() > 10.0, "mean {}", a.mean());
}

#[test]
fn a_paused_session_reruns_only_what_a_change_calls_for() {
    let v = start(scene(), None, "127.0.0.1:0");
    let mut page = Page::open(&v);
    let paused = page.pause();
    let k = paused.index();

    page.send(r#"{"type":"step"}"#);
    let stepped = page.frame_where(|f| f.index() == k + 1);
    assert!(stepped.ran("simulate") && stepped.ran("density") && stepped.ran("draw"));
    assert_eq!(stepped.header["playing"], false);

    // The camera: shading and drawing only.
    page.send(r#"{"type":"orbit","yaw_deg":40,"pitch_deg":10}"#);
    let turned = page.frame();
    assert_eq!(turned.index(), k + 1, "the same frame, seen from elsewhere");
    assert_eq!(turned.stages_run(), ["shade", "draw"]);
    assert_ne!(turned.jpeg, stepped.jpeg);
    page.send(r#"{"type":"zoom","factor":0.8}"#);
    assert_eq!(page.frame().stages_run(), ["shade", "draw"]);
    page.send(r#"{"type":"reset_camera"}"#);
    let back = page.frame();
    assert_eq!(back.stages_run(), ["shade", "draw"]);
    assert_eq!(
        back.jpeg, stepped.jpeg,
        "the framed camera again, the same picture"
    );

    // The light: the shadow stages, shading and drawing; no simulation.
    page.send(r#"{"type":"light","index":0,"azimuth_deg":-120,"elevation_deg":30}"#);
    let lit = page.frame();
    assert_eq!(lit.index(), k + 1);
    assert_eq!(
        lit.stages_run(),
        ["density", "transmittance", "filter", "shade", "draw"]
    );
    let az = lit.header["lights"][0]["azimuth_deg"].as_f64().unwrap();
    assert!((az + 120.0).abs() < 0.01, "{az}");
    assert_ne!(lit.jpeg, back.jpeg);

    // Self-shadowing off: no shadow stage runs, and the hair is brighter.
    page.send(r#"{"type":"effect","name":"self_shadow","on":false}"#);
    let bright = page.frame();
    assert_eq!(bright.stages_run(), ["shade", "draw"]);
    assert_eq!(bright.header["effects"]["self_shadow"], false);
    // (The mean is over the whole frame, background included: the
    // shadow darkens the hair by a few levels, the frame by about one.)
    assert!(
        bright.mean() > lit.mean() + 0.5,
        "unshadowed {} vs shadowed {}",
        bright.mean(),
        lit.mean()
    );
    // And on again: the same picture as before it went off.
    page.send(r#"{"type":"effect","name":"self_shadow","on":true}"#);
    let again = page.frame();
    assert!(again.ran("density") && !again.ran("simulate"));
    assert_eq!(again.jpeg, lit.jpeg);

    // Another method and its main setting; the map's cells.
    page.send(r#"{"type":"shadow","method":"deep-opacity-map","setting":6}"#);
    let dom = page.frame();
    assert_eq!(dom.header["shadow"]["method"], "deep-opacity-map");
    assert_eq!(dom.header["shadow"]["setting"]["name"], "layers");
    assert_eq!(dom.header["shadow"]["setting"]["value"], 6.0);
    assert!(dom.ran("density") && !dom.ran("simulate"));
    page.send(r#"{"type":"shadow","method":"density-map","cells":32}"#);
    let coarse = page.frame();
    assert_eq!(coarse.header["shadow"]["cells"], 32);
    assert!(coarse.ran("density") && !coarse.ran("simulate"));
    assert_ne!(coarse.jpeg, lit.jpeg);

    // Playing again moves the hair.
    page.send(r#"{"type":"play"}"#);
    let moving = page.frame_where(|f| f.index() > k + 1);
    assert!(moving.ran("simulate"));
}

#[test]
fn bad_messages_get_an_error_naming_what_is_wrong_and_the_page_stays() {
    let v = start(scene(), None, "127.0.0.1:0");
    let mut page = Page::open(&v);
    page.pause();
    for (msg, names) in [
        ("hello", "expected"),
        (r#"{"type":"fly"}"#, "fly"),
        (r#"{"type":"zoom","factor":-2}"#, "factor"),
        (r#"{"type":"effect","name":"fur","on":true}"#, "fur"),
        (
            r#"{"type":"light","index":3,"azimuth_deg":0,"elevation_deg":0}"#,
            "light 3",
        ),
        (
            r#"{"type":"light","index":0,"azimuth_deg":0,"elevation_deg":0,"distance":5}"#,
            "directional",
        ),
        (
            r#"{"type":"effect","name":"multiple_scattering","on":true}"#,
            "marschner",
        ),
        (
            r#"{"type":"shadow","method":"opacity-shadow-map","setting":1}"#,
            "slices",
        ),
    ] {
        page.send(msg);
        let e = page.error();
        assert!(e.contains(names), "{msg}: {e}");
    }
    page.send_message(Message::Binary(vec![1, 2, 3].into()));
    assert!(page.error().contains("JSON text"));
    // Still served.
    page.send(r#"{"type":"step"}"#);
    let f = page.frame();
    assert!(f.ran("simulate"));
    assert_eq!(f.header["error"], serde_json::Value::Null);
}

#[test]
fn an_oversized_message_closes_the_socket() {
    let v = start(scene(), None, "127.0.0.1:0");
    let mut page = Page::open(&v);
    page.frame();
    page.send(&format!(
        r#"{{"type":"play","pad":"{}"}}"#,
        "x".repeat(8000)
    ));
    while let Some(m) = page.next() {
        assert!(m.is_ok(), "closed, not answered: {m:?}");
    }
    // The session still serves other pages.
    let mut other = Page::open(&v);
    other.frame();
}

#[test]
fn several_pages_watch_one_session_and_a_stalled_one_holds_up_nobody() {
    let v = start(scene(), None, "127.0.0.1:0");
    let mut a = Page::open(&v);
    let mut b = Page::open(&v);
    // A page that never reads.
    let stalled = Page::open(&v);
    let first = b.frame().index();
    let mut last = first;
    for _ in 0..40 {
        let f = b.frame();
        assert!(f.index() >= last);
        last = f.index();
    }
    assert!(last >= first + 20, "frames kept coming: {first} to {last}");
    // One page pauses; the other sees it, on the same frame.
    let paused = a.pause();
    let seen = b.frame_where(|f| f.header["playing"] == false);
    assert_eq!(seen.index(), paused.index());
    drop(stalled);
    b.send(r#"{"type":"step"}"#);
    assert_eq!(a.frame().index(), paused.index() + 1);
}

/// `GET path` on `addr`; the status line.
fn get(addr: std::net::SocketAddr, path: &str) -> String {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut out = String::new();
    let _ = s.read_to_string(&mut out);
    out
}

#[test]
fn the_page_is_served_whole_and_beyond_loopback_a_token_is_needed() {
    let local = start(scene(), None, "127.0.0.1:0");
    let page = get(local.bound.addr, "/");
    assert!(page.starts_with("HTTP/1.1 200"), "{page}");
    assert!(page.contains("<canvas id=\"view\""));
    // Nothing fetched from elsewhere.
    assert!(!page.contains("http://") && !page.contains("https://"));
    assert!(get(local.bound.addr, "/nothing").starts_with("HTTP/1.1 404"));

    let open = start(scene(), None, "0.0.0.0:0");
    let token = open.bound.token.clone().expect("a token beyond loopback");
    assert_eq!(token.len(), 32);
    assert!(open.bound.url().ends_with(&format!("/?token={token}")));
    let addr = std::net::SocketAddr::from(([127, 0, 0, 1], open.bound.addr.port()));
    assert!(get(addr, "/").starts_with("HTTP/1.1 403"));
    assert!(get(addr, "/?token=wrong").starts_with("HTTP/1.1 403"));
    assert!(get(addr, &format!("/?token={token}")).starts_with("HTTP/1.1 200"));
    let refused = Page::open_url(&format!("ws://{addr}/ws")).err().unwrap();
    assert!(refused.to_string().contains("403"), "{refused}");
    let mut page = Page::open(&open);
    page.frame();
}

/// A worker in this process, on a free port.
fn start_worker() -> std::net::SocketAddr {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(cluster::serve_worker(
            cluster::WorkerService::default(),
            "127.0.0.1:0".parse().unwrap(),
            &cluster::Listen::default(),
            move |b| tx.send(b.addr).unwrap(),
            std::future::pending::<()>(),
        ))
        .unwrap();
    });
    rx.recv_timeout(Duration::from_secs(30)).unwrap()
}

fn connect_to(workers: Vec<String>) -> viewer::Connect {
    let options = cluster::Options {
        deadline: Duration::from_secs(60),
        connect_timeout: Duration::from_secs(10),
        tls: None,
        token: None,
        draw: cluster::DrawAt::SortLast,
    };
    Box::new(move |scene: &engine::Scene| {
        let ex = cluster::RemoteExecutor::connect(&workers, scene, &options)
            .map_err(|e| engine::EngineError::Executor(Box::new(e)))?;
        Ok(Box::new(ex) as Box<dyn engine::Executor>)
    })
}

/// Steps a paused page until frame `index`.
fn step_to(page: &mut Page, index: u64) -> common::Frame {
    loop {
        page.send(r#"{"type":"step"}"#);
        let f = page.frame_where(|f| f.header["playing"] == false && f.ran("simulate"));
        assert!(f.index() <= index, "past frame {index}: {}", f.index());
        if f.index() == index {
            return f;
        }
    }
}

#[test]
fn workers_give_the_frames_of_one_process_through_every_change() {
    let workers: Vec<String> = (0..2).map(|_| start_worker().to_string()).collect();
    let remote = start(scene(), Some(connect_to(workers)), "127.0.0.1:0");
    let local = start(scene(), None, "127.0.0.1:0");
    let mut r = Page::open(&remote);
    let mut l = Page::open(&local);
    let at = r.pause().index().max(l.pause().index()) + 2;
    let (fr, fl) = (step_to(&mut r, at), step_to(&mut l, at));
    assert_eq!(fr.header["workers"], 1);
    assert!(fr.jpeg == fl.jpeg, "frame {at}: not the same picture");
    for (control, what) in [
        (
            r#"{"type":"light","index":0,"azimuth_deg":100,"elevation_deg":20}"#,
            "light",
        ),
        (r#"{"type":"orbit","yaw_deg":-30,"pitch_deg":5}"#, "orbit"),
        (
            r#"{"type":"effect","name":"self_shadow","on":false}"#,
            "self_shadow off",
        ),
        (
            r#"{"type":"effect","name":"self_shadow","on":true}"#,
            "self_shadow on",
        ),
        (
            r#"{"type":"shadow","method":"density-map","cells":40}"#,
            "cells",
        ),
        (
            r#"{"type":"shadow","method":"deep-opacity-map"}"#,
            "a method that runs on the coordinator",
        ),
        (r#"{"type":"step"}"#, "a step with that method"),
        (
            r#"{"type":"shadow","method":"density-map"}"#,
            "the density map again",
        ),
        (r#"{"type":"step"}"#, "a step on the workers"),
    ] {
        r.send(control);
        l.send(control);
        let (fr, fl) = (r.frame(), l.frame());
        assert_eq!(fr.header["error"], serde_json::Value::Null, "{what}");
        assert_eq!(fr.index(), fl.index(), "{what}");
        assert!(fr.jpeg == fl.jpeg, "after {what}: not the same picture");
    }
}

#[test]
fn a_point_light_moves_about_the_hair_and_a_place_inside_it_is_refused() {
    let text = format!(
        "{}\n[light]\nposition = [40.0, 30.0, 40.0]\n",
        common::SCENE
    );
    let scene = engine::Scene::from_toml_str(&text, std::path::Path::new("point.toml")).unwrap();
    let v = start(scene, None, "127.0.0.1:0");
    let mut page = Page::open(&v);
    let paused = page.pause();
    assert_eq!(paused.header["lights"][0]["kind"], "point");
    page.send(r#"{"type":"light","index":0,"azimuth_deg":-60,"elevation_deg":20,"distance":80}"#);
    let moved = page.frame();
    let l = &moved.header["lights"][0];
    assert!((l["distance"].as_f64().unwrap() - 80.0).abs() < 1e-3, "{l}");
    assert!(
        (l["azimuth_deg"].as_f64().unwrap() + 60.0).abs() < 0.01,
        "{l}"
    );
    assert_eq!(
        moved.stages_run(),
        ["density", "transmittance", "filter", "shade", "draw"]
    );
    // At the hair's centre the light is inside what it lights: the frame
    // fails, the page is told, and the light goes back.
    page.send(r#"{"type":"light","index":0,"azimuth_deg":0,"elevation_deg":0,"distance":0.5}"#);
    let failed = page.frame_where(|f| !f.header["error"].is_null());
    let e = failed.header["error"].as_str().unwrap();
    assert!(e.contains("inside") || e.contains("behind"), "{e}");
    let back = page.frame_where(|f| f.header["error"].is_null());
    assert!((back.header["lights"][0]["distance"].as_f64().unwrap() - 80.0).abs() < 1e-3);
    assert!(
        back.jpeg == moved.jpeg,
        "the picture before the failed move"
    );
}

#[test]
fn stopping_the_viewer_closes_every_page() {
    let v = start(scene(), None, "127.0.0.1:0");
    let mut page = Page::open(&v);
    page.frame();
    drop(v);
    // Frames, then the close: no wait for the page to leave first.
    while let Some(m) = page.next() {
        assert!(m.is_ok(), "{m:?}");
    }
}
