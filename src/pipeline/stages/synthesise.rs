//! `synthesise`: natural-language goals → reward programs (paper section 3.4). For each goal of a goal
//! file (or each line of a file of sentences) it asks an LLM for a program with the parse / check /
//! execute repair loop of `reward::synth`, giving it few-shot (goal, program) examples from the goal
//! file (never the goal itself), the library's labels with their parameter keys (learned by annotating
//! probe traces), the DSL reference and the environment's scene in words. Offline (no endpoint, or
//! `mode = "goal_file"`) it copies the goal file's hand-written programs, so a pipeline runs without a
//! model. Writes the `reward_programs` table, which `optimise` reads when this stage is its input.
//!
//! **Owns:** the stage kind, the `reward_programs` table (schema, writing, [`read_programs`]).
//! **Does not:** talk HTTP (`llm`), parse or check programs (`reward`), describe scenes
//! (`optimise::problem`).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::array::{Array, AsArray, BooleanArray, Int64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::detector_setup::{DetectorSetup, SandboxParams};
use crate::builtin::Location;
use crate::detect::Annotation;
use crate::envs::Environment;
use crate::envs::iphyre::IphyreEnv;
use crate::envs::phyre::{BallAction, PhyreEnv, TaskSet, dataset_tasks};
use crate::envs::pool::{PoolEnv, Shot};
use crate::llm::{LlmClient, LlmConfig, LlmSettings};
use crate::optimise::{IphyreProblem, Layout, PhyreProblem, PoolProblem, Problem, ShotBounds};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::reward::annotate::{annotate, probe_schema};
use crate::reward::goals::GoalSet;
use crate::reward::synth::{SynthRequest, few_shot, synthesise};
use crate::store::RunDir;
use crate::trace::{Env, Trace};

/// Where the programs come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SynthMode {
    /// `llm` when an endpoint (llm.base_url or ANNOTRACE_LLM_BASE_URL) or a replay run is configured,
    /// else `goal_file`.
    #[default]
    Auto,
    /// Synthesise every program with the LLM.
    Llm,
    /// Copy the goal file's hand-written programs (the offline baseline; no sentence file).
    GoalFile,
}

/// The parameters of a `synthesise` stage.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct SynthesiseParams {
    /// Environment of the goals.
    pub env: Env,
    /// Goal file: the goals to synthesise (unless `sentences` is given) and the few-shot examples
    /// (default: `data/goals/<env>.toml`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub goals: Option<String>,
    /// Only these goals of the goal file.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub goal_ids: Option<Vec<String>>,
    /// A file of goal sentences, one a line (`#` comments, blank lines skipped), relative to the
    /// project; goal ids are `s1`, `s2`, …. Needs an LLM.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sentences: Option<String>,
    /// LLM or the goal file's programs; auto = llm when an endpoint is configured.
    pub mode: SynthMode,
    /// Few-shot (goal, program) examples from the goal file per prompt.
    pub examples: u64,
    /// Repair rounds after the first answer.
    pub max_repairs: u64,
    /// LLM settings (base_url, model, max_calls, temperature, replay, …; docs/llm.md), over the
    /// ANNOTRACE_LLM_* variables.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub llm: Option<LlmSettings>,
    /// Detector library whose labels the programs use (default: the goal file's `library`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub library: Option<String>,
    /// Python worker processes for the probe annotation (0 = one per core).
    pub workers: u64,
    /// Wall-clock limit of one detector call (s).
    pub timeout: f64,
    /// Address-space limit of a worker (MiB).
    pub memory_mb: u64,
}

impl Default for SynthesiseParams {
    fn default() -> Self {
        let s = SandboxParams::default();
        SynthesiseParams {
            env: Env::Pooltool,
            goals: None,
            goal_ids: None,
            sentences: None,
            mode: SynthMode::Auto,
            examples: 3,
            max_repairs: 3,
            llm: None,
            library: None,
            workers: s.workers,
            timeout: s.timeout,
            memory_mb: s.memory_mb,
        }
    }
}

