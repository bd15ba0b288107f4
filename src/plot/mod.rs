//! Plots: one small module for every figure annotrace draws, as SVG for papers and PNG for quick looks.
//!
//! `figure` lays out and encodes a [`Figure`] (axes with labels and units, lines with ±std bands,
//! points, grouped bars, a legend); `kinds` holds the plot kinds of a run (success vs budget,
//! convergence per 10 % bin, success vs library size, fitness over candidates per label, learning
//! statistics per environment), each an SQL query giving long-format rows and its axes; `examples`
//! draws the annotation-examples figure (frames of a trace above its pattern timeline).
//!
//! **Does not:** read run folders or run queries (the `plot` stage and `annotrace plot` do), or
//! aggregate data beyond its queries. The optimisation experiment's figure (`optimise::plot`) is drawn
//! here too.

pub mod examples;
mod figure;
pub mod kinds;

pub use figure::{Axis, Figure, Mark, PALETTE, Point, Series, colour, png, svg};
pub use kinds::{PlotKind, Row, RowsError, X, figure_of, rows_of};
