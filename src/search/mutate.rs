//! The offline `mutate` proposer: seeded edits on the Python syntax tree (numeric constants scaled to
//! their magnitude, comparison operators, recombination of two parents' functions), no LLM.
//!
//! Each proposal starts `mutate.py` (standard library only) in a fresh `python3 -I -S -B` process with
//! an empty environment; the script only parses and unparses code with `ast` (it never runs it) and caps
//! its own memory and CPU time. Given the same parents and seed it returns the same child, so a search
//! with this proposer is reproducible. It does not repair: a broken child is simply a failed candidate.
//!
//! **Owns:** the script and its invocation. **Does not:** validate or run children.

use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Stdio};

use serde_json::{Value, json};

use super::proposer::{Proposal, ProposalRequest, ProposeError, Proposer};
use crate::detect::DetectorError;

/// The edit script, embedded in the binary.
pub const MUTATE_PY: &str = include_str!("mutate.py");

/// The `mutate` proposer.
#[derive(Clone, Debug)]
pub struct MutateProposer {
    python: PathBuf,
    max_edits: u32,
}

impl MutateProposer {
    /// Finds `python3` on the `PATH` (or uses `python`); `max_edits` edits at most per child (≥ 1).
    pub fn new(python: Option<PathBuf>, max_edits: u32) -> Result<Self, ProposeError> {
        let python = match python {
            Some(p) => p,
            None => {
                let out = Command::new("python3")
                    .args(["-c", "import sys; print(sys.executable)"])
                    .output()
                    .map_err(|e| {
                        ProposeError::Unavailable(format!("no python3 on the PATH: {e}"))
                    })?;
                let p = String::from_utf8_lossy(&out.stdout).trim().to_string();
                if !out.status.success() || p.is_empty() {
                    return Err(ProposeError::Unavailable(
                        "python3 on the PATH did not report its executable".into(),
                    ));
                }
                PathBuf::from(p)
            }
        };
        Ok(MutateProposer {
            python,
            max_edits: max_edits.max(1),
        })
    }

    /// The child of `parents` (first is the one edited) under `seed`, and the edits made.
    pub fn mutate(
        &self,
        parents: &[&str],
        seed: u64,
    ) -> Result<(String, Vec<String>), ProposeError> {
        let input = json!({"parents": parents, "seed": seed, "max_edits": self.max_edits});
        let mut child = Command::new(&self.python)
            .args(["-I", "-S", "-B", "-c", MUTATE_PY])
            .env_clear()
            .env("PYTHONHASHSEED", "0")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| ProposeError::Unavailable(format!("{}: {e}", self.python.display())))?;
        let body = input.to_string();
        let mut stdin = child.stdin.take().expect("piped");
        let writer = std::thread::spawn(move || stdin.write_all(body.as_bytes()));
        let out = child
            .wait_with_output()
            .map_err(|e| ProposeError::Other(format!("mutate.py: {e}")))?;
        let _ = writer.join();
        let reply: Value = serde_json::from_slice(&out.stdout).map_err(|e| {
            ProposeError::Other(format!(
                "mutate.py gave no answer ({e}; exit {}; {})",
                out.status,
                String::from_utf8_lossy(&out.stderr).trim()
            ))
        })?;
        if reply["ok"].as_bool() == Some(true) {
            let code = reply["code"].as_str().unwrap_or_default().to_string();
            let edits = reply["edits"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|e| e.as_str().map(String::from))
                .collect();
            Ok((code, edits))
        } else {
            Err(ProposeError::Other(
                reply["error"]
                    .as_str()
                    .unwrap_or("mutate.py failed")
                    .to_string(),
            ))
        }
    }
}

impl Proposer for MutateProposer {
    fn name(&self) -> &str {
        "mutate"
    }

    fn propose(&self, req: &ProposalRequest) -> Result<Proposal, ProposeError> {
        let parents: Vec<&str> = req.parents.iter().map(|p| p.code.as_str()).collect();
        let (code, _) = self.mutate(&parents, req.seed)?;
        Ok(Proposal {
            code,
            ..Proposal::default()
        })
    }

    fn repair(
        &self,
        _req: &ProposalRequest,
        _code: &str,
        _error: &DetectorError,
        _attempt: u32,
    ) -> Result<Option<Proposal>, ProposeError> {
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const A: &str = "def helper(x):\n    return x > 0.5\n\ndef find_pattern(trace):\n    if helper(0.7) and 3 <= 4:\n        return []\n    return []\n";
    const B: &str =
        "def helper(x):\n    return x < 2.0\n\ndef find_pattern(trace):\n    return []\n";

    #[test]
    fn children_are_seeded_parse_and_differ_from_the_parent() {
        let m = MutateProposer::new(None, 3).unwrap();
        let (c1, e1) = m.mutate(&[A, B], 11).unwrap();
        let (c2, _) = m.mutate(&[A, B], 11).unwrap();
        assert_eq!(c1, c2, "same seed, same child");
        assert!(!e1.is_empty());
        assert!(c1.contains("def find_pattern(trace)"));
        let children: std::collections::BTreeSet<String> =
            (0..20).map(|s| m.mutate(&[A, B], s).unwrap().0).collect();
        assert!(children.len() > 5, "{children:?}");
        // Every edit kind shows up over a few seeds.
        let edits: Vec<String> = (0..40)
            .flat_map(|s| m.mutate(&[A, B], s).unwrap().1)
            .collect();
        for kind in ["const", "compare", "splice"] {
            assert!(
                edits.iter().any(|e| e.starts_with(kind)),
                "{kind}: {edits:?}"
            );
        }
    }

    #[test]
    fn unparsable_or_uneditable_parents_are_errors_not_panics() {
        let m = MutateProposer::new(None, 2).unwrap();
        assert!(matches!(
            m.mutate(&["def find_pattern(:"], 1),
            Err(ProposeError::Other(e)) if e.contains("does not parse")
        ));
        assert!(
            m.mutate(&["def find_pattern(t):\n    return []\n"], 1)
                .is_err()
        );
    }
}
