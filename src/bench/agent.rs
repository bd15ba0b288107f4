//! The agents: [`RandomAgent`] (uniform over the answer format), [`SearchAgent`] (tries candidates in
//! the simulator before answering: an upper bound of what the attempts allow) and [`LlmAgent`] (an
//! OpenAI-compatible model through [`crate::llm::LlmClient`], prompts from `prompts/bench/`).
//!
//! Every agent answers with text in the format, and the same strict parser reads it, so offline agents
//! and models are scored alike. Agents keep no state between calls: the [`View`] holds the task, the
//! attempt and the history, so a resumed or replayed benchmark asks exactly the same questions.

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use serde_json::json;

use super::BenchError;
use super::action::{Answer, Format, Invalid, fmt_num, parse};
use super::feedback::{Feedback, FeedbackMode, Image};
use super::task::{Simulators, TaskScene, attempt};
use crate::llm::{ChatRequest, LlmClient, Message, Part, Prompts, Role};
use crate::rng::{SplitMix64, finalize, keyed_stream};

/// Which agent.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum AgentKind {
    /// Uniform over the answer format (seeded).
    #[default]
    Random,
    /// Simulates up to `search_budget` candidates per attempt and answers the first that solves.
    Search,
    /// A language model behind an OpenAI-compatible endpoint.
    Llm,
}

impl AgentKind {
    /// The kind's name.
    pub fn as_str(self) -> &'static str {
        match self {
            AgentKind::Random => "random",
            AgentKind::Search => "search",
            AgentKind::Llm => "llm",
        }
    }
}

/// The verdict of an earlier attempt.
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict {
    /// The action ran and did not solve the task.
    Failed,
    /// The answer was not a valid action.
    Invalid(Invalid),
}

/// One earlier attempt as the agent sees it.
#[derive(Clone, Debug)]
pub struct Turn {
    /// The agent's whole answer.
    pub answer: String,
    /// The action in canonical form, when the answer parsed.
    pub action: Option<String>,
    /// What happened.
    pub verdict: Verdict,
    /// The feedback given.
    pub feedback: Feedback,
}

/// What an agent is asked.
#[derive(Clone, Copy, Debug)]
pub struct View<'a> {
    /// The answer format.
    pub format: Format,
    /// The feedback mode (for the prompts).
    pub feedback: FeedbackMode,
    /// The benchmark seed.
    pub seed: u64,
    /// The task's position in the benchmark.
    pub task_index: usize,
    /// The state the attempt starts from.
    pub scene: &'a TaskScene,
    /// The images shown with the task.
    pub intro: &'a [Image],
    /// 1-based attempt number.
    pub attempt: usize,
    /// Attempts per task.
    pub attempts: usize,
    /// Earlier attempts of this task.
    pub history: &'a [Turn],
}

/// An agent's answer and what it cost.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Reply {
    /// The answer text.
    pub text: String,
    /// Prompt tokens (models only).
    pub tokens_in: u64,
    /// Completion tokens (models only).
    pub tokens_out: u64,
    /// The model's seconds (as recorded; 0 for offline agents), rounded to the millisecond.
    pub seconds: f64,
    /// Simulations the agent ran itself (search).
    pub simulations: u64,
}

