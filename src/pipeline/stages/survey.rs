//! `survey`: writes the survey page of the paper's appendix D (`crate::survey`): each chosen trace's
//! rollout as an animated PNG beside one of its summaries, rated 1–7, conditions and order shuffled per
//! participant with the seed; and the `survey_items` table (what the page offers), which
//! `import-survey` checks answers against.
//!
//! **Conditions** are the summarisers of the run's `summaries` table (`offline`, `frames`,
//! `annotations`). When a summariser wrote summaries in more than one setting for an environment (two
//! libraries, or a subset of labels), each setting is a condition of its own, named
//! `summariser:library:patterns`. **Items** are traces with a summary in every chosen condition: all of
//! them, or `traces` drawn with the seed (SplitMix64, a partial Fisher–Yates shuffle of the eligible
//! traces sorted by environment and id), or `trace_ids`; items are listed by environment and id.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use arrow::array::{Array, AsArray};
use arrow::datatypes::Int64Type;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::trace_files::{env_trace_ids, read_traces_by_id};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::rng::SplitMix64;
use crate::store::{RunDir, read_file};
use crate::survey::{
    Item, PageText, SURVEY_ITEMS, SummaryRef, Survey, SurveyError, SurveyWriter, VideoOptions,
    Videos, survey_id, valid_participant,
};
use crate::trace::Env;

/// The `survey` stage kind.
pub static KIND: StageKind = StageKind {
    name: "survey",
    summary: "write a survey page: rollout animations beside one summary each, rated 1–7 (appendix D)",
    doc: "Writes a static page (opens from the file system, no server) on which participants rate \
          summaries of rollouts on a 1–7 Likert scale: each chosen trace's rollout as an animated PNG \
          encoded in Rust (drawn by the renderers of `annotrace render`) beside ONE of its summaries \
          from the `summaries` table. The order of the items and the condition (summariser) shown for \
          each are shuffled per participant with the seed, identically in the page and in \
          `import-survey`; answers stay in the browser (localStorage) and are downloaded as CSV. Also \
          writes the `survey_items` table. The folder is built aside and swapped in whole.",
    writes: "survey_items; exports/<stage>/ (index.html, survey.js, survey.css, data/, media/)",
    params: ParamsOf::of::<SurveyParams>(),
    build,
};

/// The parameters of a `survey` stage.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct SurveyParams {
    /// Folder to write the page to, relative to the project folder (default:
    /// `<run>/exports/<stage>`). Its old contents are replaced.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub out: Option<String>,
    /// Only traces of these environments (default: every environment with summaries).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub envs: Vec<Env>,
    /// Items: this many traces drawn with the seed from those with a summary in every condition
    /// (0: all of them).
    pub traces: u64,
    /// Only these traces (each needs a summary in every condition) instead of a seeded sample.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub trace_ids: Vec<String>,
    /// The conditions compared (default: every condition of the run's summaries), e.g. `["frames",
    /// "annotations"]`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub conditions: Vec<String>,
    /// Seed of the sample and of every participant's shuffle (default: the pipeline's seed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Participant ids P001…PNNN listed on the start page as links (0: participants type an id).
    pub participants: u64,
    /// Side of the animation (px).
    pub size: u64,
    /// Frames per second of simulated time (the animation plays in real time).
    pub fps: f64,
    /// At most this many frames per animation (longer rollouts get fewer per second).
    pub max_frames: u64,
    /// The page's title.
    pub title: String,
    /// The question asked of every item.
    pub question: String,
    /// The label of rating 1.
    pub low: String,
    /// The label of rating 7.
    pub high: String,
}