/// The `synthesise` stage kind.
pub static KIND: StageKind = StageKind {
    name: "synthesise",
    summary: "natural-language goals to reward programs through an LLM with repair (offline: the goal file's)",
    doc: "For each goal of `goals` (or each line of `sentences`), asks the LLM for a reward program: the \
          prompt holds the goal, the DSL reference, the library's labels with their parameter keys (learned \
          by annotating probe traces of the environment), the first held-out scene in words and `examples` \
          few-shot (goal, program) pairs from the goal file, never the goal itself. A program that does not \
          parse, check or run on the probe trace is sent back with the interpreter's error, up to \
          `max_repairs` times. Offline (mode goal_file, or auto without an endpoint) the goal file's \
          hand-written programs are copied. Writes reward_programs (goal, sentence, origin, program, \
          accepted, attempts, errors, calls); an optimise stage with this stage as input optimises them.",
    writes: "reward_programs, llm_calls",
    params: ParamsOf::of::<SynthesiseParams>(),
    build,
};

/// One goal to synthesise.
#[derive(Debug, Clone)]
struct Item {
    id: String,
    sentence: String,
    /// The goal file's program, when the goal is in it.
    program: Option<String>,
}

/// The `synthesise` stage.
#[derive(Debug)]
pub struct SynthesiseStage {
    env: Env,
    goals: GoalSet,
    items: Vec<Item>,
    mode: SynthMode,
    examples: usize,
    max_repairs: usize,
    llm: LlmSettings,
    setup: DetectorSetup,
    inputs_text: String,
}

fn read_sentences(path: &Path) -> Result<Vec<Item>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let items: Vec<Item> = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .enumerate()
        .map(|(i, l)| Item {
            id: format!("s{}", i + 1),
            sentence: l.to_string(),
            program: None,
        })
        .collect();
    if items.is_empty() {
        return Err(format!("{}: no goal sentence in the file", path.display()));
    }
    Ok(items)
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: SynthesiseParams = def.params()?;
    let env = p.env;
    let rel = p
        .goals
        .clone()
        .unwrap_or_else(|| format!("data/goals/{env}.toml"));
    let at = Location::file(&spec.project_dir, Path::new(&rel));
    let goals = GoalSet::open(&at, &spec.project_dir)
        .map_err(|e| BuildError::param("goals", e.to_string()))?;
    if goals.env != env {
        return Err(BuildError::param(
            "goals",
            format!("{} is for {}, not {env}", at.path().display(), goals.env),
        ));
    }
    let mut inputs_text = at
        .read_to_string()
        .map_err(|e| BuildError::param("goals", e.to_string()))?;
    let items = match &p.sentences {
        Some(f) => {
            if p.goal_ids.is_some() {
                return Err(BuildError::param(
                    "goal_ids",
                    "goal_ids selects goals of the goal file; it cannot be used with `sentences`",
                ));
            }
            if p.mode == SynthMode::GoalFile {
                return Err(BuildError::param(
                    "sentences",
                    "sentences have no hand-written programs: use mode = \"llm\" or \"auto\"",
                ));
            }
            let path: PathBuf = spec.project_dir.join(f);
            let items = read_sentences(&path).map_err(|e| BuildError::param("sentences", e))?;
            inputs_text.push_str(&std::fs::read_to_string(&path).unwrap_or_default());
            items
        }
        None => {
            let ids: Vec<String> = match &p.goal_ids {
                Some(ids) => ids.clone(),
                None => goals.goals.iter().map(|g| g.id.clone()).collect(),
            };
            let mut items = Vec::new();
            for id in ids {
                let g = goals.get(&id).ok_or_else(|| {
                    BuildError::param(
                        "goal_ids",
                        format!("no goal {id:?} in {}", at.path().display()),
                    )
                })?;
                items.push(Item {
                    id,
                    sentence: g.sentence.clone(),
                    program: Some(g.program.clone()),
                });
            }
            items
        }
    };
    let sandbox = SandboxParams {
        env,
        library: p
            .library
            .clone()
            .or_else(|| goals.library.as_ref().map(|l| l.as_param())),
        workers: p.workers,
        timeout: p.timeout,
        memory_mb: p.memory_mb,
    };
    let setup = DetectorSetup::new(&sandbox, spec)?;
    let mut llm = p.llm.clone().unwrap_or_default();
    if let Some(r) = &llm.replay {
        llm.replay = Some(spec.project_dir.join(r));
    }
    Ok(Box::new(SynthesiseStage {
        env,
        goals,
        items,
        mode: p.mode,
        examples: p.examples as usize,
        max_repairs: p.max_repairs as usize,
        llm,
        setup,
        inputs_text,
    }))
}