/// An agent.
pub trait Agent: Send + Sync {
    /// `random`, `search`, `llm`.
    fn kind(&self) -> AgentKind;
    /// The model name (empty for offline agents).
    fn model(&self) -> String {
        String::new()
    }
    /// The answer to `view`.
    fn answer(&self, view: &View<'_>) -> Result<Reply, BenchError>;
}

/// The random stream of (seed, task, attempt) for an agent `salt`.
fn stream(salt: &str, view: &View<'_>) -> SplitMix64 {
    keyed_stream(
        finalize(view.seed ^ crate::digest::sha256_u64(&[salt.as_bytes()])),
        view.task_index as u64,
        view.attempt as u64,
    )
}

/// A uniformly drawn answer in `format` (I-PHYRE: each removable block removed with probability ½ at
/// a uniform time on the 0.1 s grid; free billiards: V0 in [0.5, 8] m/s, φ in [0, 360), θ in [0, 45],
/// (a, b) uniform in the disc of radius 0.5).
pub fn random_answer(format: Format, scene: &TaskScene, rng: &mut SplitMix64) -> String {
    match format {
        Format::PhyreGrid => format!("Cell: {}, Radius: {}", 1 + rng.below(64), 1 + rng.below(8)),
        Format::IphyreRemovals => {
            let mut items = Vec::new();
            for index in 0..scene.blocks() {
                if rng.next_f64() < 0.5 {
                    let tenths = 1 + rng.below(150);
                    items.push(format!(
                        "{{\"time\": {}, \"index\": {index}}}",
                        fmt_num(tenths as f64 / 10.0)
                    ));
                }
            }
            format!("[{}]", items.join(", "))
        }
        Format::PoolDeepphy => {
            let all = crate::envs::pool::deepphy::DeepphyAction::all();
            all[rng.below(all.len())].text()
        }
        Format::PoolFree => {
            let v0 = rng.uniform(0.5, 8.0);
            let phi = rng.uniform(0.0, 360.0);
            let theta = rng.uniform(0.0, 45.0);
            let (r, ang) = (
                0.5 * rng.next_f64().sqrt(),
                rng.uniform(0.0, std::f64::consts::TAU),
            );
            Answer::PoolFree(crate::envs::pool::Shot {
                v0: (v0 * 1000.0).round() / 1000.0,
                phi: ((phi * 1000.0).round() / 1000.0).min(359.999),
                theta: (theta * 1000.0).round() / 1000.0,
                a: (r * ang.cos() * 1000.0).round() / 1000.0,
                b: (r * ang.sin() * 1000.0).round() / 1000.0,
            })
            .text()
        }
    }
}

/// Uniform over the answer format, seeded by (seed, task, attempt).
#[derive(Clone, Copy, Debug, Default)]
pub struct RandomAgent;

impl Agent for RandomAgent {
    fn kind(&self) -> AgentKind {
        AgentKind::Random
    }
    fn answer(&self, view: &View<'_>) -> Result<Reply, BenchError> {
        let mut rng = stream("bench-random", view);
        Ok(Reply {
            text: random_answer(view.format, view.scene, &mut rng),
            ..Reply::default()
        })
    }
}

/// Tries up to `budget` random candidates per attempt in the simulator (skipping answers already given
/// and invalid ones) and answers the first that solves the task from the current state, else the last
/// valid candidate tried. With `budget` × attempts simulations per task it bounds from above what an
/// agent that only samples could reach.
#[derive(Clone, Debug)]
pub struct SearchAgent {
    /// Candidates simulated per attempt at most.
    pub budget: usize,
    /// The simulators.
    pub sims: Simulators,
}

impl Agent for SearchAgent {
    fn kind(&self) -> AgentKind {
        AgentKind::Search
    }
    fn answer(&self, view: &View<'_>) -> Result<Reply, BenchError> {
        let mut rng = stream("bench-search", view);
        let given: Vec<&str> = view
            .history
            .iter()
            .filter_map(|t| t.action.as_deref())
            .collect();
        let mut fallback: Option<String> = None;
        let mut simulations = 0u64;
        // Draws beyond the budget only skip repeats and invalid candidates; they are bounded too.
        for _ in 0..self.budget.max(1) * 8 {
            if simulations as usize >= self.budget.max(1) {
                break;
            }
            let text = random_answer(view.format, view.scene, &mut rng);
            let Ok(answer) = parse(view.format, &text, view.scene.blocks()) else {
                continue;
            };
            let canonical = answer.text();
            if given.contains(&canonical.as_str()) {
                continue;
            }
            match attempt(&self.sims, view.scene, &answer) {
                Ok(r) => {
                    simulations += 1;
                    if r.success {
                        return Ok(Reply {
                            text: canonical,
                            simulations,
                            ..Reply::default()
                        });
                    }
                    fallback = Some(canonical);
                }
                Err(Ok(_invalid)) => continue,
                Err(Err(e)) => return Err(e),
            }
        }
        let text = fallback.unwrap_or_else(|| random_answer(view.format, view.scene, &mut rng));
        Ok(Reply {
            text,
            simulations,
            ..Reply::default()
        })
    }
}

/// Images of at most this many earlier attempts are sent (DeepPHY's `max_image_history`).
pub const MAX_IMAGE_HISTORY: usize = 5;

/// The built-in benchmark templates.
pub const TEMPLATES: [(&str, &str); 3] = [
    (
        "bench/system.j2",
        include_str!("../../prompts/bench/system.j2"),
    ),
    ("bench/task.j2", include_str!("../../prompts/bench/task.j2")),
    (
        "bench/feedback.j2",
        include_str!("../../prompts/bench/feedback.j2"),
    ),
];

/// Adds the benchmark templates to `prompts` (read from its folder when there).
pub fn add_templates(prompts: &mut Prompts) -> Result<(), crate::llm::LlmError> {
    for (name, text) in TEMPLATES {
        prompts.add_template(name, text)?;
    }
    Ok(())
}

fn env_name(scene: &TaskScene) -> &'static str {
    match scene {
        TaskScene::Phyre(_) => "phyre",
        TaskScene::Iphyre(_) => "iphyre",
        TaskScene::Pool(_) => "pooltool",
    }
}

