//! Runs on object storage (feature `s3`), against a local S3-compatible server started by the test:
//! moto in server mode, on loopback, from a venv cached under `$HOME/.cache/annotrace/moto-venv`
//! (created with `python3 -m venv` and `pip install 'moto[server]==5.2.5'` the first time; override with
//! `ANNOTRACE_MOTO_VENV`). The sharded pipeline of `shard.rs` runs as separate `annotrace` processes
//! into `s3://…`, one killed and rerun, then `--finalize`, and every table equals the single-process
//! local run; conditional puts refuse the losing writer.

use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use annotrace::store::remote::RemoteRun;
use annotrace::store::{Manifest, StoreError};

use crate::common::{Ran, TestRun};
use crate::shard::{PIPELINE, tables_and_rows};

/// The venv holding moto: created once per machine (under a lock, as tests run in parallel).
fn moto_venv() -> PathBuf {
    let dir = std::env::var_os("ANNOTRACE_MOTO_VENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(std::env::var_os("HOME").expect("HOME is set"))
                .join(".cache/annotrace/moto-venv")
        });
    let server = dir.join("bin/moto_server");
    if server.exists() {
        return dir;
    }
    std::fs::create_dir_all(dir.parent().unwrap()).unwrap();
    let lock = std::fs::File::create(dir.with_extension("lock")).unwrap();
    lock.lock().unwrap();
    if !server.exists() {
        // A half-made venv of an interrupted install is made again from scratch.
        let _ = std::fs::remove_dir_all(&dir);
        let ok = Command::new("python3")
            .args(["-m", "venv"])
            .arg(&dir)
            .status()
            .expect("python3 runs")
            .success();
        assert!(ok, "python3 -m venv {} failed", dir.display());
        let ok = Command::new(dir.join("bin/pip"))
            .args([
                "install",
                "--quiet",
                "--disable-pip-version-check",
                "moto[server]==5.2.5",
            ])
            .status()
            .expect("pip runs")
            .success();
        assert!(ok, "pip install moto[server] failed");
    }
    dir
}

/// A moto S3 server on a free loopback port, stopped when dropped.
struct Moto {
    child: Child,
    port: u16,
}

