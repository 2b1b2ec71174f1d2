//! What the in-process protocol tests share.

use std::net::SocketAddr;
use std::time::Duration;

use cluster::Listen;
use engine::{Scene, Sequence};

/// A small simulated scene: the smooth style, thinned, on a dancing head.
#[allow(dead_code)]
pub(crate) const DANCE: &str = r#"
[hair]
style = "smooth"
strands_per_wisp = 4

[render]
width = 160
height = 90

[animation]
motion = "dance"
fps = 30

[dynamics]
settle = 0.1
"#;

/// `frames` pictures of `scene` in one process, as `render --frames` makes them.
#[allow(dead_code)]
pub(crate) fn local_frames(scene: &Scene, frames: usize) -> Vec<image::RgbImage> {
    let mut seq = Sequence::new(scene).unwrap();
    // As `render --frames` does: the camera frames all of them.
    seq.expect_frames(frames as u64);
    (0..frames)
        .map(|_| seq.next_frame().unwrap().0.clone())
        .collect()
}

/// A worker on a free localhost port in a background runtime, listening as
/// `listen` says, and a switch that stops it (the server closes; calls in
/// flight finish, new ones find no server). A dropped switch never stops
/// the worker.
pub(crate) fn start_worker_with(listen: Listen) -> (SocketAddr, tokio::sync::oneshot::Sender<()>) {
    start_service(cluster::WorkerService::default(), listen)
}