fn with_images(role: Role, text: String, images: &[Image]) -> Message {
    let mut parts = vec![Part::Text(text)];
    for im in images {
        parts.push(Part::png(&im.png));
    }
    Message { role, parts }
}

/// The conversation of `view`: system rules, the task with its images, then for each earlier attempt
/// the answer given and its feedback (images only for the last [`MAX_IMAGE_HISTORY`] attempts).
pub fn messages(prompts: &Prompts, view: &View<'_>) -> Result<Vec<Message>, crate::llm::LlmError> {
    let env = env_name(view.scene);
    let mut out = vec![Message::system(prompts.render(
        "bench/system.j2",
        json!({"env": env, "format": view.format.as_str(), "attempts": view.attempts,
               "feedback": view.feedback.as_str()}),
    )?)];
    let captions: Vec<&str> = view.intro.iter().map(|i| i.caption.as_str()).collect();
    out.push(with_images(
        Role::User,
        prompts.render(
            "bench/task.j2",
            json!({"env": env, "task": view.scene.id(), "description": view.scene.description(),
                   "blocks": view.scene.blocks(), "images": captions}),
        )?,
        view.intro,
    ));
    let first_images = view.history.len().saturating_sub(MAX_IMAGE_HISTORY);
    for (i, turn) in view.history.iter().enumerate() {
        out.push(Message::text(Role::Assistant, turn.answer.clone()));
        let images: &[Image] = if i >= first_images {
            &turn.feedback.images
        } else {
            &[]
        };
        let captions: Vec<&str> = images.iter().map(|i| i.caption.as_str()).collect();
        let invalid = match &turn.verdict {
            Verdict::Invalid(r) => Some(r.to_string()),
            Verdict::Failed => None,
        };
        out.push(with_images(
            Role::User,
            prompts.render(
                "bench/feedback.j2",
                json!({"env": env, "attempt": i + 1, "attempts": view.attempts,
                       "action": turn.action, "invalid": invalid, "feedback": view.feedback.as_str(),
                       "annotations": turn.feedback.text, "images": captions}),
            )?,
            images,
        ));
    }
    Ok(out)
}

/// A language model agent.
#[derive(Debug)]
pub struct LlmAgent {
    /// The client (recording to the run's `llm_calls`, replaying when configured).
    pub client: Arc<LlmClient>,
    /// Templates, with the benchmark's added ([`add_templates`]).
    pub prompts: Arc<Prompts>,
}

