//! `annotrace bench`: end-to-end speed as a user meets it — `annotrace simulate` from the command line
//! into Parquet — for each row of the throughput table (docs/performance.md, "End to end").
//!
//! Each case runs this same binary's `simulate` command as a child process (`RAYON_NUM_THREADS` set to
//! the thread count) into a fresh run folder, times the whole process, then reads the Parquet footers
//! for the trace and frame-row counts and sums the file sizes. Nothing here is simulated in-process, so
//! the figures include start-up, sharding, the manifest and the commit, exactly as `simulate` pays them.
//! `--scale` shrinks every case in proportion (the side-by-side script uses it to fit a time budget).
//!
//! The `annotate` case measures the next command a user runs on those traces: the built-in pooltool
//! library over the `pool` case's shots. The shots are simulated once, untimed; each thread count
//! then times `annotrace annotate --workers <threads>` on its own copy of them (a run folder takes
//! one annotate stage), and the CPU time includes the detector workers, which `annotate` waits for.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, anyhow};
use parquet::file::reader::{FileReader, SerializedFileReader};

use annotrace::store::{Codec, ColumnSink, ParquetSettings, ParquetSink, Stats};
use annotrace::trace::view::ColumnView;

use super::{CliError, CliResult};

/// The Cargo profile that built this binary (`debug`, `release`, `dist`), from `build.rs`.
const BUILD_PROFILE: &str = env!("ANNOTRACE_PROFILE");

/// What a case times.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Timed {
    /// `simulate` with the case's arguments.
    Simulate,
    /// `annotate` with the built-in library, over traces simulated (untimed) with the case's
    /// arguments; the thread count is the number of workers.
    Annotate,
}

/// One row of the throughput table.
#[derive(Clone, Copy, Debug)]
struct Case {
    name: &'static str,
    what: &'static str,
    timed: Timed,
    /// `simulate` arguments before scaling; `{n}` is replaced by the scaled count.
    args: &'static [&'static str],
    /// The count `--scale` multiplies.
    count: u64,
    /// What the count counts.
    unit: &'static str,
}

const CASES: &[Case] = &[
    Case {
        name: "pool",
        what: "billiards, racks x 1 shot, dt 0.01",
        timed: Timed::Simulate,
        args: &[
            "--env", "pooltool", "--scenes", "{n}", "--shots", "1", "--dt", "0.01",
        ],
        count: 2000,
        unit: "shots",
    },
    Case {
        name: "phyre-1",
        what: "PHYRE, tasks x 1 action, every step",
        timed: Timed::Simulate,
        args: &[
            "--env", "phyre", "--scenes", "{n}", "--shots", "1", "--stride", "1",
        ],
        count: 500,
        unit: "episodes",
    },
    Case {
        name: "phyre-6",
        what: "PHYRE, tasks x 1 action, stride 6",
        timed: Timed::Simulate,
        args: &[
            "--env", "phyre", "--scenes", "{n}", "--shots", "1", "--stride", "6",
        ],
        count: 500,
        unit: "episodes",
    },
    Case {
        name: "iphyre",
        what: "I-PHYRE 60 fps, 40 games x click sets",
        timed: Timed::Simulate,
        args: &[
            "--env", "iphyre", "--games", "all", "--shots", "{n}", "--fps", "60",
        ],
        count: 25,
        unit: "episodes",
    },
    Case {
        name: "annotate",
        what: "billiards, 12 built-in detectors over the pool case's shots",
        timed: Timed::Annotate,
        args: &[
            "--env", "pooltool", "--scenes", "{n}", "--shots", "1", "--dt", "0.01",
        ],
        count: 2000,
        unit: "traces",
    },
];

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Cases to run, comma-separated: pool, phyre-1, phyre-6, iphyre, annotate, or all.
    #[arg(long, default_value = "all")]
    cases: String,
    /// Thread counts, comma-separated (each case runs once per count; for `annotate`, the number of
    /// detector workers).
    #[arg(long, default_value = "1,2")]
    threads: String,
    /// Multiplies every case's size (racks, tasks, click sets per game); 1 = the table.
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
    /// Seed of the simulated datasets.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Folder for the run folders (default: a fresh folder in the system's temporary folder,
    /// removed afterwards); kept when given.
    #[arg(long)]
    dir: Option<PathBuf>,
    /// Also write the results as JSON Lines to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Instead of the cases: re-encode the trace tables of this run folder with each Parquet setting
    /// annotrace considered (codec and level, float dictionaries and encodings, statistics, page and
    /// row-group size), one write per trace's worth of rows as `simulate` writes them, and print time
    /// (the faster of two passes) and size per setting.
    #[arg(long, conflicts_with_all = ["cases", "threads", "scale"])]
    settings: Option<PathBuf>,
}

