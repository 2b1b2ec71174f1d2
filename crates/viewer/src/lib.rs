//! The browser viewer: `wisplight view` serves a page (embedded here, no
//! file fetched from anywhere) that shows the animation as it renders,
//! frames streamed over a WebSocket as JPEG, and steers it: play, pause,
//! step, orbit and zoom, the lights, each effect, the shadow method, its
//! main setting and its cells.
//!
//! One thread owns the frame pipeline ([`engine::Sequence`], in this
//! process or through cluster workers) and applies the pages' controls
//! between frames; a change reruns only the stages it calls for (the
//! sequence's own bookkeeping: a camera move shades and draws, a light
//! move shadows, shades and draws, and none of them simulates). Each frame
//! is published as the latest; a page sends it when it can, so a slow or
//! stalled page misses frames and slows nobody. This crate and the
//! cluster crate are the only ones that know networking.

mod control;
mod server;
mod session;

pub use control::{Control, EFFECTS, MAX_MESSAGE};
pub use server::{Bound, MAX_VIEWERS, Options, run};
pub use session::Connect;

/// Errors of the viewer, each naming what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// A page's message that cannot be taken: not JSON, an unknown
    /// control, a field missing or out of range.
    #[error("bad message: {0}")]
    BadMessage(String),
    /// A camera control before the first frame framed the camera.
    #[error("the camera moves once the first frame is drawn")]
    NotYet,
    /// A frame that failed.
    #[error(transparent)]
    Engine(#[from] engine::EngineError),
    /// A picture that could not be encoded.
    #[error(transparent)]
    Raster(#[from] raster::RasterError),
    /// The address cannot be listened on.
    #[error("cannot listen on {addr}: {error}{}", busy_hint(error))]
    Listen {
        /// The address.
        addr: std::net::SocketAddr,
        /// Why.
        error: std::io::Error,
    },
    /// The server stopped with an error.
    #[error("the viewer's server failed: {0}")]
    Serve(std::io::Error),
    /// No access token could be made.
    #[error("no randomness for the access token: {0}")]
    Token(String),
}

/// What to do when the address is taken.
fn busy_hint(error: &std::io::Error) -> &'static str {
    if error.kind() == std::io::ErrorKind::AddrInUse {
        " (another program holds this port: give --listen 127.0.0.1:0 for a free one, or \
         another port)"
    } else {
        ""
    }
}