impl Agent for LlmAgent {
    fn kind(&self) -> AgentKind {
        AgentKind::Llm
    }
    fn model(&self) -> String {
        self.client.model().to_string()
    }
    fn answer(&self, view: &View<'_>) -> Result<Reply, BenchError> {
        let mut req =
            ChatRequest::new("benchmark").seed(stream("bench-llm", view).next_u64() >> 11);
        req.messages = messages(&self.prompts, view)?;
        let reply = self.client.chat(&req)?;
        Ok(Reply {
            text: reply.content,
            tokens_in: reply.tokens_in,
            tokens_out: reply.tokens_out,
            seconds: (reply.latency.as_secs_f64() * 1000.0).round() / 1000.0,
            simulations: 0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::task::{TaskChoice, choose_tasks};
    use crate::envs::phyre::EvalSetup;
    use crate::trace::Env;

    /// The conversation as a person reads it: roles, texts, images as `[image]`.
    fn transcript(msgs: &[Message]) -> String {
        let mut out = String::new();
        for m in msgs {
            out.push_str(&format!("=== {:?}\n", m.role));
            for p in &m.parts {
                match p {
                    Part::Text(t) => out.push_str(t),
                    Part::ImageUrl(u) => {
                        assert!(u.starts_with("data:image/png;base64,"));
                        out.push_str("[image]");
                    }
                }
                out.push('\n');
            }
        }
        out
    }

    fn image(caption: &str) -> Image {
        Image {
            caption: caption.into(),
            png: vec![0x89, b'P', b'N', b'G'],
        }
    }

    /// Every environment × feedback mode: the system rules, the task, an invalid answer and a failed one
    /// with its feedback.
    #[test]
    fn prompts_per_environment_and_feedback_mode_snapshot() {
        let sims = Simulators::new().unwrap();
        let mut prompts = Prompts::builtin();
        add_templates(&mut prompts).unwrap();
        let cases = [
            (
                Env::Phyre,
                Format::PhyreGrid,
                "Cell: 70, Radius: 2",
                "Cell: 12, Radius: 3",
            ),
            (
                Env::Iphyre,
                Format::IphyreRemovals,
                "remove the left block",
                "[{\"time\": 1.5, \"index\": 0}]",
            ),
            (
                Env::Pooltool,
                Format::PoolDeepphy,
                "Speed: Fast",
                "Speed: High, Strikespot: Top Spin",
            ),
            (
                Env::Pooltool,
                Format::PoolFree,
                "V0: 3",
                "V0: 3, phi: 90, theta: 0, a: 0, b: 0.2",
            ),
        ];
        for (env, format, bad, good) in cases {
            let scene = choose_tasks(
                &sims,
                &TaskChoice {
                    env,
                    count: 1,
                    ids: vec![],
                    phyre_setup: EvalSetup::WithinTemplate,
                    phyre_fold: 0,
                    pool_seed: 1,
                },
            )
            .unwrap()
            .remove(0);
            let invalid = parse(format, bad, scene.blocks()).unwrap_err();
            let action = parse(format, good, scene.blocks()).unwrap().text();
            for mode in [
                FeedbackMode::None,
                FeedbackMode::ImageOnly,
                FeedbackMode::Annotations,
            ] {
                let fb = match mode {
                    FeedbackMode::None => Feedback::default(),
                    FeedbackMode::ImageOnly => Feedback {
                        text: None,
                        images: vec![image("t = 0.0 s"), image("t = 1.0 s")],
                    },
                    FeedbackMode::Annotations => Feedback {
                        text: Some("trace x: 10 steps\npatterns (steps, time, label: objects; key parameters):\n2-4 t0.20 bounce: 3".into()),
                        images: vec![],
                    },
                };
                let history = vec![
                    Turn {
                        answer: bad.into(),
                        action: None,
                        verdict: Verdict::Invalid(invalid.clone()),
                        feedback: Feedback::default(),
                    },
                    Turn {
                        answer: good.into(),
                        action: Some(action.clone()),
                        verdict: Verdict::Failed,
                        feedback: fb,
                    },
                ];
                let intro = [image("initial scene")];
                let view = View {
                    format,
                    feedback: mode,
                    seed: 1,
                    task_index: 0,
                    scene: &scene,
                    intro: &intro,
                    attempt: 3,
                    attempts: 10,
                    history: &history,
                };
                let msgs = messages(&prompts, &view).unwrap();
                insta::assert_snapshot!(
                    format!("bench_{}_{}", format.as_str(), mode.as_str()),
                    transcript(&msgs)
                );
            }
        }
    }

    #[test]
    fn random_answers_always_parse_and_are_seeded() {
        let sims = Simulators::new().unwrap();
        for (env, format) in [
            (Env::Phyre, Format::PhyreGrid),
            (Env::Iphyre, Format::IphyreRemovals),
            (Env::Pooltool, Format::PoolDeepphy),
            (Env::Pooltool, Format::PoolFree),
        ] {
            let scene = choose_tasks(
                &sims,
                &TaskChoice {
                    env,
                    count: 1,
                    ids: vec![],
                    phyre_setup: EvalSetup::WithinTemplate,
                    phyre_fold: 0,
                    pool_seed: 1,
                },
            )
            .unwrap()
            .remove(0);
            let view = |attempt| View {
                format,
                feedback: FeedbackMode::None,
                seed: 9,
                task_index: 2,
                scene: &scene,
                intro: &[],
                attempt,
                attempts: 10,
                history: &[],
            };
            let a = RandomAgent.answer(&view(1)).unwrap().text;
            assert_eq!(a, RandomAgent.answer(&view(1)).unwrap().text);
            for n in 1..50 {
                let t = RandomAgent.answer(&view(n)).unwrap().text;
                parse(format, &t, scene.blocks()).unwrap_or_else(|e| panic!("{t}: {e}"));
            }
        }
    }
}
