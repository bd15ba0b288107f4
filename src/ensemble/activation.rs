//! Activation clustering at annotation time (paper section 3.3, "pattern activation clustering"): the
//! patterns a label's K member detectors found in one trace are grouped into clusters of agreeing
//! activations, and a cluster becomes one ensemble annotation when enough reliable members agree.
//!
//! **Linking.** Two patterns a and b of *different* members of the same label and trace are linked when
//! all three hold (two patterns of one member are separate detections and never linked directly):
//! - *objects* (the shared θ): they name at least one common object id, or both name none;
//! - *time*: the gap between their inclusive step ranges, `max(s_a, s_b) − min(e_a, e_b)`, is at most
//!   ε_t timesteps (overlapping ranges have a gap ≤ 0);
//! - *space*: the centroids of their objects' centres at their first steps are at most
//!   ε_s × `nearby_scale` apart (`envs::EnvFacts`; pooltool metres, PHYRE 256 px, I-PHYRE 600 px, so
//!   the paper's (0.05, 4), (0.00625, 2) and (0.005, 1) read as 12.8 px, 3.75 px and 5 mm). A pattern
//!   whose objects are not in the trace (a cushion, the table) has no centroid and passes this test.
//!
//! Clusters are the connected components of that relation (single linkage).
//!
//! **Activation.** Member ℓ votes `v_ℓ = max(w_ℓ · t_ℓ, 0)` (reliability weight × training reward);
//! when every vote of the label is 0 (all rewards ≤ 0), the votes are the weights `max(w_ℓ, 0)`, and
//! when those are 0 too, 1 each. A cluster's activation is `a_C = Σ_{ℓ ∈ C} v_ℓ / Σ_ℓ v_ℓ` (each member
//! counted once), in [0, 1]; the cluster fires when `a_C > γ`.
//!
//! **The annotations** of a fired cluster are the patterns of its leader (the member with the largest
//! vote, ties to the earlier member) in the cluster, each with its span, objects and parameters, so a
//! one-member ensemble reports exactly its member's patterns. Their
//! detector id is the label's ensemble id ([`ensemble_id`]), its `activation` is a_C and its
//! `metadata` is `{"ensemble": {"activation", "members", "leader"}, "member": <the leader's metadata>}`.
//!
//! **Owns:** the linking rule, the cluster activation and the ensemble annotations. **Does not:** run
//! detectors (`detect::WorkerPool`) or choose members (`ensemble::kmeans`, `ensemble::represent`).

use std::collections::{BTreeMap, HashMap};

use rayon::prelude::*;
use serde_json::json;

use crate::detect::{Annotation, Detector, DetectorId, EnsembleSettings, Library};
use crate::trace::{Body, Env, FramedTrace, PoolRows, Trace};

/// A trace as the linking rule reads it: its id and steps, and the objects of a step with their
/// centres, from its objects or from its billiard frame rows (the same ids and centres).
enum Objects<'a> {
    Built(&'a Trace),
    Rows(&'a Trace, Box<PoolRows<'a>>),
}

impl<'a> Objects<'a> {
    /// The view of a trace read from a run's tables.
    fn of_framed(t: &'a FramedTrace) -> Self {
        match t.pool_rows() {
            Some(rows) => Objects::Rows(t.shell(), Box::new(rows)),
            None => Objects::Built(t.shell()),
        }
    }

    /// The trace (its id and steps; its objects only when `Built`).
    fn trace(&self) -> &Trace {
        match self {
            Objects::Built(t) | Objects::Rows(t, _) => t,
        }
    }
}

/// One member of a label's ensemble: its detector id, reliability weight w and training reward t.
#[derive(Clone, Debug, PartialEq)]
pub struct Member {
    /// The member detector.
    pub id: DetectorId,
    /// Reliability weight w.
    pub weight: f64,
    /// Training reward t.
    pub reward: f64,
}

/// One label's ensemble as the combination step sees it.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelEnsemble {
    /// The environment (decides the unit of ε_s).
    pub env: Env,
    /// The label.
    pub label: String,
    /// Threshold γ on the normalised cluster activation.
    pub gamma: f64,
    /// Spatial tolerance ε_s, in the environment's `nearby_scale` unit.
    pub eps_s: f64,
    /// Temporal tolerance ε_t (timesteps).
    pub eps_t: f64,
    /// The members, in manifest order.
    pub members: Vec<Member>,
}

/// The id of a label's ensemble: a detector id over the environment, the label and the member ids, so
/// the same members give the same id in every run.
pub fn ensemble_id(env: Env, label: &str, members: &[DetectorId]) -> DetectorId {
    let ids: Vec<&str> = members.iter().map(DetectorId::as_str).collect();
    DetectorId::of(env, label, &format!("ensemble\n{}", ids.join("\n")))
}

