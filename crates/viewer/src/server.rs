//! The HTTP side: `GET /` gives the page, `GET /ws` upgrades to the
//! WebSocket that carries frames out and controls in.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc::{SyncSender, TrySendError};
use std::time::Duration;

use axum::Router;
use axum::body::Bytes;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Query, State};
use axum::http::{StatusCode, header};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use engine::Scene;
use tokio::sync::{mpsc, watch};

use crate::ViewerError;
use crate::control::{Control, MAX_MESSAGE};
use crate::session::{Connect, Input, Session, Viewers};

/// The page, with its script and style inline.
const PAGE: &str = include_str!("page.html");

/// Pages that may watch at once; more are refused (503).
pub const MAX_VIEWERS: usize = 32;

/// Seconds a page may take to take one frame before it is let go.
const SEND_TIMEOUT: Duration = Duration::from_secs(10);

/// Controls waiting for the session at most; more are refused as busy.
const QUEUE: usize = 64;

/// How the viewer serves.
#[derive(Debug, Clone)]
pub struct Options {
    /// Where to listen (port 0 picks a free port).
    pub listen: SocketAddr,
    /// Cluster workers the frames run on (0: this process), for the page.
    pub workers: usize,
}

/// Where the viewer listens, once bound, and the token a page must give
/// (listening beyond loopback).
#[derive(Debug, Clone)]
pub struct Bound {
    /// The address listened on.
    pub addr: SocketAddr,
    /// The token pages must give (listening beyond loopback).
    pub token: Option<String>,
}

impl Bound {
    /// The page's address, with the token when one is needed.
    pub fn url(&self) -> String {
        match &self.token {
            Some(t) => format!("http://{}/?token={t}", self.addr),
            None => format!("http://{}/", self.addr),
        }
    }
}

#[derive(Clone)]
struct Shared {
    inputs: SyncSender<Input>,
    frames: watch::Receiver<Option<Bytes>>,
    viewers: Viewers,
    token: Option<Arc<str>>,
    /// Turns true when the server stops.
    stop: watch::Receiver<bool>,
}

#[derive(serde::Deserialize)]
struct Access {
    token: Option<String>,
}

impl Shared {
    fn allows(&self, access: &Access) -> bool {
        match &self.token {
            None => true,
            Some(t) => access
                .token
                .as_deref()
                .is_some_and(|given| constant_time_eq(given.as_bytes(), t.as_bytes())),
        }
    }
}

fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// A new access token: 128 random bits, in hex.
fn token() -> Result<String, ViewerError> {
    let mut b = [0u8; 16];
    getrandom::fill(&mut b).map_err(|e| ViewerError::Token(e.to_string()))?;
    Ok(b.iter().map(|x| format!("{x:02x}")).collect())
}