/// The Parquet settings `--settings` compares, the default first.
fn candidate_settings() -> Vec<(&'static str, ParquetSettings, bool)> {
    // The default until session 8 (2026-11-24): zstd 3, statistics on every column, 20,000-row
    // pages; every other candidate changes it in one or a few ways.
    let d = ParquetSettings {
        codec: Codec::Zstd(3),
        label_stats: true,
        page_rows: 20_000,
        ..ParquetSettings::default()
    };
    let with = |f: &dyn Fn(&mut ParquetSettings)| {
        let mut s = d;
        f(&mut s);
        s
    };
    let fast = with(&|s| {
        s.label_stats = false;
        s.page_rows = 1 << 16;
    });
    let arrow: Vec<(&'static str, ParquetSettings)> = vec![
        (
            "zstd 3, no float dictionary, page statistics everywhere, 20,000-row pages (the default before session 8)",
            d,
        ),
        (
            "zstd 3, dictionary on floats too (the default before 2026-11-24)",
            with(&|s| s.float_dictionary = true),
        ),
        ("zstd 1", with(&|s| s.codec = Codec::Zstd(1))),
        ("zstd 9", with(&|s| s.codec = Codec::Zstd(9))),
        ("lz4 (raw)", with(&|s| s.codec = Codec::Lz4Raw)),
        ("snappy", with(&|s| s.codec = Codec::Snappy)),
        ("uncompressed", with(&|s| s.codec = Codec::None)),
        (
            "zstd 3, byte-stream-split floats",
            with(&|s| s.float_byte_stream_split = true),
        ),
        (
            "zstd 1, byte-stream-split floats",
            with(&|s| {
                s.codec = Codec::Zstd(1);
                s.float_byte_stream_split = true;
            }),
        ),
        (
            "lz4, byte-stream-split floats",
            with(&|s| {
                s.codec = Codec::Lz4Raw;
                s.float_byte_stream_split = true;
            }),
        ),
        (
            "zstd 3, no statistics on label strings",
            with(&|s| s.label_stats = false),
        ),
        (
            "zstd 3, chunk statistics only",
            with(&|s| s.stats = Stats::Chunk),
        ),
        ("zstd 3, 64 Ki-row pages", with(&|s| s.page_rows = 1 << 16)),
        (
            "zstd 3, 1 Mi-row row groups",
            with(&|s| s.row_group_rows = 1 << 20),
        ),
        (
            "zstd 3, 8 Ki-row row groups",
            with(&|s| s.row_group_rows = 1 << 13),
        ),
        (
            "zstd 1, no label statistics, 64 Ki-row pages (the default now: other tables)",
            with(&|s| {
                *s = fast;
                s.codec = Codec::Zstd(1);
            }),
        ),
        (
            "zstd 1, byte-stream-split floats, no label statistics, 64 Ki-row pages",
            with(&|s| {
                *s = fast;
                s.codec = Codec::Zstd(1);
                s.float_byte_stream_split = true;
            }),
        ),
        (
            "lz4, no label statistics, 64 Ki-row pages",
            with(&|s| {
                *s = fast;
                s.codec = Codec::Lz4Raw;
            }),
        ),
        (
            "uncompressed, no label statistics, 64 Ki-row pages",
            with(&|s| {
                *s = fast;
                s.codec = Codec::None;
            }),
        ),
    ];
    let default = ParquetSettings::default();
    let column = |codec| ParquetSettings { codec, ..default };
    let floats = |float_hash_log, float_raw_literals| ParquetSettings {
        float_hash_log,
        float_raw_literals,
        ..default
    };
    let columns: Vec<(&'static str, ParquetSettings)> = vec![
        (
            "column writer, zstd 1 (the default now: timesteps and frames; PHYRE's and I-PHYRE's float pages)",
            default,
        ),
        (
            "column writer, zstd 1, 2^12-entry hash table for per-row floats",
            floats(12, false),
        ),
        (
            "column writer, zstd 1, 2^10-entry hash table for per-row floats",
            floats(10, false),
        ),
        (
            "column writer, zstd 1, 2^12-entry hash table and raw literals for per-row floats",
            floats(12, true),
        ),
        (
            "column writer, zstd 1, 2^10-entry hash table and raw literals for per-row floats (billiards' default now)",
            ParquetSettings::for_frames(Some(annotrace::trace::Env::Pooltool)),
        ),
        ("column writer, zstd 3", column(Codec::Zstd(3))),
        ("column writer, zstd -1 (fast)", column(Codec::Zstd(-1))),
        ("column writer, zstd -5 (fast)", column(Codec::Zstd(-5))),
        ("column writer, lz4 (raw)", column(Codec::Lz4Raw)),
        ("column writer, snappy", column(Codec::Snappy)),
        ("column writer, uncompressed", column(Codec::None)),
    ];
    arrow
        .into_iter()
        .map(|(n, s)| (n, s, false))
        .chain(columns.into_iter().map(|(n, s)| (n, s, true)))
        .collect()
}
/// `--settings RUN`: every trace table file of the run re-encoded with each candidate setting.
fn compare_settings(run: &Path) -> anyhow::Result<()> {
    let run_dir = annotrace::store::RunDir::new(run);
    let mut files = Vec::new();
    let mut traces = 0u64;
    for table in annotrace::trace::schema::TRACE_TABLES {
        let schema = annotrace::trace::schema::table_schema(table).expect("a trace table");
        for f in run_dir.table(table)?.files {
            let batches = annotrace::store::read_file(&f.path)?;
            if table == "traces" {
                traces += batches.iter().map(|b| b.num_rows() as u64).sum::<u64>();
            }
            files.push((table, schema.clone(), batches, f.bytes));
        }
    }
    if files.is_empty() {
        return Err(anyhow!("{}: no trace tables to re-encode", run.display()));
    }
    let rows: u64 = files
        .iter()
        .flat_map(|(_, _, b, _)| b.iter().map(|b| b.num_rows() as u64))
        .sum();
    let on_disk: u64 = files.iter().map(|f| f.3).sum();
    let scratch = std::env::temp_dir().join(format!("annotrace-settings-{}", std::process::id()));
    fs::create_dir_all(&scratch)?;
    println!(
        "{} trace(s), {rows} rows in {} file(s), {:.2} MB on disk; profile {}",
        traces,
        files.len(),
        on_disk as f64 / 1e6,
        BUILD_PROFILE
    );
    println!(
        "| setting | encode s (wall) | encode CPU s | M rows per CPU s | MB | MB per 1,000 traces | frames MB | size vs the first |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|");
    let mut base = None;
    let result = (|| -> anyhow::Result<()> {
        for (name, settings, column_writer) in candidate_settings() {
            // Each setting twice; the faster pass counts (the machine is shared).
            let (mut secs, mut cpu) = (f64::INFINITY, f64::INFINITY);
            let (mut bytes, mut frames_bytes) = (0u64, 0u64);
            for _pass in 0..2 {
                (bytes, frames_bytes) = (0, 0);
                let start = Instant::now();
                let cpu0 = cpu_s(libc::RUSAGE_SELF);
                for (i, (table, schema, batches, _)) in files.iter().enumerate() {
                    let target = scratch.join(format!("{i}.parquet"));
                    // One write per trace's worth of rows, as the `simulate` stage writes them.
                    let table_rows: usize = batches.iter().map(|b| b.num_rows()).sum();
                    let chunk = (table_rows / traces.max(1) as usize).max(1);
                    let slices = || {
                        batches.iter().flat_map(move |b| {
                            (0..b.num_rows())
                                .step_by(chunk)
                                .map(move |at| b.slice(at, chunk.min(b.num_rows() - at)))
                        })
                    };
                    // The column writer takes the tables `simulate` gives it (timesteps, frames).
                    let (path, _) = if column_writer
                        && matches!(*table, "timesteps" | "frames")
                        && ColumnSink::supports(schema, &settings)
                    {
                        let mut sink = ColumnSink::create(&target, schema.clone(), &settings)?;
                        for b in slices() {
                            let views: Option<Vec<ColumnView<'_>>> =
                                b.columns().iter().map(ColumnView::from_array).collect();
                            let views = views.ok_or_else(|| {
                                anyhow!("{table}: a column the column writer cannot take")
                            })?;
                            sink.append(b.num_rows(), &views)?;
                        }
                        sink.commit()?
                    } else {
                        let mut sink =
                            ParquetSink::create_with(&target, schema.clone(), &settings)?;
                        for b in slices() {
                            sink.write(&b)?;
                        }
                        sink.commit()?
                    };
                    let n = fs::metadata(&path)?.len();
                    bytes += n;
                    if *table == "frames" {
                        frames_bytes += n;
                    }
                }
                secs = secs.min(start.elapsed().as_secs_f64());
                cpu = cpu.min(cpu_s(libc::RUSAGE_SELF) - cpu0);
            }
            let base = *base.get_or_insert(bytes);
            println!(
                "| {name} | {secs:.2} | {cpu:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.3} |",
                rows as f64 / cpu.max(1e-9) / 1e6,
                bytes as f64 / 1e6,
                bytes as f64 / 1e3 / traces.max(1) as f64,
                frames_bytes as f64 / 1e6,
                bytes as f64 / base as f64
            );
        }
        Ok(())
    })();
    let _ = fs::remove_dir_all(&scratch);
    result
}

