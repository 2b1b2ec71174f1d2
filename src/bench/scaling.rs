//! `wisplight bench scaling`: the same frames in one process and on 1, 2,
//! 3, ... local worker processes, with where each frame's time and bytes
//! went.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use crate::cmd::median;
use anyhow::{Context, bail};

use super::nodes::{Nodes, Request};

#[derive(Debug, clap::Args)]
pub struct ScalingArgs {
    /// Scene file (TOML); the built-in scene (the smooth style, parted, on a
    /// dancing head with a face, seen from three quarters) when omitted.
    scene: Option<PathBuf>,
    /// Worker counts to measure, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3", value_name = "N,N,...",
          value_parser = clap::value_parser!(u32).range(1..=64))]
    workers: Vec<u32>,
    /// Timed frames per configuration (after 2 untimed frames: the first
    /// settles the hair).
    #[arg(long, default_value_t = 10, value_name = "N",
          value_parser = clap::value_parser!(u64).range(1..=10_000))]
    frames: u64,
    /// How the hair is drawn, comma-separated, each measured in turn:
    /// `auto` (sort-middle, sort-last or the coordinator's draw, chosen
    /// frame by frame by their measured cost; the report says which it
    /// took and why),
    /// `sort-middle` (each worker shades its strands and sends their
    /// segments to the worker that owns their rows, which rasterizes
    /// them), `sort-last` (each worker rasterizes its strands, the
    /// workers composite their partial pictures), `coordinator` (the
    /// paper's scheme: the coordinator draws every strand).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "auto",
        value_name = "SCHEME,..."
    )]
    draw: Vec<crate::cmd::cluster::Draw>,
    /// The plot of median frame times (PNG, and the same chart as SVG
    /// beside it).
    #[arg(long, default_value = "scaling.png", value_name = "FILE.png")]
    plot: PathBuf,
    /// Also print the result as one JSON object on the last stdout line.
    #[arg(long)]
    json: bool,
    /// Give every node (the coordinator, which also runs the single-process
    /// frames, and each worker) this many cores of CPU time: a cgroup v1
    /// quota, and pinning with taskset. Needs root; skipped (and said so)
    /// otherwise.
    #[arg(long, value_name = "CORES")]
    node_cpus: Option<f64>,
    /// Put every worker in its own network namespace behind a link of this
    /// many Mbit/s each way (veth on a bridge, tc tbf). Needs root; skipped
    /// (and said so) otherwise.
    #[arg(long, value_name = "MBIT",
          value_parser = clap::value_parser!(u32).range(1..=400_000))]
    link_mbit: Option<u32>,
    #[command(flatten)]
    pub threads: crate::cmd::Threads,
}

/// The `wisplight` program that serves the workers: beside this one (as
/// cargo builds and installs them).
fn wisplight_program() -> anyhow::Result<std::path::PathBuf> {
    let me = std::env::current_exe().context("cannot find this program")?;
    let beside = me.with_file_name("wisplight");
    if beside.is_file() {
        Ok(beside)
    } else {
        Err(crate::cmd::usage(format!(
            "bench scaling starts `wisplight worker` processes: no wisplight beside {} \
             (`cargo install --path . --locked` installs both programs, `cargo build --release` \
             builds both into target/release)",
            me.display()
        )))
    }
}

/// A worker process on a free localhost port.
struct WorkerProcess {
    child: Child,
    addr: String,
}

impl WorkerProcess {
    /// Worker `node` (1-based), on its emulated node when there are any.
    fn start(nodes: &Nodes, node: u32) -> anyhow::Result<WorkerProcess> {
        let exe = wisplight_program()?;
        let mut cmd = nodes.worker_command(&exe, node);
        let mut child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .context("cannot start a worker process")?;
        if let Err(e) = nodes.place(child.id(), node) {
            let _ = child.kill();
            let _ = child.wait();
            return Err(e.context(format!("cannot place worker {node} on its node")));
        }
        let mut line = String::new();
        let out = child.stdout.take().context("no worker stdout")?;
        BufReader::new(out)
            .read_line(&mut line)
            .context("cannot read the worker's address")?;
        let Some(addr) = line.trim().strip_prefix("listening on ") else {
            let _ = child.kill();
            bail!("a worker printed {line:?} instead of its address");
        };
        Ok(WorkerProcess {
            addr: addr.to_string(),
            child,
        })
    }
}

