//! The identification task: for each trace, a chooser is shown the trace and `options` summaries —
//! the trace's own and `options − 1` of other traces, drawn with the trial's seed and shuffled — and
//! picks one. The accuracy (chance: 1 / options) is what the paper's ensemble calibration maximises.
//!
//! [`identification_accuracy`] summarises the traces and runs the trials; [`identify`] runs the trials
//! on summaries already written; [`options_for`] is the seeded draw alone.

use crate::detect::Annotation;
use crate::digest::words_u64;
use crate::rng::SplitMix64;
use crate::trace::Trace;

use super::choose::{Chooser, TrialView};
use super::{Summariser, SummaryError};

/// How the task is posed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IdentifyParams {
    /// Summaries shown per trial, the trace's own included (the paper: 8).
    pub options: usize,
    /// Seed of the draws and of the chooser's requests.
    pub seed: u64,
}

impl Default for IdentifyParams {
    fn default() -> Self {
        IdentifyParams {
            options: 8,
            seed: 0,
        }
    }
}

/// One trial.
#[derive(Clone, Debug, PartialEq)]
pub struct Trial {
    /// The trace shown.
    pub trace_id: String,
    /// The traces whose summaries were shown, in the order shown.
    pub shown: Vec<String>,
    /// The position (0-based) of the trace's own summary.
    pub correct: usize,
    /// The position chosen, when the answer could be read.
    pub chosen: Option<usize>,
    /// Why the answer could not be read.
    pub reason: Option<String>,
    /// Prompt tokens.
    pub tokens_in: u64,
    /// Completion tokens.
    pub tokens_out: u64,
    /// Seconds.
    pub seconds: f64,
    /// The `llm_calls` call id (empty offline).
    pub call_id: String,
}

impl Trial {
    /// Whether the trace's own summary was chosen.
    pub fn success(&self) -> bool {
        self.chosen == Some(self.correct)
    }
}

/// The trials and their accuracy.
#[derive(Clone, Debug, PartialEq)]
pub struct Identification {
    /// One per trace, in the traces' order.
    pub trials: Vec<Trial>,
    /// Trials whose own summary was chosen / trials.
    pub accuracy: f64,
    /// 1 / options.
    pub chance: f64,
}

/// The draw of trial `target` among `n` traces: the indices of the traces whose summaries are shown,
/// in order, and the position of the target's own. Depends only on (`n`, `target`, `options`, `seed`).
pub fn options_for(n: usize, target: usize, options: usize, seed: u64) -> (Vec<usize>, usize) {
    let mut rng = SplitMix64::new(words_u64(&[seed, target as u64, 0x1D]));
    let mut others: Vec<usize> = (0..n).filter(|&i| i != target).collect();
    let k = options.saturating_sub(1).min(others.len());
    // A partial Fisher–Yates shuffle: the first k are a uniform sample without replacement.
    for i in 0..k {
        let j = i + rng.below(others.len() - i);
        others.swap(i, j);
    }
    let mut shown: Vec<usize> = others[..k].to_vec();
    let at = rng.below(k + 1);
    shown.insert(at, target);
    (shown, at)
}

/// Whether trials over the traces `ids` can be run with `params`: at least 2 options, at least as
/// many traces, no trace twice.
pub fn check<S: AsRef<str>>(ids: &[S], params: &IdentifyParams) -> Result<(), SummaryError> {
    check_sizes(ids.len(), params)?;
    let mut ids: Vec<&str> = ids.iter().map(AsRef::as_ref).collect();
    ids.sort_unstable();
    if let Some(w) = ids.windows(2).find(|w| w[0] == w[1]) {
        return Err(SummaryError::Setup(format!(
            "trace {} is given twice",
            w[0]
        )));
    }
    Ok(())
}

/// [`check`] without the duplicate check (which sorts every trace id), for `n` traces.
fn check_sizes(n: usize, params: &IdentifyParams) -> Result<(), SummaryError> {
    if params.options < 2 {
        return Err(SummaryError::Setup(format!(
            "options must be at least 2, found {}",
            params.options
        )));
    }
    if n < params.options {
        return Err(SummaryError::Setup(format!(
            "{n} trace(s) cannot give {} different summaries per trial; give at least {} traces",
            params.options, params.options
        )));
    }
    Ok(())
}

