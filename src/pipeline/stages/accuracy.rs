//! `accuracy`: runs a detector library over the run's traces and scores its event-grounded labels
//! against the simulator's events (precision, recall, F1 per label; `detect::accuracy` defines the
//! matching), writing the `accuracy` table.
//! Every environment: billiards (pooltool events), I-PHYRE and PHYRE (contact and action events).

use std::collections::BTreeMap;
use std::sync::Arc;

use arrow::array::{Float64Array, Int64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::annotate::{annotations_of, status_counts};
use super::detector_setup::{DetectorSetup, SandboxParams};
use super::trace_files::{read_traces, trace_file_sets};
use crate::detect::accuracy::{
    LabelScore, Miss, grounded, markdown, scorable, score_trace_listing, truth,
};
use crate::detect::tables::{first_annotated_trace, read_annotations_of};
use crate::detect::{Annotation, WorkerPool};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::trace::{Env, Trace};

/// The parameters of an `accuracy` stage.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct AccuracyParams {
    /// The library, environment and sandbox limits.
    #[serde(flatten)]
    pub sandbox: SandboxParams,
    /// Time tolerance (s) around a detection's span when matching an event.
    pub tolerance: f64,
    /// Contacts of the same pair (or ball and cushion) closer than this (s) are one event (PHYRE,
    /// I-PHYRE: a contact that begins again within this long after it ended).
    pub merge: f64,
    /// Give the detectors the traces without their event log (scoring still uses it): measures what
    /// they infer from the timesteps alone.
    pub hide_events: bool,
    /// Score the run's annotations table (rows of this library's detectors, written by an annotate
    /// stage listed in `inputs`) instead of running the detectors again.
    pub use_annotations: bool,
    /// List up to this many disagreements per label (truth events no detection matched, detections
    /// matching no event) in the stage's summary, to see why a label scores what it does; 0 lists none.
    pub list: u64,
}

impl Default for AccuracyParams {
    fn default() -> Self {
        AccuracyParams {
            sandbox: SandboxParams::default(),
            tolerance: 0.05,
            merge: 0.05,
            hide_events: false,
            use_annotations: false,
            list: 0,
        }
    }
}

/// The `accuracy` stage kind.
pub static KIND: StageKind = StageKind {
    name: "accuracy",
    summary: "score a library's event-grounded labels against simulator events (P/R/F1)",
    doc: "Runs a detector library over every trace of `env` in the run (like annotate, without writing \
          annotations) and scores the event-grounded labels against the simulator's event log. Pooltool: cue strike, \
          ball collision (same-pair contacts closer than `merge` merged), cushion rebound, ball pocketed, \
          rolling/sliding ball (sliding-to-rolling transitions) and spinning ball; I-PHYRE: collision \
          (contact_begin, chatter merged) and object removal (effective action_applied); PHYRE: moving \
          object hits stationary object (contact_begin of a moving and a resting body). A detection \
          matches an event of its label whose objects it all names and falls in its time span ± \
          `tolerance`. Imported traces without the events that ground the labels are not scored. Writes the accuracy table (one row per label).",
    writes: "accuracy",
    params: ParamsOf::of::<AccuracyParams>(),
    build,
};

/// What an `accuracy` stage reports (its manifest summary, read back by `annotrace accuracy`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct AccuracySummary {
    /// The environment.
    pub env: Env,
    /// The library's name.
    pub library: String,
    /// Traces scored.
    pub traces: u64,
    /// Traces without the events that ground the labels (not scored).
    pub unscored: u64,
    /// Time tolerance (s) around a detection's span.
    pub tolerance: f64,
    /// Contacts closer than this (s) are one event.
    pub merge: f64,
    /// Whether the detectors saw the traces without their event log.
    pub hide_events: bool,
    /// Detector calls by status.
    pub statuses: BTreeMap<String, u64>,
    /// One score per scored label.
    pub scores: Vec<ScoreSummary>,
    /// The scores as a Markdown table.
    pub markdown: String,
    /// Up to `list` disagreements per label (the `list` parameter), by label, trace and time.
    #[serde(default)]
    pub misses: Vec<Miss>,
}

