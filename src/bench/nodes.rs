//! Emulated nodes for `bench scaling` on one machine (root only): an equal
//! CPU share per node (a cgroup v1 CPU quota, plus `taskset` pinning), and
//! for each worker a network namespace behind a bandwidth-limited link
//! (a veth pair on a bridge, `tc tbf` in both directions).
//!
//! Node 0 is this process (the coordinator, and the single-process run);
//! node i >= 1 is worker i. Everything made is named after this process's
//! id, removed when the [`Nodes`] is dropped, and swept up by a later run
//! if this one was killed.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

const CPU_ROOT: &str = "/sys/fs/cgroup/cpu";
/// cgroup v1's CPU period, microseconds.
const PERIOD_US: u64 = 100_000;

/// What a run asked for.
#[derive(Debug, Clone, Copy)]
pub struct Request {
    /// Cores of CPU time per node.
    pub node_cpus: Option<f64>,
    /// Megabits per second per worker link, each direction.
    pub link_mbit: Option<u32>,
    /// Workers to place (the largest count measured).
    pub workers: u32,
}

/// The nodes made, and what could not be made and why.
#[derive(Debug, Default)]
pub struct Nodes {
    pid: u32,
    /// One cgroup per node (index 0 = this process), when CPU limits apply.
    cgroups: Vec<PathBuf>,
    node_cpus: Option<f64>,
    cores: usize,
    /// The bridge, when bandwidth limits apply.
    bridge: Option<String>,
    /// The worker namespaces, in node order (node 1 first).
    namespaces: Vec<String>,
    subnet: u8,
    /// Whether `taskset` pins the nodes to cores.
    taskset: bool,
    /// Human-readable notes: what was applied, or why not.
    pub notes: Vec<String>,
}

impl Nodes {
    /// Sets up what `req` asks for, as far as this machine permits: every
    /// part that cannot be made is skipped, with the reason in `notes`.
    pub fn new(req: Request, cores: usize) -> Nodes {
        let pid = std::process::id();
        let mut nodes = Nodes::default();
        nodes.pid = pid;
        nodes.cores = cores;
        nodes.subnet = (pid % 200 + 20) as u8;
        if req.node_cpus.is_none() && req.link_mbit.is_none() {
            nodes.notes.push(
                "no CPU or bandwidth limits applied: every process shares the machine".into(),
            );
            return nodes;
        }
        if !is_root() {
            if req.node_cpus.is_some() {
                nodes
                    .notes
                    .push("CPU limits NOT applied: cgroups need root".into());
            }
            if req.link_mbit.is_some() {
                nodes
                    .notes
                    .push("bandwidth limits NOT applied: network namespaces need root".into());
            }
            return nodes;
        }
        sweep_stale();
        if let Some(c) = req.node_cpus {
            nodes.taskset = has("taskset");
            let note = match nodes.cpu_limits(c, req.workers) {
                Err(e) => {
                    nodes.remove_cgroups();
                    format!("CPU limits NOT applied: {e}")
                }
                Ok(()) => format!(
                    "CPU limits applied: {} nodes (coordinator + {} workers) of {c} cores each (cgroup v1 quota {} us per {PERIOD_US} us){}",
                    req.workers + 1,
                    req.workers,
                    quota_us(c),
                    if nodes.taskset {
                        ", pinned with taskset"
                    } else {
                        ""
                    }
                ),
            };
            nodes.notes.push(note);
        }
        if let Some(m) = req.link_mbit {
            let note = match nodes.links(m, req.workers) {
                Err(e) => {
                    nodes.remove_links();
                    format!("bandwidth limits NOT applied: {e}")
                }
                Ok(()) => format!(
                    "bandwidth limits applied: each worker in its own network namespace behind a {m} Mbit/s link each way (veth, tc tbf); no added latency"
                ),
            };
            nodes.notes.push(note);
        }
        nodes
    }

    pub fn cpu_limited(&self) -> bool {
        !self.cgroups.is_empty()
    }

    pub fn bandwidth_limited(&self) -> bool {
        self.bridge.is_some()
    }

    /// Rayon threads for a worker: its whole cores, at least one.
    pub fn worker_threads(&self) -> Option<u32> {
        self.node_cpus
            .filter(|_| self.cpu_limited())
            .map(|c| c.ceil().max(1.0) as u32)
    }

