//! `annotrace tables`: a run's tables with row counts, file counts and schemas.

use std::path::PathBuf;

use super::{CliResult, open_query};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder.
    #[arg(long)]
    run: PathBuf,
    /// Only names and row counts, no schemas.
    #[arg(long)]
    brief: bool,
}

pub fn run(args: Args) -> CliResult {
    let q = open_query(&args.run)?;
    for t in q.tables()? {
        println!("{}: {} rows in {} file(s)", t.name, t.rows, t.files);
        if !args.brief {
            for f in t.schema.fields() {
                println!(
                    "  {:<20} {}{}",
                    f.name(),
                    f.data_type(),
                    if f.is_nullable() { "" } else { " not null" }
                );
            }
        }
    }
    Ok(0)
}