impl LabelEnsemble {
    /// The label ensembles of `detectors` (those with a membership), in order of their first member.
    pub fn of_detectors(detectors: &[Detector]) -> Vec<LabelEnsemble> {
        let mut out: Vec<(std::sync::Arc<EnsembleSettings>, LabelEnsemble)> = Vec::new();
        for d in detectors {
            let Some(m) = &d.ensemble else { continue };
            let member = Member {
                id: d.id.clone(),
                weight: d.weight,
                reward: m.reward,
            };
            match out
                .iter_mut()
                .find(|(s, _)| std::sync::Arc::ptr_eq(s, &m.settings))
            {
                Some((_, e)) => e.members.push(member),
                None => {
                    let s = &m.settings;
                    out.push((
                        s.clone(),
                        LabelEnsemble {
                            env: d.env,
                            label: s.label.clone(),
                            gamma: s.gamma,
                            eps_s: s.eps_s,
                            eps_t: s.eps_t,
                            members: vec![member],
                        },
                    ));
                }
            }
        }
        out.into_iter().map(|(_, e)| e).collect()
    }

    /// The label's ensemble id.
    pub fn id(&self) -> DetectorId {
        let ids: Vec<DetectorId> = self.members.iter().map(|m| m.id.clone()).collect();
        ensemble_id(self.env, &self.label, &ids)
    }

    /// Each member's vote (see the module docs), in member order.
    pub fn votes(&self) -> Vec<f64> {
        let v: Vec<f64> = self
            .members
            .iter()
            .map(|m| (m.weight * m.reward).max(0.0))
            .collect();
        if v.iter().sum::<f64>() > 0.0 {
            return v;
        }
        let w: Vec<f64> = self.members.iter().map(|m| m.weight.max(0.0)).collect();
        if w.iter().sum::<f64>() > 0.0 {
            return w;
        }
        vec![1.0; self.members.len()]
    }

    /// The ensemble annotations of `trace` from its member patterns `anns` (patterns of other
    /// detectors or traces are ignored), ordered by start, end and leader.
    pub fn annotate_trace(&self, trace: &Trace, anns: &[&Annotation]) -> Vec<Annotation> {
        let items: Vec<(usize, &Annotation)> = anns
            .iter()
            .filter(|a| a.trace_id == trace.trace_id)
            .filter_map(|a| {
                self.members
                    .iter()
                    .position(|m| m.id == a.detector_id)
                    .map(|k| (k, *a))
            })
            .collect();
        if items.is_empty() {
            return Vec::new();
        }
        self.clusters(&Objects::Built(trace), &items, &Prepared::of(self))
    }

    /// The ensemble annotations of `trace` from `items`, its member patterns with their member's
    /// index, in the order given.
    fn clusters(
        &self,
        view: &Objects<'_>,
        items: &[(usize, &Annotation)],
        prepared: &Prepared,
    ) -> Vec<Annotation> {
        let trace = view.trace();
        let scale = crate::envs::facts(self.env).nearby_scale;
        let mut id_buf = String::new();
        let centres: Vec<Option<(f64, f64)>> = items
            .iter()
            .map(|(_, a)| centroid(view, a, &mut id_buf))
            .collect();
        let n = items.len();
        let mut parent: Vec<usize> = (0..n).collect();
        // Pairs are tested in order of start step, and a pattern stops looking once the others start
        // more than ε_t after it ends: no later one can be linked to it. The linked pairs, and so the
        // components (each rooted at its smallest index, `union`), are those of testing every pair.
        let mut by_start: Vec<usize> = (0..n).collect();
        by_start.sort_by_key(|&i| items[i].1.start_step);
        for (p, &i) in by_start.iter().enumerate() {
            let reach = items[i].1.end_step as f64 + self.eps_t;
            for &j in &by_start[p + 1..] {
                if items[j].1.start_step as f64 > reach {
                    break;
                }
                let (a, b) = (items[i].1, items[j].1);
                if items[i].0 != items[j].0
                    && linked(a, b, centres[i], centres[j], self.eps_s * scale, self.eps_t)
                {
                    union(&mut parent, i, j);
                }
            }
        }
        let mut groups: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        for i in 0..n {
            let r = find(&mut parent, i);
            groups.entry(r).or_default().push(i);
        }
        let Prepared { id, votes, total } = prepared;
        let mut out = Vec::new();
        for group in groups.values() {
            let mut members: Vec<usize> = group.iter().map(|&i| items[i].0).collect();
            members.sort_unstable();
            members.dedup();
            let activation = members.iter().map(|&k| votes[k]).sum::<f64>() / total;
            if activation.is_nan() || activation <= self.gamma {
                continue;
            }
            // The leader: largest vote, ties to the earlier member; each of its patterns here.
            let lead = members.iter().copied().fold(members[0], |best, k| {
                if votes[k] > votes[best] { k } else { best }
            });
            let ids: Vec<&str> = members
                .iter()
                .map(|&k| self.members[k].id.as_str())
                .collect();
            for pattern in group
                .iter()
                .map(|&i| items[i])
                .filter(|(k, _)| *k == lead)
                .map(|(_, a)| a)
            {
                out.push(Annotation {
                    detector_id: id.clone(),
                    trace_id: trace.trace_id.clone(),
                    label: self.label.clone(),
                    seq: 0,
                    start_step: pattern.start_step,
                    end_step: pattern.end_step,
                    t_start: pattern.t_start,
                    t_end: pattern.t_end,
                    objects: pattern.objects.clone(),
                    parameters: pattern.parameters.clone(),
                    provenance: pattern.provenance.clone(),
                    metadata: Some(json!({
                        "ensemble": {
                            "activation": activation,
                            "members": ids,
                            "leader": self.members[lead].id.as_str(),
                        },
                        "member": pattern.metadata.clone(),
                    })),
                    activation,
                });
            }
        }
        sort_by_span_then_metadata(&mut out);
        for (seq, a) in out.iter_mut().enumerate() {
            a.seq = seq;
        }
        out
    }
}