/// One row of the `reward_programs` table.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgramRow {
    /// Goal id (`s<k>` for the k-th line of a sentence file).
    pub goal: String,
    /// The goal sentence.
    pub sentence: String,
    /// `llm` or `goal file`.
    pub origin: String,
    /// The accepted program (none when every attempt failed).
    pub program: Option<String>,
    /// LLM calls made (0 for the goal file's programs).
    pub attempts: i64,
    /// The errors of the rejected attempts, in order.
    pub errors: Vec<String>,
    /// The `llm_calls` ids, in order.
    pub calls: Vec<String>,
}

fn table_schema() -> Arc<Schema> {
    Arc::new(Schema::new(vec![
        Field::new("goal", DataType::Utf8, false),
        Field::new("sentence", DataType::Utf8, false),
        Field::new("origin", DataType::Utf8, false),
        Field::new("program", DataType::Utf8, true),
        Field::new("accepted", DataType::Boolean, false),
        Field::new("attempts", DataType::Int64, false),
        Field::new("errors", DataType::Utf8, false),
        Field::new("calls", DataType::Utf8, false),
    ]))
}

fn batch(rows: &[ProgramRow]) -> Result<RecordBatch, arrow::error::ArrowError> {
    let s = |f: fn(&ProgramRow) -> &str| {
        Arc::new(StringArray::from_iter_values(rows.iter().map(f))) as Arc<dyn Array>
    };
    let js = |f: fn(&ProgramRow) -> &Vec<String>| {
        Arc::new(StringArray::from_iter_values(
            rows.iter().map(|r| json!(f(r)).to_string()),
        )) as Arc<dyn Array>
    };
    RecordBatch::try_new(
        table_schema(),
        vec![
            s(|r| &r.goal),
            s(|r| &r.sentence),
            s(|r| &r.origin),
            Arc::new(StringArray::from(
                rows.iter().map(|r| r.program.clone()).collect::<Vec<_>>(),
            )),
            Arc::new(BooleanArray::from(
                rows.iter().map(|r| r.program.is_some()).collect::<Vec<_>>(),
            )),
            Arc::new(Int64Array::from_iter_values(
                rows.iter().map(|r| r.attempts),
            )),
            js(|r| &r.errors),
            js(|r| &r.calls),
        ],
    )
}

/// The `reward_programs` rows of a run (every partition), in file order.
pub fn read_programs(run: &RunDir) -> Result<Vec<ProgramRow>, StageError> {
    let mut out = Vec::new();
    for f in run.table("reward_programs")?.files {
        for b in crate::store::read_file(&f.path)? {
            let col = |i: usize| b.column(i).as_string::<i32>().clone();
            let (goal, sentence, origin, program) = (col(0), col(1), col(2), col(3));
            let attempts = b
                .column(5)
                .as_primitive::<arrow::datatypes::Int64Type>()
                .clone();
            let (errors, calls) = (col(6), col(7));
            let list = |s: &str| serde_json::from_str::<Vec<String>>(s).unwrap_or_default();
            for i in 0..b.num_rows() {
                out.push(ProgramRow {
                    goal: goal.value(i).to_string(),
                    sentence: sentence.value(i).to_string(),
                    origin: origin.value(i).to_string(),
                    program: (!program.is_null(i)).then(|| program.value(i).to_string()),
                    attempts: attempts.value(i),
                    errors: list(errors.value(i)),
                    calls: list(calls.value(i)),
                });
            }
        }
    }
    Ok(out)
}

