//! The LLM proposer: child detectors and repairs from a chat-completions model.
//!
//! [`LlmProposer::propose`] renders `prompts/evolve.j2` (the environment's trace layout, the detector
//! contract, the parents with their fitness terms, the library's labels), asks the shared
//! [`LlmClient`] with the request's seed, and extracts the program from the answer.
//! [`LlmProposer::repair`] does the same with `prompts/repair.j2`, fed with the validator's error
//! category, message, line and column. Recording, replay, retries and the budget are the client's.
//!
//! **Owns:** turning a [`ProposalRequest`] into prompts and answers into [`Proposal`]s, and mapping the
//! client's errors onto [`ProposeError`]. **Does not:** talk HTTP (`llm/`), validate or score code.

use std::path::Path;
use std::sync::Arc;

use super::proposer::{Proposal, ProposalRequest, ProposeError, Proposer};
use crate::detect::DetectorError;
use crate::llm::{
    ChatReply, ChatRequest, EvolveContext, LlmClient, LlmConfig, LlmError, LlmSettings, ParentView,
    Prompts, RepairContext, extract_code,
};
use crate::rng;
use crate::store::RunDir;

/// Purpose tags of this proposer's calls in `llm_calls`.
pub const PURPOSE_EVOLVE: &str = "evolve";
/// See [`PURPOSE_EVOLVE`].
pub const PURPOSE_REPAIR: &str = "repair";

/// A [`Proposer`] backed by an OpenAI-compatible endpoint.
#[derive(Debug, Clone)]
pub struct LlmProposer {
    client: Arc<LlmClient>,
    prompts: Arc<Prompts>,
    name: String,
    temperature: Option<f64>,
}

impl LlmProposer {
    /// A proposer asking `client` with `prompts`; its name is `llm:<model>`.
    pub fn new(client: Arc<LlmClient>, prompts: Arc<Prompts>) -> Self {
        let name = format!("llm:{}", client.model());
        LlmProposer {
            client,
            prompts,
            name,
            temperature: None,
        }
    }

    /// A proposer from settings (a pipeline's `[llm]` table or command-line flags) over the
    /// `ANNOTRACE_LLM_*` variables read through `env`, recording into `run`'s `llm_calls`, with the
    /// templates of `prompts_dir` (built-in ones where it has none). The client is shared: take it back
    /// with [`LlmProposer::client`] for usage figures.
    pub fn from_settings(
        settings: &LlmSettings,
        env: &dyn Fn(&str) -> Option<String>,
        run: Option<&RunDir>,
        prompts_dir: Option<&Path>,
    ) -> Result<Self, LlmError> {
        let config = LlmConfig::resolve(settings, env)?;
        let client = LlmClient::new(config, run)?;
        let prompts = Prompts::load(prompts_dir)?;
        let mut p = LlmProposer::new(Arc::new(client), Arc::new(prompts));
        p.temperature = settings.temperature;
        Ok(p)
    }

    /// Sets the sampling temperature of proposals (repairs use the same); the client's default
    /// otherwise.
    pub fn with_temperature(mut self, t: f64) -> Self {
        self.temperature = Some(t);
        self
    }

    /// The client (for its usage figures).
    pub fn client(&self) -> &LlmClient {
        &self.client
    }

    /// One request; `step` orders it in the client's queue when every slot is taken (a round's
    /// proposals and repairs before the next round's).
    fn ask(
        &self,
        purpose: &str,
        prompt: String,
        seed: u64,
        step: u64,
    ) -> Result<Proposal, ProposeError> {
        let system = self.prompts.system().map_err(unavailable)?;
        let mut req = ChatRequest::new(purpose)
            .system(system)
            .user(prompt)
            .seed(seed)
            .order(step);
        req.temperature = self.temperature;
        let reply = self.client.chat(&req).map_err(map_error)?;
        to_proposal(&reply)
    }
}

fn to_proposal(reply: &ChatReply) -> Result<Proposal, ProposeError> {
    match extract_code(&reply.content) {
        Ok(code) => Ok(Proposal {
            code,
            tokens_in: reply.tokens_in,
            tokens_out: reply.tokens_out,
            calls: 1,
        }),
        // The tokens of an answer without code stay recorded in `llm_calls` (call `reply.call_id`).
        Err(e) => Err(ProposeError::Other(format!(
            "no usable code in the answer (call {}): {e}",
            reply.call_id
        ))),
    }
}

fn unavailable(e: LlmError) -> ProposeError {
    ProposeError::Unavailable(e.to_string())
}

