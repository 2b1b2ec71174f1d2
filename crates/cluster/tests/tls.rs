//! Mutual TLS over real sockets on localhost: a coordinator with the
//! cluster's credentials gets the same bytes as one process, with the
//! workers compositing the pictures among themselves over TLS too; a
//! client with no certificate or a certificate from another CA is refused
//! by the worker; a coordinator refuses a worker whose certificate another
//! CA signed or that does not name the host dialled.

mod common;

use std::net::SocketAddr;
use std::sync::OnceLock;
use std::time::Duration;

use cluster::Listen;
use cluster::Pki;
use cluster::{ClusterError, RemoteExecutor, Tls};
use engine::{Executor, LocalExecutor, Strands};
use glam::Vec3;
use shadow::{DensityMap, Fiber, Light, LightFrame};
use strands::{Style, StyleParams, WispModel};

/// The cluster's credentials (workers valid for 127.0.0.1 and localhost).
fn pki() -> &'static Pki {
    static PKI: OnceLock<Pki> = OnceLock::new();
    PKI.get_or_init(|| Pki::generate(&["127.0.0.1".into(), "localhost".into()]).unwrap())
}

/// Another cluster's credentials.
fn other() -> &'static Pki {
    static PKI: OnceLock<Pki> = OnceLock::new();
    PKI.get_or_init(|| Pki::generate(&["127.0.0.1".into()]).unwrap())
}

/// Hair of this process, posed through no executor.
fn here(hair: &strands::Hair) -> Strands<'_> {
    Strands::Here { hair, posed: None }
}

/// A worker serving mutual TLS with `tls`, on a free port.
fn start_worker(tls: Tls) -> SocketAddr {
    common::start_worker_with(Listen {
        tls: Some(tls),
        health: None,
        token: None,
    })
    .0
}

fn fiber() -> Fiber {
    Fiber::new(0.1, 0.5).unwrap()
}

fn options(tls: Option<&Tls>, secs: u64) -> cluster::Options {
    cluster::Options {
        deadline: Duration::from_secs(secs),
        connect_timeout: Duration::from_secs(5),
        tls: tls.cloned(),
        token: None,
        // The strands are sent for any hair.
        draw: cluster::DrawAt::Coordinator,
    }
}

fn connect(addr: SocketAddr, tls: Option<&Tls>) -> Result<RemoteExecutor, ClusterError> {
    RemoteExecutor::connect(
        &[addr.to_string()],
        &engine::Scene::default(),
        &options(tls, 5),
    )
}

#[test]
fn a_coordinator_with_the_clusters_credentials_gets_the_local_bytes() {
    let addrs: Vec<String> = (0..2)
        .map(|_| start_worker(pki().worker()).to_string())
        .collect();
    let mut p = StyleParams::new(Style::Smooth);
    p.strands_per_wisp = 3;
    let hair = WispModel::generate(&p).interpolate();
    let light = Light::directional(Vec3::new(0.9, -0.35, -0.25)).unwrap();
    let frame = LightFrame::fit(&light, hair.points(), 64).unwrap();
    let tls = pki().coordinator();
    let mut remote =
        RemoteExecutor::connect(&addrs, &engine::Scene::default(), &options(Some(&tls), 20))
            .unwrap();
    let (mut a, mut b) = (DensityMap::new(frame), DensityMap::new(frame));
    LocalExecutor
        .density(0, &mut a, here(&hair), &fiber())
        .unwrap();
    remote.density(0, &mut b, here(&hair), &fiber()).unwrap();
    let ta = LocalExecutor.transmittance(0, &a).unwrap();
    let tb = remote.transmittance(0, &b).unwrap();
    let mut checked = 0;
    for p in hair.points().iter().step_by(7) {
        let (x, y) = (ta.optical_depth(*p, true), tb.optical_depth(*p, true));
        assert_eq!(x.to_bits(), y.to_bits(), "at {p}");
        checked += usize::from(x > 0.0);
    }
    assert!(checked > 100, "only {checked} shadowed points compared");
    // And the health check, over the same credentials.
    assert!(cluster::check_health(&addrs[0], Duration::from_secs(5), Some(&tls)).unwrap());
}

/// `frames` frames of the small dance drawn on `workers` workers serving
/// with `worker` and a coordinator dialling with `coordinator`, each
/// checked against one process: the bytes and times counted.
fn drawn_over_tls(
    worker: &Tls,
    coordinator: &Tls,
    workers: usize,
    frames: usize,
) -> (cluster::Traffic, cluster::Timing) {
    let scene =
        engine::Scene::from_toml_str(common::DANCE, std::path::Path::new("dance.toml")).unwrap();
    let want = common::local_frames(&scene, frames);
    let addrs: Vec<String> = (0..workers)
        .map(|_| start_worker(worker.clone()).to_string())
        .collect();
    let mut o = options(Some(coordinator), 20);
    o.draw = cluster::DrawAt::SortLast;
    let remote = RemoteExecutor::connect(&addrs, &scene, &o).unwrap();
    let (traffic, timing) = (remote.traffic(), remote.timing());
    let mut seq = engine::Sequence::new(&scene).unwrap();
    seq.set_executor(Box::new(remote)).unwrap();
    seq.expect_frames(want.len() as u64);
    for (i, w) in want.iter().enumerate() {
        assert!(seq.next_frame().unwrap().0 == w, "frame {i}");
    }
    let t = *traffic.lock().unwrap();
    (t, *timing.lock().unwrap())
}