impl Default for SurveyParams {
    fn default() -> Self {
        let v = VideoOptions::default();
        SurveyParams {
            out: None,
            envs: Vec::new(),
            traces: 20,
            trace_ids: Vec::new(),
            conditions: Vec::new(),
            seed: None,
            participants: 0,
            size: v.size as u64,
            fps: v.fps,
            max_frames: v.max_frames as u64,
            title: "How well does the summary describe the video?".into(),
            question: "How accurately does the summary describe what happens in the video?".into(),
            low: "not at all accurate".into(),
            high: "completely accurate".into(),
        }
    }
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: SurveyParams = def.params()?;
    if !(16..=1024).contains(&p.size) {
        return Err(BuildError::param(
            "size",
            format!("must be 16–1024 px, found {}", p.size),
        ));
    }
    if !(p.fps.is_finite() && p.fps > 0.0 && p.fps <= 60.0) {
        return Err(BuildError::param(
            "fps",
            format!("must be a number in (0, 60], found {}", p.fps),
        ));
    }
    if !(1..=1000).contains(&p.max_frames) {
        return Err(BuildError::param(
            "max_frames",
            format!("must be 1–1000, found {}", p.max_frames),
        ));
    }
    if p.participants > 10_000 {
        return Err(BuildError::param(
            "participants",
            format!("at most 10000 listed ids, found {}", p.participants),
        ));
    }
    if let Some(o) = &p.out
        && (o.is_empty() || PathBuf::from(o).file_name().is_none())
    {
        return Err(BuildError::param(
            "out",
            format!("{o:?} is not a folder path"),
        ));
    }
    let mut seen = BTreeSet::new();
    if let Some(c) = p.conditions.iter().find(|c| !seen.insert(c.as_str())) {
        return Err(BuildError::param(
            "conditions",
            format!("{c:?} is listed twice"),
        ));
    }
    let participants: Vec<String> = (1..=p.participants).map(|k| format!("P{k:03}")).collect();
    debug_assert!(participants.iter().all(|p| valid_participant(p)));
    Ok(Box::new(SurveyStage {
        out: p.out.as_ref().map(|o| spec.project_dir.join(o)),
        seed: p.seed.unwrap_or(spec.seed),
        video: VideoOptions {
            size: p.size as u32,
            fps: p.fps,
            max_frames: p.max_frames as usize,
        },
        page: PageText {
            title: p.title.clone(),
            question: p.question.clone(),
            low: p.low.clone(),
            high: p.high.clone(),
            participants,
        },
        p,
    }))
}

/// The `survey` stage.
#[derive(Debug)]
pub struct SurveyStage {
    p: SurveyParams,
    out: Option<PathBuf>,
    seed: u64,
    video: VideoOptions,
    page: PageText,
}

/// What a `survey` stage records in the manifest (the command prints it).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SurveySummary {
    /// The survey's id (in every CSV row it exports).
    pub survey: String,
    /// The page folder.
    pub folder: String,
    /// Its page.
    pub index: String,
    /// The seed of the shuffle.
    pub seed: u64,
    /// The conditions compared.
    pub conditions: Vec<String>,
    /// Items per environment.
    pub items: BTreeMap<String, u64>,
    /// Bytes of the folder (page, data and animations).
    pub bytes: u64,
    /// Bytes of the animations.
    pub media_bytes: u64,
    /// Frames over all animations.
    pub frames: u64,
}

impl From<SurveyError> for StageError {
    fn from(e: SurveyError) -> Self {
        match e {
            SurveyError::Io { path, source } => StageError::Io { path, source },
            SurveyError::Internal(m) => StageError::Internal(m),
            SurveyError::Apng(e) => StageError::Internal(e.to_string()),
            other => StageError::Input(other.to_string()),
        }
    }
}

/// One `summaries` row, as the survey uses it.
#[derive(Clone, Debug)]
struct Row {
    env: Env,
    trace_id: String,
    seed: i64,
    summary: SummaryRef,
}

/// Every `summaries` row of the run in `envs` (all environments when empty).
fn summary_rows(run: &RunDir, envs: &[Env]) -> Result<Vec<Row>, StageError> {
    let mut out = Vec::new();
    for f in run.table("summaries")?.files {
        let Some(env) = f.env else { continue };
        if !envs.is_empty() && !envs.contains(&env) {
            continue;
        }
        for b in read_file(&f.path)? {
            let bad = |n: &str| {
                StageError::Store(crate::store::StoreError::Schema {
                    path: f.path.clone(),
                    message: format!("no column {n} of the expected type"),
                })
            };
            let s = |n: &str| {
                b.column_by_name(n)
                    .and_then(|c| c.as_string_opt::<i32>().cloned())
                    .ok_or_else(|| bad(n))
            };
            let i = |n: &str| {
                b.column_by_name(n)
                    .and_then(|c| c.as_primitive_opt::<Int64Type>().cloned())
                    .ok_or_else(|| bad(n))
            };
            let (trace, library, summariser, text) =
                (s("trace_id")?, s("library")?, s("summariser")?, s("text")?);
            let (patterns, seed) = (i("patterns")?, i("seed")?);
            for r in 0..b.num_rows() {
                if trace.is_null(r) || summariser.is_null(r) || text.is_null(r) {
                    continue;
                }
                out.push(Row {
                    env,
                    trace_id: trace.value(r).to_string(),
                    seed: seed.value(r),
                    summary: SummaryRef {
                        summariser: summariser.value(r).to_string(),
                        library: library.value(r).to_string(),
                        patterns: patterns.value(r),
                        text: text.value(r).to_string(),
                    },
                });
            }
        }
    }
    Ok(out)
}