/// CPU time a process has used so far, all its threads (live and exited),
/// user and system, ms: `utime + stime` of `/proc/PID/stat`, in clock ticks
/// of 10 ms (Linux's `USER_HZ` is 100). `None` where the kernel does not
/// say.
fn cpu_ms(pid: &str) -> Option<f64> {
    stat_cpu_ms(&std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?)
}

/// `utime + stime` of a `/proc/PID/stat` line, ms.
fn stat_cpu_ms(stat: &str) -> Option<f64> {
    // The command name (field 2) may hold spaces and parentheses; the
    // fields after it start past its last closing parenthesis: state is
    // field 3, utime 14, stime 15.
    let rest = &stat[stat.rfind(')')? + 1..];
    let mut f = rest.split_whitespace().skip(11);
    let utime: f64 = f.next()?.parse().ok()?;
    let stime: f64 = f.next()?.parse().ok()?;
    Some((utime + stime) * 10.0)
}

impl WorkerProcess {
    fn cpu_ms(&self) -> Option<f64> {
        cpu_ms(&self.child.id().to_string())
    }

    /// The most memory the worker has held resident so far, MB (`VmHWM`
    /// of `/proc/PID/status`; `ip netns exec` runs the worker in its own
    /// process): `None` where the kernel does not say.
    fn peak_mb(&self) -> Option<f64> {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.child.id())).ok()?;
        let kb: f64 = status
            .lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))?
            .trim()
            .strip_suffix("kB")?
            .trim()
            .parse()
            .ok()?;
        Some(kb / 1024.0)
    }
}

impl Drop for WorkerProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Medians of one configuration, over its timed frames.
#[derive(Debug, Clone)]
struct Row {
    label: String,
    /// `None` for the single process.
    draw: Option<cluster::DrawAt>,
    workers: u32,
    frame_ms: f64,
    /// Wall time of the Simulate calls, and the slowest worker's compute in them.
    step_ms: f64,
    step_compute_ms: f64,
    pose_ms: f64,
    density_ms: f64,
    transmittance_ms: f64,
    /// Wall time of the Draw calls, and the slowest worker's compute in them.
    draw_ms: f64,
    draw_compute_ms: f64,
    /// Compositing on the workers: the slowest worker's wait for the
    /// others' stripes, and its resolving of its band.
    band_wait_ms: f64,
    band_composite_ms: f64,
    /// The rest of the frame on the coordinator (with workers drawing: the
    /// head and compositing; with the coordinator drawing: posing,
    /// filtering, shading, drawing); both: the self-collision field.
    coordinator_ms: f64,
    wire_mb: f64,
    /// The bytes of the timed frame with the median total, by stage.
    wire: cluster::Traffic,
    identical: bool,
    /// Each worker's peak resident memory at the run's end, MB.
    peak_mb: Vec<Option<f64>>,
    /// CPU time a timed frame, ms (mean over the timed frames): this
    /// process's, and each worker's.
    cpu_ms: Option<f64>,
    worker_cpu_ms: Vec<Option<f64>>,
    /// The mean of the timed frames, ms: what the CPU times are shares of.
    mean_frame_ms: f64,
    /// Timed frames drawn with each scheme (sort-middle, sort-last, the
    /// coordinator's draw), and what `auto` estimated a frame of each to
    /// cost at the end, ms.
    frames: [u32; 3],
    estimate_ms: [f64; 3],
}

