//! Cluster mode as a user runs it: three worker processes on localhost
//! (ephemeral ports), a coordinator, and the same bytes as `render`, even
//! when a worker dies mid-animation, and two coordinators sharing workers
//! (and a silent address) each get their own pictures.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

mod common;

use common::Worker;

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_wisplight")
}

/// The workers' addresses, comma-separated, for `--workers`.
fn addr_list(workers: &[Worker]) -> String {
    workers
        .iter()
        .map(|w| w.addr.as_str())
        .collect::<Vec<_>>()
        .join(",")
}

/// The bytes of frame `i` of a `%d` file pattern.
fn frame_bytes(pattern: &Path, i: usize) -> Vec<u8> {
    std::fs::read(pattern.to_str().unwrap().replace("%d", &i.to_string())).unwrap()
}

fn run(args: &[&str]) -> Output {
    Command::new(bin()).args(args).output().unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("wisplight-cluster-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `frames` frames of `scene` by `render` into `local` (which must work)
/// and by a coordinator of `workers` into `remote`, the hair drawn where
/// `draw` says: the coordinator's output.
fn render_both_drawing(
    scene: &Path,
    workers: &str,
    frames: &str,
    local: &Path,
    remote: &Path,
    draw: &str,
) -> Output {
    let o = run(&["render", s(scene), "--frames", frames, "-o", s(local)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    run(&[
        "coordinator",
        s(scene),
        "--workers",
        workers,
        "--frames",
        frames,
        "--draw",
        draw,
        "-o",
        s(remote),
    ])
}

/// The smooth style, small, on a dancing head.
const SCENE: &str = "[hair]\nstyle = \"smooth\"\nstrands_per_wisp = 4\n\n[render]\nwidth = 160\nheight = 90\n\n[animation]\nmotion = \"dance\"\n\n[dynamics]\nsettle = 0.1\n";

#[test]
fn three_workers_render_the_same_bytes_as_one_process_and_stop_on_sigterm() {
    let dir = scratch("same");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let workers: Vec<Worker> = (0..3).map(|_| Worker::start()).collect();
    let list = addr_list(&workers);

    // A still (frame 0) and a short animation, drawn on the workers
    // (`auto`, the default, sort-middle and sort-last) and on the
    // coordinator (the paper's scheme).
    for (frames, name, draw) in [
        ("1", "still_%d.png", "auto"),
        ("3", "anim_%d.png", "auto"),
        ("3", "middle_%d.png", "sort-middle"),
        ("3", "last_%d.png", "sort-last"),
        ("3", "paper_%d.png", "coordinator"),
    ] {
        let local = dir.join(format!("local_{name}"));
        let remote = dir.join(format!("remote_{name}"));
        let o = render_both_drawing(&scene, &list, frames, &local, &remote, draw);
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{e}");
        assert!(e.contains("3 workers, bytes on the wire: frame 0"), "{e}");
        for i in 0..frames.parse::<usize>().unwrap() {
            let (a, b) = (frame_bytes(&local, i), frame_bytes(&remote, i));
            assert!(
                a == b,
                "frame {i} of {frames} differs between one process and three workers ({draw} drawing)"
            );
        }
    }
    for w in workers {
        let status = w.stop();
        assert!(
            status.success(),
            "a worker stops cleanly on SIGTERM: {status}"
        );
    }
}

#[test]
fn a_worker_killed_mid_animation_changes_no_byte_and_is_reported() {
    let dir = scratch("kill");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, SCENE).unwrap();
    // The second worker is killed (SIGKILL) once the coordinator has
    // written its third frame: mid-animation, at whatever stage it is in.
    let mut workers = [Worker::start(), Worker::start(), Worker::start()];
    let list = addr_list(&workers);
    let (frames, n) = ("12", 12);
    let local = dir.join("local_%d.png");
    let remote = dir.join("remote_%d.png");
    let o = run(&["render", s(&scene), "--frames", frames, "-o", s(&local)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let coordinator = Command::new(bin())
        .args([
            "coordinator",
            s(&scene),
            "--workers",
            &list,
            "--frames",
            frames,
            "-o",
        ])
        .arg(&remote)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let third = dir.join("remote_2.png");
    for _ in 0..3000 {
        if third.exists() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    assert!(third.exists(), "the coordinator wrote its third frame");
    let killed = dir.join(format!("remote_{}.png", n - 1));
    assert!(!killed.exists(), "the last frame is not written yet");
    workers[1].child.kill().unwrap();
    workers[1].child.wait().unwrap();
    let o = coordinator.wait_with_output().unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{e}");
    assert!(
        e.contains("worker lost")
            && e.contains(&workers[1].addr)
            && e.contains("1 lost on the way"),
        "the loss is logged with the worker's address: {e}"
    );
    for i in 0..n {
        let (a, b) = (frame_bytes(&local, i), frame_bytes(&remote, i));
        assert!(a == b, "frame {i} differs after a worker died");
    }
}

#[test]
fn a_coordinator_without_reachable_workers_says_which_and_fails() {
    let dir = scratch("dead");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, SCENE).unwrap();
    // A port that was free a moment ago.
    let free = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .to_string();
    let o = run(&[
        "coordinator",
        s(&scene),
        "--workers",
        &free,
        "--deadline",
        "2",
        "-o",
        s(&dir.join("x.png")),
    ]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains(&free) && e.lines().count() == 1, "{e}");
    assert!(!dir.join("x.png").exists());
    let o = run(&["coordinator", s(&scene), "-o", s(&dir.join("x.png"))]);
    assert_eq!(o.status.code(), Some(2), "--workers is required");
    let o = run(&[
        "coordinator",
        s(&scene),
        "--workers",
        &free,
        "--deadline",
        "0",
    ]);
    assert_eq!(o.status.code(), Some(2));
}

/// Another scene: other hair, another fiber, another size.
const CURLY: &str = "[hair]\nstyle = \"curly\"\nstrands_per_wisp = 3\n\n[fiber]\nwidth = 0.2\nopacity = 0.6\n\n[render]\nwidth = 120\nheight = 80\n\n[shadow]\ncells = 48\n\n[animation]\nmotion = \"dance\"\n\n[dynamics]\nsettle = 0.1\n";

#[test]
fn two_coordinators_share_workers_and_a_silent_one_each_getting_its_own_pictures() {
    let dir = scratch("shared");
    let workers: Vec<Worker> = (0..2).map(|_| Worker::start()).collect();
    // Accepts connections and never answers.
    let silent = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let list = format!(
        "{},{},{}",
        workers[0].addr,
        silent.local_addr().unwrap(),
        workers[1].addr
    );
    let runs: Vec<(&str, PathBuf, PathBuf, Child)> = [("smooth", SCENE), ("curly", CURLY)]
        .into_iter()
        .map(|(name, text)| {
            let scene = dir.join(format!("{name}.toml"));
            std::fs::write(&scene, text).unwrap();
            let out = dir.join(format!("{name}_remote_%d.png"));
            let child = Command::new(bin())
                .args(["coordinator", s(&scene), "--workers", &list])
                .args(["--connect-timeout", "2", "--frames", "4", "-o", s(&out)])
                .stderr(Stdio::piped())
                .spawn()
                .unwrap();
            (name, scene, out, child)
        })
        .collect();
    for (name, scene, out, child) in runs {
        let o = child.wait_with_output().unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{name}: {e}");
        assert!(e.contains(&silent.local_addr().unwrap().to_string()), "{e}");
        assert!(e.contains("2 workers, bytes on the wire"), "{e}");
        let local = dir.join(format!("{name}_local_%d.png"));
        let r = run(&["render", s(&scene), "--frames", "4", "-o", s(&local)]);
        assert!(r.status.success());
        for i in 0..4 {
            let frame = |p: &Path| p.to_str().unwrap().replace("%d", &i.to_string());
            assert!(
                std::fs::read(frame(&local)).unwrap() == std::fs::read(frame(&out)).unwrap(),
                "frame {i} of {name} differs from one process"
            );
        }
    }
}

#[test]
fn bench_scaling_reports_every_configuration_and_writes_its_plot() {
    let dir = scratch("scaling");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let plot = dir.join("scaling.png");
    let o = run(&[
        "bench",
        "scaling",
        s(&scene),
        "--workers",
        "1,2",
        "--draw",
        "sort-middle",
        "--frames",
        "3",
        "--plot",
        s(&plot),
        "--json",
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // With --json, stdout is the JSON alone (the table goes to stderr).
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(String::from_utf8_lossy(&o.stderr).contains("frame ms"));
    let configs = j["configs"].as_array().unwrap();
    assert_eq!(configs.len(), 2);
    for (c, k) in configs.iter().zip([1, 2]) {
        assert_eq!(c["workers"], k);
        assert_eq!(c["identical"], true);
        assert!(c["frame_ms"].as_f64().unwrap() > 0.0);
        assert!(c["wire_mb_per_frame"].as_f64().unwrap() > 0.0);
        // Each worker's peak memory: a few MB at least (its scene and
        // hair), and not absurd.
        let peaks = c["worker_peak_mb"].as_array().unwrap();
        assert_eq!(peaks.len(), k);
        assert!(
            peaks
                .iter()
                .all(|p| (1.0..4096.0).contains(&p.as_f64().unwrap())),
            "{peaks:?}"
        );
        // Each worker's CPU time a frame, and the coordinator's.
        let cpu = c["worker_cpu_ms_per_frame"].as_array().unwrap();
        assert_eq!(cpu.len(), k);
        assert!(
            cpu.iter()
                .chain([&c["coordinator_cpu_ms_per_frame"]])
                .all(|ms| ms.as_f64().is_some_and(|ms| ms >= 0.0)),
            "{cpu:?}"
        );
        // The median frame's bytes by stage add up to its total; an
        // animated, self-shadowed frame steps wisps, fills and sweeps.
        let w = &c["wire_bytes_median_frame"];
        let part = |k: &str| w[k].as_u64().unwrap();
        let parts = [
            "assign_sent",
            "step_sent",
            "wisps_received",
            "strands_sent",
            "density_received",
            "density_sent",
            "slabs_received",
            "pose",
            "draw_sent",
            "layers_received",
            "stripes_between_workers",
            "bands_received",
            "density_between_workers",
            "swept_between_workers",
        ];
        assert_eq!(parts.iter().map(|k| part(k)).sum::<u64>(), part("total"));
        // Drawing on the workers: one worker leaves the drawing to the
        // coordinator (its partial picture would only cross the wire to
        // be composited there), which gathers its density and sweeps the
        // map itself; two sum and sweep the maps among themselves,
        // composite the picture, and send finished bands.
        assert_eq!(c["draw"], "sort-middle");
        let frames = ["sort_middle", "sort_last", "coordinator"]
            .map(|s| c[format!("frames_{s}").as_str()].as_u64());
        let want = if k == 1 { [0, 0, 3] } else { [3, 0, 0] };
        assert_eq!(frames, want.map(Some));
        let (drawn, none): (&[&str], &[&str]) = if k == 1 {
            // The coordinator sweeps and draws: no column goes out, no
            // slab or picture comes back.
            (
                &[],
                &[
                    "density_sent",
                    "slabs_received",
                    "draw_sent",
                    "layers_received",
                    "density_between_workers",
                    "swept_between_workers",
                ],
            )
        } else {
            (
                &[
                    "draw_sent",
                    "stripes_between_workers",
                    "bands_received",
                    "density_between_workers",
                    "swept_between_workers",
                ],
                &["density_sent", "slabs_received", "layers_received"],
            )
        };
        for k in ["step_sent", "wisps_received", "density_received"]
            .iter()
            .chain(drawn)
        {
            assert!(part(k) > 0, "{k} in {w}");
        }
        for k in none {
            assert_eq!(part(k), 0, "{k} in {w}");
        }
    }
    assert!(
        j["single_process_cpu_ms_per_frame"]
            .as_f64()
            .is_some_and(|ms| ms >= 0.0)
    );
    assert_eq!(
        j["cores"].as_u64().unwrap() as usize,
        std::thread::available_parallelism().unwrap().get()
    );
    let img = image::open(&plot).unwrap();
    assert_eq!((img.width(), img.height()), (1100, 680));
    let svg = std::fs::read_to_string(plot.with_extension("svg")).unwrap();
    assert!(svg.contains(r#"width="1100" height="680""#), "{svg}");
}

#[test]
fn bench_scaling_emulates_nodes_when_permitted_and_leaves_nothing_behind() {
    let dir = scratch("nodes");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let child = Command::new(bin())
        .args([
            "bench",
            "scaling",
            s(&scene),
            "--workers",
            "1,2",
            "--frames",
            "1",
        ])
        .args([
            "--node-cpus",
            "0.5",
            "--link-mbit",
            "100",
            "--json",
            "--plot",
        ])
        .arg(dir.join("p.png"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    let o = child.wait_with_output().unwrap();
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(o.status.success(), "{err}");
    let j: serde_json::Value = serde_json::from_str(out.lines().last().unwrap()).unwrap();
    // Applied or not, it says which, on stderr and in the JSON.
    let notes: Vec<&str> = j["limits"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect();
    assert_eq!(notes.len(), 2, "{notes:?}");
    for (note, key) in notes.iter().zip(["cpu_limits", "bandwidth_limits"]) {
        assert!(err.contains(note), "{err}");
        let applied = j[key].as_bool().unwrap();
        assert_eq!(applied, !note.contains("NOT applied"), "{note}");
    }
    for c in j["configs"].as_array().unwrap() {
        assert_eq!(c["identical"], true);
    }
    // Nothing of this run is left: no namespace, bridge or cgroup.
    let tag = format!("wisplight-{pid}-");
    let netns = Command::new("ip").args(["netns", "list"]).output();
    if let Ok(n) = netns {
        assert!(!String::from_utf8_lossy(&n.stdout).contains(&tag));
    }
    let links = Command::new("ip").args(["-o", "link"]).output();
    if let Ok(l) = links {
        assert!(!String::from_utf8_lossy(&l.stdout).contains(&format!("wl{pid}")));
    }
    if let Ok(d) = std::fs::read_dir("/sys/fs/cgroup/cpu") {
        for e in d.flatten() {
            assert!(!e.file_name().to_string_lossy().starts_with(&tag));
        }
    }
}

#[test]
fn with_mutual_tls_only_the_clusters_coordinator_gets_work_done() {
    let dir = scratch("tls");
    let pki = dir.join("pki");
    let o = run(&["certs", s(&pki)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // Keys are their owner's alone; certificates are for anyone to read.
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = |n: &str| std::fs::metadata(pki.join(n)).unwrap().permissions().mode() & 0o777;
        for k in ["ca.key", "worker.key", "coordinator.key"] {
            assert_eq!(mode(k), 0o600, "{k}");
        }
        assert_ne!(mode("ca.pem") & 0o044, 0, "ca.pem");
    }
    // Run again: refuses to overwrite the keys, exit 1, files unchanged.
    let key = std::fs::read(pki.join("ca.key")).unwrap();
    let o = run(&["certs", s(&pki)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("already exists"));
    assert_eq!(std::fs::read(pki.join("ca.key")).unwrap(), key);

    let f = |n: &str| pki.join(n).to_str().unwrap().to_string();
    // A free port for the plain health port (bound, learnt, released).
    let health = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .to_string();
    let w = Worker::start_with(&[
        "--health-listen",
        &health,
        "--tls-ca",
        &f("ca.pem"),
        "--tls-cert",
        &f("worker.pem"),
        "--tls-key",
        &f("worker.key"),
    ]);
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, SCENE).unwrap();
    let local = dir.join("local.png");
    let o = run(&["render", s(&scene), "-o", s(&local)]);
    assert!(o.status.success());
    let remote = dir.join("remote.png");
    let coordinator = |cert: &str, key: &str| {
        run(&[
            "coordinator",
            s(&scene),
            "--workers",
            &w.addr,
            "--tls-ca",
            &f("ca.pem"),
            "--tls-cert",
            &f(cert),
            "--tls-key",
            &f(key),
            "-o",
            s(&remote),
        ])
    };
    let o = coordinator("coordinator.pem", "coordinator.key");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(std::fs::read(&local).unwrap() == std::fs::read(&remote).unwrap());
    std::fs::remove_file(&remote).unwrap();

    // Without credentials: refused, with a hint, and no picture.
    let o = run(&[
        "coordinator",
        s(&scene),
        "--workers",
        &w.addr,
        "-o",
        s(&remote),
    ]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains(&w.addr) && e.contains("--tls-ca"), "{e}");
    assert!(!remote.exists());
    // A worker's certificate gets through the handshake (workers call each
    // other to composite pictures) but cannot drive the worker.
    let o = coordinator("worker.pem", "worker.key");
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("wisplight-coordinator"), "{e}");
    assert!(!remote.exists());
    // Half the options is a usage error.
    let o = run(&["health", &w.addr, "--tls-ca", &f("ca.pem")]);
    assert_eq!(o.status.code(), Some(2));
    let o = run(&[
        "health",
        &w.addr,
        "--tls-ca",
        &f("ca.pem"),
        "--tls-cert",
        &f("coordinator.pem"),
        "--tls-key",
        &f("coordinator.key"),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // Probes without credentials use the plain health port.
    let o = run(&["health", &health]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(w.stop().success());
}

/// Runs of [`a_stopped_worker_is_the_one_dropped_whichever_it_is`]: each
/// worker stopped in turn, then two at once, on rigid and on simulated
/// hair, `WISPLIGHT_STOP_CYCLES` times over (1 by default: 8 runs).
fn stop_cycles() -> usize {
    std::env::var("WISPLIGHT_STOP_CYCLES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1)
}

#[test]
fn a_stopped_worker_is_the_one_dropped_whichever_it_is() {
    let dir = scratch("sigstop");
    // Rigid hair: no Simulate calls, so the stop lands in a stage where the
    // workers wait on each other (summing the maps, compositing);
    // simulated hair: it may land in a Simulate call too. A map and a picture
    // large enough that a stopped peer's calls fill up and block the
    // others' sends.
    let base = "[hair]\nstyle = \"smooth\"\nstrands_per_wisp = 4\n\n[render]\nwidth = 640\nheight = 360\n\n\
         [shadow]\ncells = 128\n\n[animation]\nmotion = \"dance\"\n";
    let (frames, n) = ("8", 8);
    let mut scenes = Vec::new();
    for (name, effects) in [
        ("rigid", "\n[effects]\ndynamics = false\n"),
        ("simulated", ""),
    ] {
        let scene = dir.join(format!("{name}.toml"));
        std::fs::write(&scene, format!("{base}{effects}")).unwrap();
        let local = dir.join(format!("{name}_local_%d.png"));
        let o = run(&["render", s(&scene), "--frames", frames, "-o", s(&local)]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        scenes.push((name, scene, local));
    }
    let cases: [&[usize]; 4] = [&[0], &[1], &[2], &[0, 2]];
    let runs = (0..stop_cycles())
        .flat_map(|_| &scenes)
        .flat_map(|sc| cases.map(|c| (sc, c)));
    for (run_index, ((name, scene, local), stopped)) in runs.enumerate() {
        // The workers compose and sum among themselves, so the healthy
        // ones wait on the stopped ones: they must not be blamed for it.
        let workers = [Worker::start(), Worker::start(), Worker::start()];
        let list = addr_list(&workers);
        let remote = dir.join(format!("remote{run_index}_%d.png"));
        let coordinator = Command::new(bin())
            .args([
                "coordinator",
                s(scene),
                "--workers",
                &list,
                "--deadline",
                "3",
            ])
            .args(["--frames", frames, "-o"])
            .arg(&remote)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let second = dir.join(format!("remote{run_index}_1.png"));
        for _ in 0..3000 {
            if second.exists() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        assert!(second.exists(), "the coordinator wrote its second frame");
        let pids: Vec<String> = stopped
            .iter()
            .map(|&w| workers[w].child.id().to_string())
            .collect();
        let signal = |sig: &str| {
            for pid in &pids {
                Command::new("kill").args([sig, pid]).status().unwrap();
            }
        };
        signal("-STOP");
        let o = coordinator.wait_with_output().unwrap();
        signal("-CONT");
        let e = String::from_utf8_lossy(&o.stderr);
        let case = format!("run {run_index}, {name} hair, workers {stopped:?} stopped");
        assert!(o.status.success(), "{case}: {e}");
        let lost: Vec<&str> = e.lines().filter(|l| l.contains("worker lost")).collect();
        assert_eq!(lost.len(), stopped.len(), "{case}; lost: {lost:#?}");
        for &w in stopped {
            let blamed = &workers[w].addr;
            assert!(
                lost.iter()
                    .any(|l| l.contains(&format!("worker {blamed} "))),
                "{case}: worker {w} ({blamed}) not the one dropped: {lost:#?}"
            );
        }
        for i in 0..n {
            let (a, b) = (frame_bytes(local, i), frame_bytes(&remote, i));
            assert!(a == b, "{case}: frame {i} differs from one process");
        }
    }
}