/// The condition name of each row (see the module doc).
fn condition_names(rows: &[Row]) -> Vec<String> {
    let mut settings: BTreeMap<(&str, Env), BTreeSet<(&str, i64)>> = BTreeMap::new();
    for r in rows {
        settings
            .entry((&r.summary.summariser, r.env))
            .or_default()
            .insert((&r.summary.library, r.summary.patterns));
    }
    let split: BTreeSet<&str> = settings
        .iter()
        .filter(|(_, s)| s.len() > 1)
        .map(|((name, _), _)| *name)
        .collect();
    rows.iter()
        .map(|r| {
            let s = &r.summary;
            if split.contains(s.summariser.as_str()) {
                format!("{}:{}:{}", s.summariser, s.library, s.patterns)
            } else {
                s.summariser.clone()
            }
        })
        .collect()
}

impl SurveyStage {
    /// The survey's conditions and items (without the id), from the run's summaries.
    fn design(&self, run: &RunDir) -> Result<(Vec<String>, Vec<Item>), StageError> {
        let rows = summary_rows(run, &self.p.envs)?;
        let names = condition_names(&rows);
        let found: BTreeSet<&str> = names.iter().map(String::as_str).collect();
        let conditions: Vec<String> = if self.p.conditions.is_empty() {
            found.iter().map(|s| s.to_string()).collect()
        } else {
            if let Some(c) = self
                .p
                .conditions
                .iter()
                .find(|c| !found.contains(c.as_str()))
            {
                return Err(StageError::Input(format!(
                    "survey: condition {c:?} has no summaries in the run (its conditions: {})",
                    if found.is_empty() {
                        "none".to_string()
                    } else {
                        found.iter().copied().collect::<Vec<_>>().join(", ")
                    }
                )));
            }
            self.p.conditions.clone()
        };
        // (env, trace) → condition index → the row with the lowest seed.
        let mut by: BTreeMap<(Env, String), BTreeMap<usize, &Row>> = BTreeMap::new();
        for (r, name) in rows.iter().zip(&names) {
            let Some(c) = conditions.iter().position(|x| x == name) else {
                continue;
            };
            let slot = by.entry((r.env, r.trace_id.clone())).or_default();
            match slot.get(&c) {
                Some(old) if old.seed <= r.seed => {}
                _ => {
                    slot.insert(c, r);
                }
            }
        }
        let eligible: Vec<(Env, String)> = by
            .iter()
            .filter(|(_, m)| m.len() == conditions.len())
            .map(|(k, _)| k.clone())
            .collect();
        let chosen: Vec<(Env, String)> = if !self.p.trace_ids.is_empty() {
            let mut out = Vec::new();
            for id in &self.p.trace_ids {
                let hit = eligible.iter().find(|(_, t)| t == id).ok_or_else(|| {
                    StageError::Input(format!(
                        "survey: trace {id:?} has no summary in every condition ({})",
                        conditions.join(", ")
                    ))
                })?;
                if !out.contains(hit) {
                    out.push(hit.clone());
                }
            }
            out
        } else if self.p.traces == 0 || self.p.traces as usize >= eligible.len() {
            eligible.clone()
        } else {
            let mut pool = eligible.clone();
            let mut rng = SplitMix64::new(self.seed);
            let k = self.p.traces as usize;
            for i in 0..k {
                let j = i + rng.below(pool.len() - i);
                pool.swap(i, j);
            }
            pool.truncate(k);
            pool.sort();
            pool
        };
        if chosen.is_empty() {
            return Err(StageError::TooFewTraces {
                stage: "survey",
                what: format!(
                    "traces with a summary in every condition ({})",
                    if conditions.is_empty() {
                        "no summaries".to_string()
                    } else {
                        conditions.join(", ")
                    }
                ),
                needed: 1,
                found: 0,
                hint: ": run `summarise` stages first (one per condition)",
            });
        }
        let items = chosen
            .into_iter()
            .map(|(env, trace_id)| {
                let m = &by[&(env, trace_id.clone())];
                Item {
                    trace_id,
                    env: env.as_str().to_string(),
                    summaries: (0..conditions.len())
                        .map(|c| m[&c].summary.clone())
                        .collect(),
                }
            })
            .collect();
        Ok((conditions, items))
    }
}

