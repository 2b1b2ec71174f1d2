//! The worker's open connections, by the client's address: a session
//! whose coordinator's connection has closed ends soon after, not at the
//! idle limit.

use std::collections::HashMap;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpStream;
use tonic::transport::server::{Connected, TcpConnectInfo};

/// How many connections are open from each client address.
#[derive(Debug, Default)]
pub(super) struct Connections {
    open: Mutex<HashMap<SocketAddr, usize>>,
}

impl Connections {
    /// Whether a connection from `addr` is open.
    pub(super) fn is_open(&self, addr: SocketAddr) -> bool {
        self.open
            .lock()
            .map(|o| o.get(&addr).is_some_and(|&n| n > 0))
            // A poisoned map knows nothing: keep the session.
            .unwrap_or(true)
    }

    /// `stream`, counted open until it is dropped.
    pub(super) fn track(self: &Arc<Self>, stream: TcpStream) -> Tracked {
        let addr = stream.peer_addr().ok();
        if let (Some(a), Ok(mut o)) = (addr, self.open.lock()) {
            *o.entry(a).or_default() += 1;
        }
        Tracked {
            inner: stream,
            addr,
            connections: self.clone(),
        }
    }
}

/// An accepted connection, counted in [`Connections`] while it lives.
#[derive(Debug)]
pub(super) struct Tracked {
    inner: TcpStream,
    addr: Option<SocketAddr>,
    connections: Arc<Connections>,
}

impl Drop for Tracked {
    fn drop(&mut self) {
        if let (Some(a), Ok(mut o)) = (self.addr, self.connections.open.lock())
            && let Some(n) = o.get_mut(&a)
        {
            *n -= 1;
            if *n == 0 {
                o.remove(&a);
            }
        }
    }
}

impl Connected for Tracked {
    type ConnectInfo = TcpConnectInfo;

    fn connect_info(&self) -> TcpConnectInfo {
        self.inner.connect_info()
    }
}

impl AsyncRead for Tracked {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl AsyncWrite for Tracked {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.inner).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.inner).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }
}
