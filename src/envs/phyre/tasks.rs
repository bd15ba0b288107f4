//! [`TaskSet`]: the 2,500 PHYRE ball-tier tasks, loaded fast and lazily.
//!
//! The committed file `data/tasks/phyre_ball_tasks.jsonl.gz` (314 KB, embedded in the binary) is
//! decompressed once, on first use, into one ~10 MB string; a scan of its lines records each task id and
//! the byte range of its line. A task is parsed only when asked for ([`TaskSet::get`]), so listing ids or
//! simulating one task never parses the other 2,499.

use std::io::Read;
use std::ops::Range;
use std::sync::OnceLock;

use super::error::{PhyreError, Result};
use super::task::Task;

/// The committed ball-tier task file (PHYRE 0.2.2, Apache-2.0; see `data/README.md`).
pub const DEFAULT_TASKS_GZ: &[u8] = include_bytes!("../../../data/tasks/phyre_ball_tasks.jsonl.gz");

/// A set of PHYRE tasks, one JSON line each, indexed by task id.
#[derive(Debug)]
pub struct TaskSet {
    text: String,
    /// (task id, line byte range, 1-based line number), sorted by task id.
    index: Vec<(String, Range<usize>, usize)>,
}

fn bad(field: String, message: impl Into<String>) -> PhyreError {
    PhyreError::InvalidTask {
        field,
        message: message.into(),
    }
}

/// The task id at the start of a line written by `export_ball_tasks.py` (`{"task_id":"00000:000",…`),
/// without parsing the rest.
fn leading_task_id(line: &str) -> Option<&str> {
    let rest = line.trim_start().strip_prefix('{')?.trim_start();
    let rest = rest.strip_prefix("\"task_id\"")?.trim_start();
    let rest = rest.strip_prefix(':')?.trim_start();
    let rest = rest.strip_prefix('"')?;
    let end = rest.find('"')?;
    Some(&rest[..end])
}