/// What one case measured.
#[derive(Debug, serde::Serialize)]
struct Measured {
    case: &'static str,
    what: &'static str,
    threads: usize,
    items: u64,
    unit: &'static str,
    traces: u64,
    frame_rows: u64,
    wall_s: f64,
    /// CPU time of the process (user + system): on a shared machine a steadier measure than wall time.
    cpu_s: f64,
    items_per_s: f64,
    /// Wall milliseconds per item (the unit of `annotate`'s goal: ms per trace).
    wall_ms_per_item: f64,
    /// Items per CPU second.
    items_per_cpu_s: f64,
    frame_rows_per_s: f64,
    /// Frame rows per CPU second (per core).
    frame_rows_per_cpu_s: f64,
    parquet_bytes: u64,
    parquet_bytes_per_1000_traces: f64,
    frames_bytes: u64,
    profile: &'static str,
}

fn parse_list<T: std::str::FromStr>(s: &str, flag: &str) -> Result<Vec<T>, CliError> {
    s.split(',')
        .map(|p| {
            p.trim()
                .parse()
                .map_err(|_| CliError::input(anyhow!("{flag}: {p:?} is not a valid entry")))
        })
        .collect()
}

fn cases(list: &str) -> Result<Vec<Case>, CliError> {
    if list.trim() == "all" {
        return Ok(CASES.to_vec());
    }
    list.split(',')
        .map(|name| {
            CASES
                .iter()
                .find(|c| c.name == name.trim())
                .copied()
                .ok_or_else(|| {
                    CliError::input(anyhow!(
                        "--cases: unknown case {name:?} (expected pool, phyre-1, phyre-6, iphyre, annotate or all)"
                    ))
                })
        })
        .collect()
}

