//! The attempt loop of one task: ask the agent, parse strictly, simulate, judge, build the feedback,
//! and again, up to the attempt limit or the first success. One [`Row`] per attempt.

use std::time::Instant;

use super::BenchError;
use super::action::{Answer, Format, parse};
use super::agent::{Agent, Turn, Verdict, View};
use super::feedback::{Feedback, FeedbackMode, feedback, task_images};
use super::task::{Simulators, TaskScene, attempt};
use crate::detect::{Detector, WorkerPool};

/// How the tasks of a benchmark are played.
#[derive(Clone, Debug)]
pub struct Settings {
    /// The answer format.
    pub format: Format,
    /// The feedback after a failed attempt.
    pub feedback: FeedbackMode,
    /// Attempts per task.
    pub attempts: usize,
    /// Keyframes per failed rollout (image-only feedback).
    pub keyframes: usize,
    /// Image size (px).
    pub image_size: u32,
    /// The benchmark seed (the agents' streams and request seeds).
    pub seed: u64,
    /// The library's name (annotations feedback; empty otherwise).
    pub library: String,
    /// Detectors of the library that annotate (0 unless annotations feedback).
    pub patterns: usize,
}

/// The detectors that annotate rollouts for `annotations` feedback, and their worker pool.
#[derive(Clone, Copy)]
pub struct Annotator<'a> {
    /// The worker pool.
    pub pool: &'a WorkerPool,
    /// The library's detectors.
    pub detectors: &'a [Detector],
}

/// One attempt: a row of the `benchmark` table.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Task id.
    pub task: String,
    /// Seed index.
    pub seed: i64,
    /// 1-based attempt.
    pub attempt: i64,
    /// The action in canonical form, or the answer (at most 200 characters) when it did not parse.
    pub action: String,
    /// The answer was a valid action.
    pub valid: bool,
    /// Why it was not (`unparsable: …`, `out_of_range: …`, `occluding: …`).
    pub reason: Option<String>,
    /// The attempt solved the task.
    pub success: bool,
    /// Answer format (`phyre-grid`, `iphyre-removals`, `pool-deepphy`, `pool-free`).
    pub format: String,
    /// Feedback mode.
    pub feedback: String,
    /// Library of the annotations (empty when none).
    pub library: String,
    /// Detectors of the library used (0 when none).
    pub patterns: i64,
    /// Agent kind.
    pub agent: String,
    /// Model (empty for offline agents).
    pub model: String,
    /// Prompt tokens.
    pub prompt_tokens: i64,
    /// Completion tokens.
    pub completion_tokens: i64,
    /// The model's seconds (0 for offline agents).
    pub seconds: f64,
    /// Simulations the agent ran itself (search).
    pub simulations: i64,
}

/// A played task.
#[derive(Clone, Debug)]
pub struct Played {
    /// One row per attempt.
    pub rows: Vec<Row>,
    /// Harness seconds (everything but the agent: images, parsing, simulation, annotation, feedback).
    pub harness_s: f64,
    /// Agent seconds measured here (the model's wall time, or the search agent's simulations).
    pub agent_s: f64,
}

fn excerpt(s: &str) -> String {
    let t = s.trim();
    if t.chars().count() <= 200 {
        t.to_string()
    } else {
        t.chars().take(199).chain(['…']).collect()
    }
}

/// Plays task number `task_index` (seed index `seed_index`) with `agent`.
pub fn play_task(
    sims: &Simulators,
    agent: &dyn Agent,
    annotator: Option<Annotator<'_>>,
    settings: &Settings,
    seed_index: u64,
    task_index: usize,
    task: &TaskScene,
) -> Result<Played, BenchError> {
    let mut harness = 0.0;
    let mut agent_s = 0.0;
    let t0 = Instant::now();
    let intro = task_images(task, sims, settings.image_size)?;
    harness += t0.elapsed().as_secs_f64();
    let mut scene = task.clone();
    let mut history: Vec<Turn> = Vec::new();
    let mut rows = Vec::new();
    let seed = crate::rng::finalize(settings.seed ^ seed_index.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    for n in 1..=settings.attempts {
        let view = View {
            format: settings.format,
            feedback: settings.feedback,
            seed,
            task_index,
            scene: &scene,
            intro: &intro,
            attempt: n,
            attempts: settings.attempts,
            history: &history,
        };
        let ta = Instant::now();
        let reply = agent.answer(&view)?;
        agent_s += ta.elapsed().as_secs_f64();
        let th = Instant::now();
        let parsed = parse(settings.format, &reply.text, scene.blocks());
        let (verdict, action, success, fb, next) = match parsed {
            Err(invalid) => (
                Verdict::Invalid(invalid),
                None,
                false,
                Feedback::default(),
                None,
            ),
            Ok(answer) => {
                let canonical = answer.text();
                match attempt(sims, &scene, &answer) {
                    Err(Ok(invalid)) => (
                        Verdict::Invalid(invalid),
                        Some(canonical),
                        false,
                        Feedback::default(),
                        None,
                    ),
                    Err(Err(e)) => return Err(e),
                    Ok(r) if r.success => (
                        Verdict::Failed,
                        Some(canonical),
                        true,
                        Feedback::default(),
                        None,
                    ),
                    Ok(r) => {
                        let last_removal = match &answer {
                            Answer::Iphyre(rs) => rs.iter().map(|x| x.time).fold(0.0, f64::max),
                            _ => 0.0,
                        };
                        // No feedback after the last attempt: nothing would read it.
                        let fb = if n < settings.attempts {
                            let anns = match (settings.feedback, annotator) {
                                (FeedbackMode::Annotations, Some(a)) => {
                                    crate::reward::annotate::annotate(
                                        a.pool,
                                        a.detectors,
                                        std::slice::from_ref(&r.trace),
                                    )
                                    .0
                                }
                                _ => Vec::new(),
                            };
                            feedback(
                                settings.feedback,
                                sims,
                                &scene,
                                &r.next,
                                &r.trace,
                                last_removal,
                                &anns,
                                settings.keyframes,
                                settings.image_size,
                            )?
                        } else {
                            Feedback::default()
                        };
                        (Verdict::Failed, Some(canonical), false, fb, Some(r.next))
                    }
                }
            }
        };
        harness += th.elapsed().as_secs_f64();
        let (valid, reason) = match &verdict {
            Verdict::Invalid(i) => (false, Some(i.to_string())),
            Verdict::Failed => (true, None),
        };
        rows.push(Row {
            task: task.id().to_string(),
            seed: seed_index as i64,
            attempt: n as i64,
            action: if valid {
                action.clone().unwrap_or_default()
            } else {
                excerpt(&reply.text)
            },
            valid,
            reason,
            success,
            format: settings.format.as_str().into(),
            feedback: settings.feedback.as_str().into(),
            library: settings.library.clone(),
            patterns: settings.patterns as i64,
            agent: agent.kind().as_str().into(),
            model: agent.model(),
            prompt_tokens: reply.tokens_in as i64,
            completion_tokens: reply.tokens_out as i64,
            seconds: reply.seconds,
            simulations: reply.simulations as i64,
        });
        if success {
            break;
        }
        history.push(Turn {
            answer: reply.text,
            action,
            verdict,
            feedback: fb,
        });
        if let Some(next) = next {
            scene = next;
        }
    }
    Ok(Played {
        rows,
        harness_s: harness,
        agent_s,
    })
}
