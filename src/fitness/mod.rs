//! Fitness of detector programs (section 3.2 and Algorithm 3 of the paper).
//!
//! **Owns:** the terms of a candidate's fitness ([`FitnessTerms`]).
//! **Does not:** run detectors (`detect/`) or choose them (`search/`).

mod terms;

pub use self::terms::FitnessTerms;
