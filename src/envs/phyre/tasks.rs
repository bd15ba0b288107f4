//! [`TaskSet`]: the 2,500 PHYRE ball-tier tasks, loaded fast and lazily.
//!
//! The committed file `data/tasks/phyre_ball_tasks.jsonl.zst` (189 KB, zstd, embedded in the binary) is
//! decompressed once, on first use, into one ~10 MB string; a scan of its lines records each task id and
//! the byte range of its line. A task is parsed only when asked for ([`TaskSet::get`]), so listing ids or
//! simulating one task never parses the other 2,499. (zstd rather than gzip: it saves about 3 ms of
//! CPU in every process that reads a PHYRE task; `docs/performance.md`, "the task set in zstd" under
//! session 31.)

use std::ops::Range;
use std::sync::OnceLock;

use super::error::{PhyreError, Result};
use super::task::Task;

/// The committed ball-tier task file (PHYRE 0.2.2, Apache-2.0; see `data/README.md`): JSON Lines,
/// zstd-compressed with its content size in the frame header.
pub const DEFAULT_TASKS_ZST: &[u8] =
    include_bytes!("../../../data/tasks/phyre_ball_tasks.jsonl.zst");

/// SHA-256 of [`DEFAULT_TASKS_ZST`]'s text, decompressed (a unit test holds the file to it).
pub const DEFAULT_TASKS_TEXT_SHA256: &str =
    "55fa9c292e784bab69bcf14cad45d390f6e3496c3f549a4cd7cf61b47132b9a6";

/// What a `simulate` stage's fingerprint records of the task data. For this text it is
/// `9b0dafdd8ff08c9e`, the first 16 hex digits of the SHA-256 of the gzip file the same text was
/// committed in before (`phyre_ball_tasks.jsonl.gz`), so that runs made then keep their fingerprints
/// and are not simulated again for a change of container. A different text must record the first 16
/// hex digits of its own SHA-256 (a unit test checks this once the text changes).
pub const DEFAULT_TASKS_FINGERPRINT: &str = "9b0dafdd8ff08c9e";

/// The decompressed text of the committed task file is at most this large (it is 9.9 MB).
const MAX_TASK_TEXT: u64 = 1 << 30;

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
            .get_or_init(|| TaskSet::from_zstd(DEFAULT_TASKS_ZST).map_err(|e| e.to_string()))
            .as_ref()
            .map_err(|m| bad("data/tasks/phyre_ball_tasks.jsonl.zst".into(), m.clone()))
    }

    /// Decompresses and indexes zstd-compressed JSON Lines (one frame whose header gives its
    /// decompressed size, as the `zstd` command line writes it).
    pub fn from_zstd(bytes: &[u8]) -> Result<TaskSet> {
        let size = match zstd::zstd_safe::get_frame_content_size(bytes) {
            Ok(Some(n)) if n <= MAX_TASK_TEXT => n as usize,
            Ok(Some(n)) => {
                return Err(bad(
                    "zstd".into(),
                    format!("{n} bytes decompressed, more than {MAX_TASK_TEXT}"),
                ));
            }
            Ok(None) => {
                return Err(bad(
                    "zstd".into(),
                    "the frame header gives no decompressed size",
                ));
            }
            Err(_) => return Err(bad("zstd".into(), "not a zstd frame")),
        };
        let raw =
            zstd::bulk::decompress(bytes, size).map_err(|e| bad("zstd".into(), e.to_string()))?;
        let text = String::from_utf8(raw).map_err(|e| bad("zstd".into(), e.to_string()))?;
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
        assert!(TaskSet::from_zstd(b"not zstd").is_err());
        // A frame without its size in the header is refused by name.
        let mut enc = zstd::stream::Encoder::new(Vec::new(), 3).unwrap();
        enc.include_contentsize(false).unwrap();
        std::io::Write::write_all(&mut enc, b"{\"task_id\":\"a\"}\n").unwrap();
        let e = TaskSet::from_zstd(&enc.finish().unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("no decompressed size"), "{e}");
        let sized = zstd::bulk::compress(b"{\"task_id\":\"a\"}\n", 3).unwrap();
        assert_eq!(TaskSet::from_zstd(&sized).unwrap().len(), 1);
    }

    #[test]
    fn the_committed_text_is_the_one_the_fingerprint_names() {
        use sha2::{Digest, Sha256};
        let size = zstd::zstd_safe::get_frame_content_size(DEFAULT_TASKS_ZST)
            .unwrap()
            .unwrap();
        let text = zstd::bulk::decompress(DEFAULT_TASKS_ZST, size as usize).unwrap();
        let sha = crate::digest::hex(&Sha256::digest(&text));
        assert_eq!(
            sha, DEFAULT_TASKS_TEXT_SHA256,
            "the task file changed: update both constants"
        );
        // The text committed as gzip until session 31 keeps that file's fingerprint; any other
        // text fingerprints as its own hash.
        if sha != "55fa9c292e784bab69bcf14cad45d390f6e3496c3f549a4cd7cf61b47132b9a6" {
            assert_eq!(DEFAULT_TASKS_FINGERPRINT, &sha[..16]);
        }
    }
}
