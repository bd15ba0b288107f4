//! Writing the report folder: the page and its hand-written assets, the trace list, and one small
//! script per trace, built in a hidden folder next to the target and renamed into place.
//!
//! Browsers refuse `fetch` of `file://` URLs, so data travels as scripts: `data/index.js` sets
//! `window.ANNOTRACE_INDEX`, and `data/t/NNNNNN.js` calls `annotraceLoaded({...})` when the page adds
//! it as a `<script>` on demand (a run of 10,000 traces opens with only the list loaded).
//!
//! **Owns:** the folder layout and the swap: the new folder is complete on disk before it replaces
//! the old one (old renamed aside, new renamed in, old removed), so a reader sees the old report or
//! the new one, never a mixture. **Does not:** decide which traces go in (the stage does).

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde_json::{Value, json};

use super::ReportError;
use super::payload::{TraceViews, index_row, trace_payload};
use super::scene::scene;
use crate::envs::pool::PoolConfig;
use crate::trace::Trace;

/// The page and its assets, compiled into the binary.
const ASSETS: [(&str, &str); 3] = [
    ("index.html", include_str!("assets/index.html")),
    ("viewer.js", super::VIEWER_JS),
    ("viewer.css", include_str!("assets/viewer.css")),
];

/// A report being written.
#[derive(Debug)]
pub struct SiteWriter {
    target: PathBuf,
    tmp: PathBuf,
    rows: Vec<Value>,
    files: Vec<PathBuf>,
    config: PoolConfig,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ReportError + '_ {
    move |source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn write(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    let mut f = fs::File::create(path).map_err(io(path))?;
    f.write_all(bytes).map_err(io(path))?;
    f.sync_all().map_err(io(path))
}

/// The file of trace number `index`, relative to the report folder.
pub fn trace_file(index: usize) -> String {
    format!("data/t/{index:06}.js")
}

impl SiteWriter {
    /// Starts a report that will replace `target` when finished (a leftover temporary folder from a
    /// killed run is removed first).
    pub fn create(target: &Path) -> Result<SiteWriter, ReportError> {
        let parent = target.parent().unwrap_or(Path::new("."));
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .ok_or_else(|| ReportError::Target(target.to_path_buf()))?;
        fs::create_dir_all(parent).map_err(io(parent))?;
        let tmp = parent.join(format!(".{name}.tmp-{}", std::process::id()));
        if tmp.exists() {
            fs::remove_dir_all(&tmp).map_err(io(&tmp))?;
        }
        let t = tmp.join("data").join("t");
        fs::create_dir_all(&t).map_err(io(&t))?;
        Ok(SiteWriter {
            target: target.to_path_buf(),
            tmp,
            rows: Vec::new(),
            files: Vec::new(),
            config: PoolConfig::default_7ft(),
        })
    }

    /// Adds a trace: writes its script and remembers its row of the list.
    pub fn add(&mut self, trace: &Trace, views: &TraceViews) -> Result<(), ReportError> {
        let index = self.rows.len();
        let scene = scene(trace, &self.config)?;
        let payload = trace_payload(index, trace, &scene, views);
        let rel = trace_file(index);
        let path = self.tmp.join(&rel);
        let mut body = b"annotraceLoaded(".to_vec();
        serde_json::to_writer(&mut body, &payload)
            .map_err(|e| ReportError::Internal(e.to_string()))?;
        body.extend_from_slice(b");\n");
        write(&path, &body)?;
        self.files.push(PathBuf::from(rel));
        self.rows.push(index_row(index, trace, views));
        Ok(())
    }

    /// How many traces were added.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// Whether no trace was added.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Writes the list and the assets, then swaps the folder into place. Returns every file of the
    /// report (absolute paths), the page first.
    pub fn finish(
        mut self,
        title: &str,
        libraries: &[String],
    ) -> Result<Vec<PathBuf>, ReportError> {
        let index = json!({
            "title": title,
            "generator": format!("annotrace {}", env!("CARGO_PKG_VERSION")),
            "libraries": libraries,
            "columns": ["index", "trace_id", "env", "task_id", "success", "terminal_status",
                        "n_steps", "n_events", "duration", "annotations", "labels", "tokens"],
            "traces": self.rows,
        });
        let body = format!(
            "window.ANNOTRACE_INDEX = {};\n",
            serde_json::to_string(&index).map_err(|e| ReportError::Internal(e.to_string()))?
        );
        write(&self.tmp.join("data/index.js"), body.as_bytes())?;
        let mut files: Vec<PathBuf> = ASSETS.iter().map(|(n, _)| PathBuf::from(n)).collect();
        for (name, text) in ASSETS {
            write(&self.tmp.join(name), text.as_bytes())?;
        }
        files.push(PathBuf::from("data/index.js"));
        files.append(&mut self.files);
        swap_in(&self.tmp, &self.target)?;
        Ok(files.into_iter().map(|f| self.target.join(f)).collect())
    }
}

/// Replaces `target` with the finished folder `tmp` (a sibling of it): the old folder is renamed aside,
/// the new one renamed in, the parent synced, the old one removed, so a reader sees one or the other.
/// The survey page (`crate::survey`) is swapped in the same way.
pub(crate) fn swap_in(tmp: &Path, target: &Path) -> Result<(), ReportError> {
    crate::store::swap_dir(tmp, target).map_err(io(target))
}

impl Drop for SiteWriter {
    /// An unfinished report leaves nothing behind.
    fn drop(&mut self) {
        if self.tmp.exists() {
            let _ = fs::remove_dir_all(&self.tmp);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_finished_report_replaces_the_old_one_and_an_abandoned_one_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("report");
        fs::create_dir_all(&target).unwrap();
        fs::write(target.join("stale.txt"), "old").unwrap();
        let mut w = SiteWriter::create(&target).unwrap();
        let trace = crate::testutil::synthetic_trace(crate::trace::Env::Pooltool, 0, 5, 3);
        w.add(&trace, &TraceViews::default()).unwrap();
        let files = w.finish("test", &[]).unwrap();
        assert!(target.join("index.html").is_file());
        assert!(!target.join("stale.txt").exists(), "the old report is gone");
        assert!(files.iter().all(|f| f.is_file()), "{files:?}");
        assert!(files.contains(&target.join(trace_file(0))));
        let index = fs::read_to_string(target.join("data/index.js")).unwrap();
        assert!(index.starts_with("window.ANNOTRACE_INDEX = {"));
        // An abandoned writer removes its temporary folder and leaves the report as it was.
        let w = SiteWriter::create(&target).unwrap();
        drop(w);
        let names: Vec<String> = fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["report"]);
    }
}