impl TaskSet {
    /// The committed 2,500 tasks, decompressed and indexed on first use and shared afterwards.
    pub fn default_tasks() -> Result<&'static TaskSet> {
        static DEFAULT: OnceLock<std::result::Result<TaskSet, String>> = OnceLock::new();
        DEFAULT
            .get_or_init(|| TaskSet::from_gzip(DEFAULT_TASKS_GZ).map_err(|e| e.to_string()))
            .as_ref()
            .map_err(|m| bad("data/tasks/phyre_ball_tasks.jsonl.gz".into(), m.clone()))
    }

    /// Decompresses and indexes gzipped JSON Lines.
    pub fn from_gzip(bytes: &[u8]) -> Result<TaskSet> {
        let mut text = String::with_capacity(bytes.len() * 32);
        flate2::read::GzDecoder::new(bytes)
            .read_to_string(&mut text)
            .map_err(|e| bad("gzip".into(), e.to_string()))?;
        TaskSet::from_jsonl(text)
    }

    /// Indexes JSON Lines text, one task per line (blank lines skipped). Ids must be unique; only the
    /// leading `task_id` of each line is read here, the rest on [`TaskSet::get`].
    pub fn from_jsonl(text: String) -> Result<TaskSet> {
        let mut index = Vec::with_capacity(2500);
        let mut start = 0;
        for (n, line) in text.split_inclusive('\n').enumerate() {
            let range = start..start + line.trim_end().len();
            start += line.len();
            if line.trim().is_empty() {
                continue;
            }
            let id = leading_task_id(line).ok_or_else(|| {
                bad(
                    format!("line {}", n + 1),
                    "expected a JSON object starting with \"task_id\"",
                )
            })?;
            index.push((id.to_string(), range, n + 1));
        }
        index.sort_by(|a, b| a.0.cmp(&b.0));
        if let Some(w) = index.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(bad("task_id".into(), format!("{:?} appears twice", w[0].0)));
        }
        Ok(TaskSet { text, index })
    }

    /// Number of tasks.
    pub fn len(&self) -> usize {
        self.index.len()
    }

    /// True when there are no tasks.
    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// Every task id, sorted.
    pub fn ids(&self) -> impl ExactSizeIterator<Item = &str> + '_ {
        self.index.iter().map(|(id, _, _)| id.as_str())
    }

    /// The task id at sorted position `i`.
    pub fn id_at(&self, i: usize) -> Option<&str> {
        self.index.get(i).map(|(id, _, _)| id.as_str())
    }

    /// Whether the set has task `id`.
    pub fn contains(&self, id: &str) -> bool {
        self.position(id).is_some()
    }

    /// The sorted position of task `id` (stable for a given task file; seeds datasets).
    pub fn position(&self, id: &str) -> Option<usize> {
        self.index
            .binary_search_by(|(k, _, _)| k.as_str().cmp(id))
            .ok()
    }

    /// The template ids (`00000` …), sorted, each once.
    pub fn templates(&self) -> Vec<&str> {
        let mut t: Vec<&str> = self
            .ids()
            .map(|id| id.split(':').next().unwrap_or(id))
            .collect();
        t.dedup();
        t
    }

    /// The task ids of template `template`, sorted.
    pub fn template_tasks(&self, template: &str) -> Vec<&str> {
        self.ids()
            .filter(|id| id.split(':').next() == Some(template))
            .collect()
    }

    /// Parses task `id`.
    pub fn get(&self, id: &str) -> Result<Task> {
        let i = self
            .position(id)
            .ok_or_else(|| PhyreError::UnknownTask { id: id.to_string() })?;
        let (_, range, line) = &self.index[i];
        Task::from_json_line(&self.text[range.clone()], &format!("line {line}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::phyre::task::{Color, Shape};

    #[test]
    fn the_committed_tasks_index_and_parse() {
        let set = TaskSet::default_tasks().unwrap();
        assert_eq!(set.len(), 2500);
        assert_eq!(set.templates().len(), 25);
        assert_eq!(set.template_tasks("00007").len(), 100);
        assert_eq!(set.id_at(0), Some("00000:000"));
        let t = set.get("00000:000").unwrap();
        assert_eq!((t.body1, t.body2), (4, 5));
        assert_eq!(t.bodies.len(), 6);
        assert!(t.bodies[..4].iter().all(|b| b.is_wall && !b.dynamic));
        assert_eq!(t.bodies[4].color, Color::Green);
        assert_eq!(t.bodies[4].shapes, vec![Shape::Circle { radius: 7.5 }]);
        assert!(t.two_ball_goal());
        // Jars are three convex polygons on one body.
        let jar_task = set.get(set.template_tasks("00005")[0]).unwrap();
        let jar = jar_task
            .bodies
            .iter()
            .find(|b| b.shape_type == "jar")
            .unwrap();
        assert_eq!(jar.shapes.len(), 3);
        assert!(!jar_task.two_ball_goal());
        let err = set.get("00099:000").unwrap_err().to_string();
        assert!(err.contains("00099:000"), "{err}");
    }

    #[test]
    fn every_task_parses() {
        let set = TaskSet::default_tasks().unwrap();
        for id in set.ids() {
            let t = set.get(id).unwrap();
            assert_eq!(t.task_id, id);
            assert_eq!(t.bodies[t.body1].color, Color::Green, "{id}");
            assert!(t.bodies[t.body1].dynamic, "{id}");
        }
    }

    #[test]
    fn bad_lines_are_named() {
        let e = TaskSet::from_jsonl("{\"task_id\":\"a\"}\nnot json\n".into()).unwrap_err();
        assert!(e.to_string().contains("line 2"), "{e}");
        let e =
            TaskSet::from_jsonl("{\"task_id\":\"a\"}\n{\"task_id\":\"a\"}\n".into()).unwrap_err();
        assert!(e.to_string().contains("twice"), "{e}");
        let set = TaskSet::from_jsonl("{\"task_id\":\"a\", \"x\": 1}\n".into()).unwrap();
        let e = set.get("a").unwrap_err().to_string();
        assert!(e.contains("line 1"), "{e}");
        assert!(TaskSet::from_gzip(b"not gzip").is_err());
    }
}