fn ids_of(traces: &[Trace]) -> Vec<&str> {
    traces.iter().map(|t| t.trace_id.as_str()).collect()
}

/// The trials over `traces` whose summaries are `summaries` (same order), with `chooser`.
pub fn identify(
    traces: &[Trace],
    annotations: &[Annotation],
    summaries: &[String],
    chooser: &dyn Chooser,
    params: &IdentifyParams,
) -> Result<Identification, SummaryError> {
    check(&ids_of(traces), params)?;
    let own = crate::detect::by_trace(traces, annotations.iter().cloned());
    identify_grouped(traces, &own, summaries, chooser, params)
}

/// [`identify`] with each trace's own annotations (`own[i]` those of `traces[i]`), once [`check`]
/// has passed.
fn identify_grouped(
    traces: &[Trace],
    own: &[Vec<Annotation>],
    summaries: &[String],
    chooser: &dyn Chooser,
    params: &IdentifyParams,
) -> Result<Identification, SummaryError> {
    let ids = ids_of(traces);
    if summaries.len() != traces.len() {
        return Err(SummaryError::Setup(format!(
            "{} summaries for {} traces",
            summaries.len(),
            traces.len()
        )));
    }
    let trials = traces
        .iter()
        .zip(own)
        .enumerate()
        .map(|(i, (t, own))| {
            let view = chooser.view(t, own)?;
            trial(&ids, &view, summaries, chooser, params, i)
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(score(trials, params.options))
}

/// Trial `i` of [`identify`] alone, over the traces `ids` (the `summarise` stage runs trials one by
/// one so that it can resume, and holds the chooser's views rather than the traces); `view` is what
/// `chooser` took of trace `ids[i]` ([`Chooser::view`]). It does not look for a trace given twice:
/// call [`check`] once before the trials.
pub fn trial<S: AsRef<str>>(
    ids: &[S],
    view: &TrialView,
    summaries: &[String],
    chooser: &dyn Chooser,
    params: &IdentifyParams,
    i: usize,
) -> Result<Trial, SummaryError> {
    check_sizes(ids.len(), params)?;
    if summaries.len() != ids.len() || i >= ids.len() {
        return Err(SummaryError::Setup(format!(
            "trial {i} of {} traces with {} summaries",
            ids.len(),
            summaries.len()
        )));
    }
    let (shown, correct) = options_for(ids.len(), i, params.options, params.seed);
    let texts: Vec<&str> = shown.iter().map(|&k| summaries[k].as_str()).collect();
    let choice = chooser.choose(view, &texts, words_u64(&[params.seed, i as u64, 0x2D]))?;
    Ok(Trial {
        trace_id: ids[i].as_ref().to_string(),
        shown: shown.iter().map(|&k| ids[k].as_ref().to_string()).collect(),
        correct,
        chosen: choice.index,
        reason: choice.reason,
        tokens_in: choice.tokens_in,
        tokens_out: choice.tokens_out,
        seconds: choice.seconds,
        call_id: choice.call_id,
    })
}

/// The accuracy of `trials`.
pub(crate) fn score(trials: Vec<Trial>, options: usize) -> Identification {
    let right = trials.iter().filter(|t| t.success()).count();
    Identification {
        accuracy: right as f64 / trials.len().max(1) as f64,
        chance: 1.0 / options.max(1) as f64,
        trials,
    }
}

/// Summarises every trace with `summariser`, then runs [`identify`] with `chooser`: the objective of
/// the ensemble calibration (the paper: 20 traces, 8 summaries per trial).
pub fn identification_accuracy(
    traces: &[Trace],
    annotations: &[Annotation],
    summariser: &dyn Summariser,
    chooser: &dyn Chooser,
    params: &IdentifyParams,
) -> Result<Identification, SummaryError> {
    check(&ids_of(traces), params)?;
    let own = crate::detect::by_trace(traces, annotations.iter().cloned());
    let summaries = traces
        .iter()
        .zip(&own)
        .map(|(t, own)| summariser.summarise(t, own).map(|s| s.text))
        .collect::<Result<Vec<_>, _>>()?;
    identify_grouped(traces, &own, &summaries, chooser, params)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::summary::offline::tests::{ann, trace};
    use crate::summary::{OfflineChooser, OfflineSummariser};

    #[test]
    fn draws_are_seeded_distinct_and_uniform() {
        let (a, at) = options_for(20, 5, 8, 3);
        assert_eq!(a.len(), 8);
        assert_eq!(a[at], 5);
        let mut sorted = a.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), 8, "distinct: {a:?}");
        assert_eq!(options_for(20, 5, 8, 3), (a.clone(), at));
        assert_ne!(options_for(20, 5, 8, 4).0, a);
        // The position of the true summary is uniform over the 8 slots (within 3 sigma over 8000 draws).
        let mut counts = [0usize; 8];
        let mut seen = [0usize; 20];
        for s in 0..8000 {
            let (shown, at) = options_for(20, 0, 8, s);
            counts[at] += 1;
            for k in shown {
                seen[k] += 1;
            }
        }
        for c in counts {
            assert!(
                (c as f64 - 1000.0).abs() < 3.0 * (1000.0f64 * 7.0 / 8.0).sqrt(),
                "{counts:?}"
            );
        }
        // Every other trace is a distractor equally often (7/19 of the trials each).
        for &c in &seen[1..] {
            let p = 7.0 / 19.0;
            assert!(
                (c as f64 - 8000.0 * p).abs() < 4.0 * (8000.0 * p * (1.0 - p)).sqrt(),
                "{seen:?}"
            );
        }
    }

    #[test]
    fn accuracy_is_perfect_with_distinct_annotations_and_chance_without() {
        let traces: Vec<Trace> = (0..10).map(|i| trace(&format!("t{i}"))).collect();
        let anns: Vec<Annotation> = (0..10)
            .map(|i| {
                ann(
                    &format!("t{i}"),
                    &format!("event{i}"),
                    &[&format!("ball{i}")],
                    i,
                    0.1 * i as f64,
                )
            })
            .collect();
        let p = IdentifyParams {
            options: 8,
            seed: 1,
        };
        let r = identification_accuracy(&traces, &anns, &OfflineSummariser, &OfflineChooser, &p)
            .unwrap();
        assert_eq!(r.accuracy, 1.0, "{:#?}", r.trials);
        assert_eq!(r.chance, 0.125);
        // No annotations: every summary reads the same, the chooser guesses.
        let mut total = 0.0;
        for seed in 0..40 {
            let p = IdentifyParams { options: 8, seed };
            total += identification_accuracy(&traces, &[], &OfflineSummariser, &OfflineChooser, &p)
                .unwrap()
                .accuracy;
        }
        let mean = total / 40.0;
        assert!((mean - 0.125).abs() < 0.06, "{mean}");
    }

    #[test]
    fn bad_setups_are_refused() {
        let traces: Vec<Trace> = (0..5).map(|i| trace(&format!("t{i}"))).collect();
        let p = IdentifyParams {
            options: 8,
            seed: 1,
        };
        let e = identify(&traces, &[], &vec![String::new(); 5], &OfflineChooser, &p).unwrap_err();
        assert!(e.to_string().contains("give at least 8 traces"), "{e}");
        let p = IdentifyParams {
            options: 1,
            seed: 1,
        };
        assert!(identify(&traces, &[], &vec![String::new(); 5], &OfflineChooser, &p).is_err());
        let mut twice = traces.clone();
        twice[1].trace_id = "t0".into();
        let p = IdentifyParams {
            options: 3,
            seed: 1,
        };
        let e = identify(&twice, &[], &vec![String::new(); 5], &OfflineChooser, &p).unwrap_err();
        assert!(e.to_string().contains("given twice"), "{e}");
        assert!(identify(&traces, &[], &[], &OfflineChooser, &p).is_err());
    }
}