/// What the combination needs of a label's ensemble on every trace, computed once: its id and the
/// members' votes with their sum.
struct Prepared {
    id: DetectorId,
    votes: Vec<f64>,
    total: f64,
}

impl Prepared {
    fn of(e: &LabelEnsemble) -> Self {
        let votes = e.votes();
        Prepared {
            id: e.id(),
            total: votes.iter().sum(),
            votes,
        }
    }
}

/// Orders ensemble annotations by (start, end), ties by the text of their metadata — the order of
/// `sort_by` with that comparator (both are stable), with the metadata written out only for the
/// annotations that tie on their span.
fn sort_by_span_then_metadata(out: &mut [Annotation]) {
    out.sort_by_key(|a| (a.start_step, a.end_step));
    let mut lo = 0;
    while lo < out.len() {
        let span = (out[lo].start_step, out[lo].end_step);
        let hi = lo
            + out[lo..]
                .iter()
                .take_while(|a| (a.start_step, a.end_step) == span)
                .count();
        if hi - lo > 1 {
            out[lo..hi].sort_by_cached_key(|a| a.metadata.as_ref().map(|m| m.to_string()));
        }
        lo = hi;
    }
}

/// Whether two member patterns are linked (see the module docs); `eps_s` is already in trace units.
/// The three tests are pure, so they run cheapest first and stop at the first that fails.
fn linked(
    a: &Annotation,
    b: &Annotation,
    ca: Option<(f64, f64)>,
    cb: Option<(f64, f64)>,
    eps_s: f64,
    eps_t: f64,
) -> bool {
    let gap = a.start_step.max(b.start_step) - a.end_step.min(b.end_step);
    let time = gap as f64 <= eps_t; // false for a NaN ε_t: links nothing
    if !time {
        return false;
    }
    let objects = (a.objects.is_empty() && b.objects.is_empty())
        || a.objects.iter().any(|o| b.objects.contains(o));
    objects
        && match (ca, cb) {
            (Some(p), Some(q)) => within(p.0 - q.0, p.1 - q.1, eps_s),
            _ => true,
        }
}

/// `dx.hypot(dy) <= eps`, the same answer for every input, without `hypot` where the squared
/// distance decides it. `hypot` is within one ulp of the true distance D, and for operands and `eps`
/// between 1e-100 and 1e100 in size, `dx * dx + dy * dy` is within a few ulps of D² and `eps * eps`
/// within one of eps² (no overflow, and an underflowed square is far below `eps * eps`): a squared
/// distance more than a relative 1e-9 away from `eps * eps` cannot be on the other side of it from
/// `hypot`'s answer. Anything nearer, or outside those sizes (infinities and NaN included), asks `hypot`.
fn within(dx: f64, dy: f64, eps: f64) -> bool {
    const LO: f64 = 1e-100;
    const HI: f64 = 1e100;
    if (LO..=HI).contains(&eps) && dx.abs() <= HI && dy.abs() <= HI {
        let d2 = dx * dx + dy * dy;
        let e2 = eps * eps;
        if d2 < e2 * (1.0 - 1e-9) {
            return true;
        }
        if d2 > e2 * (1.0 + 1e-9) {
            return false;
        }
    }
    dx.hypot(dy) <= eps
}