impl Moto {
    fn start() -> Moto {
        let venv = moto_venv();
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let child = Command::new(venv.join("bin/moto_server"))
            .args(["-H", "127.0.0.1", "-p", &port.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("moto_server starts");
        let moto = Moto { child, port };
        let start = Instant::now();
        while TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "moto_server did not listen on port {port}"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        moto
    }

    fn endpoint(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }

    /// The variables every client of this server gets.
    fn env(&self, cache: &Path) -> Vec<(String, String)> {
        vec![
            ("AWS_ENDPOINT_URL".into(), self.endpoint()),
            ("AWS_ALLOW_HTTP".into(), "true".into()),
            ("AWS_ACCESS_KEY_ID".into(), "testing".into()),
            ("AWS_SECRET_ACCESS_KEY".into(), "testing".into()),
            ("AWS_REGION".into(), "us-east-1".into()),
            ("ANNOTRACE_S3_CACHE".into(), cache.to_string_lossy().into()),
        ]
    }

    /// Creates a bucket (moto's Python client, from the same venv).
    fn bucket(&self, name: &str) {
        let ok = Command::new(moto_venv().join("bin/python"))
            .args([
                "-c",
                &format!(
                    "import boto3; boto3.client('s3', endpoint_url='{}', region_name='us-east-1', \
                     aws_access_key_id='testing', aws_secret_access_key='testing').create_bucket(Bucket='{name}')",
                    self.endpoint()
                ),
            ])
            .status()
            .unwrap()
            .success();
        assert!(ok, "creating bucket {name}");
    }

    /// A client of the library, for what the command line does not show.
    fn open(&self, url: &str) -> RemoteRun {
        let config: Vec<(String, String)> = vec![
            ("aws_endpoint".into(), self.endpoint()),
            ("aws_allow_http".into(), "true".into()),
            ("aws_access_key_id".into(), "testing".into()),
            ("aws_secret_access_key".into(), "testing".into()),
            ("aws_region".into(), "us-east-1".into()),
        ];
        RemoteRun::open_with(url, &config).unwrap()
    }
}

impl Drop for Moto {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `annotrace` with the server's variables.
struct S3Cli<'a> {
    t: &'a TestRun,
    env: Vec<(String, String)>,
}

impl S3Cli<'_> {
    fn cmd(&self, args: &[&str], extra: &[(&str, &str)]) -> Command {
        let mut c = self.t.cmd();
        for (k, v) in &self.env {
            c.env(k, v);
        }
        for (k, v) in extra {
            c.env(k, v);
        }
        c.args(args);
        c
    }

    fn run(&self, args: &[&str]) -> Ran {
        self.cmd(args, &[]).output().unwrap().into()
    }

    fn spawn(&self, args: &[&str]) -> Child {
        self.cmd(args, &[])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    }
}

fn wait(child: Child) -> Ran {
    child.wait_with_output().unwrap().into()
}

/// Every published file of a run with its bytes (relative path → bytes), `detector_calls` left out
/// (wall and CPU seconds differ between any two runs).
fn published(run: &Path) -> Vec<(String, Vec<u8>)> {
    let m = crate::common::read_json(&run.join("manifest.json"));
    let mut out = Vec::new();
    for (_, stage) in m["stages"].as_object().unwrap() {
        assert_eq!(stage["status"], "finished", "{stage}");
        for o in stage["outputs"].as_array().unwrap() {
            let p = o["path"].as_str().unwrap().to_string();
            if !p.starts_with("detector_calls/") {
                out.push((p.clone(), std::fs::read(run.join(&p)).unwrap()));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn sharded_processes_on_s3_one_killed_then_finalize_equal_the_local_single_run() {
    let moto = Moto::start();
    moto.bucket("runs");
    let t = TestRun::new();
    t.write("pipelines/p.toml", PIPELINE);
    let cli = S3Cli {
        t: &t,
        env: moto.env(&t.path("s3-cache")),
    };
    let url = "s3://runs/study/sharded";
    t.run(&["run", "pipelines/p.toml", "--run-dir", "runs/single"])
        .ok();

    // Shard 1 of 3 is killed half-way through its second unit of `sim`.
    let killed: Ran = cli
        .cmd(
            &[
                "run",
                "pipelines/p.toml",
                "--run-dir",
                url,
                "--shard",
                "1/3",
            ],
            &[
                ("ANNOTRACE_FAULT", "sim:mid-shard=1"),
                ("RAYON_NUM_THREADS", "1"),
            ],
        )
        .output()
        .unwrap()
        .into();
    assert_ne!(killed.code, Some(0), "the fault kills the shard");
    // Nothing is published before every slice is done, and --finalize says which are missing.
    cli.run(&["tables", "--run", url, "--brief"])
        .ok()
        .stdout_has("traces: 0 rows in 0 file(s)");
    cli.run(&["run", "pipelines/p.toml", "--run-dir", url, "--finalize"])
        .code(1)
        .stderr_has("stage sim: no slice is finished");

    // The three shards as separate processes (shard 1 rerun), then the finalisation.
    let args = |i: &'static str| ["run", "pipelines/p.toml", "--run-dir", url, "--shard", i];
    let children = [
        cli.spawn(&args("1/3")),
        cli.spawn(&args("0/3")),
        cli.spawn(&args("2/3")),
    ];
    for r in children.into_iter().map(wait) {
        r.ok();
    }
    // The SQL stage is left to --finalize.
    cli.run(&["tables", "--run", url, "--brief"])
        .ok()
        .stdout_has("traces: 12 rows");
    assert!(!cli.run(&["tables", "--run", url]).stdout.contains("counts"));
    cli.run(&["run", "pipelines/p.toml", "--run-dir", url, "--finalize"])
        .ok()
        .stderr_has("[counts] done");

    // Every table, through `tables` and `query` on the remote run, equals the local single run's.
    let remote = tables_and_rows_with(&cli, url);
    let local = tables_and_rows(&t, "runs/single");
    assert_eq!(remote, local);

    // Every published object is byte-identical to the local run's file, and the summaries summed from
    // the slices' records are the single process's.
    let store = moto.open(url);
    let copy = t.path("pulled");
    store.pull(&copy).unwrap().expect("the run has a manifest");
    let (a, b) = (published(&copy), published(&t.path("runs/single")));
    assert_eq!(
        a.iter().map(|(p, _)| p).collect::<Vec<_>>(),
        b.iter().map(|(p, _)| p).collect::<Vec<_>>()
    );
    for ((p, x), (_, y)) in a.iter().zip(&b) {
        assert!(x == y, "{p} differs from the single-process run");
    }
    let summary = |run: &Path, stage: &str| {
        crate::common::read_json(&run.join("manifest.json"))["stages"][stage]["summary"].clone()
    };
    for stage in ["sim", "acc"] {
        assert_eq!(
            summary(&copy, stage),
            summary(&t.path("runs/single"), stage)
        );
    }

    // --finalize removed what no manifest names (the committed slices): every object left is the
    // manifest, a published file or a journal file.
    assert_eq!(store.orphans().unwrap(), Vec::<String>::new());
    assert!(store.list(".staging").unwrap().is_empty());

    // The reading commands that take one trace, and `verify`, work on the remote run through a pulled
    // copy: `show` and `export` print what they print for the local single run.
    let first = t.csv(
        "runs/single",
        "SELECT trace_id FROM traces ORDER BY trace_id LIMIT 1",
    );
    let id = first.lines().nth(1).expect("a trace").trim().to_string();
    for cmd in ["show", "export"] {
        let remote = cli.run(&[cmd, "--run", url, "--trace", &id]);
        remote.ok();
        let single = t.path("runs/single");
        let local = cli.run(&[cmd, "--run", single.to_str().unwrap(), "--trace", &id]);
        local.ok();
        assert_eq!(remote.stdout, local.stdout, "`{cmd}` of {id}");
    }
    cli.run(&["verify", "--run", url])
        .ok()
        .stdout_has("journal file(s); ok");

    // A one-stage command on the remote run: `annotate` adds its stage, published like the others.
    cli.run(&["annotate", "--run", url, "--workers", "2"])
        .ok()
        .stdout_has("annotated 12 pooltool trace(s)");
    let n = cli.run(&[
        "query",
        "SELECT count(*) AS n FROM detector_calls",
        "--run",
        url,
        "--format",
        "csv",
    ]);
    n.ok();
    let local_calls = t.csv("runs/single", "SELECT count(*) AS n FROM detector_calls");
    let calls = |csv: &str| csv.lines().nth(1).unwrap().parse::<u64>().unwrap();
    assert_eq!(
        calls(&n.stdout),
        2 * calls(&local_calls),
        "ann's and annotate's calls"
    );
}

/// `tables_and_rows` through the server's variables.
fn tables_and_rows_with(cli: &S3Cli<'_>, url: &str) -> (String, Vec<String>) {
    // The shard test's helper runs `annotrace` without extra variables; run the same commands here.
    let tables = cli.run(&["tables", "--run", url]);
    tables.ok();
    let sorted = |csv: String| {
        let mut lines: Vec<&str> = csv.lines().collect();
        lines[1..].sort_unstable();
        lines.join("\n")
    };
    let csv = |sql: &str| {
        let r = cli.run(&["query", sql, "--run", url, "--format", "csv"]);
        r.ok();
        r.stdout
    };
    let mut rows = Vec::new();
    for name in crate::shard::TABLES {
        rows.push(sorted(csv(&format!("SELECT * FROM {name}"))));
    }
    rows.push(sorted(csv(crate::shard::CALLS_SQL)));
    (tables.stdout.clone(), rows)
}

#[test]
fn conditional_puts_refuse_the_losing_writer() {
    let moto = Moto::start();
    moto.bucket("runs");
    let store = moto.open("s3://runs/conflict");

    // Creating the manifest: the second creator loses.
    let mut m = Manifest::new();
    let first = store.put_manifest(m.to_bytes(), None).unwrap();
    let lost = store.put_manifest(m.to_bytes(), None).unwrap_err();
    assert!(matches!(lost, StoreError::Conflict { .. }), "{lost}");
    // Two writers that read the same version: the first replace wins, the second is refused, and the
    // stored manifest is the winner's.
    let (_, _, etag) = store.load_manifest().unwrap().unwrap();
    assert_eq!(etag, first);
    m.pipeline = Some(annotrace::store::manifest::PipelineInfo {
        name: "winner".into(),
        ..Default::default()
    });
    store.put_manifest(m.to_bytes(), Some(&etag)).unwrap();
    m.pipeline.as_mut().unwrap().name = "loser".into();
    let lost = store.put_manifest(m.to_bytes(), Some(&etag)).unwrap_err();
    assert!(
        lost.to_string()
            .contains("another writer replaced manifest.json since this process read it"),
        "{lost}"
    );
    let (stored, _, _) = store.load_manifest().unwrap().unwrap();
    assert_eq!(stored.pipeline.unwrap().name, "winner");
    // An immutable object is written once.
    assert!(store.put_new("x/a", b"one".to_vec()).unwrap());
    assert!(!store.put_new("x/a", b"two".to_vec()).unwrap());
    assert_eq!(store.get("x/a").unwrap().unwrap(), b"one");

    // On the command line: the same shard index twice at once, then two finalizers at once. A loser
    // stops with the conflict (exit 5) or finds the winner's commit; the run is whole either way.
    let t = TestRun::new();
    t.write("pipelines/p.toml", PIPELINE);
    let cli = S3Cli {
        t: &t,
        env: moto.env(&t.path("s3-cache")),
    };
    let url = "s3://runs/twice";
    let shard = |i: &'static str| ["run", "pipelines/p.toml", "--run-dir", url, "--shard", i];
    // `--until sim`: a shard of the whole pipeline would wait for slice 1/2 of `sim`, which on object
    // storage no waiting shard computes for another (all n processes must run at once).
    let sim_only = [
        "run",
        "pipelines/p.toml",
        "--run-dir",
        url,
        "--shard",
        "0/2",
        "--until",
        "sim",
    ];
    let twins: Vec<Ran> = [cli.spawn(&sim_only), cli.spawn(&sim_only)]
        .into_iter()
        .map(wait)
        .collect();
    let loser_or_ok = |r: &Ran| {
        if r.code != Some(0) {
            r.code(5).stderr_has("another");
        }
    };
    assert!(
        twins.iter().any(|r| r.code == Some(0)),
        "one of the twins succeeds"
    );
    twins.iter().for_each(loser_or_ok);
    for r in [cli.spawn(&shard("0/2")), cli.spawn(&shard("1/2"))]
        .into_iter()
        .map(wait)
    {
        r.ok();
    }
    let finalizers: Vec<Ran> = (0..2)
        .map(|_| cli.spawn(&["run", "pipelines/p.toml", "--run-dir", url, "--finalize"]))
        .collect::<Vec<_>>()
        .into_iter()
        .map(wait)
        .collect();
    assert!(finalizers.iter().any(|r| r.code == Some(0)));
    finalizers.iter().for_each(loser_or_ok);
    t.run(&["run", "pipelines/p.toml", "--run-dir", "runs/single"])
        .ok();
    assert_eq!(
        tables_and_rows_with(&cli, url),
        tables_and_rows(&t, "runs/single")
    );
}