/// One label's score.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ScoreSummary {
    /// The label.
    pub label: String,
    /// Ground-truth events.
    pub events: u64,
    /// Detections.
    pub detections: u64,
    /// Precision.
    pub precision: f64,
    /// Recall.
    pub recall: f64,
    /// F1.
    pub f1: f64,
}

/// The `accuracy` stage.
#[derive(Debug)]
pub struct AccuracyStage {
    setup: DetectorSetup,
    use_annotations: bool,
    hide_events: bool,
    tolerance: f64,
    merge: f64,
    list: u64,
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: AccuracyParams = def.params()?;
    let setup = DetectorSetup::new(&p.sandbox, spec)?;
    let num = |k: &'static str, v: f64| -> Result<f64, BuildError> {
        if v >= 0.0 && v.is_finite() {
            Ok(v)
        } else {
            Err(BuildError::param(
                k,
                format!("`{k}` must be >= 0, found {v}"),
            ))
        }
    };
    Ok(Box::new(AccuracyStage {
        use_annotations: p.use_annotations,
        hide_events: p.hide_events,
        tolerance: num("tolerance", p.tolerance)?,
        merge: num("merge", p.merge)?,
        list: p.list,
        setup,
    }))
}

/// The `accuracy` table's schema.
fn schema() -> Arc<Schema> {
    Arc::new(Schema::new(vec![
        Field::new("label", DataType::Utf8, false),
        Field::new("events", DataType::Int64, false),
        Field::new("detections", DataType::Int64, false),
        Field::new("true_positives", DataType::Int64, false),
        Field::new("false_positives", DataType::Int64, false),
        Field::new("false_negatives", DataType::Int64, false),
        Field::new("precision", DataType::Float64, false),
        Field::new("recall", DataType::Float64, false),
        Field::new("f1", DataType::Float64, false),
    ]))
}

fn batch(scores: &[LabelScore]) -> Result<RecordBatch, StageError> {
    let ints = |f: fn(&LabelScore) -> u64| {
        Arc::new(Int64Array::from_iter_values(
            scores.iter().map(|s| f(s) as i64),
        ))
    };
    let floats =
        |f: fn(&LabelScore) -> f64| Arc::new(Float64Array::from_iter_values(scores.iter().map(f)));
    Ok(RecordBatch::try_new(
        schema(),
        vec![
            Arc::new(StringArray::from_iter_values(
                scores.iter().map(|s| s.label.as_str()),
            )),
            ints(|s| s.events),
            ints(|s| s.detections),
            ints(|s| s.true_positives),
            ints(|s| s.false_positives),
            ints(|s| s.false_negatives),
            floats(LabelScore::precision),
            floats(LabelScore::recall),
            floats(LabelScore::f1),
        ],
    )?)
}