/// The centroid of a pattern's objects' centres at its first step (the nearest step at or after it),
/// or `None` when none of its objects is in the trace there. `buf` is scratch space for object ids.
fn centroid(view: &Objects<'_>, a: &Annotation, buf: &mut String) -> Option<(f64, f64)> {
    let steps = &view.trace().timesteps;
    let i = steps
        .partition_point(|t| t.index < a.start_step)
        .min(steps.len().checked_sub(1)?);
    let (mut x, mut y, mut n) = (0.0, 0.0, 0usize);
    let mut add = |id: &str, (cx, cy): (f64, f64)| {
        if a.objects.iter().any(|o| o == id) {
            x += cx;
            y += cy;
            n += 1;
        }
    };
    match view {
        Objects::Built(t) => {
            for o in &t.timesteps[i].objects {
                add(object_id(&o.body, buf), o.body.centre());
            }
        }
        Objects::Rows(_, rows) => {
            for b in rows.steps().balls(i) {
                add(b.ball_id, (b.position[0], b.position[1]));
            }
        }
    }
    (n > 0).then(|| (x / n as f64, y / n as f64))
}

/// [`Body::object_id`] without allocating: a ball's id, or the index written into `buf`.
fn object_id<'a>(body: &'a Body, buf: &'a mut String) -> &'a str {
    use std::fmt::Write;
    match body {
        Body::Pool(b) => &b.ball_id,
        Body::Phyre(o) => {
            buf.clear();
            let _ = write!(buf, "{}", o.object_index);
            buf
        }
        Body::Iphyre(o) => {
            buf.clear();
            let _ = write!(buf, "{}", o.index);
            buf
        }
    }
}

fn find(parent: &mut [usize], i: usize) -> usize {
    let mut r = i;
    while parent[r] != r {
        r = parent[r];
    }
    let mut j = i;
    while parent[j] != r {
        let next = parent[j];
        parent[j] = r;
        j = next;
    }
    r
}

fn union(parent: &mut [usize], a: usize, b: usize) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        parent[hi] = lo;
    }
}

/// Replaces the member patterns of every ensemble label among `detectors` by the ensemble annotations
/// of their traces; patterns of other detectors pass through unchanged (a plain library's annotations
/// are returned as they are). Ensemble annotations follow the others, by trace then label.
pub fn combine(detectors: &[Detector], traces: &[Trace], anns: Vec<Annotation>) -> Vec<Annotation> {
    combine_views(detectors, traces, |t| Objects::Built(t), anns)
}

/// [`combine`] over traces read from a run's tables, reading a billiards trace's balls from its frame
/// rows when they are still columns (the same annotations).
pub fn combine_framed(
    detectors: &[Detector],
    traces: &[FramedTrace],
    anns: Vec<Annotation>,
) -> Vec<Annotation> {
    combine_views(detectors, traces, |t| Objects::of_framed(t), anns)
}

fn combine_views<T: Sync>(
    detectors: &[Detector],
    traces: &[T],
    view: impl Fn(&T) -> Objects<'_> + Sync,
    anns: Vec<Annotation>,
) -> Vec<Annotation> {
    let ensembles = LabelEnsemble::of_detectors(detectors);
    if ensembles.is_empty() {
        return anns;
    }
    // Each member id's ensembles, with its (first) position among each one's members.
    let mut roles: HashMap<&str, Vec<(usize, usize)>> = HashMap::new();
    for (e, ens) in ensembles.iter().enumerate() {
        for (k, m) in ens.members.iter().enumerate() {
            let r = roles.entry(m.id.as_str()).or_default();
            if !r.iter().any(|&(f, _)| f == e) {
                r.push((e, k));
            }
        }
    }
    let (members, mut out): (Vec<Annotation>, Vec<Annotation>) = anns
        .into_iter()
        .partition(|a| roles.contains_key(a.detector_id.as_str()));
    // Member patterns grouped by trace and ensemble once, in their order, so a batch costs its
    // patterns, not traces × patterns.
    let mut by_trace: HashMap<&str, Vec<Vec<(usize, &Annotation)>>> = HashMap::new();
    for a in &members {
        let slots = by_trace
            .entry(a.trace_id.as_str())
            .or_insert_with(|| vec![Vec::new(); ensembles.len()]);
        for &(e, k) in &roles[a.detector_id.as_str()] {
            slots[e].push((k, a));
        }
    }
    let prepared: Vec<Prepared> = ensembles.iter().map(Prepared::of).collect();
    // Traces are combined on every core (the detector workers wait meanwhile), in trace order.
    let per_trace: Vec<Vec<Annotation>> = traces
        .par_iter()
        .map(|trace| {
            let mut found = Vec::new();
            let view = view(trace);
            if let Some(slots) = by_trace.get(view.trace().trace_id.as_str()) {
                for ((e, items), p) in ensembles.iter().zip(slots).zip(&prepared) {
                    if !items.is_empty() {
                        found.extend(e.clusters(&view, items, p));
                    }
                }
            }
            found
        })
        .collect();
    out.extend(per_trace.into_iter().flatten());
    out
}

