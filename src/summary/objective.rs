//! The paper's objective for ensemble calibration (b), section 3.3: the traces are annotated with a
//! candidate ensemble configuration, each annotated trace is summarised in natural language, and a
//! chooser (a vision-language model) shown a trace and `options` summaries, one of them its own, picks
//! one; the share of right picks is the score ([`identification_accuracy`]).
//!
//! **Owns:** the bridge from an ensemble configuration to the identification task, as an
//! [`Objective`]. **Does not:** choose the configurations (`ensemble::calibrate`), run detectors (the
//! member patterns are computed once by the caller), or build the LLM client (the stage does; every
//! call goes through it, so it is recorded in `llm_calls` and replayable).

use super::{Chooser, Identification, IdentifyParams, Summariser, identification_accuracy};
use crate::detect::Annotation;
use crate::ensemble::activation::LabelEnsemble;
use crate::ensemble::calibrate::{Objective, ObjectiveError};
use crate::trace::Trace;

/// Identification accuracy of the ensembles' annotations on a fixed set of traces.
pub struct IdentificationObjective<'a> {
    traces: &'a [Trace],
    /// Member patterns per trace (trace order).
    by_trace: Vec<Vec<&'a Annotation>>,
    summariser: &'a dyn Summariser,
    chooser: &'a dyn Chooser,
    params: IdentifyParams,
    /// Every scored point's identification, in order (for the stage's output).
    pub history: Vec<Identification>,
}

impl<'a> IdentificationObjective<'a> {
    /// The objective over `traces` (at least `params.options` of them) with the members' patterns
    /// `anns` on them.
    pub fn new(
        traces: &'a [Trace],
        anns: &'a [Annotation],
        summariser: &'a dyn Summariser,
        chooser: &'a dyn Chooser,
        params: IdentifyParams,
    ) -> Self {
        let by_trace = crate::detect::by_trace(traces, anns);
        IdentificationObjective {
            traces,
            by_trace,
            summariser,
            chooser,
            params,
            history: Vec::new(),
        }
    }

    /// The annotations of every trace under `ensembles` (one per label).
    pub fn annotations(&self, ensembles: &[LabelEnsemble]) -> Vec<Annotation> {
        let mut out = Vec::new();
        for (t, members) in self.traces.iter().zip(&self.by_trace) {
            for e in ensembles {
                out.extend(e.annotate_trace(t, members));
            }
        }
        out
    }
}

impl Objective for IdentificationObjective<'_> {
    fn name(&self) -> &str {
        "identification"
    }

    fn score(&mut self, ensembles: &[LabelEnsemble]) -> Result<f64, ObjectiveError> {
        let anns = self.annotations(ensembles);
        let id = identification_accuracy(
            self.traces,
            &anns,
            self.summariser,
            self.chooser,
            &self.params,
        )
        .map_err(|e| ObjectiveError {
            objective: "identification".into(),
            message: e.to_string(),
        })?;
        let acc = id.accuracy;
        self.history.push(id);
        Ok(acc)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::DetectorId;
    use crate::ensemble::activation::Member;
    use crate::summary::offline::tests::{ann, trace};
    use crate::summary::{OfflineChooser, OfflineSummariser};
    use crate::trace::Env;

    #[test]
    fn the_score_is_the_identification_accuracy_of_the_ensemble_annotations() {
        let traces: Vec<Trace> = (0..8).map(|i| trace(&format!("t{i}"))).collect();
        // One member fires on every trace, naming a different object per trace.
        let id = DetectorId::of(Env::Pooltool, "event", "");
        let anns: Vec<Annotation> = (0..8)
            .map(|i| {
                ann(
                    &format!("t{i}"),
                    "event",
                    &[&format!("ball{i}")],
                    i,
                    0.1 * i as f64,
                )
            })
            .collect();
        let e = |gamma: f64| LabelEnsemble {
            env: Env::Pooltool,
            label: "event".into(),
            gamma,
            eps_s: 0.005,
            eps_t: 1.0,
            members: vec![Member {
                id: id.clone(),
                weight: 1.0,
                reward: 0.5,
            }],
        };
        let params = IdentifyParams {
            options: 8,
            seed: 1,
        };
        let (s, c) = (OfflineSummariser, OfflineChooser);
        let mut o = IdentificationObjective::new(&traces, &anns, &s, &c, params);
        assert_eq!(o.name(), "identification");
        // γ = 0.5: the one-member cluster (a = 1) fires, every summary names its own ball: 1.0.
        assert_eq!(o.score(&[e(0.5)]).unwrap(), 1.0);
        let want = identification_accuracy(&traces, &anns, &s, &c, &params).unwrap();
        assert_eq!(o.history[0].accuracy, want.accuracy);
        // No ensemble: no annotations, the summaries are alike and the chooser is at chance.
        let none = o.score(&[]).unwrap();
        let want = identification_accuracy(&traces, &[], &s, &c, &params).unwrap();
        assert_eq!(none, want.accuracy);
        assert!(none < 1.0);
        // Too few traces for 8 options is an objective error, not a score.
        let mut small = IdentificationObjective::new(&traces[..4], &anns, &s, &c, params);
        assert!(small.score(&[e(0.5)]).is_err());
    }
}