impl Stage for AccuracyStage {
    /// The library's hash, the worker and the ground-truth rules: changing any of them rescores.
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        Ok(json!({
            "library": self.setup.library.fingerprint(),
            "worker": crate::detect::worker_fingerprint(),
            "truth": crate::detect::accuracy::rules_fingerprint(),
        }))
    }

    /// Its units are the trace file sets, named by index, each recording its label counts; the
    /// `accuracy` table is summed from them at the commit.
    fn shardable(&self) -> bool {
        true
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let lib = &self.setup.library;
        let sets = trace_file_sets(ctx.run(), self.setup.env)?;
        ctx.progress().set_total(ctx.stage_id(), sets.len() as u64);
        let mut pool: Option<WorkerPool> = None;
        // A run without annotations is an error even when it has no traces to score.
        if self.use_annotations && first_annotated_trace(ctx.run(), self.setup.env)?.is_none() {
            return Err(StageError::Input(
                "use_annotations is set but the run has no annotations for this environment \
                 (list the annotate stage in `inputs`)"
                    .into(),
            ));
        }
        let mut scores: BTreeMap<String, LabelScore> = BTreeMap::new();
        let mut statuses: BTreeMap<String, u64> = BTreeMap::new();
        let mut misses: Vec<Miss> = Vec::new();
        let mut n_traces = 0usize;
        let mut unscored = 0usize;
        for (i, set) in sets.iter().enumerate() {
            let unit = format!("{i:05}");
            if !ctx.owns(&unit) {
                // Another process's slice (`--shard`): its record is summed at the commit.
                continue;
            }
            let record = match ctx.finished_shard(&unit)? {
                Some(r) => r,
                None => {
                    let r = self.score_set(ctx, set, &mut pool)?;
                    ctx.finish_shard(&unit, &r)?;
                    r
                }
            };
            add_unit(&record, &mut scores, &mut statuses, &mut misses, self.list)?;
            n_traces += record["traces"].as_u64().unwrap_or(0) as usize;
            unscored += record["unscored"].as_u64().unwrap_or(0) as usize;
            ctx.progress().advance(ctx.stage_id(), 1);
        }
        if ctx.slice().is_some() {
            return Ok(StageOutput::default());
        }
        let ordered: Vec<LabelScore> = grounded(self.setup.env)
            .iter()
            .filter_map(|l| scores.get(*l).cloned())
            .collect();
        let n = ctx.write_batch("accuracy", self.setup.env, "00000", &batch(&ordered)?)?;
        let min_f1 = ordered.iter().map(LabelScore::f1).fold(1.0_f64, f64::min);
        let mut rows = BTreeMap::new();
        rows.insert("accuracy".to_string(), n);
        Ok(StageOutput {
            rows,
            files: Vec::new(),
            summary: serde_json::to_value(AccuracySummary {
                env: self.setup.env,
                library: lib.name.clone(),
                traces: (n_traces - unscored) as u64,
                unscored: unscored as u64,
                tolerance: self.tolerance,
                merge: self.merge,
                hide_events: self.hide_events,
                statuses: statuses.clone(),
                scores: ordered
                    .iter()
                    .map(|s| ScoreSummary {
                        label: s.label.clone(),
                        events: s.events,
                        detections: s.detections,
                        precision: s.precision(),
                        recall: s.recall(),
                        f1: s.f1(),
                    })
                    .collect(),
                markdown: markdown(&ordered),
                misses,
            })
            .unwrap_or(Value::Null),
            line: format!(
                "{} trace(s), {} event-grounded label(s) of {}: lowest F1 {min_f1:.3}{}",
                n_traces - unscored,
                ordered.len(),
                lib.name,
                if unscored > 0 {
                    format!(" ({unscored} trace(s) without a contact log not scored)")
                } else {
                    String::new()
                }
            ),
        })
    }
}