/// The `detectors` rows an ensemble library adds: one pseudo-detector per ensemble label, with the
/// label's ensemble id, whose "code" lists its members and settings (the ensemble annotations name it).
pub fn ensemble_detectors(library: &Library) -> Vec<Detector> {
    LabelEnsemble::of_detectors(&library.detectors)
        .into_iter()
        .map(|e| {
            let mut code = format!(
                "# ensemble of {} member(s): gamma = {}, eps_s = {}, eps_t = {}\n",
                e.members.len(),
                e.gamma,
                e.eps_s,
                e.eps_t
            );
            for m in &e.members {
                code.push_str(&format!(
                    "# member {} weight {} reward {}\n",
                    m.id, m.weight, m.reward
                ));
            }
            Detector {
                id: e.id(),
                label: e.label.clone(),
                aliases: Vec::new(),
                env: e.env,
                source: format!("{}/ensemble:{}", library.name, e.label),
                code,
                weight: 1.0,
                ensemble: None,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use serde_json::json;

    use super::*;
    use crate::detect::{EnsembleSettings, Membership, Pattern};

    /// `within` answers as `hypot(dx, dy) <= eps` does: on seeded random operands over 600 orders of
    /// magnitude, on tolerances set exactly at `hypot`'s answer and one ulp either side of it (where
    /// the squared distance cannot decide), and on zeros, subnormals, infinities and NaN.
    #[test]
    fn the_squared_distance_test_answers_as_hypot_does() {
        let mut rng = crate::rng::SplitMix64::new(7);
        let sized = |rng: &mut crate::rng::SplitMix64| {
            let sign = if rng.below(2) == 0 { 1.0 } else { -1.0 };
            sign * rng.next_f64() * 10f64.powi(rng.below(601) as i32 - 300)
        };
        let specials = [
            0.0,
            -0.0,
            f64::MIN_POSITIVE,
            5e-324,
            1e-100,
            1e100,
            1e200,
            f64::MAX,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        let (mut decided, mut cases) = (0, 0);
        let mut check = |dx: f64, dy: f64, eps: f64| {
            cases += 1;
            let (d2, e2) = (dx * dx + dy * dy, eps * eps);
            if d2 < e2 * (1.0 - 1e-9) || d2 > e2 * (1.0 + 1e-9) {
                decided += 1;
            }
            assert_eq!(
                within(dx, dy, eps),
                dx.hypot(dy) <= eps,
                "dx {dx:e} dy {dy:e} eps {eps:e}"
            );
        };
        for _ in 0..200_000 {
            let (dx, dy) = (sized(&mut rng), sized(&mut rng));
            let h = dx.hypot(dy);
            // Near the boundary: the squared distance is never decisive there.
            for eps in [
                h,
                h.next_up(),
                h.next_down(),
                h * (1.0 + 1e-12),
                h * (1.0 - 1e-12),
            ] {
                check(dx, dy, eps);
            }
            // Tolerances within a few orders of magnitude of the distance, and anywhere.
            check(dx, dy, h * 10f64.powf(rng.uniform(-3.0, 3.0)));
            check(dx, dy, sized(&mut rng).abs());
        }
        for &dx in &specials {
            for &dy in &specials {
                for &eps in &specials {
                    check(dx, dy, eps);
                    check(dx, dy, -eps);
                }
            }
        }
        // Five of the seven checks per draw sit at the boundary; the other two are mostly decided.
        assert!(
            decided > cases / 10,
            "{decided} of {cases} decided by the squared distance"
        );
    }

    /// A pooltool trace of 20 steps: ball `cue` at (0.01 s, 0), `1` at (1 + 0.01 s, 2), `2` at
    /// (2 + 0.01 s, 4) at step s (metres).
    fn trace() -> Trace {
        crate::testutil::synthetic_trace(Env::Pooltool, 0, 20, 3)
    }

    fn ann(d: &Detector, t: &Trace, seq: usize, s: i64, e: i64, objects: &[&str]) -> Annotation {
        let details: serde_json::Map<String, serde_json::Value> = objects
            .iter()
            .map(|o| (o.to_string(), json!({"ball_id": o})))
            .collect();
        Annotation::new(
            d,
            t,
            seq,
            Pattern {
                label: d.label.clone(),
                start_step: s,
                end_step: e,
                parameters: json!({"object_details": details})
                    .as_object()
                    .unwrap()
                    .clone(),
                provenance: None,
                metadata: Some(json!({"seq": seq})),
            },
        )
    }

    /// Members A (w 1, t 0.6), B (w 1, t 0.3), C (w 0.5, t 0.2): votes 0.6, 0.3, 0.1 of 1.0.
    fn members(gamma: f64, eps_s: f64, eps_t: f64) -> Vec<Detector> {
        let code = |n: &str| format!("def find_pattern(trace):\n    return []  # {n}\n");
        let mut ds: Vec<Detector> = ["a", "b", "c"]
            .iter()
            .map(|n| Detector::new(Env::Pooltool, "hit", &code(n), n))
            .collect();
        let settings = Arc::new(EnsembleSettings {
            label: "hit".into(),
            gamma,
            eps_s,
            eps_t,
            k: 3,
            members: ds.iter().map(|d| d.id.clone()).collect(),
        });
        for (d, (w, t)) in ds.iter_mut().zip([(1.0, 0.6), (1.0, 0.3), (0.5, 0.2)]) {
            d.weight = w;
            d.ensemble = Some(Arc::new(Membership {
                settings: settings.clone(),
                reward: t,
                run: "evolve".into(),
                candidate: String::new(),
                cluster: 0,
            }));
        }
        ds
    }

    fn patterns(ds: &[Detector], t: &Trace) -> Vec<Annotation> {
        let (a, b, c) = (&ds[0], &ds[1], &ds[2]);
        vec![
            ann(a, t, 0, 5, 5, &["cue"]),
            ann(b, t, 0, 6, 6, &["cue"]),
            ann(c, t, 0, 15, 15, &["1"]),
            ann(a, t, 1, 10, 12, &["1", "2"]),
            ann(c, t, 1, 10, 10, &["2"]),
            ann(b, t, 1, 18, 18, &[]),
            ann(c, t, 2, 18, 19, &[]),
        ]
    }

    fn summary(out: &[Annotation]) -> Vec<(i64, i64, f64, Vec<String>)> {
        out.iter()
            .map(|a| {
                let m = &a.metadata.as_ref().unwrap()["ensemble"]["members"];
                let ids = m
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_str().unwrap().to_string())
                    .collect();
                (
                    a.start_step,
                    a.end_step,
                    (a.activation * 1e9).round() / 1e9,
                    ids,
                )
            })
            .collect()
    }

    #[test]
    fn hand_computed_clusters_activations_and_threshold() {
        let t = trace();
        let ds = members(0.5, 0.02, 1.0);
        let ids: Vec<String> = ds.iter().map(|d| d.id.to_string()).collect();
        let e = &LabelEnsemble::of_detectors(&ds)[0];
        assert_eq!(e.votes(), vec![0.6, 0.3, 0.1]);
        let anns = patterns(&ds, &t);
        let refs: Vec<&Annotation> = anns.iter().collect();
        // A@5 and B@6: same ball, one step apart, 1 cm apart (≤ 2 cm) → a = 0.9. A@10-12 {1, 2} and
        // C@10 {2}: centroids (1.6, 3) and (2.1, 4) are 1.118 m apart → A alone, 0.6 > 0.5. C@15 alone
        // (0.1) and {B, C}@18 (no objects, 0.4) stay below γ.
        let out = e.annotate_trace(&t, &refs);
        assert_eq!(
            summary(&out),
            vec![
                (5, 5, 0.9, vec![ids[0].clone(), ids[1].clone()]),
                (10, 12, 0.6, vec![ids[0].clone()]),
            ]
        );
        assert_eq!(out[0].detector_id, e.id());
        assert_eq!((out[0].seq, out[1].seq), (0, 1));
        assert_eq!(out[0].objects, vec!["cue".to_string()]);
        assert_eq!(
            out[0].metadata.as_ref().unwrap()["member"],
            json!({"seq": 0})
        );
        assert_eq!(
            out[1].metadata.as_ref().unwrap()["ensemble"]["leader"],
            json!(ids[0])
        );
        // γ = 0.35: {B, C}@18 (0.4) fires too, led by B (the larger vote), with B's span.
        let low = LabelEnsemble {
            gamma: 0.35,
            ..e.clone()
        };
        let out = low.annotate_trace(&t, &refs);
        assert_eq!(
            summary(&out)[2],
            (18, 18, 0.4, vec![ids[1].clone(), ids[2].clone()])
        );
        // ε_s = 5 mm (the paper's pooltool value): A@5 and B@6 are 1 cm apart → separate; A fires
        // alone with 0.6.
        let tight = LabelEnsemble {
            eps_s: 0.005,
            ..e.clone()
        };
        assert_eq!(
            summary(&tight.annotate_trace(&t, &refs))[0],
            (5, 5, 0.6, vec![ids[0].clone()])
        );
        // ε_t = 0: one step apart is too far in time as well.
        let now = LabelEnsemble {
            eps_t: 0.0,
            ..e.clone()
        };
        assert_eq!(summary(&now.annotate_trace(&t, &refs)).len(), 2);
        assert_eq!(summary(&now.annotate_trace(&t, &refs))[0].2, 0.6);
    }

    #[test]
    fn a_long_pattern_links_to_later_short_ones_whatever_their_order() {
        // A@2-16 on the cue ball spans B@14 and C@15 (also the cue ball); given out of start order,
        // with a short A@3 in between that ends long before them. The sweep by start step must still
        // link A@2-16 with B@14 and C@15 (one cluster: 0.6 + 0.3 + 0.1 = 1.0), as testing every pair does.
        let t = trace();
        let ds = members(0.5, 10.0, 0.0);
        let ids: Vec<String> = ds.iter().map(|d| d.id.to_string()).collect();
        let e = &LabelEnsemble::of_detectors(&ds)[0];
        let anns = [
            ann(&ds[2], &t, 0, 15, 15, &["cue"]),
            ann(&ds[0], &t, 0, 3, 3, &["2"]),
            ann(&ds[1], &t, 0, 14, 14, &["cue"]),
            ann(&ds[0], &t, 1, 2, 16, &["cue"]),
        ];
        let refs: Vec<&Annotation> = anns.iter().collect();
        assert_eq!(
            summary(&e.annotate_trace(&t, &refs)),
            vec![(2, 16, 1.0, ids.clone()), (3, 3, 0.6, vec![ids[0].clone()]),]
        );
    }

    #[test]
    fn a_member_s_own_patterns_stay_separate_detections() {
        let t = trace();
        let ds = members(0.5, 0.02, 1.0);
        // A alone (K = 1 in effect): two hits of the cue ball one step apart stay two annotations.
        let one = LabelEnsemble {
            members: vec![LabelEnsemble::of_detectors(&ds)[0].members[0].clone()],
            ..LabelEnsemble::of_detectors(&ds)[0].clone()
        };
        let anns = [
            ann(&ds[0], &t, 0, 3, 3, &["cue"]),
            ann(&ds[0], &t, 1, 4, 4, &["cue"]),
        ];
        let refs: Vec<&Annotation> = anns.iter().collect();
        let out = one.annotate_trace(&t, &refs);
        assert_eq!(
            out.iter()
                .map(|a| (a.start_step, a.activation))
                .collect::<Vec<_>>(),
            vec![(3, 1.0), (4, 1.0)]
        );
        // B@4 is within one step and 1 cm of both A@3 and A@4: one cluster {A@3, A@4, B@4} of
        // activation 0.9, which reports both of the leader A's patterns.
        let mut anns = anns.to_vec();
        anns.push(ann(&ds[1], &t, 0, 4, 4, &["cue"]));
        let refs: Vec<&Annotation> = anns.iter().collect();
        let e = &LabelEnsemble::of_detectors(&ds)[0];
        let got: Vec<(i64, f64)> = e
            .annotate_trace(&t, &refs)
            .iter()
            .map(|a| (a.start_step, (a.activation * 1e9).round() / 1e9))
            .collect();
        assert_eq!(got, vec![(3, 0.9), (4, 0.9)]);
    }

    #[test]
    fn a_trace_read_with_its_balls_as_columns_combines_as_its_objects_do() {
        use crate::trace::{FramedTrace, TraceBatchBuilder, TraceRows};
        let config = crate::envs::pool::PoolConfig::default_7ft();
        let opts = crate::envs::pool::TraceOptions { dt: 0.05 };
        let shot = crate::envs::pool::dataset_trace(&config, 4, 0, &opts).unwrap();
        for t in [trace(), shot] {
            let b = TraceBatchBuilder::from_trace(&t, "scene", "test").unwrap();
            let framed = FramedTrace::decode(&TraceRows {
                env: t.env,
                trace: &b.traces,
                timesteps: &b.timesteps,
                frames: &b.frames,
                events: &b.events,
            })
            .unwrap();
            assert!(framed.is_columns());
            let last = t.timesteps.last().unwrap().index;
            let ids: Vec<String> = t.timesteps[0]
                .objects
                .iter()
                .map(|o| o.body.object_id())
                .collect();
            // Patterns of the three members at steps spread over the trace, each naming one or
            // two balls, at tolerances from tight (space decides) to loose.
            for (gamma, eps_s, eps_t) in [(0.0, 0.02, 1.0), (0.3, 0.5, 3.0), (0.5, 0.002, 8.0)] {
                let ds = members(gamma, eps_s, eps_t);
                let mut anns = Vec::new();
                for i in 0..24usize {
                    let s = (i as i64 * 7919) % (last + 1);
                    let objs = [&ids[i % ids.len()], &ids[(i / 2) % ids.len()]];
                    let objs: Vec<&str> = objs[..1 + i % 2].iter().map(|s| s.as_str()).collect();
                    anns.push(ann(&ds[i % 3], &t, i, s, (s + 2).min(last), &objs));
                }
                let whole = combine(&ds, std::slice::from_ref(&t), anns.clone());
                let columns = combine_framed(&ds, std::slice::from_ref(&framed), anns);
                let clustered = |a: &Annotation| {
                    a.metadata
                        .as_ref()
                        .is_some_and(|m| m.get("ensemble").is_some())
                };
                assert!(whole.iter().any(clustered));
                assert_eq!(columns, whole, "γ {gamma}, ε_s {eps_s}, ε_t {eps_t}");
            }
        }
    }

    #[test]
    fn object_ids_without_allocating_are_the_bodies_ids() {
        let mut buf = String::new();
        for env in [Env::Pooltool, Env::Phyre, Env::Iphyre] {
            let t = crate::testutil::synthetic_trace(env, 0, 2, 3);
            for o in &t.timesteps[0].objects {
                assert_eq!(object_id(&o.body, &mut buf), o.body.object_id());
            }
        }
    }

    #[test]
    fn ties_on_the_span_are_ordered_by_the_metadata_text_as_a_full_sort_orders_them() {
        let t = trace();
        let d = &members(0.5, 0.02, 1.0)[0];
        let mut anns: Vec<Annotation> = [
            (3, 4, 2.5),
            (1, 2, 10.0),
            (3, 4, 10.0),
            (3, 4, -1.0),
            (1, 1, 0.0),
        ]
        .iter()
        .map(|&(s, e, m)| {
            let mut a = ann(d, &t, 0, s, e, &["cue"]);
            a.metadata = Some(json!({"x": m}));
            a
        })
        .collect();
        let mut full = anns.clone();
        full.sort_by(|a, b| {
            (a.start_step, a.end_step)
                .cmp(&(b.start_step, b.end_step))
                .then_with(|| {
                    a.metadata
                        .as_ref()
                        .map(|m| m.to_string())
                        .cmp(&b.metadata.as_ref().map(|m| m.to_string()))
                })
        });
        sort_by_span_then_metadata(&mut anns);
        assert_eq!(anns, full);
        // "10.0" sorts before "2.5" as text.
        let xs: Vec<f64> = anns
            .iter()
            .map(|a| a.metadata.as_ref().unwrap()["x"].as_f64().unwrap())
            .collect();
        assert_eq!(xs, vec![0.0, 10.0, -1.0, 10.0, 2.5]);
    }

    #[test]
    fn votes_fall_back_to_weights_then_to_one() {
        let mut ds = members(0.5, 0.02, 1.0);
        for d in &mut ds {
            let mut m = (**d.ensemble.as_ref().unwrap()).clone();
            m.reward = -1.0;
            d.ensemble = Some(Arc::new(m));
        }
        let e = &LabelEnsemble::of_detectors(&ds)[0];
        assert_eq!(e.votes(), vec![1.0, 1.0, 0.5]);
        let zero = LabelEnsemble {
            members: e
                .members
                .iter()
                .map(|m| Member {
                    weight: 0.0,
                    ..m.clone()
                })
                .collect(),
            ..e.clone()
        };
        assert_eq!(zero.votes(), vec![1.0; 3]);
    }

    #[test]
    fn combine_replaces_member_patterns_and_passes_others_through() {
        let t = trace();
        let mut ds = members(0.5, 0.02, 1.0);
        let plain = Detector::new(
            Env::Pooltool,
            "other",
            "def find_pattern(trace):\n    return []\n",
            "x",
        );
        let mut anns = patterns(&ds, &t);
        let other = ann(&plain, &t, 0, 3, 4, &["1"]);
        anns.insert(0, other.clone());
        ds.push(plain);
        let out = combine(&ds, std::slice::from_ref(&t), anns);
        assert_eq!(out.len(), 3);
        assert_eq!(out[0], other);
        assert_eq!((out[1].start_step, out[1].label.as_str()), (5, "hit"));
        assert!((out[2].activation - 0.6).abs() < 1e-12);
        // A plain library's annotations are returned as they are.
        let p = vec![other.clone()];
        assert_eq!(combine(&ds[3..], std::slice::from_ref(&t), p.clone()), p);
    }
}
