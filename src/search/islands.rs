//! The program database of one label's search: FunSearch's islands (appendix F, Algorithm 1) and the two
//! baselines (`hill-climb`, `best-of-n`) behind one interface.
//!
//! **Islands.** Programs live on I islands that evolve independently. An island groups its programs in
//! clusters by *score signature* — (ρ, η) rounded to 3 decimals, i.e. programs whose annotations score
//! alike — and a cluster's score is its best ν. To build a request the search samples an island with
//! probabilities softmax(best ν / T_island), then up to s distinct clusters with softmax(score / T_c),
//! where T_c falls from `T_c0` to 0 over each `period` programs of the island (as in FunSearch), then one
//! program per cluster with softmax over negated, normalised length (shorter programs preferred). Parents
//! go best first. Every T_r steps the weaker half of the islands (by best ν, ties broken by a seeded
//! jitter) is emptied and refounded with the best program of a randomly chosen surviving island.
//! **hill-climb** keeps one program, the best so far, and always mutates it. **best-of-n** always
//! mutates the seed program g₀ and keeps the best child.
//!
//! Every random choice takes an explicit [`SplitMix64`], so a search is a function of its seed.

use std::collections::BTreeMap;

use crate::fitness::FitnessTerms;
use crate::rng::SplitMix64;

/// How a search picks parents and keeps programs.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum Strategy {
    /// FunSearch's island model.
    Island,
    /// Always mutate the best program so far.
    HillClimb,
    /// Always mutate the seed program; keep the best child.
    BestOfN,
}

impl Strategy {
    /// The command-line spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            Strategy::Island => "island",
            Strategy::HillClimb => "hill-climb",
            Strategy::BestOfN => "best-of-n",
        }
    }
}

impl std::str::FromStr for Strategy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "island" => Ok(Strategy::Island),
            "hill-climb" | "hill_climb" | "hillclimb" => Ok(Strategy::HillClimb),
            "best-of-n" | "best_of_n" => Ok(Strategy::BestOfN),
            _ => Err(format!(
                "unknown strategy {s:?} (expected island, hill-climb or best-of-n)"
            )),
        }
    }
}

/// A scored program in the database.
#[derive(Clone, Debug, PartialEq)]
pub struct Program {
    /// Hash of its code (the candidate's `code_hash`).
    pub hash: String,
    /// Its source.
    pub code: String,
    /// Its fitness terms.
    pub terms: FitnessTerms,
    /// Lines of code.
    pub lines: usize,
}

/// Sampling temperatures of the island model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Temperatures {
    /// Island choice: softmax(best ν / this).
    pub island: f64,
    /// Initial cluster temperature T_c0.
    pub cluster: f64,
    /// Programs over which T_c falls from T_c0 to 0 (then starts again).
    pub period: usize,
}

impl Temperatures {
    /// FunSearch's temperatures.
    pub const DEFAULT: Temperatures = Temperatures {
        island: 0.1,
        cluster: 0.1,
        period: 30_000,
    };
}

impl Default for Temperatures {
    fn default() -> Self {
        Temperatures::DEFAULT
    }
}

#[derive(Clone, Debug, Default)]
struct Island {
    clusters: BTreeMap<(i64, i64), Vec<Program>>,
    count: usize,
    best: Option<Program>,
}

impl Island {
    fn insert(&mut self, p: Program) {
        let key = (
            (p.terms.rho * 1000.0).round() as i64,
            (p.terms.eta * 1000.0).round() as i64,
        );
        if self.best.as_ref().is_none_or(|b| p.terms.nu > b.terms.nu) {
            self.best = Some(p.clone());
        }
        self.clusters.entry(key).or_default().push(p);
        self.count += 1;
    }

    fn best_nu(&self) -> f64 {
        self.best.as_ref().map_or(f64::NEG_INFINITY, |b| b.terms.nu)
    }
}

