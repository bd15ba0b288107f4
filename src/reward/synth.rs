//! Synthesis of reward programs from natural-language goals with an LLM, with repair: the prompt
//! gives the goal, the DSL reference, the library summary (labels, aliases, parameter keys), a
//! scene summary (optionally the scene's image) and few-shot (goal, program) examples — the paper's
//! P_r(G, P, Θ, D, {(Ĝ_k, r̂_k)}) — ([`few_shot`] draws them from a goal file, never the goal itself); the program is taken from the answer's ```dsl fence;
//! when it does not parse, check or run on a probe trace of the scene, the model is shown its program
//! and the interpreter's message and asked for a corrected one, up to a retry limit. Every call goes
//! through [`LlmClient`], which records it in the run's `llm_calls` table when it has a run.

use crate::detect::Annotation;
use crate::llm::{ChatRequest, LlmClient, LlmError, Message, fences, strip_think};
use crate::trace::{Env, Trace};

use super::error::RewardError;
use super::facts::AnnotatedTrace;
use super::program::Program;
use super::schema::Schema;
use super::{compile, evaluate};

/// The DSL reference given to models (our wording of the paper's appendix E reference).
pub fn dsl_reference(env: Env) -> String {
    let units = crate::envs::facts(env).units;
    let mut s = String::from(
        "A reward program is ONE expression built from these functions (names in capitals, labels as strings):\n\
- PATTERN(\"label\", {\"key\": value}?, key=value...): true when a pattern with that label occurs and its parameters match every given key. ball=\"id\" requires the pattern's subject (first object) to be that object; contains=[\"id\", ...] requires it to name all of them.\n\
- PATTERN_COUNT(\"label\", ..., min_count=n): true when at least n such patterns occur.\n\
- AND(e1, e2, ...), OR(e1, e2, ...), NOT(e).\n\
- AFTER(a, b, min_delta=None, max_delta=None, first_params=None, second_params=None): true when a starts at or after b (delay t_a - t_b in seconds within the optional bounds). a and b are labels or event expressions (PATTERN, PATTERN_COUNT, CUE_HIT, AFTER, WITHIN, OR of those); first_params/second_params filter a and b when they are labels. To say \"X, then Y\" write AFTER(Y, X).\n\
- WITHIN(a, b, window, event_params=None, reference_params=None): a starts at most `window` seconds after b.\n\
- COUNT(\"label\", n, params=None), GT(\"label\", n, params=None), LT(\"label\", n, params=None): exactly / more than / fewer than n occurrences.\n\
- NEARBY_AT(obj_id, x, y, t, threshold_strength=0.1): the object is within the radius of (x, y) at normalised time t in [0, 1] (0 = start, 1 = end). Units: ",
    );
    s.push_str(units);
    s.push_str(".\n- NEAR(a, b, threshold_strength=0.1): at some moment the outlines of objects a and b are within the radius of each other (same units); partial credit by their closest approach.\n\
- OBJECT_ID(color, shape): the id of the object with that colour and shape, for use as an argument (shape \"object\" matches any shape; in ball=, contains= and NEAR it stands for every such object).\n");
    if env == Env::Pooltool {
        s.push_str(
            "- CUE_HIT(ball): true when the first ball the cue ball touches is `ball` (an event at that contact).\n\
- POCKETED(ball, pocket=None): true when `ball` drops (into that pocket: lb, lc, lt, rb, rc, rt), an event at the drop.\n\
Ball ids are strings: \"cue\", \"1\" ... \"9\" (1 yellow, 2 blue, 3 red, 4 purple, 5 orange, 6 green, 7 brown, 8 black, 9 yellow stripe).\n",
        );
    }
    s.push_str(
        "Scoring: when the expression is a top-level AND, the reward is the fraction of its clauses that hold (COUNT, GT, LT, PATTERN_COUNT, NEARBY_AT and NEAR give partial credit by their distance to satisfaction), so an AND of several steps towards the goal is easiest to optimise.\n\
Rules: use only the labels and parameter keys of the library summary; arguments of NEARBY_AT and NEAR are positional; no comments.\n",
    );
    s
}

