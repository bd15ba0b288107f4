//! Pooling: every valid candidate of one environment's discovery runs, per label, read from the
//! `candidates` tables of evolve stages (of this run, or of other run folders).
//!
//! A candidate is *valid* when it was scored (status `ok` or `seed`) and its ν is finite. The same code
//! found by several runs is pooled once, under the run where it scored best (ties to the earlier
//! source). Each label keeps at most `max_per_label` candidates, best ν first (ties to shorter code, then
//! code hash), and is ordered that way.
//!
//! **Owns:** reading and filtering `candidates` rows. **Does not:** run candidates (`signature`) or
//! cluster them (`kmeans`).

use std::collections::BTreeMap;

use arrow::array::{Array, AsArray};
use arrow::datatypes::{Float64Type, Int64Type, UInt64Type};

use crate::store::{RunDir, StoreError};
use crate::trace::Env;

/// One pooled candidate.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pooled {
    /// Where it came from: `<stage>` for this run, `<run folder>/<stage>` for another.
    pub source: String,
    /// Its label.
    pub label: String,
    /// `candidates.code_hash`.
    pub code_hash: String,
    /// The code.
    pub code: String,
    /// Training fitness ν.
    pub nu: f64,
    /// Training ρ.
    pub rho: f64,
    /// Lines of code.
    pub lines: i64,
    /// The search seed of its run.
    pub seed: u64,
}

/// Where candidates are read from: a run folder, named `name` in provenance (empty for this run), and
/// the evolve stages whose rows count (`None`: every stage of the run).
#[derive(Clone, Debug)]
pub struct Source {
    /// The run folder.
    pub run: RunDir,
    /// Its name in provenance (`""` for the current run).
    pub name: String,
    /// The stages (`run_stage` values) to read; `None` for all.
    pub stages: Option<Vec<String>>,
}

/// Every valid candidate row of `env` from every source, per label (labels in `labels` only, when
/// given), in file order, duplicates included (see [`dedup`]).
pub fn read_all(
    sources: &[Source],
    env: Env,
    labels: Option<&[String]>,
) -> Result<BTreeMap<String, Vec<Pooled>>, StoreError> {
    let mut by_label: BTreeMap<String, Vec<Pooled>> = BTreeMap::new();
    for src in sources {
        for f in src.run.table("candidates")?.files {
            if f.env != Some(env) {
                continue;
            }
            for b in crate::store::read_file(&f.path)? {
                let col = |n: &str| {
                    b.column_by_name(n)
                        .cloned()
                        .ok_or_else(|| StoreError::Schema {
                            path: f.path.clone(),
                            message: format!("no column {n} (not a candidates table?)"),
                        })
                };
                let (stage, label, hash, code, status) = (
                    col("run_stage")?,
                    col("label")?,
                    col("code_hash")?,
                    col("code")?,
                    col("status")?,
                );
                let (nu, rho, lines, seed) = (col("nu")?, col("rho")?, col("lines")?, col("seed")?);
                let (stage, label, hash, code, status) = (
                    stage.as_string::<i32>(),
                    label.as_string::<i32>(),
                    hash.as_string::<i32>(),
                    code.as_string::<i32>(),
                    status.as_string::<i32>(),
                );
                let (nu, rho) = (
                    nu.as_primitive::<Float64Type>(),
                    rho.as_primitive::<Float64Type>(),
                );
                let (lines, seed) = (
                    lines.as_primitive::<Int64Type>(),
                    seed.as_primitive::<UInt64Type>(),
                );
                for i in 0..b.num_rows() {
                    let st = stage.value(i);
                    if src
                        .stages
                        .as_ref()
                        .is_some_and(|s| !s.iter().any(|x| x == st))
                    {
                        continue;
                    }
                    if !matches!(status.value(i), "ok" | "seed") || nu.is_null(i) {
                        continue;
                    }
                    let l = label.value(i);
                    if labels.is_some_and(|ls| !ls.iter().any(|x| x == l)) {
                        continue;
                    }
                    let v = nu.value(i);
                    if !v.is_finite() || code.value(i).trim().is_empty() {
                        continue;
                    }
                    let source = if src.name.is_empty() {
                        st.to_string()
                    } else {
                        format!("{}/{st}", src.name)
                    };
                    let p = Pooled {
                        source,
                        label: l.to_string(),
                        code_hash: hash.value(i).to_string(),
                        code: code.value(i).to_string(),
                        nu: v,
                        rho: if rho.is_null(i) {
                            f64::NAN
                        } else {
                            rho.value(i)
                        },
                        lines: lines.value(i),
                        seed: seed.value(i),
                    };
                    by_label.entry(p.label.clone()).or_default().push(p);
                }
            }
        }
    }
    Ok(by_label)
}

/// One label's pool: each code once (under the source where it scored best, ties to the earlier row),
/// best first, at most `max` candidates.
pub fn dedup(rows: &[Pooled], max: usize) -> Vec<Pooled> {
    let mut list: Vec<Pooled> = Vec::new();
    for p in rows {
        match list.iter_mut().find(|q| q.code_hash == p.code_hash) {
            Some(q) if p.nu > q.nu => *q = p.clone(),
            Some(_) => {}
            None => list.push(p.clone()),
        }
    }
    sort_best_first(&mut list);
    list.truncate(max.max(1));
    list
}

/// The best row of each source (in order of first appearance): each run's own single best program.
pub fn best_per_source(rows: &[Pooled]) -> Vec<Pooled> {
    let mut sources: Vec<&str> = Vec::new();
    for p in rows {
        if !sources.contains(&p.source.as_str()) {
            sources.push(&p.source);
        }
    }
    sources
        .iter()
        .filter_map(|s| {
            let mut mine: Vec<Pooled> = rows.iter().filter(|p| p.source == *s).cloned().collect();
            sort_best_first(&mut mine);
            mine.into_iter().next()
        })
        .collect()
}

/// Best ν first, ties to shorter code, then to the smaller code hash.
pub fn sort_best_first(list: &mut [Pooled]) {
    list.sort_by(|a, b| {
        b.nu.total_cmp(&a.nu)
            .then(a.lines.cmp(&b.lines))
            .then_with(|| a.code_hash.cmp(&b.code_hash))
    });
}
