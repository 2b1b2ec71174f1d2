//! A viewer in this process, and a page's side of its WebSocket.

#![allow(dead_code)]

use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use tokio_tungstenite::tungstenite::Message;

/// A small scene: the smooth style dancing, few strands, a small picture,
/// a head that casts and takes shadow.
pub(crate) const SCENE: &str = r#"
[hair]
style = "smooth"
strands_per_wisp = 4

[head]
radius = 10

[render]
width = 192
height = 108

[shadow]
cells = 64

[animation]
motion = "dance"
fps = 30

[dynamics]
settle = 0.1
"#;

pub(crate) fn scene() -> engine::Scene {
    engine::Scene::from_toml_str(SCENE, Path::new("viewer-test.toml")).unwrap()
}

/// A running viewer and the switch that stops it.
pub(crate) struct Viewer {
    pub bound: viewer::Bound,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
}

impl Drop for Viewer {
    fn drop(&mut self) {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
    }
}

/// Serves `scene` on `listen`, through `connect` (workers) or here.
pub(crate) fn start(
    scene: engine::Scene,
    connect: Option<viewer::Connect>,
    listen: &str,
) -> Viewer {
    let (tx, rx) = std::sync::mpsc::channel();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let listen: SocketAddr = listen.parse().unwrap();
    std::thread::spawn(move || {
        let options = viewer::Options {
            listen,
            workers: usize::from(connect.is_some()),
        };
        let out = viewer::run(
            &scene,
            connect,
            &options,
            |b| tx.send(b.clone()).unwrap(),
            async {
                let _ = stopped.await;
            },
        );
        if let Err(e) = out {
            panic!("the viewer failed: {e}");
        }
    });
    let bound = rx
        .recv_timeout(Duration::from_secs(120))
        .expect("the viewer started");
    Viewer {
        bound,
        stop: Some(stop),
    }
}

/// One frame as a page receives it.
#[derive(Debug, Clone)]
pub(crate) struct Frame {
    pub header: serde_json::Value,
    pub jpeg: Vec<u8>,
}

impl Frame {
    pub(crate) fn parse(bytes: &[u8]) -> Frame {
        let n = u32::from_le_bytes(bytes[..4].try_into().unwrap()) as usize;
        let header = serde_json::from_slice(&bytes[4..4 + n]).unwrap();
        Frame {
            header,
            jpeg: bytes[4 + n..].to_vec(),
        }
    }

    pub(crate) fn index(&self) -> u64 {
        self.header["stats"]["index"].as_u64().unwrap()
    }

    pub(crate) fn ran(&self, stage: &str) -> bool {
        self.header["stats"]["stages"][stage]["ran"]
            .as_bool()
            .unwrap_or_else(|| panic!("no stage {stage} in {}", self.header))
    }

    /// The stages that ran, in the order a frame runs them.
    pub(crate) fn stages_run(&self) -> Vec<String> {
        self.stage_names()
            .into_iter()
            .filter(|n| self.ran(n))
            .collect()
    }

    pub(crate) fn stage_names(&self) -> Vec<String> {
        self.header["stage_names"]
            .as_array()
            .unwrap()
            .iter()
            .map(|n| n.as_str().unwrap().to_string())
            .collect()
    }

    pub(crate) fn image(&self) -> image::RgbImage {
        image::load_from_memory_with_format(&self.jpeg, image::ImageFormat::Jpeg)
            .unwrap()
            .to_rgb8()
    }

    /// Mean luminance of the picture, 0 to 255.
    pub(crate) fn mean(&self) -> f64 {
        let img = self.image();
        let sum: f64 = img
            .pixels()
            .map(|p| 0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2]))
            .sum();
        sum / f64::from(img.width() * img.height())
    }
}

type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// A page: its socket, on a runtime of its own.
pub(crate) struct Page {
    rt: tokio::runtime::Runtime,
    ws: Socket,
}

impl Page {
    pub(crate) fn open(v: &Viewer) -> Page {
        let url = match &v.bound.token {
            Some(t) => format!("ws://127.0.0.1:{}/ws?token={t}", v.bound.addr.port()),
            None => format!("ws://{}/ws", v.bound.addr),
        };
        Page::open_url(&url).unwrap()
    }

    pub(crate) fn open_url(url: &str) -> Result<Page, tokio_tungstenite::tungstenite::Error> {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let (ws, _) = rt.block_on(tokio_tungstenite::connect_async(url))?;
        Ok(Page { rt, ws })
    }

    pub(crate) fn send(&mut self, json: &str) {
        self.rt
            .block_on(self.ws.send(Message::Text(json.into())))
            .unwrap();
    }

    pub(crate) fn send_message(&mut self, m: Message) {
        self.rt.block_on(self.ws.send(m)).unwrap();
    }

    /// The next message, text or frame; `None` once the socket closed.
    pub(crate) fn next(&mut self) -> Option<Result<Frame, serde_json::Value>> {
        loop {
            let m = self
                .rt
                .block_on(async {
                    tokio::time::timeout(Duration::from_secs(120), self.ws.next()).await
                })
                .expect("a message within two minutes")?;
            match m {
                Ok(Message::Binary(b)) => return Some(Ok(Frame::parse(&b))),
                Ok(Message::Text(t)) => return Some(Err(serde_json::from_str(&t).unwrap())),
                Ok(Message::Close(_)) | Err(_) => return None,
                Ok(_) => continue,
            }
        }
    }

    pub(crate) fn frame(&mut self) -> Frame {
        match self.next().expect("the socket is open") {
            Ok(f) => f,
            Err(e) => panic!("an error instead of a frame: {e}"),
        }
    }

    /// The first frame whose header satisfies `pred`.
    pub(crate) fn frame_where(&mut self, pred: impl Fn(&Frame) -> bool) -> Frame {
        loop {
            let f = self.frame();
            if pred(&f) {
                return f;
            }
        }
    }

    /// The next error message, skipping frames.
    pub(crate) fn error(&mut self) -> String {
        loop {
            match self.next().expect("the socket is open") {
                Ok(_) => continue,
                Err(e) => {
                    assert_eq!(e["type"], "error", "{e}");
                    return e["message"].as_str().unwrap().to_string();
                }
            }
        }
    }

    /// Pauses and gives the frame the pause settled on.
    pub(crate) fn pause(&mut self) -> Frame {
        self.send(r#"{"type":"pause"}"#);
        self.frame_where(|f| f.header["playing"] == false)
    }
}