/// Index drawn from softmax(scores / temperature) (argmax for a temperature ≤ 0).
fn softmax_pick(scores: &[f64], temperature: f64, rng: &mut SplitMix64) -> usize {
    let u = rng.next_f64();
    if scores.is_empty() {
        return 0;
    }
    let max = scores.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    if temperature.is_nan() || temperature <= 1e-9 || !max.is_finite() {
        return scores.iter().position(|&s| s == max).unwrap_or(0);
    }
    let w: Vec<f64> = scores
        .iter()
        .map(|s| ((s - max) / temperature).exp())
        .collect();
    let total: f64 = w.iter().sum();
    let mut r = u * total;
    for (i, x) in w.iter().enumerate() {
        if r < *x {
            return i;
        }
        r -= x;
    }
    w.len() - 1
}

/// The programs of one label's search.
#[derive(Clone, Debug)]
pub struct Database {
    strategy: Strategy,
    islands: Vec<Island>,
    seed: Program,
    best: Program,
    temps: Temperatures,
}

impl Database {
    /// A database whose every island holds the seed program g₀ (scored).
    pub fn new(strategy: Strategy, islands: usize, seed: Program, temps: Temperatures) -> Self {
        let n = if strategy == Strategy::Island {
            islands.max(1)
        } else {
            1
        };
        let mut isl = vec![Island::default(); n];
        for i in &mut isl {
            i.insert(seed.clone());
        }
        Database {
            strategy,
            islands: isl,
            best: seed.clone(),
            seed,
            temps,
        }
    }

    /// Number of islands.
    pub fn islands(&self) -> usize {
        self.islands.len()
    }

    /// The best program so far (the seed until a child beats it).
    pub fn best(&self) -> &Program {
        &self.best
    }

    /// The best ν of each island.
    pub fn island_bests(&self) -> Vec<f64> {
        self.islands.iter().map(Island::best_nu).collect()
    }

    /// An island and up to `s` parents from it, best first.
    pub fn sample(&self, s: usize, rng: &mut SplitMix64) -> (usize, Vec<Program>) {
        match self.strategy {
            Strategy::HillClimb => (0, vec![self.best.clone()]),
            Strategy::BestOfN => (0, vec![self.seed.clone()]),
            Strategy::Island => {
                let bests = self.island_bests();
                let i = softmax_pick(&bests, self.temps.island, rng);
                (i, self.sample_island(i, s.max(1), rng))
            }
        }
    }

    fn sample_island(&self, i: usize, s: usize, rng: &mut SplitMix64) -> Vec<Program> {
        let isl = &self.islands[i];
        let period = self.temps.period.max(1);
        let tc = self.temps.cluster * (1.0 - (isl.count % period) as f64 / period as f64);
        let mut clusters: Vec<&Vec<Program>> = isl.clusters.values().collect();
        let mut out = Vec::new();
        while out.len() < s && !clusters.is_empty() {
            let scores: Vec<f64> = clusters
                .iter()
                .map(|c| {
                    c.iter()
                        .map(|p| p.terms.nu)
                        .fold(f64::NEG_INFINITY, f64::max)
                })
                .collect();
            let k = softmax_pick(&scores, tc, rng);
            let c = clusters.remove(k);
            let (lo, hi) = c.iter().fold((usize::MAX, 0), |(lo, hi), p| {
                (lo.min(p.lines), hi.max(p.lines))
            });
            let span = (hi - lo).max(1) as f64;
            let short: Vec<f64> = c.iter().map(|p| -((p.lines - lo) as f64 / span)).collect();
            out.push(c[softmax_pick(&short, 1.0, rng)].clone());
        }
        out.sort_by(|a, b| b.terms.nu.total_cmp(&a.terms.nu));
        out
    }

    /// Adds a scored child to `island` (hill-climb keeps it only if it beats the best; best-of-n only
    /// tracks the best).
    pub fn insert(&mut self, island: usize, p: Program) {
        let better = p.terms.nu > self.best.terms.nu;
        match self.strategy {
            Strategy::Island => {
                let i = island.min(self.islands.len() - 1);
                self.islands[i].insert(p.clone());
            }
            Strategy::HillClimb => {
                if better {
                    self.islands[0] = Island::default();
                    self.islands[0].insert(p.clone());
                }
            }
            Strategy::BestOfN => {}
        }
        if better {
            self.best = p;
        }
    }