/// Rows and bytes of the Parquet files under `dir` (recursively), per table folder.
fn parquet_totals(dir: &Path, table: Option<&str>) -> anyhow::Result<(u64, u64)> {
    let (mut rows, mut bytes) = (0u64, 0u64);
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in fs::read_dir(&d).with_context(|| d.display().to_string())? {
            let path = entry?.path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if path.is_dir() {
                if !name.starts_with('.') {
                    stack.push(path);
                }
            } else if name.ends_with(".parquet") {
                let rel = path.strip_prefix(dir).unwrap_or(&path);
                let first = rel
                    .components()
                    .next()
                    .map(|c| c.as_os_str().to_string_lossy());
                if table.is_some_and(|t| first.as_deref() != Some(t)) {
                    continue;
                }
                bytes += fs::metadata(&path)?.len();
                let file = fs::File::open(&path)?;
                let reader =
                    SerializedFileReader::new(file).with_context(|| path.display().to_string())?;
                rows += reader.metadata().file_metadata().num_rows() as u64;
            }
        }
    }
    Ok((rows, bytes))
}

/// CPU seconds (user + system) of every child process waited for so far.
fn children_cpu_s() -> f64 {
    cpu_s(libc::RUSAGE_CHILDREN)
}

/// CPU seconds (user + system) of `who` (`RUSAGE_SELF`, `RUSAGE_CHILDREN`).
fn cpu_s(who: libc::c_int) -> f64 {
    // SAFETY: getrusage writes one `rusage` struct into the zeroed value it is given.
    let usage = unsafe {
        let mut u: libc::rusage = std::mem::zeroed();
        libc::getrusage(who, &mut u);
        u
    };
    let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 / 1e6;
    secs(usage.ru_utime) + secs(usage.ru_stime)
}

