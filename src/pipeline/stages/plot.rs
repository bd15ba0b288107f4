//! `plot`: draws one of the run's figures (`plot::PlotKind`) as SVG and/or PNG under `exports/`.
//!
//! The table kinds run their query over the run (`plot::kinds`) and draw the rows; the
//! annotation-examples figure reads one trace and its annotations (the given trace, else the first
//! annotated trace of the run) and draws its frames above its pattern timeline (`plot::examples`).

use std::path::PathBuf;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use crate::detect::tables::{first_annotated_trace, read_annotations};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::plot::{PlotKind, examples, figure_of, png, rows_of, svg};
use crate::query::RunQuery;
use crate::store::{read_trace, write_atomic};
use crate::trace::Env;

/// The `plot` stage kind.
pub static KIND: StageKind = StageKind {
    name: "plot",
    summary: "draw a figure of the run (success vs budget, convergence, library size, fitness, learning statistics, annotation examples) as SVG/PNG",
    doc: "Draws one figure (`plot`) into exports/<file>.svg and/or .png, with axis labels and units: \
          success-budget (optimisation: success rate against budget, mean ± std over seeds), convergence \
          (evolution_convergence: similarity of each 10 % budget bin to the final bin), library-size \
          (benchmark: success with annotation feedback against patterns in the library), identification-size \
          (identification: accuracy against patterns, ± standard error over trials), fitness \
          (candidates: best ν so far per label), learning-stats (candidates: executable and activation \
          shares per environment), annotation-examples (frames of a trace above its pattern timeline). \
          The SVG carries every label; the PNG is the same figure without text. With `skip_empty`, a query \
          without rows writes nothing instead of failing.",
    writes: "exports/<file>.svg, exports/<file>.png",
    params: ParamsOf::of::<PlotParams>(),
    build,
};

/// Which files a `plot` stage writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum PlotFormat {
    /// SVG and PNG.
    #[default]
    Both,
    /// SVG only.
    Svg,
    /// PNG only.
    Png,
}

/// The parameters of a `plot` stage.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct PlotParams {
    /// The figure: success-budget, convergence, library-size, identification-size, fitness,
    /// learning-stats or annotation-examples.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plot: Option<PlotKind>,
    /// File name stem under exports/ (default: the figure's name).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    /// Files to write.
    pub format: PlotFormat,
    /// Title line (default: the figure's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub title: Option<String>,
    /// annotation-examples: the trace (default: the first annotated trace of the run).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trace: Option<String>,
    /// annotation-examples: frames drawn above the timeline.
    pub frames: u32,
    /// When the query gives no rows (e.g. library-size before any LLM benchmark ran), write no figure
    /// and say so instead of failing.
    pub skip_empty: bool,
}

impl Default for PlotParams {
    fn default() -> Self {
        PlotParams {
            plot: None,
            file: None,
            format: PlotFormat::Both,
            title: None,
            trace: None,
            frames: 5,
            skip_empty: false,
        }
    }
}

fn build(def: &StageDef, _spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: PlotParams = def.params()?;
    let Some(kind) = p.plot else {
        let names: Vec<&str> = PlotKind::ALL.iter().map(|k| k.name()).collect();
        return Err(BuildError {
            param: None,
            message: format!("needs `plot`: one of {}", names.join(", ")),
        });
    };
    if !(1..=12).contains(&p.frames) {
        return Err(BuildError::param(
            "frames",
            format!("must be within 1..=12, found {}", p.frames),
        ));
    }
    let file = p.file.unwrap_or_else(|| kind.name().to_string());
    if file.is_empty() || file.contains(['/', '\\']) || file.starts_with('.') {
        return Err(BuildError::param(
            "file",
            format!("{file:?} must be a plain file name stem (it is written under exports/)"),
        ));
    }
    Ok(Box::new(PlotStage {
        kind,
        file,
        format: p.format,
        title: p.title,
        trace: p.trace,
        frames: p.frames as usize,
        skip_empty: p.skip_empty,
    }))
}

/// The `plot` stage.
#[derive(Debug)]
pub struct PlotStage {
    kind: PlotKind,
    file: String,
    format: PlotFormat,
    title: Option<String>,
    trace: Option<String>,
    frames: usize,
    skip_empty: bool,
}

/// What a `plot` stage records in the manifest.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PlotSummary {
    /// The figure.
    pub plot: String,
    /// Files written, relative to the run.
    pub files: Vec<String>,
    /// Series drawn (annotation-examples: timeline rows).
    pub series: usize,
    /// Why nothing was drawn (`skip_empty` with no rows).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skipped: Option<String>,
}

impl PlotStage {
    /// The first trace of the run with annotations, in file order.
    fn first_annotated(&self, ctx: &StageContext<'_>) -> Result<String, StageError> {
        for env in Env::ALL {
            if let Some(id) = first_annotated_trace(ctx.run(), env)? {
                return Ok(id);
            }
        }
        Err(StageError::Input(
            "plot annotation-examples: the run has no annotations; run an annotate stage first or \
             name a `trace`"
                .into(),
        ))
    }

