//! Mutual TLS between the coordinator and its workers (rustls; tonic
//! serves, [`dial`] connects).
//!
//! Both sides hold the same three PEM files' roles: a CA certificate that
//! signed the *other* side's certificate, their own certificate chain, and
//! their own private key. With TLS on, a worker accepts a connection only
//! from a client whose certificate chains to its CA.
//!
//! Roles, each a DNS name among a certificate's subject alternative names:
//! - Serving: whoever dials a worker (the coordinator, or a fellow worker
//!   in a round) talks to it only once the handshake showed a certificate
//!   of the CA that names the host dialled (or `--tls-domain`) **and**
//!   [`WORKER_NAME`], before any byte of a call is sent.
//! - Calling: every certificate of the CA gets through a worker's
//!   handshake, but only one that names [`COORDINATOR_NAME`] may drive a
//!   worker (Hello, Assign, Simulate and the stages). Workers' certificates do
//!   not name it: they may only make the calls workers make of each other
//!   (Prove, Exchange and Composite).

mod dial;
mod pki;

use std::path::Path;

use tonic::transport::{Certificate, Identity, ServerTlsConfig};

use crate::ClusterError;

pub(crate) use dial::{Connector, connector};
pub use pki::Pki;

/// The DNS name (subject alternative name) that makes a client
/// certificate a coordinator's.
pub const COORDINATOR_NAME: &str = "wisplight-coordinator";

/// The DNS name (subject alternative name) that makes a certificate a
/// worker's: no one dials a server whose certificate lacks it.
pub const WORKER_NAME: &str = "wisplight-worker";

/// Who may make a call, when the worker serves mutual TLS.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Caller {
    /// Only a coordinator: its certificate names [`COORDINATOR_NAME`].
    Coordinator,
    /// A fellow worker or a coordinator: any certificate of the CA.
    Peer,
}

