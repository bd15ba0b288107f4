//! `TestRun`: a temporary project folder, the `annotrace` binary, and helpers to write inputs and read
//! outputs.

#![allow(dead_code)]

pub mod chat_server;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use annotrace::trace::{Env, Trace, json};

/// A temporary folder to run `annotrace` in.
pub struct TestRun {
    pub dir: tempfile::TempDir,
}

/// The finished command: status and output as text.
pub struct Ran {
    pub code: Option<i32>,
    pub stdout: String,
    pub stderr: String,
}

impl Ran {
    pub fn ok(&self) -> &Self {
        assert_eq!(
            self.code,
            Some(0),
            "expected success\nstdout:\n{}\nstderr:\n{}",
            self.stdout,
            self.stderr
        );
        self
    }

    pub fn code(&self, code: i32) -> &Self {
        assert_eq!(
            self.code,
            Some(code),
            "expected exit {code}\nstdout:\n{}\nstderr:\n{}",
            self.stdout,
            self.stderr
        );
        self
    }

    pub fn stderr_has(&self, needle: &str) -> &Self {
        assert!(
            self.stderr.contains(needle),
            "stderr lacks {needle:?}:\n{}",
            self.stderr
        );
        self
    }

    pub fn stdout_has(&self, needle: &str) -> &Self {
        assert!(
            self.stdout.contains(needle),
            "stdout lacks {needle:?}:\n{}",
            self.stdout
        );
        self
    }
}

impl From<Output> for Ran {
    fn from(o: Output) -> Self {
        Ran {
            code: o.status.code(),
            stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
            stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
        }
    }
}

/// The repository root (for the committed examples, pipelines and SQL).
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

impl TestRun {
    pub fn new() -> Self {
        TestRun {
            dir: tempfile::tempdir().expect("temp dir"),
        }
    }

    pub fn path(&self, rel: &str) -> PathBuf {
        self.dir.path().join(rel)
    }

    /// The `annotrace` command, run in the temporary folder.
    pub fn cmd(&self) -> Command {
        let mut c = Command::new(env!("CARGO_BIN_EXE_annotrace"));
        c.current_dir(self.dir.path())
            .env_remove("ANNOTRACE_FAULT")
            .env_remove("ANNOTRACE_LOG");
        c
    }

    /// Runs `annotrace ARGS…`.
    pub fn run(&self, args: &[&str]) -> Ran {
        self.cmd()
            .args(args)
            .output()
            .expect("annotrace runs")
            .into()
    }

    /// Runs `annotrace ARGS…` with extra environment variables.
    pub fn run_env(&self, args: &[&str], env: &[(&str, &str)]) -> Ran {
        let mut c = self.cmd();
        for (k, v) in env {
            c.env(k, v);
        }
        c.args(args).output().expect("annotrace runs").into()
    }

    /// Writes a file (creating folders) and returns its path.
    pub fn write(&self, rel: &str, text: &str) -> PathBuf {
        let p = self.path(rel);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(&p, text).unwrap();
        p
    }

    /// Writes traces as JSON Lines.
    pub fn write_jsonl(&self, rel: &str, traces: &[Trace]) -> PathBuf {
        let mut text = String::new();
        for t in traces {
            text.push_str(&json::to_value(t).to_string());
            text.push('\n');
        }
        self.write(rel, &text)
    }

    /// Query a run and return CSV.
    pub fn csv(&self, run: &str, sql: &str) -> String {
        let r = self.run(&["query", sql, "--run", run, "--format", "csv"]);
        r.ok();
        r.stdout
    }

    /// Every file below `rel`, relative, sorted.
    pub fn files(&self, rel: &str) -> Vec<String> {
        let root = self.path(rel);
        let mut out = Vec::new();
        let mut stack = vec![root.clone()];
        while let Some(d) = stack.pop() {
            let Ok(entries) = std::fs::read_dir(&d) else {
                continue;
            };
            for e in entries.flatten() {
                let p = e.path();
                if p.is_dir() {
                    stack.push(p);
                } else {
                    out.push(
                        p.strip_prefix(&root)
                            .unwrap()
                            .to_string_lossy()
                            .into_owned(),
                    );
                }
            }
        }
        out.sort();
        out
    }
}

/// The example trace of an environment, as committed in `data/examples/`.
pub fn example(env: Env) -> PathBuf {
    let name = match env {
        Env::Pooltool => "pooltool_straight_shot.json",
        Env::Phyre => "phyre_drop.json",
        Env::Iphyre => "iphyre_support.json",
    };
    repo().join("data/examples").join(name)
}

/// The example trace of an environment (`example`), read.
pub fn example_trace(env: Env) -> Trace {
    let path = example(env);
    let text = std::fs::read_to_string(&path).unwrap();
    json::read_str(&path.display().to_string(), &text, env)
        .remove(0)
        .unwrap()
}

/// Reads a JSON file.
pub fn read_json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}
