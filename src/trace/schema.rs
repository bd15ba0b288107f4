//! Arrow schemas of the trace tables: `scenes`, `traces`, `timesteps`, `frames` and `events`.
//!
//! Every table is stored as one Parquet dataset per run, hive-partitioned by `env=` (the `env` column
//! comes from the folder name, not from the files). Strings that repeat row after row (trace and object
//! ids, kinds, shapes, colours, motion states) are dictionary-encoded. JSON-valued columns hold compact
//! JSON text. `docs/schema.md` documents every column; a test keeps the two in step.

use std::sync::{Arc, LazyLock};

use arrow::datatypes::{DataType, Field, Schema, SchemaRef};

/// The trace tables, in the order stages write them.
pub const TRACE_TABLES: [&str; 5] = ["scenes", "traces", "timesteps", "frames", "events"];

/// The name of the partition column of every trace table.
pub const ENV_COLUMN: &str = "env";

/// Dictionary-encoded UTF-8 strings.
pub fn dict_utf8() -> DataType {
    DataType::Dictionary(Box::new(DataType::Int32), Box::new(DataType::Utf8))
}

fn f(name: &str, dt: DataType, nullable: bool) -> Field {
    Field::new(name, dt, nullable)
}

/// `scenes`: one row per scene (an initial condition that traces start from).
pub static SCENES: LazyLock<SchemaRef> = LazyLock::new(|| {
    Arc::new(Schema::new(vec![
        f("scene_id", DataType::Utf8, false),
        f("task_id", DataType::Utf8, false),
        f("source", DataType::Utf8, false),
        f("n_objects", DataType::Int64, false),
        f("spec", DataType::Utf8, false),
    ]))
});

/// `traces`: one row per trace, with its outcome and summary counts.
pub static TRACES: LazyLock<SchemaRef> = LazyLock::new(|| {
    Arc::new(Schema::new(vec![
        f("trace_id", DataType::Utf8, false),
        f("scene_id", DataType::Utf8, false),
        f("task_id", DataType::Utf8, false),
        f("n_steps", DataType::Int64, false),
        f("n_objects", DataType::Int64, false),
        f("n_frames", DataType::Int64, false),
        f("n_events", DataType::Int64, false),
        f("t_start", DataType::Float64, true),
        f("t_end", DataType::Float64, true),
        f("success", DataType::Boolean, false),
        f("terminal_status", DataType::Utf8, false),
        f("metrics", DataType::Utf8, false),
        f("outcome_extra", DataType::Utf8, true),
        f("extra", DataType::Utf8, true),
        f("source", DataType::Utf8, false),
    ]))
});

/// `timesteps`: one row per trace × step.
pub static TIMESTEPS: LazyLock<SchemaRef> = LazyLock::new(|| {
    Arc::new(Schema::new(vec![
        f("trace_id", dict_utf8(), false),
        f("step", DataType::Int64, false),
        f("t", DataType::Float64, false),
        f("n_objects", DataType::Int32, false),
        f("extra", DataType::Utf8, true),
    ]))
});

/// `frames`: one row per trace × step × object; a shared core plus nullable environment columns.
pub static FRAMES: LazyLock<SchemaRef> = LazyLock::new(|| {
    let float = |name: &str| f(name, DataType::Float64, true);
    Arc::new(Schema::new(vec![
        f("trace_id", dict_utf8(), false),
        f("step", DataType::Int64, false),
        f("t", DataType::Float64, false),
        f("slot", DataType::Int32, false),
        f("object_id", dict_utf8(), false),
        f("x", DataType::Float64, false),
        f("y", DataType::Float64, false),
        float("z"),
        float("vx"),
        float("vy"),
        float("vz"),
        float("angle"),
        float("wx"),
        float("wy"),
        float("wz"),
        f("kind", dict_utf8(), true),
        f("motion_state_code", DataType::Int32, true),
        f("motion_state", dict_utf8(), true),
        float("radius"),
        float("diameter"),
        f("shape", dict_utf8(), true),
        f("color", dict_utf8(), true),
        f("is_user_input", DataType::Boolean, true),
        float("x1"),
        float("y1"),
        float("x2"),
        float("y2"),
        float("eliminable"),
        float("dynamic"),
        f("joint", DataType::Int64, true),
        f("spring", DataType::Int64, true),
        f("extra", DataType::Utf8, true),
    ]))
});

/// `events`: one row per event, in log order.
pub static EVENTS: LazyLock<SchemaRef> = LazyLock::new(|| {
    Arc::new(Schema::new(vec![
        f("trace_id", dict_utf8(), false),
        f("seq", DataType::Int32, false),
        f("kind", dict_utf8(), false),
        f("t", DataType::Float64, true),
        f(
            "agents",
            DataType::List(Arc::new(Field::new("item", DataType::Utf8, true))),
            true,
        ),
        f("payload", DataType::Utf8, true),
        f("extra", DataType::Utf8, true),
    ]))
});

/// The schema of a trace table by name.
pub fn table_schema(name: &str) -> Option<SchemaRef> {
    match name {
        "scenes" => Some(SCENES.clone()),
        "traces" => Some(TRACES.clone()),
        "timesteps" => Some(TIMESTEPS.clone()),
        "frames" => Some(FRAMES.clone()),
        "events" => Some(EVENTS.clone()),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `docs/schema.md` lists exactly the columns of every trace table, in order, plus `env`.
    #[test]
    fn docs_match_the_schemas() {
        for table in TRACE_TABLES {
            crate::testutil::assert_documented_columns(table, &table_schema(table).unwrap());
        }
    }
}