/// [`start_worker_with`] for `service`.
#[allow(dead_code)]
pub(crate) fn start_service(
    service: cluster::WorkerService,
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
        rt.block_on(cluster::serve_worker(
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

/// A client of the worker at `addr` that has said Hello, naming the
/// session it opened in every call.
#[allow(dead_code)]
pub(crate) async fn greeted_client(addr: SocketAddr) -> cluster::SessionClient {
    let channel = tonic::transport::Endpoint::from_shared(format!("http://{addr}"))
        .unwrap()
        .connect()
        .await
        .unwrap();
    greeted_on(channel).await
}

/// [`greeted_client`] over mutual TLS: `ca` is the CA's PEM, `cert` and
/// `key` the client's, the worker's certificate must name `localhost`.
/// (tonic's own TLS client, not the crate's dialling.)
#[allow(dead_code)]
pub(crate) async fn greeted_tls_client(
    addr: SocketAddr,
    ca: &str,
    (cert, key): (&str, &str),
) -> cluster::SessionClient {
    use tonic::transport::{Certificate, ClientTlsConfig, Identity};
    let tls = ClientTlsConfig::new()
        .ca_certificate(Certificate::from_pem(ca))
        .identity(Identity::from_pem(cert, key))
        .domain_name("localhost");
    let channel = tonic::transport::Endpoint::from_shared(format!("https://{addr}"))
        .unwrap()
        .tls_config(tls)
        .unwrap()
        .connect()
        .await
        .unwrap();
    greeted_on(channel).await
}

/// A client on `channel` that has said Hello.
async fn greeted_on(channel: tonic::transport::Channel) -> cluster::SessionClient {
    let id = cluster::pb::worker_client::WorkerClient::new(channel.clone())
        .hello(cluster::pb::HelloRequest {
            protocol_version: cluster::protocol::PROTOCOL_VERSION,
            fiber_width: 0.1,
            fiber_opacity: 0.5,
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner()
        .session;
    cluster::pb::worker_client::WorkerClient::with_interceptor(
        channel,
        cluster::SessionHeader::new(&id).unwrap(),
    )
}

/// A certificate authority of a test's own, to sign certificates
/// `wisplight certs` never makes (a server of the CA without a worker's
/// role, a worker that may serve but not call).
#[allow(dead_code)]
pub(crate) struct TestCa {
    /// The CA's certificate, PEM.
    pub(crate) pem: String,
    issuer: rcgen::Issuer<'static, rcgen::KeyPair>,
}

#[allow(dead_code)]
impl TestCa {
    pub(crate) fn new() -> TestCa {
        use rcgen::{BasicConstraints, CertificateParams, IsCa, Issuer, KeyPair};
        let mut ca = CertificateParams::new(Vec::<String>::new()).unwrap();
        ca.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
        let key = KeyPair::generate().unwrap();
        let pem = ca.self_signed(&key).unwrap().pem();
        TestCa {
            pem,
            issuer: Issuer::new(ca, key),
        }
    }

    /// A certificate for `names` with the extended key usages `eku`, and
    /// its key: (certificate PEM, key PEM).
    pub(crate) fn leaf(
        &self,
        names: &[&str],
        eku: &[rcgen::ExtendedKeyUsagePurpose],
    ) -> (String, String) {
        let names = names.iter().map(|n| n.to_string()).collect::<Vec<_>>();
        let mut p = rcgen::CertificateParams::new(names).unwrap();
        p.extended_key_usages = eku.to_vec();
        let key = rcgen::KeyPair::generate().unwrap();
        let cert = p.signed_by(&key, &self.issuer).unwrap();
        (cert.pem(), key.serialize_pem())
    }

    /// [`cluster::Tls`] of this CA with a leaf's PEM.
    pub(crate) fn tls(&self, (cert, key): &(String, String)) -> cluster::Tls {
        cluster::Tls::from_pem(self.pem.as_bytes(), cert.as_bytes(), key.as_bytes())
    }
}

/// A TLS server on a free localhost port, with the certificate `cert` and
/// key `key` (PEM) and no client certificate asked, that for `secs`
/// seconds accepts connections and records what each sends once the
/// handshake is through. Joined: the connections accepted, and every
/// decrypted byte.
#[allow(dead_code)]
pub(crate) fn recording_tls_listener(
    secs: u64,
    cert: &str,
    key: &str,
) -> (String, std::thread::JoinHandle<(usize, Vec<u8>)>) {
    use rustls_pki_types::pem::PemObject;
    use tokio::io::AsyncReadExt;
    use tokio_rustls::rustls;
    let chain = rustls_pki_types::CertificateDer::pem_slice_iter(cert.as_bytes())
        .collect::<Result<Vec<_>, _>>()
        .unwrap();
    let key = rustls_pki_types::PrivateKeyDer::from_pem_slice(key.as_bytes()).unwrap();
    let mut config = rustls::ServerConfig::builder_with_provider(std::sync::Arc::new(
        rustls::crypto::ring::default_provider(),
    ))
    .with_safe_default_protocol_versions()
    .unwrap()
    .with_no_client_auth()
    .with_single_cert(chain, key)
    .unwrap();
    config.alpn_protocols = vec![b"h2".to_vec()];
    let acceptor = tokio_rustls::TlsAcceptor::from(std::sync::Arc::new(config));
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap().to_string();
    l.set_nonblocking(true).unwrap();
    let seen = std::thread::spawn(move || {
        let rt = tokio::runtime::Runtime::new().unwrap();
        rt.block_on(async move {
            let l = tokio::net::TcpListener::from_std(l).unwrap();
            let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<Vec<u8>>();
            let mut accepted = 0;
            let until = tokio::time::Instant::now() + Duration::from_secs(secs);
            while let Ok(Ok((tcp, _))) = tokio::time::timeout_at(until, l.accept()).await {
                accepted += 1;
                let (acceptor, tx) = (acceptor.clone(), tx.clone());
                tokio::spawn(async move {
                    let Ok(mut s) = acceptor.accept(tcp).await else {
                        return;
                    };
                    let mut buf = vec![0u8; 65536];
                    while let Ok(n) = s.read(&mut buf).await {
                        if n == 0 || tx.send(buf[..n].to_vec()).is_err() {
                            break;
                        }
                    }
                });
            }
            drop(tx);
            let mut got = Vec::new();
            while let Ok(b) = rx.try_recv() {
                got.extend(b);
            }
            (accepted, got)
        })
    });
    (addr, seen)
}

/// The proof of `parts` for the label `purpose` with `key`, as
/// proto/README.md and the protocol's comments define it: HMAC-SHA-256
/// of the label and each part, every one preceded by its length (4
/// bytes, big-endian). Written here from the definition, not from the
/// crate's code.
#[allow(dead_code)]
pub(crate) fn proof(key: &[u8], purpose: &str, parts: &[&[u8]]) -> Vec<u8> {
    let mut m = Vec::new();
    for p in std::iter::once(purpose.as_bytes()).chain(parts.iter().copied()) {
        m.extend_from_slice(&(p.len() as u32).to_be_bytes());
        m.extend_from_slice(p);
    }
    let k = ring::hmac::Key::new(ring::hmac::HMAC_SHA256, key);
    ring::hmac::sign(&k, &m).as_ref().to_vec()
}

/// A Hello (fiber 0.1 wide, 0.5 opaque) that answers a challenge `c`'s
/// worker gives now with the proof of `token`.
#[allow(dead_code)]
pub(crate) async fn proved_hello(
    c: &mut cluster::pb::worker_client::WorkerClient<tonic::transport::Channel>,
    token: &str,
) -> cluster::pb::HelloRequest {
    let challenge = c
        .challenge(cluster::pb::ChallengeRequest {})
        .await
        .unwrap()
        .into_inner()
        .nonce;
    let mine = [7u8; 16];
    cluster::pb::HelloRequest {
        protocol_version: cluster::protocol::PROTOCOL_VERSION,
        fiber_width: 0.1,
        fiber_opacity: 0.5,
        proof: proof(token.as_bytes(), "wisplight hello", &[&challenge, &mine]),
        challenge,
        client_nonce: mine.to_vec(),
    }
}

/// [`greeted_client`] of a worker with the cluster token `token`: its
/// Hello answers the worker's challenge with the token's proof, and the
/// worker's proof back is checked.
#[allow(dead_code)]
pub(crate) async fn proved_client(addr: SocketAddr, token: &str) -> cluster::SessionClient {
    use cluster::pb;
    let channel = tonic::transport::Endpoint::from_shared(format!("http://{addr}"))
        .unwrap()
        .connect()
        .await
        .unwrap();
    let mut c = pb::worker_client::WorkerClient::new(channel.clone());
    let hello = proved_hello(&mut c, token).await;
    let reply = c.hello(hello.clone()).await.unwrap().into_inner();
    let back = proof(
        token.as_bytes(),
        "wisplight worker",
        &[&hello.client_nonce, reply.session.as_bytes()],
    );
    assert_eq!(reply.proof, back, "the worker proved the token back");
    pb::worker_client::WorkerClient::with_interceptor(
        channel,
        cluster::SessionHeader::new(&reply.session).unwrap(),
    )
}