/// The `simulate` arguments of `case` at count `n`, into `run`.
fn simulate_args(case: &Case, n: u64, seed: u64, run: &Path) -> Vec<String> {
    let mut args: Vec<String> = vec!["-q".into(), "simulate".into()];
    args.extend(case.args.iter().map(|a| a.replace("{n}", &n.to_string())));
    args.extend(["--seed".to_string(), seed.to_string(), "--run".to_string()]);
    args.push(run.display().to_string());
    args
}

/// Runs `exe args` to its end (with `RAYON_NUM_THREADS=threads` when given); its wall and CPU
/// seconds (its own and those of the processes it waited for). With `quiet`, its standard output is
/// dropped (`annotate` prints its per-label table there, which would break the bench's own).
fn time_child(
    exe: &Path,
    args: &[String],
    threads: Option<usize>,
    quiet: bool,
) -> anyhow::Result<(f64, f64)> {
    let cpu_before = children_cpu_s();
    let start = Instant::now();
    let mut cmd = Command::new(exe);
    cmd.args(args);
    if let Some(t) = threads {
        cmd.env("RAYON_NUM_THREADS", t.to_string());
    }
    if quiet {
        cmd.stdout(std::process::Stdio::null());
    }
    let status = cmd
        .status()
        .with_context(|| format!("starting {}", exe.display()))?;
    let wall_s = start.elapsed().as_secs_f64();
    let cpu_s = children_cpu_s() - cpu_before;
    if !status.success() {
        return Err(anyhow!("annotrace {} failed: {status}", args.join(" ")));
    }
    Ok((wall_s, cpu_s))
}

/// Copies the folder `from` (files and folders, recursively) to `to`, which must not exist.
fn copy_dir(from: &Path, to: &Path) -> anyhow::Result<()> {
    fs::create_dir(to).with_context(|| to.display().to_string())?;
    for entry in fs::read_dir(from).with_context(|| from.display().to_string())? {
        let entry = entry?;
        let target = to.join(entry.file_name());
        if entry.file_type()?.is_dir() {
            copy_dir(&entry.path(), &target)?;
        } else {
            fs::copy(entry.path(), &target)
                .with_context(|| format!("copying {}", entry.path().display()))?;
        }
    }
    Ok(())
}

/// Times one case at count `n` on `threads` threads into the fresh run folder `run`; an `annotate`
/// case copies the traces simulated into `input` there first.
fn run_case(
    exe: &Path,
    case: &Case,
    n: u64,
    threads: usize,
    seed: u64,
    run: &Path,
    input: &Path,
) -> anyhow::Result<Measured> {
    let (wall_s, cpu_s, written) = match case.timed {
        Timed::Simulate => {
            let (wall, cpu) = time_child(
                exe,
                &simulate_args(case, n, seed, run),
                Some(threads),
                false,
            )?;
            (wall, cpu, None)
        }
        Timed::Annotate => {
            copy_dir(input, run)?;
            let (_, before) = parquet_totals(run, None)?;
            let args: Vec<String> = [
                "-q",
                "annotate",
                "--env",
                "pooltool",
                "--workers",
                &threads.to_string(),
                "--run",
                &run.display().to_string(),
            ]
            .map(String::from)
            .to_vec();
            let (wall, cpu) = time_child(exe, &args, None, true)?;
            let (_, after) = parquet_totals(run, None)?;
            (wall, cpu, Some(after.saturating_sub(before)))
        }
    };
    let (traces, _) = parquet_totals(run, Some("traces"))?;
    let (frame_rows, frames_bytes) = parquet_totals(run, Some("frames"))?;
    // What the timed command wrote: every table of a simulate run, the annotation tables of an
    // annotate run.
    let (parquet_bytes, frames_bytes) = match written {
        Some(bytes) => (bytes, 0),
        None => (parquet_totals(run, None)?.1, frames_bytes),
    };
    let items = match case.timed {
        Timed::Annotate => traces,
        Timed::Simulate if case.name == "iphyre" => n * 40,
        Timed::Simulate => n,
    };
    Ok(Measured {
        case: case.name,
        what: case.what,
        threads,
        items,
        unit: case.unit,
        traces,
        frame_rows,
        wall_s,
        cpu_s,
        items_per_s: items as f64 / wall_s,
        wall_ms_per_item: wall_s * 1000.0 / items.max(1) as f64,
        items_per_cpu_s: items as f64 / cpu_s.max(1e-9),
        frame_rows_per_s: frame_rows as f64 / wall_s,
        frame_rows_per_cpu_s: frame_rows as f64 / cpu_s.max(1e-9),
        parquet_bytes,
        parquet_bytes_per_1000_traces: parquet_bytes as f64 * 1000.0 / traces.max(1) as f64,
        frames_bytes,
        profile: BUILD_PROFILE,
    })
}

