//! The page in a real browser: headless Chromium loads it, and the test
//! drives it over the DevTools protocol as a user would (mouse on the
//! light pad, a drag on the picture, a click on the self-shadowing box),
//! then checks what the page received: which stages ran, and how the
//! picture it decoded changed.
//!
//! Needs Chromium (`apt-get install chromium`; `.ci/run` installs it, or
//! set WISPLIGHT_CHROMIUM to a Chromium or Chrome binary). Without one the
//! test says so and passes, except under CI, where it fails.
//! WISPLIGHT_SCREENSHOT=path.png saves the page as first seen (the
//! README's picture).

mod common;

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use base64::Engine as _;
use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

fn chromium() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("WISPLIGHT_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    ["chromium", "chromium-browser", "google-chrome"]
        .iter()
        .flat_map(|name| std::env::split_paths(&path).map(move |d| d.join(name)))
        .find(|p| p.is_file())
}

/// Headless Chromium with the DevTools protocol on a free port, and the
/// profile directory it made; killed and removed when dropped.
struct Browser {
    child: Child,
    profile: PathBuf,
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.profile);
    }
}

impl Browser {
    fn launch(bin: &PathBuf) -> (Browser, String) {
        let profile =
            std::env::temp_dir().join(format!("wisplight-chromium-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&profile);
        std::fs::create_dir_all(&profile).unwrap();
        let child = Command::new(bin)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--remote-debugging-port=0",
                "--window-size=1280,800",
            ])
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg("about:blank")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {}: {e}", bin.display()));
        let browser = Browser { child, profile };
        // Chromium writes its port and the browser's socket path here.
        let file = browser.profile.join("DevToolsActivePort");
        let start = Instant::now();
        loop {
            if let Ok(text) = std::fs::read_to_string(&file)
                && let Some((port, path)) = text.split_once('\n')
                && !path.trim().is_empty()
            {
                let url = format!("ws://127.0.0.1:{}{}", port.trim(), path.trim());
                return (browser, url);
            }
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "Chromium wrote no DevToolsActivePort"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// The DevTools protocol, on one page's session.
struct DevTools {
    rt: tokio::runtime::Runtime,
    ws: Socket,
    id: u64,
    session: Option<String>,
}

impl DevTools {
    fn connect(url: &str) -> DevTools {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let (ws, _) = rt.block_on(tokio_tungstenite::connect_async(url)).unwrap();
        DevTools {
            rt,
            ws,
            id: 0,
            session: None,
        }
    }

    fn call(&mut self, method: &str, params: Value) -> Value {
        self.id += 1;
        let mut msg = json!({"id": self.id, "method": method, "params": params});
        if let Some(s) = &self.session {
            msg["sessionId"] = json!(s);
        }
        let id = self.id;
        self.rt.block_on(async {
            self.ws
                .send(Message::Text(msg.to_string().into()))
                .await
                .unwrap();
            loop {
                let m = tokio::time::timeout(Duration::from_secs(60), self.ws.next())
                    .await
                    .expect("DevTools answers")
                    .expect("DevTools stays open")
                    .unwrap();
                let Message::Text(t) = m else { continue };
                let v: Value = serde_json::from_str(&t).unwrap();
                if v["id"] == id {
                    if let Some(e) = v.get("error") {
                        panic!("{method}: {e}");
                    }
                    return v["result"].clone();
                }
            }
        })
    }

    fn open(&mut self, url: &str) {
        let target = self.call("Target.createTarget", json!({"url": url}));
        let attached = self.call(
            "Target.attachToTarget",
            json!({"targetId": target["targetId"], "flatten": true}),
        );
        self.session = Some(attached["sessionId"].as_str().unwrap().to_string());
    }

    fn eval(&mut self, expr: &str) -> Value {
        let r = self.call(
            "Runtime.evaluate",
            json!({"expression": expr, "returnByValue": true, "awaitPromise": true}),
        );
        if let Some(e) = r.get("exceptionDetails") {
            panic!("{expr}: {e}");
        }
        r["result"]["value"].clone()
    }

    /// Waits until `expr` is true in the page.
    fn wait_for(&mut self, expr: &str, what: &str) {
        let start = Instant::now();
        while self.eval(&format!("!!({expr})")) != json!(true) {
            assert!(
                start.elapsed() < Duration::from_secs(120),
                "{what}: the page never got there; it has {}",
                self.eval("JSON.stringify(window.wisplight && wisplight.header)")
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// What the page saw last: its header, frames, picture mean.
    fn seen(&mut self) -> Value {
        self.eval("({header: wisplight.header, frames: wisplight.frames, mean: wisplight.mean, errors: wisplight.errors})")
    }

    /// The centre of element `id` (and a point `dx`, `dy` of its size
    /// from its top left corner when given), in page pixels.
    fn point(&mut self, id: &str, at: (f64, f64)) -> (f64, f64) {
        let r = self.eval(&format!(
            "(() => {{ const r = document.getElementById('{id}').getBoundingClientRect(); return [r.left, r.top, r.width, r.height]; }})()"
        ));
        let f = |i: usize| r[i].as_f64().unwrap();
        (f(0) + at.0 * f(2), f(1) + at.1 * f(3))
    }

    fn mouse(&mut self, kind: &str, (x, y): (f64, f64)) {
        self.call(
            "Input.dispatchMouseEvent",
            json!({"type": kind, "x": x, "y": y, "button": "left", "buttons": i32::from(kind != "mouseReleased"), "clickCount": 1}),
        );
    }

    fn click(&mut self, p: (f64, f64)) {
        self.mouse("mousePressed", p);
        self.mouse("mouseReleased", p);
    }
}

fn stages_run(h: &Value) -> Vec<String> {
    h["stage_names"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .filter(|n| h["stats"]["stages"][n]["ran"] == json!(true))
        .map(String::from)
        .collect()
}

#[test]
fn headless_chromium_drives_the_page_and_its_frames_change_as_they_should() {
    let Some(bin) = chromium() else {
        if std::env::var_os("CI").is_some() {
            panic!("the browser test needs Chromium: apt-get install chromium");
        }
        eprintln!("skipped: no Chromium (apt-get install chromium, or set WISPLIGHT_CHROMIUM)");
        return;
    };
    let v = common::start(common::scene(), None, "127.0.0.1:0");
    let (_browser, devtools) = Browser::launch(&bin);
    let mut page = DevTools::connect(&devtools);
    page.open(&v.bound.url());

    // Frames arrive, are decoded and drawn; the overlay lists the stages.
    page.wait_for("window.wisplight && wisplight.frames >= 3", "frames");
    let overlay = page.eval("document.getElementById('overlay').textContent");
    for stage in [
        "simulate",
        "density",
        "transmittance",
        "shade",
        "draw",
        "fps",
    ] {
        assert!(overlay.as_str().unwrap().contains(stage), "{overlay}");
    }
    if let Some(path) = std::env::var_os("WISPLIGHT_SCREENSHOT") {
        let shot = page.call("Page.captureScreenshot", json!({"format": "png"}));
        let png = base64::engine::general_purpose::STANDARD
            .decode(shot["data"].as_str().unwrap())
            .unwrap();
        std::fs::write(path, png).unwrap();
    }

    // Pause with the button.
    let play = page.point("play", (0.5, 0.5));
    page.click(play);
    page.wait_for("wisplight.header.playing === false", "paused");
    let paused = page.seen();
    let index = paused["header"]["stats"]["index"].clone();
    let seq = paused["header"]["seq"].as_u64().unwrap();

    // Turn the light: a click on the pad, a sixth across (azimuth -120)
    // and a third down (elevation 30): from behind, on the left.
    let pad = page.point("pad", (1.0 / 6.0, 1.0 / 3.0));
    page.click(pad);
    page.wait_for(
        &format!("wisplight.header.seq > {seq} && Math.abs(wisplight.header.lights[0].azimuth_deg + 120) < 2"),
        "the light turned",
    );
    let lit = page.seen();
    let h = &lit["header"];
    assert!(
        (h["lights"][0]["elevation_deg"].as_f64().unwrap() - 30.0).abs() < 2.0,
        "{h}"
    );
    assert_eq!(h["stats"]["index"], index, "paused: the same frame");
    assert_eq!(
        stages_run(h),
        ["density", "transmittance", "filter", "shade", "draw"],
        "the shadows and shading, not the simulation"
    );
    let before = paused["mean"].as_f64().unwrap();
    let after = lit["mean"].as_f64().unwrap();
    assert!(
        (after - before).abs() > 0.5,
        "the picture changed: {before} -> {after}"
    );

    // Orbit: a drag across the picture.
    let seq = h["seq"].as_u64().unwrap();
    let yaw = h["camera"]["yaw_deg"].as_f64().unwrap();
    let from = page.point("view", (0.5, 0.5));
    page.mouse("mousePressed", from);
    for k in 1..=5 {
        page.mouse("mouseMoved", (from.0 + 24.0 * f64::from(k), from.1));
    }
    page.mouse("mouseReleased", (from.0 + 120.0, from.1));
    page.wait_for(
        &format!(
            "wisplight.header.seq > {seq} && Math.abs(wisplight.header.camera.yaw_deg - {yaw}) > 10"
        ),
        "the camera turned",
    );
    let turned = page.seen();
    assert_eq!(stages_run(&turned["header"]), ["shade", "draw"]);

    // Self-shadowing off, with its box: no shadow stage runs, and the
    // hair is brighter.
    page.wait_for("!wisplight.header.playing", "still paused");
    let shadowed = turned["mean"].as_f64().unwrap();
    let seq = turned["header"]["seq"].as_u64().unwrap();
    let boxed = page.point("fx-self_shadow", (0.5, 0.5));
    page.click(boxed);
    page.wait_for(
        &format!("wisplight.header.seq > {seq} && wisplight.header.effects.self_shadow === false"),
        "self-shadowing off",
    );
    let bright = page.seen();
    assert_eq!(stages_run(&bright["header"]), ["shade", "draw"]);
    let unshadowed = bright["mean"].as_f64().unwrap();
    // (A mean over the whole page's frame, background included: the
    // hair's shadow is a few levels, about one over the frame.)
    assert!(
        unshadowed > shadowed + 0.5,
        "brighter without self-shadows: {shadowed} -> {unshadowed}"
    );
    assert_eq!(bright["errors"], json!([]));

    // Play again: the hair moves.
    let play = page.point("play", (0.5, 0.5));
    page.click(play);
    page.wait_for(
        &format!("wisplight.header.playing && wisplight.header.stats.index > {index}"),
        "playing again",
    );
}
