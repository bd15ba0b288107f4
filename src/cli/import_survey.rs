//! `annotrace import-survey`: reads the survey page's response CSVs into the `survey_responses` table
//! (the `import-survey` stage kind, as a one-stage pipeline recorded as `import-survey`). A bad row is
//! reported with its file, line and field (exit 2) and nothing is written.

use std::path::PathBuf;

use annotrace::pipeline::stages::import_survey::{
    ImportSurveyParams, ImportSurveySummary, KIND, read_responses,
};
use annotrace::store::RunDir;

use super::CliResult;
use super::one_stage::{OneStage, absolute, existing_run, summary};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder (the one the survey page was written from).
    #[arg(long)]
    run: PathBuf,
    /// Response CSVs, or folders of them (every *.csv inside). All of a study's files at once:
    /// the table is replaced by each import.
    #[arg(required = true)]
    files: Vec<PathBuf>,
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    existing_run(&args.run)?;
    let params = ImportSurveyParams {
        files: args
            .files
            .iter()
            .map(|f| absolute(f))
            .collect::<Result<_, _>>()?,
        allow_empty: false,
    };
    // Check every file before the stage reruns (a rerun first unpublishes the previous import).
    let paths: Vec<PathBuf> = params.files.iter().map(PathBuf::from).collect();
    read_responses(&RunDir::new(&args.run), &paths, false)?;
    let stage = OneStage {
        run: &args.run,
        id: "import-survey".into(),
        force: true,
        remove_new_run_on_failure: false,
    }
    .run(&KIND, &params, quiet)?;
    let s: ImportSurveySummary = summary(&stage, "import-survey")?;
    println!(
        "{} rating(s) of {} participant(s) from {} file(s) -> table survey_responses \
         (ratings per condition: annotrace query --run {} -- \"$(cat sql/survey_ratings.sql)\")",
        s.responses,
        s.participants,
        s.files,
        args.run.display()
    );
    Ok(0)
}