impl AccuracyStage {
    /// Scores the traces of one file set: its unit record (label counts, call statuses, the first
    /// `list` misses per label, traces scored and not).
    fn score_set(
        &self,
        ctx: &StageContext<'_>,
        set: &super::trace_files::TraceFileSet,
        pool: &mut Option<WorkerPool>,
    ) -> Result<Value, StageError> {
        let lib = &self.setup.library;
        let traces = read_traces(ctx.run(), set)?;
        let mut statuses: BTreeMap<String, u64> = BTreeMap::new();
        let anns = match self.use_annotations {
            true => stored_annotations(ctx, &traces, lib)?,
            false => {
                if pool.is_none() {
                    *pool = Some(self.setup.pool()?);
                }
                let pool = pool.as_ref().expect("just started");
                let batch = if self.hide_events {
                    let blind: Vec<Trace> = traces
                        .iter()
                        .map(|t| Trace {
                            events: Vec::new(),
                            ..t.clone()
                        })
                        .collect();
                    pool.run(&lib.detectors, &blind)
                } else {
                    pool.run(&lib.detectors, &traces)
                };
                for (k, v) in status_counts(&batch) {
                    *statuses.entry(k).or_default() += v;
                }
                annotations_of(lib, &traces, batch)
            }
        };
        let mut scores: BTreeMap<String, LabelScore> = BTreeMap::new();
        let mut misses: Vec<Miss> = Vec::new();
        let mut unscored = 0u64;
        for (trace, mine) in traces.iter().zip(crate::detect::by_trace(&traces, &anns)) {
            if !scorable(self.setup.env, trace) {
                unscored += 1;
                continue;
            }
            let truth = truth(self.setup.env, trace, self.merge);
            let found = score_trace_listing(
                &trace.trace_id,
                grounded(self.setup.env),
                &truth,
                &mine,
                self.tolerance,
                &mut scores,
            );
            for m in found {
                let listed = misses.iter().filter(|x| x.label == m.label).count() as u64;
                if listed < self.list {
                    misses.push(m);
                }
            }
        }
        let counts: Vec<Value> = scores
            .values()
            .map(|s| {
                json!([
                    s.label,
                    s.events,
                    s.detections,
                    s.true_positives,
                    s.false_positives,
                    s.false_negatives
                ])
            })
            .collect();
        Ok(json!({
            "traces": traces.len(),
            "unscored": unscored,
            "scores": counts,
            "statuses": statuses,
            "misses": misses,
        }))
    }
}

/// Adds one unit's record (of [`AccuracyStage::score_set`]) to the stage's sums; misses stay in unit
/// order, at most `list` per label, as one pass over every trace would list them.
fn add_unit(
    record: &Value,
    scores: &mut BTreeMap<String, LabelScore>,
    statuses: &mut BTreeMap<String, u64>,
    misses: &mut Vec<Miss>,
    list: u64,
) -> Result<(), StageError> {
    let bad = || StageError::Internal(format!("an accuracy unit record is malformed: {record}"));
    for c in record["scores"].as_array().ok_or_else(bad)? {
        let n = |k: usize| c[k].as_u64().ok_or_else(bad);
        let label = c[0].as_str().ok_or_else(bad)?.to_string();
        let s = scores.entry(label.clone()).or_insert_with(|| LabelScore {
            label,
            ..LabelScore::default()
        });
        s.events += n(1)?;
        s.detections += n(2)?;
        s.true_positives += n(3)?;
        s.false_positives += n(4)?;
        s.false_negatives += n(5)?;
    }
    for (k, v) in record["statuses"].as_object().into_iter().flatten() {
        *statuses.entry(k.clone()).or_default() += v.as_u64().unwrap_or(0);
    }
    let unit_misses: Vec<Miss> =
        serde_json::from_value(record["misses"].clone()).map_err(|_| bad())?;
    for m in unit_misses {
        let listed = misses.iter().filter(|x| x.label == m.label).count() as u64;
        if listed < list {
            misses.push(m);
        }
    }
    Ok(())
}

/// The run's `annotations` rows of `traces` written by `lib`'s detectors, in the traces' order (only
/// these traces' rows are read), each with its detector's weight as its activation.
fn stored_annotations(
    ctx: &StageContext<'_>,
    traces: &[Trace],
    lib: &crate::detect::Library,
) -> Result<Vec<Annotation>, StageError> {
    let Some(env) = traces.first().map(|t| t.env) else {
        return Ok(Vec::new());
    };
    let ids: Vec<&str> = traces.iter().map(|t| t.trace_id.as_str()).collect();
    let mut by_trace: std::collections::HashMap<String, Vec<Annotation>> = Default::default();
    for a in read_annotations_of(ctx.run(), env, &ids)? {
        if let Some(d) = lib.detectors.iter().find(|d| d.id == a.detector_id) {
            let a = Annotation {
                activation: d.weight,
                ..a
            };
            by_trace.entry(a.trace_id.clone()).or_default().push(a);
        }
    }
    Ok(traces
        .iter()
        .flat_map(|t| by_trace.remove(&t.trace_id).unwrap_or_default())
        .collect())
}
