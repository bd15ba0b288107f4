//! Ensemble libraries (paper section 3.3): for each label, the valid candidates of M independent
//! discovery runs are pooled, clustered by their annotation behaviour with K-means, and represented by
//! one detector per cluster; at annotation time the representatives' activations are clustered in space
//! and time, and a reliability-weighted vote decides which clusters fire.
//!
//! - [`pool`]: every valid candidate per label from evolve stages' `candidates` tables;
//! - [`signature`]: each candidate's activation histograms on a fixed set of traces (the histograms of
//!   d_p, `fitness::histogram`), concatenated;
//! - [`kmeans`]: seeded K-means (linfa-clustering) and the silhouette rule for K;
//! - [`represent`]: one representative per cluster (best ν, ties to shorter code) and the "-SP" pick;
//! - [`cluster`]: one label's clustering as table rows;
//! - [`activation`]: activation clustering at annotation time (ε_s, ε_t, shared objects, a_C > γ),
//!   which `annotate`, `accuracy` and the reward runtime apply to ensemble libraries;
//! - [`calibrate`] with [`gp`]: the sweep of (γ, ε_s, ε_t) and the Bayesian optimisation of weights and
//!   tolerances against a pluggable objective;
//! - [`library`]: the ensemble and -SP library folders; [`tables`]: the `ensemble_*` tables.
//!
//! **Owns:** everything above. **Does not:** parse library folders (`detect::Library` reads the
//! `[[ensemble]]` tables into `detect::Membership`), run Python in-process (`detect::WorkerPool`),
//! compute d_x or histograms (`fitness`), or decide where tables go (the `ensemble` stage does).

pub mod activation;
pub mod calibrate;
pub mod cluster;
pub mod gp;
pub mod kmeans;
pub mod library;
pub mod pool;
pub mod represent;
pub mod signature;
pub mod tables;