/// What to synthesise and how.
#[derive(Debug, Clone)]
pub struct SynthRequest<'a> {
    /// The goal sentence.
    pub goal: &'a str,
    /// Labels and parameter keys.
    pub schema: &'a Schema,
    /// The scene in words.
    pub scene_summary: String,
    /// Few-shot (goal sentence, program) examples.
    pub examples: Vec<(String, String)>,
    /// The scene's initial image (PNG), for vision models.
    pub image: Option<Vec<u8>>,
    /// A probe trace of the scene with its annotations: a program must run on it.
    pub probe: Option<(&'a Trace, &'a [Annotation])>,
    /// Repair rounds after the first answer.
    pub max_repairs: usize,
    /// Request seed.
    pub seed: u64,
    /// Sampling temperature.
    pub temperature: Option<f64>,
}

/// One call and what came of it.
#[derive(Debug, Clone, PartialEq)]
pub struct Attempt {
    /// `reward_synthesis` or `reward_repair`.
    pub purpose: String,
    /// The call id in `llm_calls`.
    pub call_id: String,
    /// The program taken from the answer, if any.
    pub program: Option<String>,
    /// Why it was rejected (extraction, parse, check or execution), if it was.
    pub error: Option<String>,
}

/// The outcome of a synthesis.
#[derive(Debug, Clone)]
pub struct Synthesis {
    /// The accepted program, if an attempt passed.
    pub program: Option<Program>,
    /// Every attempt in order.
    pub attempts: Vec<Attempt>,
}

/// Up to `n` (sentence, program) examples from `goals`, in file order, leaving out every goal whose
/// id or sentence is the one being synthesised (`goal_id`, `sentence`).
pub fn few_shot(
    goals: &[super::goals::Goal],
    goal_id: Option<&str>,
    sentence: &str,
    n: usize,
) -> Vec<(String, String)> {
    let norm = |s: &str| s.trim().to_lowercase();
    goals
        .iter()
        .filter(|g| Some(g.id.as_str()) != goal_id && norm(&g.sentence) != norm(sentence))
        .take(n)
        .map(|g| (g.sentence.clone(), g.program.trim().to_string()))
        .collect()
}

/// The few-shot block of the prompt (empty without examples).
fn examples_text(examples: &[(String, String)]) -> String {
    if examples.is_empty() {
        return String::new();
    }
    let mut s = String::from("Examples of goals and their reward programs for this environment:\n");
    for (g, p) in examples {
        s.push_str(&format!("Goal: {g}\n```dsl\n{p}\n```\n"));
    }
    s.push('\n');
    s
}

/// The prompt of the first call.
pub fn prompt(req: &SynthRequest<'_>) -> String {
    format!(
        "Write a reward program for the goal below. An optimiser will search the agent's actions for the \
         highest reward, so reward the steps that lead to the goal, not only its final state.\n\n\
         Goal: {goal}\n\n\
         DSL reference:\n{dsl}\n\
         Library summary:\n{lib}\n\
         Scene summary:\n{scene}\n\n\
         {examples}\
         Think first if you like, then give the program alone in a ```dsl fenced block.",
        goal = req.goal,
        dsl = dsl_reference(req.schema.env),
        lib = req.schema.summary(),
        scene = req.scene_summary,
        examples = examples_text(&req.examples),
    )
}

/// The reward program in an answer: the last ```dsl block, else the last fenced block that looks like a
/// call, else an `<answer>` section, else the answer itself when it starts with a call.
pub fn extract_program(answer: &str) -> Option<String> {
    let text = strip_think(answer);
    let blocks = fences(&text);
    let looks = |s: &str| {
        let t = s.trim();
        t.contains('(') && t.starts_with(|c: char| c.is_ascii_alphabetic())
    };
    if let Some(f) = blocks
        .iter()
        .rev()
        .find(|f| f.lang == "dsl" && looks(f.body))
    {
        return Some(f.body.trim().to_string());
    }
    if let Some(f) = blocks.iter().rev().find(|f| looks(f.body)) {
        return Some(f.body.trim().to_string());
    }
    if let (Some(a), Some(b)) = (text.find("<answer>"), text.find("</answer>"))
        && a + 8 <= b
        && looks(&text[a + 8..b])
    {
        return Some(text[a + 8..b].trim().to_string());
    }
    looks(&text).then(|| text.trim().to_string())
}

