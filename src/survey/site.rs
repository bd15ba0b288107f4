//! Writing the survey folder: `index.html`, `survey.js`, `survey.css`, `data/survey.js` (the survey:
//! id, seed, conditions, items with their summaries, the page's texts) and `media/NNNNNN.png` (one
//! animated PNG per item), built in a hidden folder next to the target and swapped in whole
//! (`crate::report::swap_in`, as the report), so a reader sees the old survey or the new one.
//!
//! Browsers refuse `fetch` on `file://` pages, so the data is a script setting
//! `window.ANNOTRACE_SURVEY`, and the animations are ordinary `<img>` sources.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde_json::json;

use super::SurveyError;
use super::responses::{CSV_COLUMNS, RATINGS, Survey};

/// The page and its assets, compiled into the binary.
const ASSETS: [(&str, &str); 3] = [
    ("index.html", include_str!("assets/index.html")),
    ("survey.js", super::SURVEY_JS),
    ("survey.css", include_str!("assets/survey.css")),
];

/// What the page says besides the summaries.
#[derive(Clone, Debug, PartialEq)]
pub struct PageText {
    /// The page title.
    pub title: String,
    /// The question each item asks.
    pub question: String,
    /// The scale's label at 1.
    pub low: String,
    /// The scale's label at 7.
    pub high: String,
    /// Participant ids offered as links (may be empty: ids are then typed in).
    pub participants: Vec<String>,
}

/// The id of a survey's content: 12 hex digits of the SHA-256 of its seed, conditions and items.
pub fn survey_id(seed: u64, conditions: &[String], items: &[super::Item]) -> String {
    let key = json!({
        "seed": seed,
        "conditions": conditions,
        "items": items.iter().map(|i| json!({
            "trace_id": i.trace_id,
            "env": i.env,
            "summaries": i.summaries.iter().map(|s| &s.text).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
    });
    crate::digest::sha256_hex(key.to_string().as_bytes())[..12].to_string()
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> SurveyError + '_ {
    move |source| SurveyError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn write(path: &Path, bytes: &[u8]) -> Result<(), SurveyError> {
    let mut f = fs::File::create(path).map_err(io(path))?;
    f.write_all(bytes).map_err(io(path))?;
    f.sync_all().map_err(io(path))
}

/// The animation of item `index`, relative to the survey folder.
pub fn media_file(index: usize) -> String {
    format!("media/{index:06}.png")
}

/// A survey folder being written.
#[derive(Debug)]
pub struct SurveyWriter {
    target: PathBuf,
    tmp: PathBuf,
    files: Vec<PathBuf>,
}

impl SurveyWriter {
    /// Starts a survey that will replace `target` when finished (a leftover temporary folder of a
    /// killed run is removed first).
    pub fn create(target: &Path) -> Result<SurveyWriter, SurveyError> {
        let parent = target.parent().unwrap_or(Path::new("."));
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .ok_or_else(|| SurveyError::Target(target.to_path_buf()))?;
        fs::create_dir_all(parent).map_err(io(parent))?;
        let tmp = parent.join(format!(".{name}.tmp-{}", std::process::id()));
        if tmp.exists() {
            fs::remove_dir_all(&tmp).map_err(io(&tmp))?;
        }
        for d in ["data", "media"] {
            let p = tmp.join(d);
            fs::create_dir_all(&p).map_err(io(&p))?;
        }
        Ok(SurveyWriter {
            target: target.to_path_buf(),
            tmp,
            files: Vec::new(),
        })
    }

    /// Writes the animation of item `index` (APNG bytes).
    pub fn add_video(&mut self, index: usize, apng: &[u8]) -> Result<(), SurveyError> {
        let rel = media_file(index);
        write(&self.tmp.join(&rel), apng)?;
        self.files.push(PathBuf::from(rel));
        Ok(())
    }

    /// Writes the survey's data and the page, then swaps the folder into place. Returns every file
    /// (absolute paths), the page first.
    pub fn finish(mut self, survey: &Survey, page: &PageText) -> Result<Vec<PathBuf>, SurveyError> {
        let guide = |env: &str| match env {
            "pooltool" => {
                "A billiards table seen from above. The cue ball (white) is struck once; \
                           balls roll, collide, rebound from the cushions and may drop into pockets."
            }
            "phyre" => {
                "PHYRE: a 2D physics puzzle. A red ball is placed in the scene so that, once \
                        everything falls, the green object touches the blue (or purple) one."
            }
            "iphyre" => {
                "I-PHYRE: a 2D physics puzzle. Gray blocks are removed at chosen moments so \
                         that the red ball falls off the bottom of the screen."
            }
            _ => "",
        };
        let data = json!({
            "id": survey.id,
            "title": page.title,
            "question": page.question,
            "scale": {"min": RATINGS.0, "max": RATINGS.1, "low": page.low, "high": page.high},
            "seed": survey.seed.to_string(),
            "conditions": survey.conditions,
            "columns": CSV_COLUMNS,
            "participants": page.participants,
            "generator": format!("annotrace {}", env!("CARGO_PKG_VERSION")),
            "items": survey.items.iter().enumerate().map(|(k, i)| json!({
                "trace_id": i.trace_id,
                "env": i.env,
                "guide": guide(&i.env),
                "video": media_file(k),
                "summaries": i.summaries.iter().map(|s| &s.text).collect::<Vec<_>>(),
            })).collect::<Vec<_>>(),
        });
        let body = format!(
            "window.ANNOTRACE_SURVEY = {};\n",
            serde_json::to_string(&data).map_err(|e| SurveyError::Internal(e.to_string()))?
        );
        write(&self.tmp.join("data/survey.js"), body.as_bytes())?;
        let mut files: Vec<PathBuf> = ASSETS.iter().map(|(n, _)| PathBuf::from(n)).collect();
        for (name, text) in ASSETS {
            write(&self.tmp.join(name), text.as_bytes())?;
        }
        files.push(PathBuf::from("data/survey.js"));
        files.append(&mut self.files);
        crate::report::swap_in(&self.tmp, &self.target)?;
        Ok(files.into_iter().map(|f| self.target.join(f)).collect())
    }
}

impl Drop for SurveyWriter {
    /// An unfinished survey leaves nothing behind.
    fn drop(&mut self) {
        if self.tmp.exists() {
            let _ = fs::remove_dir_all(&self.tmp);
        }
    }
}
