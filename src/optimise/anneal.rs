//! Simulated annealing over a box of continuous parameters, driven one sample at a time so that many
//! independent chains can be evaluated together in one batch ([`Annealer::propose`] then
//! [`Annealer::observe`]).
//!
//! The first sample is uniform in the box. Each later one perturbs the current point by a Gaussian
//! step whose scale shrinks geometrically from `step_start` to `step_end` (fractions of each range)
//! over the budget; periodic dimensions wrap, others reflect at their bounds. A proposal is accepted
//! when it scores at least as well as the current point, or with probability exp(Δ / T) otherwise,
//! with T falling geometrically from `t_start` to `t_end`. With a constant (binary) reward every
//! proposal is accepted, so the chain is a random walk until it finds a success. The best sample so
//! far (first reached, ties keep the earlier) is tracked.

use crate::rng::SplitMix64;

/// One dimension of the search box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dim {
    /// Lower bound.
    pub low: f64,
    /// Upper bound.
    pub high: f64,
    /// Whether the dimension wraps around (angles).
    pub periodic: bool,
}

/// The schedule of an annealing run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Schedule {
    /// Number of samples.
    pub budget: usize,
    /// Initial temperature (reward units).
    pub t_start: f64,
    /// Final temperature.
    pub t_end: f64,
    /// Initial step, as a fraction of each range.
    pub step_start: f64,
    /// Final step.
    pub step_end: f64,
}

impl Default for Schedule {
    /// 1000 samples, T from 0.1 to 0.002, steps from 20 % to 2 % of each range.
    fn default() -> Self {
        Schedule {
            budget: 1000,
            t_start: 0.1,
            t_end: 0.002,
            step_start: 0.2,
            step_end: 0.02,
        }
    }
}

fn geometric(a: f64, b: f64, frac: f64) -> f64 {
    a * (b / a).powf(frac.clamp(0.0, 1.0))
}

/// One annealing chain.
#[derive(Debug, Clone)]
pub struct Annealer {
    dims: Vec<Dim>,
    schedule: Schedule,
    rng: SplitMix64,
    current: Option<(Vec<f64>, f64)>,
    best: Option<(Vec<f64>, f64, usize)>,
    samples: usize,
}

impl Annealer {
    /// A chain over `dims`, seeded.
    pub fn new(dims: Vec<Dim>, schedule: Schedule, seed: u64) -> Self {
        Annealer {
            dims,
            schedule,
            rng: SplitMix64::new(seed ^ 0xA55A_5AA5_0F0F_F0F0),
            current: None,
            best: None,
            samples: 0,
        }
    }

    fn gauss(&mut self) -> f64 {
        let u1 = self.rng.next_f64().max(1e-300);
        let u2 = self.rng.next_f64();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    fn progress(&self) -> f64 {
        self.samples as f64 / self.schedule.budget.max(1) as f64
    }

    /// The next point to evaluate.
    pub fn propose(&mut self) -> Vec<f64> {
        let Some((cur, _)) = self.current.clone() else {
            let dims = self.dims.clone();
            return dims
                .iter()
                .map(|d| self.rng.uniform(d.low, d.high))
                .collect();
        };
        let step = geometric(
            self.schedule.step_start,
            self.schedule.step_end,
            self.progress(),
        );
        let dims = self.dims.clone();
        dims.iter()
            .zip(cur)
            .map(|(d, x)| {
                let range = d.high - d.low;
                let mut y = x + self.gauss() * step * range;
                if range <= 0.0 {
                    return d.low;
                }
                if d.periodic {
                    y = d.low + (y - d.low).rem_euclid(range);
                } else {
                    for _ in 0..4 {
                        if y < d.low {
                            y = 2.0 * d.low - y;
                        } else if y > d.high {
                            y = 2.0 * d.high - y;
                        }
                    }
                    y = y.clamp(d.low, d.high);
                }
                y
            })
            .collect()
    }

    /// Reports the score of `x` (the last proposal); returns whether it became the current point.
    pub fn observe(&mut self, x: Vec<f64>, score: f64) -> bool {
        let score = if score.is_finite() { score } else { 0.0 };
        let temp = geometric(self.schedule.t_start, self.schedule.t_end, self.progress());
        self.samples += 1;
        if self.best.as_ref().is_none_or(|b| score > b.1) {
            self.best = Some((x.clone(), score, self.samples));
        }
        let accept = match &self.current {
            None => true,
            Some((_, cur)) => score >= *cur || self.rng.next_f64() < ((score - cur) / temp).exp(),
        };
        if accept {
            self.current = Some((x, score));
        }
        accept
    }

    /// The best point so far, its score and the sample number (1-based) that found it.
    pub fn best(&self) -> Option<(&[f64], f64, usize)> {
        self.best.as_ref().map(|(x, s, k)| (x.as_slice(), *s, *k))
    }

    /// Samples observed so far.
    pub fn samples(&self) -> usize {
        self.samples
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bowl(x: &[f64]) -> f64 {
        1.0 / (1.0 + (x[0] - 0.3).powi(2) + (x[1] + 0.7).powi(2))
    }

    #[test]
    fn improves_a_smooth_reward_and_is_seeded() {
        let dims = vec![
            Dim {
                low: -2.0,
                high: 2.0,
                periodic: false,
            },
            Dim {
                low: -2.0,
                high: 2.0,
                periodic: true,
            },
        ];
        let sched = Schedule {
            budget: 300,
            ..Schedule::default()
        };
        let run = |seed| {
            let mut a = Annealer::new(dims.clone(), sched, seed);
            let mut first = None;
            for _ in 0..300 {
                let x = a.propose();
                assert!(x[0] >= -2.0 && x[0] <= 2.0 && x[1] >= -2.0 && x[1] < 2.0);
                let s = bowl(&x);
                first.get_or_insert(s);
                a.observe(x, s);
            }
            (first.unwrap(), a.best().unwrap().1)
        };
        let (first, best) = run(1);
        assert!(best > 0.99 && best > first, "{first} -> {best}");
        assert_eq!(run(1), run(1));
        assert_ne!(run(1), run(2));
    }
}