/// Whether a client that presented `certs` (leaf first; `None` without
/// TLS) may make a call meant for `caller`. Without TLS, roles are not
/// told apart (the cluster token guards the calls).
pub(crate) fn may_call(
    certs: Option<&[tonic::transport::CertificateDer<'static>]>,
    caller: Caller,
) -> Result<(), tonic::Status> {
    let Some(certs) = certs else {
        return Ok(());
    };
    if caller == Caller::Peer {
        return Ok(());
    }
    let named = certs.first().is_some_and(|leaf| names_coordinator(leaf));
    if named {
        Ok(())
    } else {
        Err(tonic::Status::permission_denied(format!(
            "only a coordinator may make this call: the client's certificate does not name \
             `{COORDINATOR_NAME}` (a worker's certificate cannot drive workers; use \
             coordinator.pem from `wisplight certs`)"
        )))
    }
}

/// [`may_call`] for the client of `req`.
pub(crate) fn request_may_call<T>(
    req: &tonic::Request<T>,
    caller: Caller,
) -> Result<(), tonic::Status> {
    may_call(req.peer_certs().as_deref().map(|c| c.as_slice()), caller)
}

/// Whether the certificate `der` is valid for the DNS name
/// [`COORDINATOR_NAME`] (its subject alternative names, as a server name
/// is checked; wildcards do not match a name without dots).
fn names_coordinator(der: &tonic::transport::CertificateDer<'_>) -> bool {
    let Ok(cert) = webpki::EndEntityCert::try_from(der) else {
        return false;
    };
    rustls_pki_types::ServerName::try_from(COORDINATOR_NAME)
        .is_ok_and(|name| cert.verify_is_valid_for_subject_name(&name).is_ok())
}

/// One side's credentials for mutual TLS, read and checked from PEM files.
#[derive(Debug, Clone)]
pub struct Tls {
    /// The CA certificate that signs the other side's, PEM.
    ca: Vec<u8>,
    /// This side's certificate chain, PEM.
    cert: Vec<u8>,
    /// This side's private key, PEM.
    key: Vec<u8>,
    /// The name the coordinator expects in a worker's certificate instead
    /// of the host part of its address.
    domain: Option<String>,
    /// Where the credentials came from, for error messages.
    origin: String,
}

impl Tls {
    /// Reads the CA certificate that signs the peers' certificates, this
    /// side's certificate (chain) and its private key, all PEM. Errors name
    /// the file and what is missing from it.
    pub fn load(ca: &Path, cert: &Path, key: &Path) -> Result<Tls, ClusterError> {
        let read = |p: &Path| {
            std::fs::read(p)
                .map_err(|e| ClusterError::Tls(format!("cannot read {}: {e}", p.display())))
        };
        let (ca_pem, cert_pem, key_pem) = (read(ca)?, read(cert)?, read(key)?);
        check_pem(&ca_pem, ca, "CERTIFICATE", "a CA certificate")?;
        check_pem(&cert_pem, cert, "CERTIFICATE", "a certificate")?;
        check_pem(&key_pem, key, "PRIVATE KEY", "a private key")?;
        let mut tls = Tls::from_pem(&ca_pem, &cert_pem, &key_pem);
        tls.origin = format!(
            "--tls-ca {}, --tls-cert {}, --tls-key {}",
            ca.display(),
            cert.display(),
            key.display()
        );
        Ok(tls)
    }

    /// Credentials from PEM text already in memory (tests, embedding).
    pub fn from_pem(ca: &[u8], cert: &[u8], key: &[u8]) -> Tls {
        Tls {
            ca: ca.to_vec(),
            cert: cert.to_vec(),
            key: key.to_vec(),
            domain: None,
            origin: "the TLS credentials".into(),
        }
    }

    /// The name to expect in a worker's certificate, instead of the host
    /// part of the address dialled.
    pub fn with_domain(mut self, domain: impl Into<String>) -> Tls {
        self.domain = Some(domain.into());
        self
    }

    /// The name expected in a worker's certificate, when set.
    pub fn domain(&self) -> Option<&str> {
        self.domain.as_deref()
    }

    /// A worker's server side: its own identity, and client certificates
    /// required and checked against the CA.
    pub(crate) fn server_config(&self) -> ServerTlsConfig {
        ServerTlsConfig::new()
            .identity(Identity::from_pem(&self.cert, &self.key))
            .client_ca_root(Certificate::from_pem(&self.ca))
            .client_auth_optional(false)
    }

    /// The name a worker dialled at `addr` (host:port) must show in its
    /// certificate: `--tls-domain`, or the host part of the address.
    fn name_for(&self, addr: &str) -> String {
        self.domain.clone().unwrap_or_else(|| host_of(addr))
    }

    /// Says which files were at fault when rustls refuses them.
    pub(crate) fn refused(&self, e: &dyn std::error::Error) -> ClusterError {
        ClusterError::Tls(format!(
            "{} were refused: {}",
            self.origin,
            crate::error::root_cause(e)
        ))
    }
}

/// A failed connection's message, with a hint when TLS on one side only
/// (or a refused certificate) is the likely cause: a worker that refuses a
/// handshake just closes the connection, which reads as a broken pipe.
pub(crate) fn explain(tls: Option<&Tls>, msg: String) -> String {
    const NETWORK: [&str; 6] = [
        "refused",
        "timed out",
        "deadline",
        "lookup",
        "No route",
        "unreachable",
    ];
    if NETWORK.iter().any(|n| msg.contains(n)) {
        return msg;
    }
    match tls {
        None => format!(
            "{msg} (if the worker serves mutual TLS, pass --tls-ca, --tls-cert and --tls-key)"
        ),
        Some(_) if !msg.contains("certificate") => format!(
            "{msg} (the worker may have refused this side's certificate: is it signed by the \
             CA the worker trusts, for client authentication? does the worker serve TLS?)"
        ),
        Some(_) if msg.contains(WORKER_NAME) => format!(
            "{msg} (a worker's certificate names the worker's role `{WORKER_NAME}`; \
             `wisplight certs` makes such certificates, older ones lack it)"
        ),
        Some(_) => msg,
    }
}

/// "10.0.0.2:7000" -> "10.0.0.2", "[::1]:7000" -> "::1", "w0.svc:7000" ->
/// "w0.svc".
fn host_of(addr: &str) -> String {
    let host = match addr.rsplit_once(':') {
        Some((h, port)) if port.bytes().all(|b| b.is_ascii_digit()) => h,
        _ => addr,
    };
    host.trim_start_matches('[')
        .trim_end_matches(']')
        .to_string()
}

/// Checks that `pem` holds a `-----BEGIN ...<label>-----` block, so a
/// swapped or empty file is named before any handshake.
fn check_pem(pem: &[u8], path: &Path, label: &str, what: &str) -> Result<(), ClusterError> {
    let text = String::from_utf8_lossy(pem);
    let end = format!("{label}-----");
    if text
        .lines()
        .any(|l| l.starts_with("-----BEGIN ") && l.trim_end().ends_with(&end))
    {
        Ok(())
    } else {
        Err(ClusterError::Tls(format!(
            "{} holds no PEM block `{label}`: expected {what}",
            path.display()
        )))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn host_of_strips_the_port_and_brackets() {
        assert_eq!(host_of("10.0.0.2:7000"), "10.0.0.2");
        assert_eq!(host_of("[::1]:7000"), "::1");
        assert_eq!(
            host_of("wisplight-worker-0.wisplight:7000"),
            "wisplight-worker-0.wisplight"
        );
        assert_eq!(host_of("localhost"), "localhost");
    }

    #[test]
    fn pem_blocks_are_checked_by_label() {
        let p = Path::new("x.pem");
        let cert = b"-----BEGIN CERTIFICATE-----\nAAAA\n-----END CERTIFICATE-----\n";
        let key = b"-----BEGIN PRIVATE KEY-----\nAAAA\n-----END PRIVATE KEY-----\n";
        let ec = b"-----BEGIN EC PRIVATE KEY-----\nAAAA\n-----END EC PRIVATE KEY-----\n";
        assert!(check_pem(cert, p, "CERTIFICATE", "a certificate").is_ok());
        assert!(check_pem(key, p, "PRIVATE KEY", "a key").is_ok());
        assert!(check_pem(ec, p, "PRIVATE KEY", "a key").is_ok());
        let e = check_pem(key, p, "CERTIFICATE", "a certificate").unwrap_err();
        assert!(e.to_string().contains("x.pem"), "{e}");
        assert!(check_pem(b"", p, "PRIVATE KEY", "a key").is_err());
    }

    fn leaf_der(pem: &str) -> tonic::transport::CertificateDer<'static> {
        use rustls_pki_types::pem::PemObject;
        tonic::transport::CertificateDer::from_pem_slice(pem.as_bytes()).unwrap()
    }

    #[test]
    fn only_the_coordinators_certificate_may_drive_a_worker() {
        let pki = Pki::generate(&["localhost".into(), "10.0.0.2".into()]).unwrap();
        let coordinator = [leaf_der(&pki.coordinator_cert)];
        let worker = [leaf_der(&pki.worker_cert)];
        assert!(may_call(Some(&coordinator), Caller::Coordinator).is_ok());
        assert!(may_call(Some(&coordinator), Caller::Peer).is_ok());
        assert!(may_call(Some(&worker), Caller::Peer).is_ok());
        let e = may_call(Some(&worker), Caller::Coordinator).unwrap_err();
        assert_eq!(e.code(), tonic::Code::PermissionDenied);
        assert!(e.message().contains(COORDINATOR_NAME), "{}", e.message());
        // Garbage instead of a certificate, or none, is no coordinator.
        let junk = [tonic::transport::CertificateDer::from(vec![
            0x30, 0x03, 1, 2, 3,
        ])];
        assert!(may_call(Some(&junk), Caller::Coordinator).is_err());
        assert!(may_call(Some(&[]), Caller::Coordinator).is_err());
        // Without TLS the roles are not told apart.
        assert!(may_call(None, Caller::Coordinator).is_ok());
    }

    #[test]
    fn a_workers_certificate_may_not_carry_the_coordinators_name() {
        let e = Pki::generate(&["localhost".into(), "Wisplight-Coordinator".into()])
            .unwrap_err()
            .to_string();
        assert!(e.contains("coordinator's name"), "{e}");
    }
}
