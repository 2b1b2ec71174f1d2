//! What the tests of the `wisplight` program share: the program run,
//! a scratch folder, worker processes.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Output, Stdio};

/// `wisplight ARGS`, run to its end.
#[allow(dead_code)] // not every test file runs the program this way
pub(crate) fn wisplight(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wisplight"))
        .args(args)
        .output()
        .expect("the binary runs")
}

/// A fresh folder for one test's files, `wisplight-TOPIC-PID-NAME` in the
/// system's temporary folder.
#[allow(dead_code)]
pub(crate) fn scratch(topic: &str, name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("wisplight-{topic}-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A worker process and the address it printed first.
pub(crate) struct Worker {
    pub(crate) child: Child,
    pub(crate) addr: String,
}

impl Worker {
    pub(crate) fn start() -> Worker {
        Worker::start_with(&[])
    }

    pub(crate) fn start_with(extra: &[&str]) -> Worker {
        let mut child = Command::new(env!("CARGO_BIN_EXE_wisplight"))
            .args(["worker", "--listen", "127.0.0.1:0"])
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("the worker starts");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let addr = line
            .trim()
            .strip_prefix("listening on ")
            .unwrap_or_else(|| panic!("first line {line:?}"))
            .to_string();
        Worker { child, addr }
    }

    /// SIGTERM, then the exit status.
    #[allow(dead_code)] // tests/farm.rs drops its workers instead
    pub(crate) fn stop(mut self) -> std::process::ExitStatus {
        Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status()
            .unwrap();
        self.child.wait().unwrap()
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