impl Row {
    fn single(frame_ms: f64) -> Row {
        Row {
            label: "1 process".into(),
            draw: None,
            workers: 0,
            frame_ms,
            step_ms: 0.0,
            step_compute_ms: 0.0,
            pose_ms: 0.0,
            density_ms: 0.0,
            transmittance_ms: 0.0,
            draw_ms: 0.0,
            draw_compute_ms: 0.0,
            band_wait_ms: 0.0,
            band_composite_ms: 0.0,
            coordinator_ms: frame_ms,
            wire_mb: 0.0,
            wire: cluster::Traffic::default(),
            identical: true,
            peak_mb: Vec::new(),
            cpu_ms: None,
            worker_cpu_ms: Vec::new(),
            mean_frame_ms: frame_ms,
            frames: [0; 3],
            estimate_ms: [0.0; 3],
        }
    }
}

pub fn run(a: ScalingArgs) -> anyhow::Result<()> {
    let scene = crate::cmd::load_scene(a.scene.as_deref())?;
    super::check_plot_path(&a.plot)?;
    let (name, threads, cores) = super::machine(a.scene.as_deref());
    if let Some(c) = a.node_cpus
        && !(c.is_finite() && c >= 0.01 && c <= cores as f64)
    {
        return Err(crate::cmd::usage(format!(
            "--node-cpus {c}: must be between 0.01 and this machine's {cores} cores"
        )));
    }
    let mut schemes: Vec<cluster::DrawAt> = Vec::new();
    for d in &a.draw {
        let d = cluster::DrawAt::from(*d);
        if !schemes.contains(&d) {
            schemes.push(d);
        }
    }
    let nodes = Nodes::new(
        Request {
            node_cpus: a.node_cpus,
            link_mbit: a.link_mbit,
            workers: a.workers.iter().copied().max().unwrap_or(1),
        },
        cores,
    );
    eprintln!(
        "bench scaling: {name}: {} timed frames per configuration on this machine's {cores} cores ({threads} threads in this process{})",
        a.frames,
        nodes
            .worker_threads()
            .map_or(String::new(), |t| format!(", {t} in each worker"))
    );
    for n in &nodes.notes {
        eprintln!("bench scaling: {n}");
    }
    let warm = 2;
    let total = warm + a.frames;
    let configs = (a.workers.len() * schemes.len()) as u64;
    let bar = crate::cmd::progress_bar(
        total * (1 + configs),
        "{bar:30} {pos}/{len} frames [{elapsed} < {eta}]",
    );

    // One process: the reference times and pictures.
    let mut seq = engine::Sequence::new(&scene).context("cannot set up the scene")?;
    seq.expect_frames(total);
    let mut pictures = Vec::new();
    let mut times = Vec::new();
    let mut cpu0 = None;
    for f in 0..total {
        if f == warm {
            cpu0 = cpu_ms("self");
        }
        let t = Instant::now();
        let (img, _) = seq.next_frame().context("cannot render")?;
        if f >= warm {
            times.push(t.elapsed().as_secs_f64() * 1e3);
            pictures.push(img.clone());
        }
        bar.inc(1);
    }
    let mean_ms = times.iter().sum::<f64>() / times.len() as f64;
    let mut rows = vec![Row::single(median(&mut times))];
    rows[0].mean_frame_ms = mean_ms;
    rows[0].cpu_ms = per_frame(cpu0, cpu_ms("self"), a.frames);

    for &draw in &schemes {
        for &k in &a.workers {
            let procs = (1..=k)
                .map(|i| WorkerProcess::start(&nodes, i))
                .collect::<anyhow::Result<Vec<_>>>()?;
            let addrs: Vec<String> = procs.iter().map(|p| p.addr.clone()).collect();
            let options = cluster::Options {
                deadline: Duration::from_secs(120),
                connect_timeout: Duration::from_secs(10),
                tls: None,
                token: None,
                draw,
            };
            let ex = cluster::RemoteExecutor::connect(&addrs, &scene, &options)
                .context("cannot start the cluster")?;
            let (traffic, timing) = (ex.traffic(), ex.timing());
            let mut seq = engine::Sequence::new(&scene).context("cannot set up the scene")?;
            seq.set_executor(Box::new(ex))
                .context("cannot start the cluster")?;
            seq.expect_frames(total);
            let mut v: [Vec<f64>; 12] = Default::default();
            let mut frames_traffic = Vec::new();
            let mut identical = true;
            let (mut cpu0, mut worker_cpu0) = (None, Vec::new());
            let mut frames0 = [0; 3];
            for f in 0..total {
                // A frame is planned in the frame before's call (its
                // stages run beside that frame's picture).
                if f + 1 == warm {
                    frames0 = lock(&timing)?.frames;
                }
                if f == warm {
                    cpu0 = cpu_ms("self");
                    worker_cpu0 = procs.iter().map(WorkerProcess::cpu_ms).collect();
                }
                let (b0, c0) = (*lock(&traffic)?, *lock(&timing)?);
                let t = Instant::now();
                let (img, _) = seq.next_frame().context("cannot render")?;
                let ms = t.elapsed().as_secs_f64() * 1e3;
                if f >= warm {
                    identical &= *img == pictures[(f - warm) as usize];
                    let (b1, c1) = (*lock(&traffic)?, *lock(&timing)?);
                    let step = c1.step_wall_ms - c0.step_wall_ms;
                    let pose = c1.pose_ms - c0.pose_ms;
                    let fill = c1.density_ms - c0.density_ms;
                    let sweep = c1.transmittance_ms - c0.transmittance_ms;
                    let drawn = c1.draw_ms - c0.draw_ms;
                    frames_traffic.push(b1.since(&b0));
                    for (v, x) in v.iter_mut().zip([
                        ms,
                        step,
                        c1.step_compute_ms - c0.step_compute_ms,
                        pose,
                        fill,
                        sweep,
                        drawn,
                        c1.draw_compute_ms - c0.draw_compute_ms,
                        ms - step - pose - fill - sweep - drawn,
                        b1.since(&b0).total() as f64 / 1e6,
                        c1.band_wait_ms - c0.band_wait_ms,
                        c1.band_composite_ms - c0.band_composite_ms,
                    ]) {
                        v.push(x);
                    }
                }
                bar.inc(1);
            }
            let end = *lock(&timing)?;
            let mean_ms = v[0].iter().sum::<f64>() / v[0].len() as f64;
            let m: Vec<f64> = v.iter_mut().map(|x| median(x)).collect();
            frames_traffic.sort_by_key(cluster::Traffic::total);
            let wire = frames_traffic
                .get(frames_traffic.len() / 2)
                .copied()
                .unwrap_or_default();
            rows.push(Row {
                label: format!(
                    "{k} worker{}{}",
                    if k == 1 { "" } else { "s" },
                    if schemes.len() > 1 || draw != cluster::DrawAt::Auto {
                        format!(", {} draws", draw.name())
                    } else {
                        String::new()
                    }
                ),
                draw: Some(draw),
                workers: k,
                frame_ms: m[0],
                step_ms: m[1],
                step_compute_ms: m[2],
                pose_ms: m[3],
                density_ms: m[4],
                transmittance_ms: m[5],
                draw_ms: m[6],
                draw_compute_ms: m[7],
                coordinator_ms: m[8],
                wire_mb: m[9],
                band_wait_ms: m[10],
                band_composite_ms: m[11],
                wire,
                identical,
                peak_mb: procs.iter().map(WorkerProcess::peak_mb).collect(),
                cpu_ms: per_frame(cpu0, cpu_ms("self"), a.frames),
                worker_cpu_ms: procs
                    .iter()
                    .zip(&worker_cpu0)
                    .map(|(p, &c0)| per_frame(c0, p.cpu_ms(), a.frames))
                    .collect(),
                mean_frame_ms: mean_ms,
                frames: [0, 1, 2].map(|i| end.frames[i] - frames0[i]),
                estimate_ms: end.estimate_ms,
            });
        }
    }
    bar.finish_and_clear();

    let single = rows[0].frame_ms;
    let one_worker = |d: Option<cluster::DrawAt>| {
        rows.iter()
            .find(|r| r.workers == 1 && r.draw == d)
            .map(|r| r.frame_ms)
    };
    // The table goes to stdout, or beside the log lines when stdout is JSON.
    let table = |line: String| {
        if a.json {
            eprintln!("{line}");
        } else {
            println!("{line}");
        }
    };
    table(format!(
        "{:<28} {:>8} {:>7} {:>7} {:>13} {:>7} {:>7} {:>13} {:>11} {:>7} {:>7} {:>5}",
        "config",
        "frame ms",
        "vs 1 w",
        "vs proc",
        "step/slowest",
        "density",
        "transm",
        "draw/slowest",
        "wait/comp",
        "coord",
        "MB",
        "same"
    ));
    for r in &rows {
        let vs1 = match (r.workers, one_worker(r.draw)) {
            (0, _) | (_, None) => "-".to_string(),
            (_, Some(o)) => format!("{:.2}x", o / r.frame_ms),
        };
        table(format!(
            "{:<28} {:>8.1} {:>7} {:>6.2}x {:>6.1}/{:<6.1} {:>7.1} {:>7.1} {:>6.1}/{:<6.1} {:>5.1}/{:<5.1} {:>7.1} {:>7.3} {:>5}",
            r.label,
            r.frame_ms,
            vs1,
            single / r.frame_ms,
            r.step_ms + r.pose_ms,
            r.step_compute_ms,
            r.density_ms,
            r.transmittance_ms,
            r.draw_ms,
            r.draw_compute_ms,
            r.band_wait_ms,
            r.band_composite_ms,
            r.coordinator_ms,
            r.wire_mb,
            if r.identical { "yes" } else { "NO" }
        ));
    }
    eprintln!(
        "bench scaling: medians per frame; step = wall time of the wisps' Simulate (or Pose) calls / the slowest worker's own compute; density = Density calls (with two workers or more drawing: the workers summing each other's columns) and merging the sums; transm = Transmittance calls and assembling the slabs (with two workers or more drawing: the coordinator's own sweep of its copy, the workers' swept columns being gathered among them; with one worker, the coordinator's sweep); draw = Draw calls, with the compositing (on the workers, or decoding partial pictures here) / the slowest worker's filter, shade and rasterization; wait/comp = compositing on the workers: the slowest worker's wait for the others' stripes of its band / its resolving of the band; coord = the rest of the frame on the coordinator (the self-collision field, and with the coordinator drawing, one worker included: posing, filtering, shading and drawing every strand, the next frame's step, density and transm running beside the drawing); MB = bytes on the wire per frame; same = pictures identical to one process"
    );
    // How busy each node was: CPU time a frame against the cores it had.
    let node_cores = a
        .node_cpus
        .filter(|_| nodes.cpu_limited())
        .unwrap_or(cores as f64);
    let busy = |cpu: Option<f64>, r: &Row| {
        cpu.map_or("?".to_string(), |c| {
            format!("{c:.1} ms ({:.2})", c / (r.mean_frame_ms * node_cores))
        })
    };
    eprintln!(
        "bench scaling: CPU time a frame (mean over the timed frames, and in brackets the share of the node's {node_cores} cores it kept busy): 1 process {}",
        busy(rows[0].cpu_ms, &rows[0])
    );
    for r in rows.iter().skip(1) {
        let each: Vec<String> = r.worker_cpu_ms.iter().map(|&c| busy(c, r)).collect();
        let together: Option<f64> = r.worker_cpu_ms.iter().copied().sum();
        eprintln!(
            "bench scaling: {}, CPU time a frame: coordinator {}; each worker {}; the workers together {}",
            r.label,
            busy(r.cpu_ms, r),
            each.join(", "),
            match (together, rows[0].cpu_ms) {
                (Some(t), Some(one)) if one > 0.0 =>
                    format!("{t:.1} ms, {:.2}x one process's", t / one),
                _ => "?".to_string(),
            }
        );
    }
    // How each configuration drew its timed frames, and why auto chose so.
    for r in rows.iter().skip(1) {
        let [middle, last, coordinator] = r.frames;
        let how = if middle + last == 0 {
            "every frame drawn on the coordinator (one worker, or the paper's scheme)".to_string()
        } else {
            format!(
                "sort-middle in {middle} frames, sort-last in {last}, on the coordinator in {coordinator}"
            )
        };
        let measured: Vec<(cluster::Scheme, f64)> = cluster::Scheme::ALL
            .into_iter()
            .zip(r.estimate_ms)
            .filter(|(_, ms)| *ms > 0.0)
            .collect();
        let why = match r.draw {
            Some(cluster::DrawAt::Auto) if !measured.is_empty() => {
                let best = measured
                    .iter()
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .map_or("?", |(s, _)| s.name());
                let each: Vec<String> = measured
                    .iter()
                    .map(|(s, ms)| format!("{} {ms:.1} ms", s.name()))
                    .collect();
                format!(
                    "; auto's estimate of a frame (the least of the last three measured of each scheme: a frame is the call that rendered it: its drawing and the next frame's stages beside it): {}, so {best}",
                    each.join(", ")
                )
            }
            _ => String::new(),
        };
        eprintln!("bench scaling: {}, drawn: {how}{why}", r.label);
    }
    for r in rows.iter().skip(1) {
        eprintln!(
            "bench scaling: {}, bytes of the median frame: {}",
            r.label,
            r.wire.summary()
        );
        let peaks: Vec<String> = r
            .peak_mb
            .iter()
            .map(|p| p.map_or("?".into(), |mb| format!("{mb:.0}")))
            .collect();
        eprintln!(
            "bench scaling: {}, peak resident memory of each worker: {} MB",
            r.label,
            peaks.join(", ")
        );
    }
    // Short labels that fit under a bar: "1 proc", and the worker count
    // with A (auto), L (sort-last), M (sort-middle) or C (the coordinator
    // draws).
    let labels: Vec<String> = rows
        .iter()
        .map(|r| match r.draw {
            None => "1 proc".to_string(),
            Some(cluster::DrawAt::SortLast) => format!("{} L", r.workers),
            Some(cluster::DrawAt::SortMiddle) => format!("{} M", r.workers),
            Some(cluster::DrawAt::Auto) => format!("{} A", r.workers),
            Some(cluster::DrawAt::Coordinator) => format!("{} C", r.workers),
        })
        .collect();
    let values: Vec<f64> = rows.iter().map(|r| r.frame_ms).collect();
    let short = a
        .scene
        .as_deref()
        .and_then(|p| p.file_name())
        .map_or("built-in".to_string(), |f| f.to_string_lossy().into_owned());
    let limits = match (nodes.cpu_limited(), nodes.bandwidth_limited()) {
        (true, true) => format!(
            ", {} cores/node, {} Mbit/s",
            a.node_cpus.unwrap_or(0.0),
            a.link_mbit.unwrap_or(0)
        ),
        (true, false) => format!(", {} cores/node", a.node_cpus.unwrap_or(0.0)),
        (false, true) => format!(", {} Mbit/s links", a.link_mbit.unwrap_or(0)),
        (false, false) => String::new(),
    };
    let chart = super::plot::bars(
        &format!("frame ms, {short}{limits}"),
        "ms",
        &labels,
        &values,
    );
    super::write_chart(&a.plot, &chart)?;
    if rows.iter().any(|r| !r.identical) {
        bail!("a cluster configuration drew different pictures from one process");
    }
    if a.json {
        let j = serde_json::json!({
            "scene": name,
            "cores": cores,
            "threads": threads,
            "frames": a.frames,
            "cpu_limits": nodes.cpu_limited(),
            "node_cpus": a.node_cpus.filter(|_| nodes.cpu_limited()),
            "bandwidth_limits": nodes.bandwidth_limited(),
            "link_mbit": a.link_mbit.filter(|_| nodes.bandwidth_limited()),
            "limits": nodes.notes,
            "single_process_ms": single,
            "single_process_cpu_ms_per_frame": rows[0].cpu_ms,
            "configs": rows.iter().skip(1).map(|r| serde_json::json!({
                "workers": r.workers,
                "draw": r.draw.map(cluster::DrawAt::name),
                "frame_ms": r.frame_ms,
                "speedup_vs_one_worker": one_worker(r.draw).map(|o| o / r.frame_ms),
                "speedup_vs_single_process": single / r.frame_ms,
                "step_ms": r.step_ms,
                "slowest_worker_ms": r.step_compute_ms,
                "pose_ms": r.pose_ms,
                "density_ms": r.density_ms,
                "transmittance_ms": r.transmittance_ms,
                "draw_ms": r.draw_ms,
                "slowest_draw_ms": r.draw_compute_ms,
                "band_wait_ms": r.band_wait_ms,
                "band_composite_ms": r.band_composite_ms,
                "coordinator_ms": r.coordinator_ms,
                "wire_mb_per_frame": r.wire_mb,
                "worker_peak_mb": r.peak_mb,
                "coordinator_cpu_ms_per_frame": r.cpu_ms,
                "worker_cpu_ms_per_frame": r.worker_cpu_ms,
                "wire_bytes_median_frame": {
                    "total": r.wire.total(),
                    "assign_sent": r.wire.assign_sent,
                    "step_sent": r.wire.step_sent,
                    "wisps_received": r.wire.wisps_received,
                    "strands_sent": r.wire.strands_sent,
                    "density_received": r.wire.density_received,
                    "density_sent": r.wire.density_sent,
                    "slabs_received": r.wire.slabs_received,
                    "pose": r.wire.pose,
                    "draw_sent": r.wire.draw_sent,
                    "layers_received": r.wire.layers_received,
                    "stripes_between_workers": r.wire.stripes_between_workers,
                    "bands_received": r.wire.bands_received,
                    "density_between_workers": r.wire.density_between_workers,
                    "swept_between_workers": r.wire.swept_between_workers,
                },
                "identical": r.identical,
                "frames_sort_middle": r.frames[0],
                "frames_sort_last": r.frames[1],
                "frames_coordinator": r.frames[2],
                "estimate_ms": {
                    "sort_middle": r.estimate_ms[0],
                    "sort_last": r.estimate_ms[1],
                    "coordinator": r.estimate_ms[2],
                },
            })).collect::<Vec<_>>(),
        });
        println!("{j}");
    }
    Ok(())
}

/// CPU ms a frame between two readings `frames` frames apart.
fn per_frame(before: Option<f64>, after: Option<f64>, frames: u64) -> Option<f64> {
    Some((after? - before?) / frames as f64)
}

fn lock<T>(m: &std::sync::Mutex<T>) -> anyhow::Result<std::sync::MutexGuard<'_, T>> {
    m.lock()
        .map_err(|_| anyhow::anyhow!("a counter's lock was poisoned"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_time_is_read_past_an_odd_command_name() {
        // pid (comm) state ppid pgrp session tty tpgid flags minflt
        // cminflt majflt cmajflt utime stime ...
        let line = "4242 (a (b) c) S 1 2 3 0 -1 4194560 10 0 0 0 123 45 0 0 20 0 9 0";
        assert_eq!(stat_cpu_ms(line), Some((123.0 + 45.0) * 10.0));
        assert_eq!(stat_cpu_ms("4242 (cut short) S 1 2"), None);
        assert_eq!(stat_cpu_ms("no parenthesis"), None);
        // This process's own.
        assert!(cpu_ms("self").is_some_and(|ms| ms >= 0.0));
    }
}
