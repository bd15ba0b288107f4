//! `annotrace verify --run DIR`: checks every published file of a run against the size and SHA-256 its
//! manifest records, every journal file (`llm_calls`) for a readable Parquet footer, and lists files in
//! table folders that no stage lists (foreign files, which readers ignore).
//!
//! Exit code 0 when nothing is damaged and no foreign file lies in a table folder, 1 otherwise (the
//! damaged and foreign files are the failed items; each is named on standard output). `annotrace run`
//! reruns the stages whose outputs are damaged.

use std::path::PathBuf;

use annotrace::pipeline::ErrorCategory;
use annotrace::store::RunDir;
use annotrace::store::verify::verify_run;

use super::{CliResult, exit_code};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder.
    #[arg(long)]
    run: PathBuf,
}

pub fn run(args: Args) -> CliResult {
    // A run on object storage is pulled first; the pull itself checks every object the manifest
    // names against its recorded size and SHA-256 and fails naming the first that differs.
    let local = super::location::local_run(&args.run)?;
    let run = RunDir::new(local.path());
    let report = verify_run(&run)?;
    for d in &report.damaged {
        println!("damaged  {} (stage {}): {}", d.path, d.stage, d.problem);
    }
    for f in &report.foreign {
        println!("foreign  {f}: no stage lists it; readers ignore it (remove it, or move it out)");
    }
    for (f, stage) in &report.unpublished {
        println!(
            "pending  {f}: stage {stage} did not finish its commit; `annotrace run` finishes or redoes it"
        );
    }
    if !report.unverified.is_empty() {
        println!(
            "note     {} file(s) have no recorded checksum (manifest format 1) and were checked for presence only; `annotrace run` records them",
            report.unverified.len()
        );
    }
    let problems = report.damaged.len() + report.foreign.len();
    println!(
        "{}: {} published file(s) ({} bytes) checked for size and SHA-256, {} journal file(s); {}",
        args.run.display(),
        report.checked,
        report.bytes,
        report.journal,
        if problems == 0 {
            "ok".to_string()
        } else {
            format!(
                "{} damaged, {} foreign",
                report.damaged.len(),
                report.foreign.len()
            )
        }
    );
    Ok(if report.is_clean() {
        0
    } else {
        exit_code(ErrorCategory::Failed)
    })
}