#[test]
fn workers_composite_among_themselves_over_tls_with_the_local_bytes() {
    let (t, timing) = drawn_over_tls(&pki().worker(), &pki().coordinator(), 3, 3);
    assert!(
        t.stripes_between_workers > 0 && t.bands_received > 0,
        "{t:?}"
    );
    assert_eq!(t.layers_received, 0, "{t:?}");
    assert_eq!(timing.composite_fallbacks, 0);
    // The maps are summed and swept among them over TLS too.
    assert!(
        t.density_between_workers > 0 && t.slabs_received == 0,
        "{t:?}"
    );
    assert_eq!(timing.exchange_fallbacks, 0);
}

/// Credentials whose workers may serve but not call (an older kind of
/// worker certificate): the CA's PEM, the worker's and the coordinator's.
fn serve_only() -> (Tls, Tls) {
    use rcgen::ExtendedKeyUsagePurpose as Eku;
    let ca = common::TestCa::new();
    let worker = ca.leaf(&["127.0.0.1", cluster::WORKER_NAME], &[Eku::ServerAuth]);
    let coordinator = ca.leaf(&[cluster::COORDINATOR_NAME], &[Eku::ClientAuth]);
    (ca.tls(&worker), ca.tls(&coordinator))
}

#[test]
fn workers_that_cannot_call_each_other_leave_the_compositing_to_the_coordinator() {
    let (worker, coordinator) = serve_only();
    let (t, timing) = drawn_over_tls(&worker, &coordinator, 2, 4);
    // Two rounds fail (the workers refuse each other's certificate), then
    // the coordinator composites every frame; nobody is dropped. So with
    // summing and sweeping the maps: two Density rounds fail, then the
    // coordinator sums the densities and hands out the columns.
    assert_eq!(timing.composite_fallbacks, 2, "{timing:?}");
    assert_eq!(timing.exchange_fallbacks, 2, "{timing:?}");
    assert_eq!(timing.workers_lost, 0, "{timing:?}");
    assert!(t.layers_received > 0);
    assert!(t.density_sent > 0 && t.slabs_received > 0, "{t:?}");
}

#[test]
fn a_worker_refuses_clients_without_the_clusters_certificate() {
    let addr = start_worker(pki().worker());
    // No TLS at all.
    let e = connect(addr, None).unwrap_err();
    assert!(matches!(e, ClusterError::Connect { .. }), "{e}");
    assert!(e.to_string().contains("--tls-ca"), "no hint: {e}");
    // A client certificate from another CA (trusting the right server).
    let rogue = Tls::from_pem(
        pki().ca_cert.as_bytes(),
        other().coordinator_cert.as_bytes(),
        other().coordinator_key.as_bytes(),
    );
    let e = connect(addr, Some(&rogue)).unwrap_err();
    assert!(matches!(e, ClusterError::Connect { .. }), "{e}");
    assert!(e.to_string().contains(&addr.to_string()), "{e}");
    // A worker's own certificate gets through the handshake (workers call
    // each other to composite a picture) but may not drive a worker: no
    // session opens.
    let e = connect(addr, Some(&pki().worker())).unwrap_err();
    assert!(matches!(e, ClusterError::Refused { .. }), "{e}");
    assert!(e.to_string().contains(cluster::COORDINATOR_NAME), "{e}");
    // Health checks are refused the same way.
    assert!(cluster::check_health(&addr.to_string(), Duration::from_secs(5), None).is_err());
    // The worker still serves the right coordinator afterwards.
    assert!(connect(addr, Some(&pki().coordinator())).is_ok());
}

#[test]
fn a_coordinator_refuses_a_worker_it_cannot_verify() {
    // A worker whose certificate another CA signed.
    let stranger = start_worker(Tls::from_pem(
        pki().ca_cert.as_bytes(),
        other().worker_cert.as_bytes(),
        other().worker_key.as_bytes(),
    ));
    let e = connect(stranger, Some(&pki().coordinator())).unwrap_err();
    assert!(e.to_string().contains("certificate"), "{e}");
    // A worker of the cluster, dialled under a name its certificate lacks.
    let addr = start_worker(pki().worker());
    let wrong = pki().coordinator().with_domain("worker.example.org");
    let e = connect(addr, Some(&wrong)).unwrap_err();
    assert!(e.to_string().contains("certificate"), "{e}");
    let right = pki().coordinator().with_domain("localhost");
    assert!(connect(addr, Some(&right)).is_ok());
}