/// Serves the viewer of `scene` until `shutdown` completes: frames through
/// the executor `connect` makes (cluster workers), or in this process.
/// The scene's frames are set up (and the workers connected) first, so
/// that a scene that cannot run fails before anything listens; `bound` is
/// then called with the address bound (and the token pages need beyond
/// loopback) before the first request is served. Blocks; not to be called
/// from async code.
pub fn run(
    scene: &Scene,
    connect: Option<Connect>,
    options: &Options,
    bound: impl FnOnce(&Bound),
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> Result<(), ViewerError> {
    let session = Session::new(scene, connect, options.workers)?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("wisplight-http")
        .enable_all()
        .build()
        .map_err(ViewerError::Serve)?;
    rt.block_on(serve(session, options, bound, shutdown))
}

async fn serve(
    session: Session,
    options: &Options,
    bound: impl FnOnce(&Bound),
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> Result<(), ViewerError> {
    let listener = tokio::net::TcpListener::bind(options.listen)
        .await
        .map_err(|error| ViewerError::Listen {
            addr: options.listen,
            error,
        })?;
    let addr = listener.local_addr().map_err(ViewerError::Serve)?;
    let token = if addr.ip().is_loopback() {
        None
    } else {
        Some(token()?)
    };
    let (inputs, received) = std::sync::mpsc::sync_channel(QUEUE);
    let (frames_tx, frames) = watch::channel(None);
    let viewers: Viewers = Arc::default();
    let thread_viewers = viewers.clone();
    std::thread::Builder::new()
        .name("wisplight-view".into())
        .spawn(move || session.run(received, frames_tx, thread_viewers))
        .map_err(ViewerError::Serve)?;
    // On shutdown every page's socket closes, so that the server's
    // graceful end does not wait for pages.
    let (stop_tx, stop) = watch::channel(false);
    let shared = Shared {
        inputs,
        frames,
        viewers,
        token: token.clone().map(Arc::from),
        stop,
    };
    bound(&Bound { addr, token });
    let app = Router::new()
        .route("/", get(page))
        .route("/ws", get(socket))
        .with_state(shared);
    axum::serve(listener, app)
        .with_graceful_shutdown(async move {
            shutdown.await;
            let _ = stop_tx.send(true);
        })
        .await
        .map_err(ViewerError::Serve)
}

async fn page(State(s): State<Shared>, Query(access): Query<Access>) -> Response {
    if !s.allows(&access) {
        return forbidden();
    }
    (
        [
            (header::CACHE_CONTROL, "no-store"),
            (
                header::CONTENT_SECURITY_POLICY,
                "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; \
                 img-src blob:; connect-src 'self'",
            ),
        ],
        Html(PAGE),
    )
        .into_response()
}

fn forbidden() -> Response {
    (
        StatusCode::FORBIDDEN,
        "this viewer listens beyond loopback: open the address it printed, with its token\n",
    )
        .into_response()
}

async fn socket(
    State(s): State<Shared>,
    Query(access): Query<Access>,
    ws: WebSocketUpgrade,
) -> Response {
    if !s.allows(&access) {
        return forbidden();
    }
    if s.viewers.load(Ordering::Relaxed) >= MAX_VIEWERS {
        return (
            StatusCode::SERVICE_UNAVAILABLE,
            format!("{MAX_VIEWERS} pages already watch this session\n"),
        )
            .into_response();
    }
    ws.max_message_size(MAX_MESSAGE)
        .max_frame_size(MAX_MESSAGE)
        .on_upgrade(move |socket| watch_session(socket, s))
}

/// Counts a page among the viewers while it lives.
struct Watching(Viewers);

impl Drop for Watching {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

/// One page: the latest frame whenever there is a newer one, controls
/// passed on to the session, and what was wrong with them sent back.
async fn watch_session(mut socket: WebSocket, s: Shared) {
    s.viewers.fetch_add(1, Ordering::Relaxed);
    let _watching = Watching(s.viewers.clone());
    let _ = s.inputs.try_send(Input::Wake);
    let mut frames = s.frames.clone();
    frames.mark_changed();
    let mut stop = s.stop.clone();
    let (errors_tx, mut errors) = mpsc::channel::<String>(8);
    loop {
        let out = tokio::select! {
            changed = frames.changed() => {
                if changed.is_err() {
                    break;
                }
                let latest = frames.borrow_and_update().clone();
                match latest {
                    Some(frame) => Message::Binary(frame),
                    None => continue,
                }
            }
            Some(e) = errors.recv() => error_message(&e),
            _ = stop.changed() => {
                let _ = socket.send(Message::Close(None)).await;
                break;
            }
            msg = socket.recv() => match msg {
                None | Some(Err(_)) | Some(Ok(Message::Close(_))) => break,
                Some(Ok(Message::Text(text))) => {
                    match Control::parse(text.as_str()) {
                        Ok(control) => match s.inputs.try_send(Input::Control {
                            control,
                            errors: errors_tx.clone(),
                        }) {
                            Ok(()) => continue,
                            Err(TrySendError::Full(_)) => {
                                error_message("busy: too many controls waiting; try again")
                            }
                            Err(TrySendError::Disconnected(_)) => break,
                        },
                        Err(e) => error_message(&e.to_string()),
                    }
                }
                Some(Ok(Message::Binary(_))) => {
                    error_message("bad message: controls are JSON text messages")
                }
                Some(Ok(_)) => continue,
            },
        };
        match tokio::time::timeout(SEND_TIMEOUT, socket.send(out)).await {
            Ok(Ok(())) => {}
            // Gone, or stalled: let it go.
            _ => break,
        }
    }
}

fn error_message(e: &str) -> Message {
    Message::Text(
        serde_json::json!({"type": "error", "message": e})
            .to_string()
            .into(),
    )
}