/// Items whose traces are read from the run at once.
const ITEMS_READ_AT_ONCE: usize = 64;

impl Stage for SurveyStage {
    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let run = ctx.run();
        let stage = ctx.stage_id();
        let folder = self
            .out
            .clone()
            .unwrap_or_else(|| run.exports_dir().join(stage));
        let (conditions, items) = self.design(run)?;
        let survey = Survey {
            id: survey_id(self.seed, &conditions, &items),
            seed: self.seed,
            conditions,
            items,
        };
        ctx.progress().set_total(stage, survey.items.len() as u64);
        let mut writer = SurveyWriter::create(&folder)?;
        let mut videos =
            Videos::new(self.video).map_err(|e| StageError::Internal(e.to_string()))?;
        let mut counts: BTreeMap<String, u64> = BTreeMap::new();
        let (mut media_bytes, mut frames) = (0u64, 0u64);
        // Every item's trace must be in the run (checked before any animation is drawn).
        let mut known: BTreeMap<String, Vec<String>> = BTreeMap::new();
        for it in &survey.items {
            let ids = match known.entry(it.env.clone()) {
                std::collections::btree_map::Entry::Occupied(o) => o.into_mut(),
                std::collections::btree_map::Entry::Vacant(v) => {
                    v.insert(match it.env.parse::<Env>() {
                        Ok(env) => env_trace_ids(run, env)?,
                        Err(_) => Vec::new(),
                    })
                }
            };
            if ids.binary_search(&it.trace_id).is_err() {
                return Err(StageError::Input(format!(
                    "survey: trace {} ({}) has summaries but is not in the run's trace tables",
                    it.trace_id, it.env
                )));
            }
        }
        // The items' traces, read by id a block at a time (the run's other traces are not read); each
        // item's animation is written as its trace is read, in the items' order.
        let mut done = 0usize;
        for (block, start) in survey
            .items
            .chunks(ITEMS_READ_AT_ONCE)
            .zip((0..).step_by(ITEMS_READ_AT_ONCE))
        {
            let ids: Vec<String> = block.iter().map(|i| i.trace_id.clone()).collect();
            for (k, (it, trace)) in block.iter().zip(read_traces_by_id(run, &ids)?).enumerate() {
                if trace.env.as_str() != it.env {
                    return Err(StageError::Input(format!(
                        "survey: trace {} is a trace of {} in the run's trace tables, not of {}",
                        it.trace_id, trace.env, it.env
                    )));
                }
                let anim = videos.animation(&trace)?;
                frames += anim.frames.len() as u64;
                let bytes = anim.encode().map_err(SurveyError::from)?;
                media_bytes += bytes.len() as u64;
                writer.add_video(start + k, &bytes)?;
                *counts.entry(it.env.clone()).or_default() += 1;
                done += 1;
                ctx.progress().advance(stage, 1);
            }
        }
        debug_assert_eq!(done, survey.items.len());
        let batch = survey.items_batch()?;
        let mut sink = ctx
            .staging()
            .sink(SURVEY_ITEMS, None, "items", batch.schema())?;
        sink.write(&batch)?;
        let (_, rows) = sink.commit()?;
        let files = writer.finish(&survey, &self.page)?;
        let bytes: u64 = files
            .iter()
            .map(|f| std::fs::metadata(f).map(|m| m.len()).unwrap_or(0))
            .sum();
        let shown = |p: &std::path::Path| {
            p.strip_prefix(run.root())
                .unwrap_or(p)
                .to_string_lossy()
                .into_owned()
        };
        let summary = SurveySummary {
            survey: survey.id.clone(),
            folder: shown(&folder),
            index: shown(&folder.join("index.html")),
            seed: self.seed,
            conditions: survey.conditions.clone(),
            items: counts,
            bytes,
            media_bytes,
            frames,
        };
        let line = format!(
            "survey {}: {} items × {} conditions ({:.1} MB) -> {}",
            survey.id,
            survey.items.len(),
            survey.conditions.len(),
            bytes as f64 / 1e6,
            summary.index
        );
        Ok(StageOutput {
            rows: [(SURVEY_ITEMS.to_string(), rows as u64)].into(),
            files,
            summary: serde_json::to_value(&summary).unwrap_or(Value::Null),
            line,
        })
    }

    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        // The page's code is part of the output.
        Ok(json!({"page": crate::digest::sha256_hex(crate::survey::SURVEY_JS.as_bytes())}))
    }
}