    /// The command that starts worker `i` (1-based): inside its namespace
    /// when links are limited.
    pub fn worker_command(&self, exe: &Path, i: u32) -> Command {
        let (listen, mut cmd) = match self.namespaces.get(i as usize - 1) {
            Some(ns) => {
                let mut c = Command::new("ip");
                c.args(["netns", "exec", ns]).arg(exe);
                (format!("{}:7000", self.worker_ip(i)), c)
            }
            None => ("127.0.0.1:0".to_string(), Command::new(exe)),
        };
        cmd.args(["worker", "--listen", &listen]);
        if let Some(t) = self.worker_threads() {
            cmd.args(["--threads", &t.to_string()]);
        }
        cmd
    }

    /// Puts process `pid` on node `node` (0 = the coordinator): its
    /// cgroup, and its cores.
    pub fn place(&self, pid: u32, node: u32) -> anyhow::Result<()> {
        let Some(cg) = self.cgroups.get(node as usize) else {
            return Ok(());
        };
        write(&cg.join("cgroup.procs"), &pid.to_string())?;
        if self.taskset {
            let mask = self.cpu_mask(node);
            run(
                "taskset",
                &["-a", "-p", &format!("{mask:x}"), &pid.to_string()],
            )?;
        }
        Ok(())
    }

    /// Node `node`'s cores: `ceil(node_cpus)` of them, round-robin.
    fn cpu_mask(&self, node: u32) -> u64 {
        let per = self.node_cpus.map_or(1, |c| c.ceil().max(1.0) as usize);
        let cores = self.cores.clamp(1, 64);
        (0..per.min(cores))
            .map(|k| 1u64 << ((node as usize * per + k) % cores))
            .fold(0, |m, b| m | b)
    }

    fn worker_ip(&self, i: u32) -> String {
        format!("10.213.{}.{}", self.subnet, 10 + i)
    }

    fn cpu_limits(&mut self, cores: f64, workers: u32) -> anyhow::Result<()> {
        if !Path::new(CPU_ROOT).join("cpu.cfs_quota_us").exists() {
            anyhow::bail!("no cgroup v1 CPU controller at {CPU_ROOT}");
        }
        self.node_cpus = Some(cores);
        for node in 0..=workers {
            let dir = Path::new(CPU_ROOT).join(format!("wisplight-{}-{node}", self.pid));
            std::fs::create_dir(&dir)
                .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", dir.display()))?;
            self.cgroups.push(dir.clone());
            write(&dir.join("cpu.cfs_period_us"), &PERIOD_US.to_string())?;
            write(&dir.join("cpu.cfs_quota_us"), &quota_us(cores).to_string())?;
        }
        self.place(self.pid, 0)
    }

    fn links(&mut self, mbit: u32, workers: u32) -> anyhow::Result<()> {
        if !has("ip") || !has("tc") {
            anyhow::bail!("`ip` and `tc` (iproute2) are needed");
        }
        let p = self.pid;
        let bridge = format!("wl{p}b");
        run("ip", &["link", "add", &bridge, "type", "bridge"])?;
        self.bridge = Some(bridge.clone());
        let gw = format!("10.213.{}.1/24", self.subnet);
        run("ip", &["addr", "add", &gw, "dev", &bridge])?;
        run("ip", &["link", "set", &bridge, "up"])?;
        // tbf needs a bucket of at least one timer tick's worth of bytes.
        let burst = format!("{}", (u64::from(mbit) * 1_000_000 / 8 / 100).max(64 * 1024));
        let rate = format!("{mbit}mbit");
        for i in 1..=workers {
            let ns = format!("wisplight-{p}-{i}");
            run("ip", &["netns", "add", &ns])?;
            self.namespaces.push(ns.clone());
            let (host, inner) = (format!("wl{p}h{i}"), format!("wl{p}n{i}"));
            run(
                "ip",
                &["link", "add", &host, "type", "veth", "peer", "name", &inner],
            )?;
            run("ip", &["link", "set", &inner, "netns", &ns])?;
            run("ip", &["link", "set", &host, "master", &bridge, "up"])?;
            let addr = format!("{}/24", self.worker_ip(i));
            run("ip", &["-n", &ns, "addr", "add", &addr, "dev", &inner])?;
            run("ip", &["-n", &ns, "link", "set", &inner, "up"])?;
            run("ip", &["-n", &ns, "link", "set", "lo", "up"])?;
            let tbf = [
                "qdisc", "add", "dev", "", "root", "tbf", "rate", &rate, "burst", &burst,
                "latency", "50ms",
            ];
            let mut to_worker = tbf;
            to_worker[3] = &host;
            run("tc", &to_worker)?;
            let mut from_worker = tbf;
            from_worker[3] = &inner;
            let mut args = vec!["netns", "exec", &ns, "tc"];
            args.extend(from_worker);
            run("ip", &args)?;
        }
        Ok(())
    }