/// Budget → ends the label's search; a bad answer → one failed step; a refused request (configuration,
/// strict-replay miss, templates, a 4xx) → ends the run as the configuration's fault; everything else
/// (unreachable endpoint after retries, recording) → ends the run as the service's.
fn map_error(e: LlmError) -> ProposeError {
    match e {
        LlmError::BudgetExhausted { what } => ProposeError::BudgetExhausted(what),
        e @ LlmError::BadResponse { .. } => ProposeError::Other(e.to_string()),
        e if e.is_refusal() => ProposeError::Refused(e.to_string()),
        e => unavailable(e),
    }
}

/// The repair seed: the request's seed mixed with the attempt, so each repair asks a new question.
/// Uses SplitMix64's output function without its increment ([`rng::finalize`], not
/// [`rng::splitmix64`]); the recorded replays key on these seeds, so it stays that way.
fn repair_seed(seed: u64, attempt: u32) -> u64 {
    rng::finalize(seed ^ u64::from(attempt).wrapping_mul(rng::GOLDEN))
}

/// (message, column) of a validator error; the line comes from [`DetectorError::line`].
fn error_parts(error: &DetectorError) -> (String, Option<u32>) {
    match error {
        DetectorError::Syntax {
            message, column, ..
        }
        | DetectorError::Forbidden {
            message, column, ..
        } => (message.clone(), *column),
        DetectorError::NoFindPattern { message }
        | DetectorError::Runtime { message, .. }
        | DetectorError::Crashed { message }
        | DetectorError::Skipped { message } => (message.clone(), None),
        DetectorError::InvalidOutput { path, message } => (format!("at {path}: {message}"), None),
        other => (other.to_string(), None),
    }
}

impl Proposer for LlmProposer {
    fn name(&self) -> &str {
        &self.name
    }

    fn propose(&self, req: &ProposalRequest) -> Result<Proposal, ProposeError> {
        let ctx = EvolveContext {
            env: req.env,
            label: req.label.clone(),
            step: req.step,
            island: req.island,
            parents: req
                .parents
                .iter()
                .map(|p| ParentView::new(&p.code, p.lines, p.fitness.as_ref()))
                .collect(),
            library_labels: req.library_labels.clone(),
        };
        let prompt = self.prompts.render("evolve.j2", ctx).map_err(unavailable)?;
        self.ask(PURPOSE_EVOLVE, prompt, req.seed, req.step)
    }

    fn repair(
        &self,
        req: &ProposalRequest,
        code: &str,
        error: &DetectorError,
        attempt: u32,
    ) -> Result<Option<Proposal>, ProposeError> {
        let (error_message, error_column) = error_parts(error);
        let ctx = RepairContext {
            env: req.env,
            label: req.label.clone(),
            code: code.to_string(),
            error_category: error.category().to_string(),
            error_message,
            error_line: error.line(),
            error_column,
            attempt,
        };
        let prompt = self.prompts.render("repair.j2", ctx).map_err(unavailable)?;
        self.ask(
            PURPOSE_REPAIR,
            prompt,
            repair_seed(req.seed, attempt),
            req.step,
        )
        .map(Some)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repair_seeds_differ_per_attempt_and_repeat() {
        assert_ne!(repair_seed(5, 1), repair_seed(5, 2));
        assert_eq!(repair_seed(5, 1), repair_seed(5, 1));
    }

    #[test]
    fn validator_errors_give_message_and_column() {
        let e = DetectorError::Syntax {
            message: "invalid syntax".into(),
            line: Some(3),
            column: Some(9),
        };
        assert_eq!(error_parts(&e), ("invalid syntax".to_string(), Some(9)));
        let o = DetectorError::InvalidOutput {
            path: "$[0].end_timestep".into(),
            message: "expected an integer".into(),
        };
        assert_eq!(
            error_parts(&o).0,
            "at $[0].end_timestep: expected an integer"
        );
    }

    #[test]
    fn budget_and_bad_answers_map_to_their_proposer_errors() {
        assert!(matches!(
            map_error(LlmError::BudgetExhausted { what: "x".into() }),
            ProposeError::BudgetExhausted(_)
        ));
        assert!(matches!(
            map_error(LlmError::BadResponse {
                url: "u".into(),
                message: "m".into()
            }),
            ProposeError::Other(_)
        ));
        assert!(matches!(
            map_error(LlmError::Connection {
                url: "u".into(),
                message: "refused".into(),
                attempts: 3
            }),
            ProposeError::Unavailable(_)
        ));
        let status = |status| LlmError::Status {
            status,
            url: "u".into(),
            body_excerpt: String::new(),
            attempts: 1,
        };
        assert!(matches!(map_error(status(401)), ProposeError::Refused(_)));
        assert!(matches!(
            map_error(status(429)),
            ProposeError::Unavailable(_)
        ));
        assert!(matches!(
            map_error(status(503)),
            ProposeError::Unavailable(_)
        ));
    }
}