    fn examples(
        &self,
        ctx: &StageContext<'_>,
    ) -> Result<(Option<String>, Vec<u8>, usize), StageError> {
        let id = match &self.trace {
            Some(t) => t.clone(),
            None => self.first_annotated(ctx)?,
        };
        let trace = read_trace(ctx.run(), &id).map_err(|e| StageError::Input(e.to_string()))?;
        let anns = read_annotations(ctx.run(), trace.env, Some(&id))?;
        let labels: std::collections::BTreeSet<&str> =
            anns.iter().map(|a| a.label.as_str()).collect();
        let render = |e: crate::envs::EnvError| StageError::Simulation {
            item: format!("trace {id}"),
            source: Box::new(e),
        };
        let s = match self.format {
            PlotFormat::Png => None,
            _ => Some(examples::svg(&trace, &anns, self.frames).map_err(render)?),
        };
        let p = match self.format {
            PlotFormat::Svg => Vec::new(),
            _ => examples::png(&trace, &anns, self.frames).map_err(render)?,
        };
        Ok((s, p, labels.len()))
    }

    /// Whether the kind's query gives no rows (or its table is missing).
    fn empty(&self, ctx: &StageContext<'_>) -> Result<bool, StageError> {
        let q = RunQuery::open(ctx.run())?;
        if !q.has_table(self.kind.table()) {
            return Ok(true);
        }
        let sql = self.kind.sql().unwrap_or_default();
        Ok(rows_of(self.kind, &q.sql(&sql)?)
            .map_err(|e| StageError::Input(e.to_string()))?
            .is_empty())
    }

    fn table_figure(
        &self,
        ctx: &StageContext<'_>,
    ) -> Result<(Option<String>, Vec<u8>, usize), StageError> {
        let q = RunQuery::open(ctx.run())?;
        let table = self.kind.table();
        if !q.has_table(table) {
            return Err(StageError::Input(format!(
                "plot {}: the run has no {table} table",
                self.kind
            )));
        }
        let sql = self.kind.sql().unwrap_or_default();
        let rows =
            rows_of(self.kind, &q.sql(&sql)?).map_err(|e| StageError::Input(e.to_string()))?;
        if rows.is_empty() {
            return Err(StageError::Input(format!(
                "plot {}: the {table} table gives no rows to draw",
                self.kind
            )));
        }
        let fig = figure_of(self.kind, &rows, self.title.as_deref());
        let s = (self.format != PlotFormat::Png).then(|| svg(&fig));
        let p = match self.format {
            PlotFormat::Svg => Vec::new(),
            _ => png(&fig).map_err(StageError::Internal)?,
        };
        Ok((s, p, fig.series.len()))
    }
}

impl Stage for PlotStage {
    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        if self.skip_empty && self.kind != PlotKind::AnnotationExamples && self.empty(ctx)? {
            let why = format!(
                "the {} table gives no rows to draw (skip_empty)",
                self.kind.table()
            );
            let summary = PlotSummary {
                plot: self.kind.name().to_string(),
                files: Vec::new(),
                series: 0,
                skipped: Some(why.clone()),
            };
            return Ok(StageOutput {
                summary: serde_json::to_value(&summary).unwrap_or(Value::Null),
                line: format!("{}: skipped: {why}", self.kind),
                ..StageOutput::default()
            });
        }
        let (svg_text, png_bytes, series) = match self.kind {
            PlotKind::AnnotationExamples => self.examples(ctx)?,
            _ => self.table_figure(ctx)?,
        };
        let dir = ctx.run().exports_dir();
        let mut files: Vec<PathBuf> = Vec::new();
        if let Some(s) = svg_text {
            let path = dir.join(format!("{}.svg", self.file));
            write_atomic(&path, s.as_bytes()).map_err(|e| StageError::io(&path, e))?;
            files.push(path);
        }
        if self.format != PlotFormat::Svg {
            let path = dir.join(format!("{}.png", self.file));
            write_atomic(&path, &png_bytes).map_err(|e| StageError::io(&path, e))?;
            files.push(path);
        }
        let shown: Vec<String> = files
            .iter()
            .map(|f| {
                f.strip_prefix(ctx.run().root())
                    .unwrap_or(f)
                    .to_string_lossy()
                    .into_owned()
            })
            .collect();
        let summary = PlotSummary {
            plot: self.kind.name().to_string(),
            files: shown.clone(),
            series,
            skipped: None,
        };
        Ok(StageOutput {
            rows: Default::default(),
            files,
            summary: serde_json::to_value(&summary).unwrap_or(Value::Null),
            line: format!("{} ({series} series) -> {}", self.kind, shown.join(", ")),
        })
    }

    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        Ok(json!({"sql": self.kind.sql()}))
    }
}
