//! The fitness terms of one candidate detector (Algorithm 3 of the paper): each term is kept, not only ν.

use serde::{Deserialize, Serialize};

/// Every term of a candidate's fitness. `nu = rho + eta - lambda - psi`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FitnessTerms {
    /// ρ: Pearson correlation between the pairwise trace distances D_x and the pairwise annotation
    /// distances D_p of the candidate, over all pairs of training traces (0 when undefined).
    pub rho: f64,
    /// η: mean novelty (annotation distance) between the candidate's annotations and each library
    /// detector's annotations, averaged over traces and library detectors (0 for an empty library).
    pub eta: f64,
    /// λ: length penalty `ln(min(lines, 1000)) / 5`.
    pub lambda: f64,
    /// ψ: time penalty, 0 when the candidate's mean annotation time t ≤ μ (the library's mean), rising
    /// linearly to 1 at t = 2μ and capped at 1.
    pub psi: f64,
    /// ν = ρ + η − λ − ψ, the score the search maximises.
    pub nu: f64,
}

impl FitnessTerms {
    /// Assemble the terms and compute ν from them.
    pub fn new(rho: f64, eta: f64, lambda: f64, psi: f64) -> Self {
        FitnessTerms {
            rho,
            eta,
            lambda,
            psi,
            nu: rho + eta - lambda - psi,
        }
    }
}
