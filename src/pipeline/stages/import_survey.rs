//! `import-survey`: reads the response CSVs that the survey page exports (`crate::survey::responses`),
//! checks every row against the run's `survey_items` (the survey id, its seed, and the trace and
//! condition each participant saw at each position), and writes the `survey_responses` table.
//!
//! All files are read and checked before anything is written, so a bad row (named by file, line and
//! field) writes nothing; `annotrace import-survey` checks them ([`read_responses`]) before it reruns
//! the stage, so the table of the previous import stays as it was. The files' contents are part of the fingerprint: a new or changed
//! CSV reruns the stage and the stages after it.

use std::path::{Path, PathBuf};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::store::{RunDir, read_file};
use crate::survey::responses::{responses_batch, responses_schema};
use crate::survey::{Design, Response, SURVEY_ITEMS, SURVEY_RESPONSES, parse_csv};

/// The `import-survey` stage kind.
pub static KIND: StageKind = StageKind {
    name: "import-survey",
    summary: "read the survey page's response CSVs into the survey_responses table",
    doc: "Reads response CSVs exported by a `survey` page (files, or folders whose *.csv files are \
          read), checks every row against the run's `survey_items` (survey id, seed, and the trace and \
          condition the participant saw at that position, recomputed from the seeded shuffle), and \
          writes one `survey_responses` row per rating. A malformed or mismatched row fails the stage \
          with its file, line and field, and nothing is written.",
    writes: "survey_responses",
    params: ParamsOf::of::<ImportSurveyParams>(),
    build,
};

/// The parameters of an `import-survey` stage.
#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct ImportSurveyParams {
    /// Response CSV files, or folders whose `*.csv` files are read, relative to the project folder.
    pub files: Vec<String>,
    /// While a study runs: a folder that does not exist yet or holds no CSV gives an empty table (the
    /// stage says so) instead of failing.
    pub allow_empty: bool,
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: ImportSurveyParams = def.params()?;
    if p.files.is_empty() {
        return Err(BuildError::param(
            "files",
            "name at least one response CSV or folder of them",
        ));
    }
    Ok(Box::new(ImportSurveyStage {
        paths: p.files.iter().map(|f| spec.project_dir.join(f)).collect(),
        allow_empty: p.allow_empty,
    }))
}

/// The `import-survey` stage.
#[derive(Debug)]
pub struct ImportSurveyStage {
    paths: Vec<PathBuf>,
    allow_empty: bool,
}

/// What an `import-survey` stage records in the manifest (the command prints it).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ImportSurveySummary {
    /// Files read.
    pub files: u64,
    /// Ratings written.
    pub responses: u64,
    /// Distinct participants.
    pub participants: u64,
}

/// Every CSV named (a folder's `*.csv` sorted by name); a missing path is an error unless
/// `allow_empty`.
fn csv_files(paths: &[PathBuf], allow_empty: bool) -> Result<Vec<PathBuf>, StageError> {
    let mut out = Vec::new();
    for p in paths {
        let meta = match std::fs::metadata(p) {
            Err(e) if allow_empty && e.kind() == std::io::ErrorKind::NotFound => continue,
            m => m.map_err(|e| StageError::io(p, e))?,
        };
        if meta.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| StageError::io(p, e))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| {
                    f.is_file() && f.extension().is_some_and(|x| x.eq_ignore_ascii_case("csv"))
                })
                .collect();
            found.sort();
            out.extend(found);
        } else {
            out.push(p.clone());
        }
    }
    Ok(out)
}

/// Reads every response CSV of `paths` (files, or folders of `*.csv`) and checks each row against the
/// run's surveys, writing nothing: the files read and their rows. `annotrace import-survey` calls it
/// before running the stage, so a bad file leaves the run's table as it was.
pub fn read_responses(
    run: &RunDir,
    paths: &[PathBuf],
    allow_empty: bool,
) -> Result<(Vec<PathBuf>, Vec<Response>), StageError> {
    let files = csv_files(paths, allow_empty)?;
    if files.is_empty() && !allow_empty {
        return Err(StageError::Input(format!(
            "import-survey: no response CSV in {} (set allow_empty while the study runs)",
            paths
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    let mut design = Design::default();
    for f in run.table(SURVEY_ITEMS)?.files {
        for b in read_file(&f.path)? {
            design.add_batch(&f.path, &b)?;
        }
    }
    if design.is_empty() && !files.is_empty() {
        return Err(StageError::Input(
            "import-survey: the run has no survey (`survey_items` is empty): run `annotrace survey` first"
                .into(),
        ));
    }
    let mut rows = Vec::new();
    for f in &files {
        rows.extend(parse_csv(f, &read(f)?)?);
    }
    design.check(&rows)?;
    Ok((files, rows))
}

fn read(path: &Path) -> Result<Vec<u8>, StageError> {
    std::fs::read(path).map_err(|e| StageError::io(path, e))
}

impl Stage for ImportSurveyStage {
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        let files = csv_files(&self.paths, self.allow_empty)?;
        let hashes: Vec<Value> = files
            .iter()
            .map(|f| {
                Ok(json!([
                    f.display().to_string(),
                    crate::digest::sha256_hex(&read(f)?)
                ]))
            })
            .collect::<Result<_, StageError>>()?;
        Ok(json!({"files": hashes}))
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let (files, rows) = read_responses(ctx.run(), &self.paths, self.allow_empty)?;
        let batch = responses_batch(&rows)?;
        let mut sink =
            ctx.staging()
                .sink(SURVEY_RESPONSES, None, "responses", responses_schema())?;
        sink.write(&batch)?;
        let (_, n) = sink.commit()?;
        let participants = rows
            .iter()
            .map(|r| (&r.survey, &r.participant))
            .collect::<std::collections::BTreeSet<_>>()
            .len() as u64;
        let summary = ImportSurveySummary {
            files: files.len() as u64,
            responses: n as u64,
            participants,
        };
        let line = if files.is_empty() {
            "no response CSV yet: survey_responses is empty".to_string()
        } else {
            format!(
                "{n} ratings of {participants} participant(s) from {} file(s) -> table {SURVEY_RESPONSES}",
                files.len()
            )
        };
        Ok(StageOutput {
            rows: [(SURVEY_RESPONSES.to_string(), n as u64)].into(),
            files: Vec::new(),
            summary: serde_json::to_value(&summary).unwrap_or(Value::Null),
            line,
        })
    }
}