    /// Empties the weaker half of the islands and refounds each with the best program of a random
    /// surviving island (island strategy only).
    pub fn reset(&mut self, rng: &mut SplitMix64) {
        let n = self.islands.len();
        if self.strategy != Strategy::Island || n < 2 {
            return;
        }
        let mut order: Vec<(f64, usize)> = self
            .islands
            .iter()
            .enumerate()
            .map(|(i, isl)| (isl.best_nu() + 1e-6 * rng.next_f64(), i))
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0));
        let weak: Vec<usize> = order[..n / 2].iter().map(|x| x.1).collect();
        let keep: Vec<usize> = order[n / 2..].iter().map(|x| x.1).collect();
        for w in weak {
            let donor = keep[rng.below(keep.len())];
            let founder = self.islands[donor]
                .best
                .clone()
                .unwrap_or_else(|| self.seed.clone());
            self.islands[w] = Island::default();
            self.islands[w].insert(founder);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prog(h: &str, rho: f64, eta: f64, lines: usize) -> Program {
        Program {
            hash: h.into(),
            code: h.into(),
            terms: FitnessTerms::new(rho, eta, 0.0, 0.0),
            lines,
        }
    }

    #[test]
    fn islands_favour_better_islands_and_shorter_programs() {
        let mut db = Database::new(
            Strategy::Island,
            2,
            prog("g0", 0.0, 0.0, 10),
            Temperatures::default(),
        );
        db.insert(1, prog("good", 0.5, 0.0, 10));
        let mut rng = SplitMix64::new(1);
        let picks: Vec<usize> = (0..200).map(|_| db.sample(2, &mut rng).0).collect();
        let on1 = picks.iter().filter(|&&i| i == 1).count();
        assert!(on1 > 190, "{on1}");
        // Same signature, different lengths: the shorter one is preferred.
        db.insert(1, prog("good-long", 0.5, 0.0, 200));
        db.insert(1, prog("good-short", 0.5, 0.0, 5));
        let mut short = 0;
        for _ in 0..300 {
            let (i, ps) = db.sample(1, &mut rng);
            if i == 1 && ps[0].hash == "good-short" {
                short += 1;
            }
        }
        assert!(short > 100, "{short}");
        assert_eq!(db.best().hash, "good");
    }

    #[test]
    fn reset_refounds_the_weaker_half_from_a_survivor() {
        let mut db = Database::new(
            Strategy::Island,
            4,
            prog("g0", 0.0, 0.0, 10),
            Temperatures::default(),
        );
        db.insert(0, prog("a", 0.9, 0.0, 10));
        db.insert(1, prog("b", 0.8, 0.0, 10));
        db.reset(&mut SplitMix64::new(3));
        let bests = db.island_bests();
        assert!(bests[2] >= 0.8 && bests[3] >= 0.8, "{bests:?}");
        assert_eq!(bests[0], 0.9);
    }

    #[test]
    fn baselines_pick_their_parents() {
        let mut hc = Database::new(
            Strategy::HillClimb,
            8,
            prog("g0", 0.0, 0.0, 10),
            Temperatures::default(),
        );
        hc.insert(5, prog("up", 0.2, 0.0, 10));
        hc.insert(0, prog("down", -0.2, 0.0, 10));
        let mut rng = SplitMix64::new(0);
        assert_eq!(hc.sample(4, &mut rng).1[0].hash, "up");
        let mut bn = Database::new(
            Strategy::BestOfN,
            8,
            prog("g0", 0.0, 0.0, 10),
            Temperatures::default(),
        );
        bn.insert(0, prog("up", 0.2, 0.0, 10));
        assert_eq!(bn.sample(4, &mut rng).1[0].hash, "g0");
        assert_eq!(bn.best().hash, "up");
        assert_eq!(
            "hill-climb".parse::<Strategy>().unwrap(),
            Strategy::HillClimb
        );
        assert!("greedy".parse::<Strategy>().is_err());
    }
}