/// The scene the prompt describes and a probe trace of it (the first held-out scene of the
/// environment's `optimise` defaults, with a plain action).
fn probe_scene(env: Env) -> Result<(String, Trace), StageError> {
    let fail = |item: &str, e: crate::envs::EnvError| StageError::Simulation {
        item: item.to_string(),
        source: Box::new(e),
    };
    match env {
        Env::Pooltool => {
            let penv = PoolEnv::default();
            let scene = crate::optimise::scenes(&penv, Layout::Scatter, 1, 1000)?.remove(0);
            let problem = PoolProblem::new(penv.clone(), ShotBounds::default())?;
            let shot = Shot {
                v0: 2.0,
                phi: 90.0,
                theta: 0.0,
                a: 0.0,
                b: 0.0,
            };
            let trace = penv
                .simulate(&scene, &shot)
                .map_err(|e| fail("billiards probe shot", e))?;
            Ok((problem.describe(&scene), trace))
        }
        Env::Phyre => {
            let set = TaskSet::default_tasks().map_err(|e| fail("PHYRE tasks", e.into()))?;
            let id = dataset_tasks(set, 1, &[]).remove(0);
            let task = set.get(&id).map_err(|e| fail("PHYRE task", e.into()))?;
            let problem = PhyreProblem {
                env: PhyreEnv::default(),
            };
            let a = BallAction {
                x: 0.5,
                y: 0.95,
                r: 0.1,
            };
            let trace = problem
                .env
                .simulate(&task, &a)
                .map_err(|e| fail("PHYRE probe action", e))?;
            Ok((problem.describe(&task), trace))
        }
        Env::Iphyre => {
            let ienv = IphyreEnv::new().map_err(|e| fail("I-PHYRE games", e))?;
            let game = ienv.games.all()[0].clone();
            let trace = ienv
                .simulate(&game, &Vec::new())
                .map_err(|e| fail("I-PHYRE probe episode", e))?;
            let problem = IphyreProblem {
                env: ienv,
                horizon: 5.0,
                never: 0.25,
            };
            Ok((problem.describe(&game), trace))
        }
    }
}

impl SynthesiseStage {
    fn use_llm(&self) -> bool {
        match self.mode {
            SynthMode::Llm => true,
            SynthMode::GoalFile => false,
            SynthMode::Auto => {
                self.llm.base_url.is_some()
                    || self.llm.replay.is_some()
                    || std::env::var(crate::llm::ENV_BASE_URL)
                        .ok()
                        .is_some_and(|v| !v.trim().is_empty())
            }
        }
    }

    fn copy_goal_file(&self) -> Result<Vec<ProgramRow>, StageError> {
        self.items
            .iter()
            .map(|it| {
                let program = it.program.clone().ok_or_else(|| {
                    StageError::Input(format!(
                        "goal {:?} has no hand-written program: synthesising it needs an LLM \
                         endpoint (llm.base_url or ANNOTRACE_LLM_BASE_URL)",
                        it.id
                    ))
                })?;
                Ok(ProgramRow {
                    goal: it.id.clone(),
                    sentence: it.sentence.clone(),
                    origin: "goal file".into(),
                    program: Some(program.trim().to_string()),
                    attempts: 0,
                    errors: Vec::new(),
                    calls: Vec::new(),
                })
            })
            .collect()
    }

