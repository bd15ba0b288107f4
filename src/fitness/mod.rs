//! Fitness of detector programs (section 3.1–3.2, Algorithm 3 and appendix F of the paper).
//!
//! A candidate detector is scored by how well the distances between its annotations of the training
//! traces follow the distances between the traces themselves (ρ), how different its annotations are from
//! the current library's (η), minus a length penalty (λ) and a time penalty (ψ): ν = ρ + η − λ − ψ.
//!
//! **Owns:** trace distance d_x with its variants ([`Dx`]) and the pairwise D_x matrix ([`distance`]), annotation histograms and
//! d_p with its variants ([`histogram`], [`Dp`]), Evaluate ([`evaluate()`]) and the `trace_distances`
//! table ([`table`]).
//! **Does not:** run detectors (`detect/`) or choose them (`search/`).

pub mod distance;
pub mod evaluate;
pub mod histogram;
pub mod table;
mod terms;

pub use self::distance::{DistanceMatrix, Dx, scene_scale};
pub use self::evaluate::{
    CandidateOutput, LibraryView, correlation, evaluate, length_penalty, time_penalty,
};
pub use self::histogram::Dp;
pub use self::terms::FitnessTerms;
