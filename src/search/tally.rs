//! Counting a search's proposals: how many the proposer was asked for, how many gave a program that
//! ran, and why the others failed. A search whose every proposal failed learned nothing — its "best"
//! detector is a seed program — so the `evolve` stage reports it as an error
//! ([`SearchError::AllProposalsFailed`](super::SearchError::AllProposalsFailed)) rather than a success;
//! partial failures are reported in its summary.
//!
//! **Owns:** [`ProposalTally`]. **Does not:** decide a stage's outcome (the stage does), or look at the
//! seed programs (round 0 is not a proposal).

use serde::{Deserialize, Serialize};

use super::candidate::CandidateRecord;

/// The proposals of one or more searches, by outcome.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ProposalTally {
    /// Proposals asked for (search steps; steps the proposer's budget stopped are not counted).
    pub asked: u64,
    /// Proposals whose program ran on the traces, possibly after repairs (scored, or a duplicate, a
    /// behavioural duplicate or a degenerate program).
    pub ran: u64,
    /// Proposals that gave no program: an answer without code, a response that was not a chat
    /// completion.
    pub no_program: u64,
    /// Proposals whose program did not run, even after repairs (a syntax or forbidden construct, a
    /// runtime error, a timeout, an invalid output).
    pub did_not_run: u64,
    /// The first failure: label, step and message.
    pub first_error: Option<String>,
}

impl ProposalTally {
    /// The tally of `records` (seed programs, with step −1, are skipped).
    pub fn of<'a>(records: impl IntoIterator<Item = &'a CandidateRecord>) -> Self {
        let mut t = ProposalTally::default();
        for r in records {
            t.add(r);
        }
        t
    }

    /// Counts one record.
    pub fn add(&mut self, r: &CandidateRecord) {
        if r.step < 0 || r.status == "budget_exhausted" {
            return;
        }
        self.asked += 1;
        if r.executable() {
            self.ran += 1;
            return;
        }
        if r.status == "proposer" {
            self.no_program += 1;
        } else {
            self.did_not_run += 1;
        }
        if self.first_error.is_none() {
            let what = r.error.as_deref().unwrap_or("no message");
            let status = if r.status == "proposer" {
                String::new()
            } else {
                format!("{} error: ", r.status)
            };
            self.first_error = Some(format!(
                "label {:?} step {}: {status}{what}",
                r.label, r.step
            ));
        }
    }

    /// Proposals that failed.
    pub fn failed(&self) -> u64 {
        self.no_program + self.did_not_run
    }

    /// True when proposals were asked for and none gave a program that ran.
    pub fn all_failed(&self) -> bool {
        self.asked > 0 && self.ran == 0
    }

    /// "`f` of `n` proposal(s) failed (a without a program, b whose program did not run); the first: …",
    /// or `None` when none failed.
    pub fn failures(&self) -> Option<String> {
        (self.failed() > 0).then(|| {
            format!(
                "{} of {} proposal(s) failed {}",
                self.failed(),
                self.asked,
                self.breakdown()
            )
        })
    }

    /// "(a without a program, b whose program did not run); the first: …".
    pub fn breakdown(&self) -> String {
        format!(
            "({} without a program, {} whose program did not run); the first: {}",
            self.no_program,
            self.did_not_run,
            self.first_error.as_deref().unwrap_or("no message")
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(step: i64, status: &str, error: Option<&str>) -> CandidateRecord {
        CandidateRecord {
            label: "ball slowing".into(),
            label_index: 0,
            seed: 0,
            strategy: "island".into(),
            proposer: "llm:m".into(),
            island: 0,
            step,
            parents: vec![],
            code_hash: String::new(),
            code: String::new(),
            status: status.into(),
            error: error.map(str::to_string),
            error_line: None,
            failed_on_probe: false,
            repairs: 0,
            terms: None,
            lines: 0,
            mean_time_s: None,
            activation_rate: None,
            signature: None,
            tokens_in: 0,
            tokens_out: 0,
            calls: 1,
            propose_s: 0.0,
            eval_s: 0.0,
        }
    }

    #[test]
    fn seeds_and_budget_stops_are_not_proposals() {
        let t = ProposalTally::of(&[
            rec(-1, "seed", None),
            rec(0, "budget_exhausted", Some("max_calls")),
        ]);
        assert_eq!(t.asked, 0);
        assert!(!t.all_failed());
        assert_eq!(t.failures(), None);
    }

    #[test]
    fn failures_are_split_by_kind_and_the_first_is_kept() {
        let records = [
            rec(-1, "seed", None),
            rec(
                0,
                "proposer",
                Some("no usable code in the answer (call s-0)"),
            ),
            rec(1, "syntax", Some("invalid syntax")),
            rec(
                2,
                "proposer",
                Some("no usable code in the answer (call s-2)"),
            ),
        ];
        let t = ProposalTally::of(&records);
        assert_eq!((t.asked, t.ran, t.no_program, t.did_not_run), (3, 0, 2, 1));
        assert!(t.all_failed());
        assert_eq!(
            t.failures().unwrap(),
            "3 of 3 proposal(s) failed (2 without a program, 1 whose program did not run); the \
             first: label \"ball slowing\" step 0: no usable code in the answer (call s-0)"
        );
        let mut partial = t.clone();
        partial.add(&rec(3, "degenerate", Some("active nowhere")));
        assert!(!partial.all_failed());
        assert_eq!(partial.ran, 1);
        assert!(
            partial
                .failures()
                .unwrap()
                .starts_with("3 of 4 proposal(s)")
        );
    }
}
