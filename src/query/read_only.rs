//! Queries only read: the check that refuses any plan which would write files or change the session.
//!
//! **Owns:** [`check_plan`], which walks a DataFusion logical plan (subqueries and `EXPLAIN ANALYZE`
//! included) and refuses `COPY`, DML (`INSERT`, `DELETE`, `UPDATE`, `TRUNCATE`, `MERGE`, `CREATE TABLE
//! … AS`), DDL (`CREATE`/`DROP` of tables, views, schemas, functions) and statements (`SET`, `PREPARE`,
//! transactions), naming the first one found; and [`check_output_path`], which keeps a result file
//! written by `query --out` out of the run's table folders. **Does not:** run anything — the caller
//! checks before executing ([`RunQuery::sql`](super::RunQuery::sql)).
//!
//! The same rules as DataFusion's `SQLOptions` with DDL, DML and statements disallowed (which
//! [`check_plan`] also applies, as a second opinion), with an error that says what was refused.

use std::path::{Path, PathBuf};

use datafusion::common::tree_node::TreeNodeRecursion;
use datafusion::execution::context::SQLOptions;
use datafusion::logical_expr::{DdlStatement, LogicalPlan, Statement, WriteOp};

use super::QueryError;

/// Refuses a plan that writes or changes state; `Ok` for plans that only read.
pub fn check_plan(plan: &LogicalPlan) -> Result<(), QueryError> {
    let mut refused = None;
    plan.apply_with_subqueries(|node| {
        refused = refusal(node);
        Ok(if refused.is_some() {
            TreeNodeRecursion::Stop
        } else {
            TreeNodeRecursion::Continue
        })
    })?;
    if let Some(statement) = refused {
        return Err(QueryError::NotReadOnly { statement });
    }
    // DataFusion's own rules; `refusal` covers every node they refuse, so this only fires if a later
    // DataFusion adds a writing node that `refusal` does not know yet.
    SQLOptions::new()
        .with_allow_ddl(false)
        .with_allow_dml(false)
        .with_allow_statements(false)
        .verify_plan(plan)
        .map_err(|e| QueryError::NotReadOnly {
            statement: e.strip_backtrace(),
        })
}

/// What a writing node does, in SQL words, or `None` for a node that only reads.
fn refusal(node: &LogicalPlan) -> Option<String> {
    Some(match node {
        LogicalPlan::Copy(c) => format!("COPY … TO '{}'", c.output_url),
        LogicalPlan::Dml(d) => {
            let op = match &d.op {
                WriteOp::Insert(op) => op.to_string().to_uppercase(),
                WriteOp::Delete => "DELETE FROM".into(),
                WriteOp::Update => "UPDATE".into(),
                WriteOp::Ctas => "CREATE TABLE … AS".into(),
                WriteOp::Truncate => "TRUNCATE".into(),
                WriteOp::MergeInto(_) => "MERGE INTO".into(),
                other => other.name().to_uppercase(),
            };
            format!("{op} {}", d.table_name)
        }
        LogicalPlan::Ddl(d) => match d {
            DdlStatement::CreateExternalTable(t) => format!("CREATE EXTERNAL TABLE {}", t.name),
            DdlStatement::CreateMemoryTable(t) => format!("CREATE TABLE {}", t.name),
            DdlStatement::CreateView(v) => format!("CREATE VIEW {}", v.name),
            DdlStatement::CreateCatalogSchema(s) => format!("CREATE SCHEMA {}", s.schema_name),
            DdlStatement::CreateCatalog(c) => format!("CREATE DATABASE {}", c.catalog_name),
            DdlStatement::CreateIndex(_) => "CREATE INDEX".into(),
            DdlStatement::DropTable(t) => format!("DROP TABLE {}", t.name),
            DdlStatement::DropView(v) => format!("DROP VIEW {}", v.name),
            DdlStatement::DropCatalogSchema(s) => format!("DROP SCHEMA {}", s.name),
            DdlStatement::CreateFunction(f) => format!("CREATE FUNCTION {}", f.name),
            DdlStatement::DropFunction(f) => format!("DROP FUNCTION {}", f.name),
        },
        LogicalPlan::Statement(s) => match s {
            Statement::TransactionStart(_) => "BEGIN TRANSACTION".into(),
            Statement::TransactionEnd(_) => "COMMIT/ROLLBACK".into(),
            Statement::SetVariable(v) => format!("SET {}", v.variable),
            Statement::ResetVariable(v) => format!("RESET {}", v.variable),
            Statement::Prepare(p) => format!("PREPARE {}", p.name),
            Statement::Execute(e) => format!("EXECUTE {}", e.name),
            Statement::Deallocate(d) => format!("DEALLOCATE {}", d.name),
        },
        _ => return None,
    })
}

/// Refuses a result file inside the run folder `run` other than under its `exports/` folder: a file
/// dropped into a table's folder would be read as part of that table. Paths outside the run are the
/// user's choice and allowed. Relative paths are taken from the current folder; symbolic links in the
/// existing part of the path are followed.
pub fn check_output_path(run: &Path, out: &Path) -> Result<(), QueryError> {
    let (Some(run_abs), Some(out_abs)) = (resolve(run), resolve(out)) else {
        return Ok(());
    };
    if out_abs.starts_with(&run_abs) && !out_abs.starts_with(run_abs.join("exports")) {
        return Err(QueryError::OutputInRun {
            path: out.to_path_buf(),
            run: run.to_path_buf(),
        });
    }
    Ok(())
}

/// The absolute form of `p` with its longest existing ancestor canonicalised (the rest appended).
fn resolve(p: &Path) -> Option<PathBuf> {
    let abs = std::path::absolute(p).ok()?;
    let mut existing = abs.as_path();
    let mut rest = Vec::new();
    loop {
        if let Ok(c) = existing.canonicalize() {
            let mut out = c;
            for part in rest.iter().rev() {
                if part == ".." {
                    out.pop();
                } else if part != "." {
                    out.push(part);
                }
            }
            return Some(out);
        }
        rest.push(
            existing
                .components()
                .next_back()?
                .as_os_str()
                .to_os_string(),
        );
        existing = existing.parent()?;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_paths_inside_the_run_must_be_under_exports() {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("r");
        std::fs::create_dir_all(run.join("traces/env=pooltool")).unwrap();
        let ok = [
            dir.path().join("out.csv"),
            run.join("exports/a.csv"),
            run.join("exports/sub/a.csv"),
            dir.path().join("r2/traces/x.parquet"),
        ];
        for p in ok {
            check_output_path(&run, &p).unwrap();
        }
        let refused = [
            run.join("traces/env=pooltool/x.parquet"),
            run.join("new_table/x.parquet"),
            run.join("manifest.json"),
            run.join("exports/../traces/x.parquet"),
        ];
        for p in refused {
            let e = check_output_path(&run, &p).unwrap_err();
            assert!(matches!(e, QueryError::OutputInRun { .. }), "{p:?}: {e}");
        }
    }

    #[cfg(unix)]
    #[test]
    fn a_link_into_the_run_is_followed() {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("r");
        std::fs::create_dir_all(run.join("traces")).unwrap();
        std::os::unix::fs::symlink(run.join("traces"), dir.path().join("link")).unwrap();
        assert!(check_output_path(&run, &dir.path().join("link/x.parquet")).is_err());
    }
}
