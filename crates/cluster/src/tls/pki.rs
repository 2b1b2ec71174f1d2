//! A small certificate authority for one cluster (`wisplight certs`).

use crate::ClusterError;

use super::{COORDINATOR_NAME, Tls, WORKER_NAME};

/// A small certificate authority for one cluster: a CA, one certificate
/// for every worker (server and client authentication, valid for `names`
/// and the role [`WORKER_NAME`]) and one for the coordinator (client
/// authentication, naming [`COORDINATOR_NAME`] and not the worker's role).
/// All PEM.
#[derive(Debug, Clone)]
pub struct Pki {
    /// The CA's certificate.
    pub ca_cert: String,
    /// The CA's private key (keep it off the nodes).
    pub ca_key: String,
    /// The workers' certificate.
    pub worker_cert: String,
    /// The workers' private key.
    pub worker_key: String,
    /// The coordinator's certificate.
    pub coordinator_cert: String,
    /// The coordinator's private key.
    pub coordinator_key: String,
}

impl Pki {
    /// Generates fresh ECDSA P-256 keys and certificates. `names` are the
    /// DNS names and IP addresses the workers are dialled by
    /// (`localhost`, `10.0.0.2`, `wisplight-worker-0.wisplight`).
    pub fn generate(names: &[String]) -> Result<Pki, ClusterError> {
        use rcgen::{
            BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer,
            KeyPair, KeyUsagePurpose,
        };
        let err = |e: rcgen::Error| ClusterError::Tls(format!("cannot make certificates: {e}"));
        if names.is_empty() {
            return Err(ClusterError::Tls(
                "the workers' certificate needs at least one name".into(),
            ));
        }
        if let Some(n) = names
            .iter()
            .find(|n| n.eq_ignore_ascii_case(COORDINATOR_NAME))
        {
            return Err(ClusterError::Tls(format!(
                "`{n}` is the coordinator's name: a worker's certificate naming it could drive \
                 other workers"
            )));
        }
        let mut ca = CertificateParams::new(Vec::<String>::new()).map_err(err)?;
        ca.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
        ca.distinguished_name
            .push(DnType::CommonName, "wisplight cluster CA");
        ca.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
        let ca_key = KeyPair::generate().map_err(err)?;
        let ca_cert = ca.self_signed(&ca_key).map_err(err)?;
        let issuer = Issuer::new(ca, ca_key);

        let leaf = |sans: Vec<String>, cn: &str, purposes: &[ExtendedKeyUsagePurpose]| {
            let mut p = CertificateParams::new(sans).map_err(err)?;
            p.distinguished_name.push(DnType::CommonName, cn);
            p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
            p.extended_key_usages = purposes.to_vec();
            p.use_authority_key_identifier_extension = true;
            let key = KeyPair::generate().map_err(err)?;
            let cert = p.signed_by(&key, &issuer).map_err(err)?;
            Ok::<_, ClusterError>((cert.pem(), key.serialize_pem()))
        };
        // Workers that composite a picture together call each other: their
        // certificate serves both ends. It names the worker's role, which
        // whoever dials a worker checks.
        let mut worker_names = names.to_vec();
        if !names.iter().any(|n| n.eq_ignore_ascii_case(WORKER_NAME)) {
            worker_names.push(WORKER_NAME.into());
        }
        let (worker_cert, worker_key) = leaf(
            worker_names,
            "wisplight worker",
            &[
                ExtendedKeyUsagePurpose::ServerAuth,
                ExtendedKeyUsagePurpose::ClientAuth,
            ],
        )?;
        let (coordinator_cert, coordinator_key) = leaf(
            vec![COORDINATOR_NAME.into()],
            "wisplight coordinator",
            &[ExtendedKeyUsagePurpose::ClientAuth],
        )?;
        Ok(Pki {
            ca_cert: ca_cert.pem(),
            ca_key: issuer.key().serialize_pem(),
            worker_cert,
            worker_key,
            coordinator_cert,
            coordinator_key,
        })
    }

    /// The worker's credentials.
    pub fn worker(&self) -> Tls {
        Tls::from_pem(
            self.ca_cert.as_bytes(),
            self.worker_cert.as_bytes(),
            self.worker_key.as_bytes(),
        )
    }

    /// The coordinator's credentials.
    pub fn coordinator(&self) -> Tls {
        Tls::from_pem(
            self.ca_cert.as_bytes(),
            self.coordinator_cert.as_bytes(),
            self.coordinator_key.as_bytes(),
        )
    }

    /// The files of a PKI directory: name, PEM text, and whether it is secret.
    pub fn files(&self) -> [(&'static str, &str, bool); 6] {
        [
            ("ca.pem", &self.ca_cert, false),
            ("ca.key", &self.ca_key, true),
            ("worker.pem", &self.worker_cert, false),
            ("worker.key", &self.worker_key, true),
            ("coordinator.pem", &self.coordinator_cert, false),
            ("coordinator.key", &self.coordinator_key, true),
        ]
    }
}
