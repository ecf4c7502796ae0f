//! A running `rig sim serve --json` for the tests that talk to a served virtual rig: started
//! at a speed with extra options, its ready line parsed, killed (SIGKILL) when dropped if a
//! test fails before it stops it.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::process::{Child, Stdio};

use serde_json::Value;

/// The served rig.
pub struct Server {
    /// The `rig sim serve` process.
    pub child: Child,
    /// Its pseudo-terminal.
    pub port: String,
    /// Its ready line.
    pub ready: Value,
}

impl Server {
    /// At `speed` virtual seconds per wall-clock second, with `extra` options.
    pub fn start_at(speed: &str, extra: &[&str]) -> Self {
        let bin = assert_cmd::cargo::cargo_bin("rig");
        let mut child = std::process::Command::new(bin)
            .args(["sim", "serve", "--json", "--speed", speed])
            .args(extra)
            .env_remove("RIG_PORT")
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("rig sim serve starts");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .expect("a ready line");
        let ready: Value =
            serde_json::from_str(&line).unwrap_or_else(|e| panic!("not JSON ({e}): {line}"));
        let port = ready["port"].as_str().expect("a port").to_string();
        Self { child, port, ready }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
