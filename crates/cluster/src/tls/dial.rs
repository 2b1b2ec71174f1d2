//! Dialling a worker over TLS: a TCP connection, then a rustls handshake
//! that accepts the server only when its certificate chains to the
//! cluster's CA, names the host dialled and names [`WORKER_NAME`]. All of
//! it happens before tonic sends the first byte of HTTP/2, so a server
//! that fails any check sees the handshake alone: no call, no hair, no
//! session id.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;

use hyper_util::rt::TokioIo;
use rustls_pki_types::pem::PemObject;
use rustls_pki_types::{CertificateDer, PrivateKeyDer, ServerName, UnixTime};
use tokio::net::TcpStream;
use tokio_rustls::TlsConnector;
use tokio_rustls::client::TlsStream;
use tokio_rustls::rustls;
use tokio_rustls::rustls::client::danger::{
    HandshakeSignatureValid, ServerCertVerified, ServerCertVerifier,
};
use tokio_rustls::rustls::client::{WebPkiServerVerifier, verify_server_name};
use tokio_rustls::rustls::server::ParsedCertificate;
use tokio_rustls::rustls::{DigitallySignedStruct, SignatureScheme};

use super::{Tls, WORKER_NAME};
use crate::ClusterError;

/// What tonic's channel dials through: a [`tower::Service`] from the
/// channel's URI to a TLS stream.
pub(crate) type Connector = tower::util::BoxCloneSyncService<
    tonic::transport::Uri,
    TokioIo<TlsStream<TcpStream>>,
    std::io::Error,
>;

/// A connector for the worker at `addr` (host:port) with this side's
/// credentials `tls`. Errors name the credentials' files when rustls
/// refuses them.
pub(crate) fn connector(tls: &Tls, addr: &str) -> Result<Connector, ClusterError> {
    let name = ServerName::try_from(tls.name_for(addr)).map_err(|e| {
        ClusterError::Tls(format!(
            "`{}` is not a name a certificate can hold: {e}",
            tls.name_for(addr)
        ))
    })?;
    let config = Arc::new(client_config(tls)?);
    let addr = addr.to_string();
    let connect = move |_: tonic::transport::Uri| {
        let (config, name, addr) = (config.clone(), name.clone(), addr.clone());
        Box::pin(async move {
            let tcp = TcpStream::connect(&addr).await?;
            tcp.set_nodelay(true)?;
            let stream = TlsConnector::from(config).connect(name, tcp).await?;
            Ok(TokioIo::new(stream))
        }) as Pin<Box<dyn Future<Output = _> + Send>>
    };
    Ok(tower::util::BoxCloneSyncService::new(tower::service_fn(
        connect,
    )))
}

/// The rustls client side: this side's certificate for the worker to
/// check, HTTP/2 by ALPN, and [`WorkerRole`] to check the worker.
fn client_config(tls: &Tls) -> Result<rustls::ClientConfig, ClusterError> {
    let bad = |what: &str, e: &dyn std::fmt::Display| {
        ClusterError::Tls(format!("{} were refused: {what}: {e}", tls.origin))
    };
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let mut roots = rustls::RootCertStore::empty();
    for ca in CertificateDer::pem_slice_iter(&tls.ca) {
        let ca = ca.map_err(|e| bad("the CA certificate", &e))?;
        roots.add(ca).map_err(|e| bad("the CA certificate", &e))?;
    }
    let chain = CertificateDer::pem_slice_iter(&tls.cert)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| bad("the certificate", &e))?;
    let key = PrivateKeyDer::from_pem_slice(&tls.key).map_err(|e| bad("the private key", &e))?;
    let webpki = WebPkiServerVerifier::builder_with_provider(Arc::new(roots), provider.clone())
        .build()
        .map_err(|e| bad("the CA certificate", &e))?;
    let mut config = rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| bad("the protocol versions", &e))?
        .dangerous()
        .with_custom_certificate_verifier(Arc::new(WorkerRole { webpki }))
        .with_client_auth_cert(chain, key)
        .map_err(|e| bad("the certificate and key", &e))?;
    config.alpn_protocols = vec![b"h2".to_vec()];
    Ok(config)
}

/// The check of a server's certificate: rustls's own (chain to the CA,
/// validity dates, the name dialled), then the worker's role.
#[derive(Debug)]
struct WorkerRole {
    webpki: Arc<WebPkiServerVerifier>,
}

impl ServerCertVerifier for WorkerRole {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        intermediates: &[CertificateDer<'_>],
        server_name: &ServerName<'_>,
        ocsp_response: &[u8],
        now: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        self.webpki.verify_server_cert(
            end_entity,
            intermediates,
            server_name,
            ocsp_response,
            now,
        )?;
        // Signed by the CA: now the role. A certificate of the CA that
        // does not name the worker role (the coordinator's, or one made
        // for anything else) serves no round.
        let role = ServerName::try_from(WORKER_NAME)
            .map_err(|e| rustls::Error::General(format!("{WORKER_NAME}: {e}")))?;
        verify_server_name(&ParsedCertificate::try_from(end_entity)?, &role)?;
        Ok(ServerCertVerified::assertion())
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        self.webpki.verify_tls12_signature(message, cert, dss)
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        self.webpki.verify_tls13_signature(message, cert, dss)
    }

    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        self.webpki.supported_verify_schemes()
    }
}