    fn with_llm(&self, ctx: &StageContext<'_>) -> Result<Vec<ProgramRow>, StageError> {
        let (scene_text, trace) = probe_scene(self.env)?;
        let pool = self.setup.pool()?;
        let library = &self.setup.library;
        let mut schema = probe_schema(library, &pool);
        let (anns, _): (Vec<Annotation>, usize) =
            annotate(&pool, &library.detectors, std::slice::from_ref(&trace));
        schema.learn_keys(&anns);
        let mut settings = self.llm.clone();
        settings.seed = Some(settings.seed.unwrap_or(ctx.seed()));
        let config = LlmConfig::resolve(&settings, &|k| std::env::var(k).ok())?;
        let client = LlmClient::new(config, Some(ctx.run()))?;
        let mut rows = Vec::new();
        ctx.progress()
            .set_total(ctx.stage_id(), self.items.len() as u64);
        for (i, it) in self.items.iter().enumerate() {
            let req = SynthRequest {
                goal: &it.sentence,
                schema: &schema,
                scene_summary: scene_text.clone(),
                examples: few_shot(
                    &self.goals.goals,
                    Some(&it.id)
                        .filter(|_| it.program.is_some())
                        .map(|s| s.as_str()),
                    &it.sentence,
                    self.examples,
                ),
                image: None,
                probe: Some((&trace, anns.as_slice())),
                max_repairs: self.max_repairs,
                seed: ctx.seed().wrapping_add(1000 * i as u64),
                temperature: None,
            };
            let out = synthesise(&client, &req);
            let out = match out {
                Ok(o) => o,
                Err(e) => {
                    let _ = client.flush();
                    return Err(e.into());
                }
            };
            rows.push(ProgramRow {
                goal: it.id.clone(),
                sentence: it.sentence.clone(),
                origin: "llm".into(),
                program: out.program.map(|p| p.source.trim().to_string()),
                attempts: out.attempts.len() as i64,
                errors: out
                    .attempts
                    .iter()
                    .filter_map(|a| a.error.clone())
                    .collect(),
                calls: out.attempts.iter().map(|a| a.call_id.clone()).collect(),
            });
            ctx.progress().advance(ctx.stage_id(), 1);
        }
        client.flush()?;
        Ok(rows)
    }
}

impl Stage for SynthesiseStage {
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        Ok(json!({
            "inputs": self.inputs_text,
            "library": self.setup.library.fingerprint(),
            "llm": self.use_llm(),
        }))
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let llm = self.use_llm();
        let rows = if llm {
            self.with_llm(ctx)?
        } else {
            self.copy_goal_file()?
        };
        let b = batch(&rows).map_err(|e| StageError::Internal(e.to_string()))?;
        let n = ctx.write_batch("reward_programs", self.env, "000", &b)?;
        let accepted = rows.iter().filter(|r| r.program.is_some()).count();
        let calls: usize = rows.iter().map(|r| r.calls.len()).sum();
        let repaired = rows
            .iter()
            .filter(|r| r.program.is_some() && r.attempts > 1)
            .count();
        let mut out_rows = std::collections::BTreeMap::new();
        out_rows.insert("reward_programs".to_string(), n);
        Ok(StageOutput {
            rows: out_rows,
            files: Vec::new(),
            summary: json!({
                "env": self.env, "origin": if llm { "llm" } else { "goal file" },
                "goals": rows.len(), "accepted": accepted, "repaired": repaired, "calls": calls,
                "failed": rows.iter().filter(|r| r.program.is_none()).map(|r| r.goal.clone()).collect::<Vec<_>>(),
            }),
            line: format!(
                "{}: {accepted}/{} program(s) {} ({repaired} after repair, {calls} LLM call(s))",
                self.env,
                rows.len(),
                if llm {
                    "synthesised"
                } else {
                    "from the goal file"
                }
            ),
        })
    }
}