#[test]
fn a_coordinator_refuses_a_server_of_the_ca_that_is_no_worker() {
    // Certificates of one CA for the host dialled: a worker's, and two
    // without the worker's role (a server's made for something else, and
    // the coordinator's own certificate serving).
    use rcgen::ExtendedKeyUsagePurpose::{ClientAuth, ServerAuth};
    let ca = common::TestCa::new();
    let coordinator = ca.tls(&ca.leaf(&[cluster::COORDINATOR_NAME], &[ClientAuth]));
    let worker = ca.leaf(
        &["127.0.0.1", cluster::WORKER_NAME],
        &[ServerAuth, ClientAuth],
    );
    let stranger = ca.leaf(&["127.0.0.1"], &[ServerAuth]);
    let posing = ca.leaf(
        &["127.0.0.1", cluster::COORDINATOR_NAME],
        &[ServerAuth, ClientAuth],
    );
    for (what, cert) in [("a server", &stranger), ("a coordinator", &posing)] {
        let addr = start_worker(ca.tls(cert));
        let e = connect(addr, Some(&coordinator)).unwrap_err();
        assert!(matches!(e, ClusterError::Connect { .. }), "{what}: {e}");
        assert!(e.to_string().contains(cluster::WORKER_NAME), "{what}: {e}");
    }
    assert!(connect(start_worker(ca.tls(&worker)), Some(&coordinator)).is_ok());
}

#[test]
fn the_clusters_certificates_name_the_roles() {
    // `wisplight certs` makes the workers' certificate name the worker's
    // role, the coordinator's not.
    let pki = Pki::generate(&["10.0.0.2".into()]).unwrap();
    let names = |pem: &str| {
        use rustls_pki_types::pem::PemObject;
        let der = rustls_pki_types::CertificateDer::from_pem_slice(pem.as_bytes()).unwrap();
        let cert = webpki::EndEntityCert::try_from(&der).unwrap();
        [cluster::WORKER_NAME, cluster::COORDINATOR_NAME, "10.0.0.2"].map(|n| {
            let n = rustls_pki_types::ServerName::try_from(n).unwrap();
            cert.verify_is_valid_for_subject_name(&n).is_ok()
        })
    };
    assert_eq!(names(&pki.worker_cert), [true, false, true]);
    assert_eq!(names(&pki.coordinator_cert), [false, true, false]);
}

#[test]
fn credentials_that_are_not_pem_are_named() {
    let dir = std::env::temp_dir().join(format!("wisplight-tls-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let ca = write("ca.pem", &pki().ca_cert);
    let cert = write("c.pem", &pki().coordinator_cert);
    let key = write("c.key", &pki().coordinator_key);
    let junk = write("junk.pem", "not a certificate\n");
    assert!(Tls::load(&ca, &cert, &key).is_ok());
    // Swapped certificate and key.
    let e = Tls::load(&ca, &key, &cert).unwrap_err().to_string();
    assert!(e.contains("c.key") && e.contains("certificate"), "{e}");
    let e = Tls::load(&junk, &cert, &key).unwrap_err().to_string();
    assert!(e.contains("junk.pem"), "{e}");
    let e = Tls::load(&ca, &cert, &dir.join("missing.key"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing.key"), "{e}");
    // A PEM block with a label but garbage inside: rustls refuses it when
    // the worker starts, and the error says which files.
    let bad_key = write(
        "bad.key",
        "-----BEGIN PRIVATE KEY-----\nAAAA\n-----END PRIVATE KEY-----\n",
    );
    let tls = Tls::load(&ca, &cert, &bad_key).unwrap();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let e = rt
        .block_on(cluster::serve_worker(
            cluster::WorkerService::default(),
            "127.0.0.1:0".parse().unwrap(),
            &Listen {
                tls: Some(tls),
                health: None,
                token: None,
            },
            |_| {},
            std::future::pending(),
        ))
        .unwrap_err()
        .to_string();
    assert!(e.contains("bad.key"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_plain_health_port_answers_probes_and_nothing_else() {
    // A free port for the health server (bound, learnt, released).
    let health: SocketAddr = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let (addr, _keep) = common::start_worker_with(Listen {
        tls: Some(pki().worker()),
        health: Some(health),
        token: None,
    });
    let deadline = Duration::from_secs(5);
    assert!(cluster::check_health(&health.to_string(), deadline, None).unwrap());
    assert!(cluster::check_health(&addr.to_string(), deadline, None).is_err());
    // The health port serves no work.
    let e = connect(health, None).unwrap_err();
    assert!(e.to_string().contains("serves no wisplight worker"), "{e}");
}