/// Parses, checks and (with a probe) runs `text`.
fn accept(text: &str, req: &SynthRequest<'_>) -> Result<Program, RewardError> {
    let p = compile(text, req.schema)?;
    if let Some((trace, anns)) = req.probe {
        evaluate(&p, &AnnotatedTrace::new(trace, anns.iter()))?;
    }
    Ok(p)
}

/// Asks `client` for a program, repairing up to `req.max_repairs` times. An error of the client (budget,
/// endpoint down) ends the synthesis as an `Err`; a model that never produces a valid program is an
/// `Ok` with no program.
pub fn synthesise(client: &LlmClient, req: &SynthRequest<'_>) -> Result<Synthesis, LlmError> {
    let first = match &req.image {
        Some(png) => Message::user_with_png(prompt(req), png),
        None => Message::user(prompt(req)),
    };
    let mut messages = vec![
        Message::system(
            "You write reward programs in a small domain-specific language for physics simulations.",
        ),
        first,
    ];
    let mut attempts = Vec::new();
    for round in 0..=req.max_repairs {
        let purpose = if round == 0 {
            "reward_synthesis"
        } else {
            "reward_repair"
        };
        let mut chat = ChatRequest::new(purpose).seed(req.seed.wrapping_add(round as u64));
        if let Some(t) = req.temperature {
            chat = chat.temperature(t);
        }
        for m in &messages {
            chat = chat.message(m.clone());
        }
        let reply = client.chat(&chat)?;
        let program = extract_program(&reply.content);
        let outcome = match &program {
            None => Err("the answer has no program: put it in a ```dsl fenced block".to_string()),
            Some(text) => accept(text, req).map_err(|e| e.to_string()),
        };
        attempts.push(Attempt {
            purpose: purpose.into(),
            call_id: reply.call_id.clone(),
            program: program.clone(),
            error: outcome.as_ref().err().cloned(),
        });
        match outcome {
            Ok(p) => {
                return Ok(Synthesis {
                    program: Some(p),
                    attempts,
                });
            }
            Err(e) => {
                messages.push(Message::text(crate::llm::Role::Assistant, reply.content));
                messages.push(Message::user(format!(
                    "That program was rejected.\nProgram:\n```dsl\n{}\n```\nInterpreter error: {e}\n\
                     Fix it and give the whole corrected program in a ```dsl fenced block.",
                    program.unwrap_or_default()
                )));
            }
        }
    }
    Ok(Synthesis {
        program: None,
        attempts,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn few_shot_examples_never_include_the_goal_itself() {
        let repo = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let set = super::super::goals::GoalSet::load(&repo.join("data/goals/pooltool.toml"), repo)
            .unwrap();
        let g = &set.goals[0];
        let ex = few_shot(&set.goals, Some(&g.id), &g.sentence, 3);
        assert_eq!(ex.len(), 3);
        assert!(ex.iter().all(|(s, _)| s != &g.sentence));
        // By sentence alone (a sentence file's goal has no id in the goal file).
        let ex = few_shot(
            &set.goals,
            None,
            &format!(" {} ", g.sentence.to_uppercase()),
            20,
        );
        assert_eq!(ex.len(), set.goals.len() - 1);
        let schema = set.schema.clone();
        let req = SynthRequest {
            goal: &g.sentence,
            schema: &schema,
            scene_summary: "a table".into(),
            examples: ex,
            image: None,
            probe: None,
            max_repairs: 0,
            seed: 1,
            temperature: None,
        };
        let p = prompt(&req);
        assert!(p.contains(&set.goals[1].sentence) && p.contains("Examples of goals"));
        assert_eq!(
            p.matches(&g.sentence).count(),
            1,
            "the goal appears once, as the goal"
        );
    }

    #[test]
    fn extracts_the_program_from_fences_and_answers() {
        let a = "<think>maybe PATTERN(x)</think>\n```python\nprint(1)\n```\n```dsl\nAND(PATTERN(\"a\"))\n```";
        assert_eq!(extract_program(a).unwrap(), "AND(PATTERN(\"a\"))");
        assert_eq!(
            extract_program("<answer>\nNOT(PATTERN(\"b\"))\n</answer>").unwrap(),
            "NOT(PATTERN(\"b\"))"
        );
        assert_eq!(extract_program("CUE_HIT(\"8\")").unwrap(), "CUE_HIT(\"8\")");
        assert!(extract_program("I cannot do that.").is_none());
    }
}
