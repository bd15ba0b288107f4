//! What a reward program may name: the library's labels (and aliases) with the parameter keys their
//! patterns emit, and the environment (which decides the built-in functions and `NEARBY_AT` units).
//!
//! Parameter keys are learned from annotations ([`Schema::learn_keys`]): a library declares labels,
//! not parameters, so the keys come from what its detectors actually wrote. A label whose keys were
//! never observed accepts any key.

use std::collections::{BTreeMap, BTreeSet};

use crate::detect::{Annotation, Library, normalise_label};
use crate::trace::Env;

/// Keys every pattern can be filtered by, whatever its detector wrote: `ball` (the pattern's subject,
/// its first object) and `contains` (objects it names).
pub const BUILTIN_KEYS: &[&str] = &["ball", "contains"];

/// One label of the library.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelInfo {
    /// The canonical label.
    pub label: String,
    /// Other spellings.
    pub aliases: Vec<String>,
    /// Top-level parameter keys seen in its patterns (without `object_details`), if any were seen.
    pub keys: Option<BTreeSet<String>>,
}

/// The labels, parameter keys and environment a program is checked against.
#[derive(Debug, Clone, PartialEq)]
pub struct Schema {
    /// The environment.
    pub env: Env,
    /// The library's name (for prompts).
    pub library: String,
    /// Labels in library order.
    pub labels: Vec<LabelInfo>,
}

impl Schema {
    /// The labels and aliases of `library`, with no parameter keys yet.
    pub fn from_library(library: &Library) -> Schema {
        Schema {
            env: library.env,
            library: library.name.clone(),
            labels: library
                .detectors
                .iter()
                .map(|d| LabelInfo {
                    label: d.label.clone(),
                    aliases: d.aliases.clone(),
                    keys: None,
                })
                .collect(),
        }
    }

    /// Adds the parameter keys found in `annotations` to their labels.
    pub fn learn_keys(&mut self, annotations: &[Annotation]) {
        let mut seen: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for a in annotations {
            seen.entry(a.label.clone())
                .or_default()
                .extend(a.parameters.keys().cloned());
        }
        self.learn_label_keys(seen);
    }

    /// Adds parameter keys, given per label as annotations spelled it (`object_details` is left out;
    /// labels match as [`normalise_label`] spells them).
    pub fn learn_label_keys(&mut self, keys: BTreeMap<String, BTreeSet<String>>) {
        let mut seen: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for (label, k) in keys {
            seen.entry(normalise_label(&label))
                .or_default()
                .extend(k.into_iter().filter(|k| k.as_str() != "object_details"));
        }
        for info in &mut self.labels {
            if let Some(k) = seen.remove(&normalise_label(&info.label)) {
                info.keys.get_or_insert_with(BTreeSet::new).extend(k);
            }
        }
    }

    /// The label `name` refers to (case-insensitive, `_`/`-` as spaces, aliases included).
    pub fn resolve(&self, name: &str) -> Option<&LabelInfo> {
        let n = normalise_label(name);
        self.labels.iter().find(|l| {
            normalise_label(&l.label) == n || l.aliases.iter().any(|a| normalise_label(a) == n)
        })
    }

    /// Whether patterns of `label` can carry `key`.
    pub fn key_known(&self, label: &LabelInfo, key: &str) -> bool {
        BUILTIN_KEYS.contains(&key)
            || label
                .keys
                .as_ref()
                .is_none_or(|k| k.contains(key) || k.iter().any(|x| x.eq_ignore_ascii_case(key)))
    }

    /// The library summary of a synthesis prompt: one line per label with its aliases and keys.
    pub fn summary(&self) -> String {
        let mut out = format!(
            "Library {} ({} labels, environment {}). Every pattern can also be filtered with ball=\"id\" \
             (the pattern's subject) and contains=[\"id\", ...] (objects it names).\n",
            self.library,
            self.labels.len(),
            self.env
        );
        for l in &self.labels {
            out.push_str(&format!("- \"{}\"", l.label));
            if !l.aliases.is_empty() {
                out.push_str(&format!(" (also: {})", l.aliases.join(", ")));
            }
            match &l.keys {
                Some(k) if !k.is_empty() => out.push_str(&format!(
                    "; parameters: {}",
                    k.iter().cloned().collect::<Vec<_>>().join(", ")
                )),
                _ => {}
            }
            out.push('\n');
        }
        out
    }
}