    fn remove_links(&mut self) {
        // Deleting a veth end deletes its pair at once; a namespace's own
        // devices would otherwise linger while the kernel tears it down.
        for (i, ns) in self.namespaces.drain(..).enumerate() {
            let _ = run("ip", &["link", "del", &format!("wl{}h{}", self.pid, i + 1)]);
            let _ = run("ip", &["netns", "del", &ns]);
        }
        if let Some(b) = self.bridge.take() {
            let _ = run("ip", &["link", "del", &b]);
        }
    }

    fn remove_cgroups(&mut self) {
        if self.cgroups.is_empty() {
            return;
        }
        // Back to the root group, so ours are empty and can go.
        let _ = write(
            &Path::new(CPU_ROOT).join("cgroup.procs"),
            &self.pid.to_string(),
        );
        if self.taskset {
            let all = (0..self.cores.clamp(1, 64)).fold(0u64, |m, k| m | (1 << k));
            let _ = run(
                "taskset",
                &["-a", "-p", &format!("{all:x}"), &self.pid.to_string()],
            );
        }
        for cg in self.cgroups.drain(..).rev() {
            let _ = std::fs::remove_dir(&cg);
        }
    }
}

impl Drop for Nodes {
    fn drop(&mut self) {
        self.remove_links();
        self.remove_cgroups();
    }
}

/// The cgroup quota for `cores` of CPU time per period.
fn quota_us(cores: f64) -> u64 {
    ((cores * PERIOD_US as f64).round() as u64).max(1000)
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| o.status.success() && String::from_utf8_lossy(&o.stdout).trim() == "0")
}

fn has(program: &str) -> bool {
    Command::new(program)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok()
}

fn run(program: &str, args: &[&str]) -> anyhow::Result<()> {
    let out = Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| anyhow::anyhow!("cannot run {program}: {e}"))?;
    if !out.status.success() {
        anyhow::bail!(
            "`{program} {}` failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    Ok(())
}

fn write(path: &Path, text: &str) -> anyhow::Result<()> {
    std::fs::write(path, text).map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))
}

/// The process id in a name made by a run (`wisplight-<pid>-<n>`,
/// `wl<pid>b`), when that process is gone.
fn dead_owner(name: &str) -> bool {
    let digits: String = name
        .trim_start_matches("wisplight-")
        .trim_start_matches("wl")
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    match digits.parse::<u32>() {
        Ok(pid) => pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists(),
        Err(_) => false,
    }
}

/// Removes what runs that were killed left behind.
fn sweep_stale() {
    if let Ok(out) = Command::new("ip").args(["netns", "list"]).output() {
        for line in String::from_utf8_lossy(&out.stdout).lines() {
            let name = line.split_whitespace().next().unwrap_or("");
            if name.starts_with("wisplight-") && dead_owner(name) {
                let _ = run("ip", &["netns", "del", name]);
            }
        }
    }
    if let Ok(out) = Command::new("ip")
        .args(["-o", "link", "show", "type", "bridge"])
        .output()
    {
        for line in String::from_utf8_lossy(&out.stdout).lines() {
            let name = line.split(':').nth(1).unwrap_or("").trim();
            if name.starts_with("wl") && name.ends_with('b') && dead_owner(name) {
                let _ = run("ip", &["link", "del", name]);
            }
        }
    }
    if let Ok(dir) = std::fs::read_dir(CPU_ROOT) {
        for e in dir.flatten() {
            let name = e.file_name().to_string_lossy().to_string();
            if name.starts_with("wisplight-") && dead_owner(&name) {
                let _ = std::fs::remove_dir(e.path());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_of_dead_runs_are_recognised() {
        assert!(!dead_owner(&format!("wisplight-{}-1", std::process::id())));
        assert!(!dead_owner("wisplight-cache"));
        assert!(!dead_owner("wlan0"));
        // Linux pids stay below 2^22.
        assert!(dead_owner("wisplight-4999999-2"));
        assert!(dead_owner("wl4999999b"));
    }

    #[test]
    fn nodes_get_distinct_cores_round_robin() {
        let mut n = Nodes::default();
        n.node_cpus = Some(0.5);
        n.cores = 2;
        assert_eq!(
            (0..4).map(|i| n.cpu_mask(i)).collect::<Vec<_>>(),
            [1, 2, 1, 2]
        );
        n.node_cpus = Some(2.0);
        n.cores = 8;
        assert_eq!(n.cpu_mask(1), 0b1100);
        assert_eq!(quota_us(0.5), 50_000);
    }
}
