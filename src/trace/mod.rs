//! The trace model and its two representations: the paper's JSON layout and the Arrow tables.
//!
//! **Owns:** the types of a trace ([`Trace`], [`Timestep`], [`Object`], [`Event`], [`Outcome`]), the
//! environments ([`Env`]), the inline strings of its per-ball fields ([`ShortStr`]), the Arrow schemas of the trace tables ([`schema`]), conversion between traces
//! and record batches ([`batch`]), traces held in columns straight from a simulator ([`frames`]), traces read from the tables with their billiard balls left in columns ([`framed`]), billiard-ball states by step read alike from either form ([`pool_steps`]), borrowed column views of them for a
//! columnar writer ([`view`]) and the
//! JSON import/export format ([`json`]).
//! **Does not:** read or write files of a run directory (`store/`), run SQL (`query/`) or order stages
//! (`pipeline/`). It imports no other annotrace module.
//!
//! Entry points: [`json::read_file`] streams traces out of JSON; [`TraceBatchBuilder`] turns them into
//! columns; [`decode_trace`] turns columns back into a trace; [`json::write_trace`] writes JSON.

pub mod batch;
mod env;
pub mod framed;
pub mod frames;
pub mod json;
mod model;
pub mod pool_steps;
pub mod schema;
mod short_str;
pub mod view;

pub use batch::{TraceBatchBuilder, TraceBatches, TraceMeta, TraceRows, decode_trace};
pub use env::{Env, UnknownEnv};
pub use framed::{FramedTrace, PoolRows};
pub use frames::{Frames, TraceColumns, TraceTables};
pub use model::{
    Body, Event, IphyreObject, JsonMap, Object, Outcome, PhyreObject, PoolBall, Timestep, Trace,
    json_map,
};
pub use pool_steps::{BallView, PoolSteps};
pub use short_str::ShortStr;