pub fn run(args: Args) -> CliResult {
    if let Some(run) = &args.settings {
        compare_settings(run).map_err(CliError::failed)?;
        return Ok(0);
    }
    let cases = cases(&args.cases)?;
    let threads: Vec<usize> = parse_list(&args.threads, "--threads")?;
    if threads.contains(&0) {
        return Err(CliError::input(anyhow!(
            "--threads: counts must be at least 1"
        )));
    }
    if !(args.scale.is_finite() && args.scale > 0.0) {
        return Err(CliError::input(anyhow!(
            "--scale: must be a positive number"
        )));
    }
    let exe = std::env::current_exe()
        .map_err(|e| CliError::new(annotrace::pipeline::ErrorCategory::Io, e))?;
    let (dir, keep) = match &args.dir {
        Some(d) => (d.clone(), true),
        None => (
            std::env::temp_dir().join(format!("annotrace-bench-{}", std::process::id())),
            false,
        ),
    };
    fs::create_dir_all(&dir).map_err(|e| CliError::io(&dir, e))?;
    let mut out = Vec::new();
    println!(
        "| case | what | threads | n | traces | frame rows | wall s | CPU s | per s (wall) | per CPU s | M frame rows/s (wall) | M frame rows per CPU s | Parquet MB per 1,000 traces | profile |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    let result = (|| -> anyhow::Result<()> {
        for case in &cases {
            let n = ((case.count as f64 * args.scale).round() as u64).max(1);
            let input = dir.join(format!("{}-input", case.name));
            if case.timed == Timed::Annotate {
                // The traces to annotate, simulated once and not timed.
                if input.exists() {
                    fs::remove_dir_all(&input).with_context(|| input.display().to_string())?;
                }
                time_child(
                    &exe,
                    &simulate_args(case, n, args.seed, &input),
                    None,
                    false,
                )?;
            }
            for &t in &threads {
                let run = dir.join(format!("{}-t{t}", case.name));
                if run.exists() {
                    fs::remove_dir_all(&run).with_context(|| run.display().to_string())?;
                }
                let m = run_case(&exe, case, n, t, args.seed, &run, &input)?;
                println!(
                    "| {} | {} | {} | {} {} | {} | {} | {:.2} | {:.2} | {:.1} {}/s | {:.1} | {:.2} | {:.2} | {:.2} | {} |",
                    m.case,
                    m.what,
                    m.threads,
                    m.items,
                    m.unit,
                    m.traces,
                    m.frame_rows,
                    m.wall_s,
                    m.cpu_s,
                    m.items_per_s,
                    m.unit,
                    m.items_per_cpu_s,
                    m.frame_rows_per_s / 1e6,
                    m.frame_rows_per_cpu_s / 1e6,
                    m.parquet_bytes_per_1000_traces / 1e6,
                    m.profile
                );
                if !keep {
                    let _ = fs::remove_dir_all(&run);
                }
                out.push(m);
            }
            if !keep && input.exists() {
                let _ = fs::remove_dir_all(&input);
            }
        }
        Ok(())
    })();
    if !keep {
        let _ = fs::remove_dir_all(&dir);
    }
    result.map_err(CliError::failed)?;
    if let Some(path) = &args.json {
        let text: String = out
            .iter()
            .map(|m| serde_json::to_string(m).unwrap_or_default() + "\n")
            .collect();
        annotrace::store::write_atomic(path, text.as_bytes()).map_err(|e| CliError::io(path, e))?;
    }
    Ok(0)
}
