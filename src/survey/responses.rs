//! The survey's two tables and the response CSV: `survey_items` (what a `survey` stage put on its page:
//! one row per item and condition), the CSV the page exports, and `survey_responses` (the checked
//! answers, one row per rating), with their Arrow schemas (`docs/schema.md`).
//!
//! The CSV has a header line and one row per rated item, in the columns of [`CSV_COLUMNS`]:
//! `survey` (the survey's id), `participant`, `seed`, `position` (1-based, in the order shown),
//! `trace_id`, `env`, `condition`, `rating` (1–7) and `answered_at` (the browser's ISO time, may be
//! empty). [`parse_csv`] reads one file; [`Design::check`] checks every row against the survey it names
//! — the id must be one of the run's surveys, the seed its seed, and the trace and condition at that
//! position exactly what [`super::assignment`] gives that participant — so a CSV of another study, a
//! hand-edited row or a mixed-up file is refused with its file, line and field.
//!
//! **Does not:** read or write run folders (the `survey` and `import-survey` stages do).

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::array::{Array, AsArray, Int64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Int64Type, Schema, SchemaRef};
use arrow::error::ArrowError;

use super::SurveyError;
use super::assign::{assignment, valid_participant};

/// The `survey_items` table's name.
pub const SURVEY_ITEMS: &str = "survey_items";
/// The `survey_responses` table's name.
pub const SURVEY_RESPONSES: &str = "survey_responses";

/// The response CSV's columns, in order (the page writes exactly these).
pub const CSV_COLUMNS: [&str; 9] = [
    "survey",
    "participant",
    "seed",
    "position",
    "trace_id",
    "env",
    "condition",
    "rating",
    "answered_at",
];

/// The lowest and highest rating (a 1–7 Likert scale).
pub(crate) const RATINGS: (i64, i64) = (1, 7);

/// One item of a survey: a trace and its summary in every condition.
#[derive(Clone, Debug, PartialEq)]
pub struct Item {
    /// The trace.
    pub trace_id: String,
    /// Its environment.
    pub env: String,
    /// Per condition (in the survey's condition order): the summary shown.
    pub summaries: Vec<SummaryRef>,
}

/// A summary as a condition of an item.
#[derive(Clone, Debug, PartialEq)]
pub struct SummaryRef {
    /// The `summaries` row's summariser.
    pub summariser: String,
    /// Its library.
    pub library: String,
    /// Its detectors.
    pub patterns: i64,
    /// The text.
    pub text: String,
}

/// One survey: its id, seed, conditions and items.
#[derive(Clone, Debug, PartialEq)]
pub struct Survey {
    /// The id (12 hex digits of the SHA-256 of its content).
    pub id: String,
    /// The seed of the per-participant shuffle.
    pub seed: u64,
    /// Condition names, in index order.
    pub conditions: Vec<String>,
    /// The items, in index order.
    pub items: Vec<Item>,
}

fn field(n: &str, t: DataType) -> Field {
    Field::new(n, t, false)
}

/// The Arrow schema of `survey_items`.
pub fn items_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        field("survey", DataType::Utf8),
        field("seed", DataType::Int64),
        field("item", DataType::Int64),
        field("trace_id", DataType::Utf8),
        field("env", DataType::Utf8),
        field("condition_index", DataType::Int64),
        field("condition", DataType::Utf8),
        field("summariser", DataType::Utf8),
        field("library", DataType::Utf8),
        field("patterns", DataType::Int64),
        field("text", DataType::Utf8),
    ]))
}

/// One `survey_items` row before it becomes columns: item index, condition index, item, summary.
type ItemRow<'a> = (usize, usize, &'a Item, &'a SummaryRef);

impl Survey {
    /// Its rows of `survey_items` (items in order, conditions in order within each).
    pub fn items_batch(&self) -> Result<RecordBatch, ArrowError> {
        let mut rows: Vec<ItemRow<'_>> = Vec::new();
        for (i, item) in self.items.iter().enumerate() {
            for (c, s) in item.summaries.iter().enumerate() {
                rows.push((i, c, item, s));
            }
        }
        let n = rows.len();
        let strs = |f: &dyn Fn(&ItemRow<'_>) -> String| {
            Arc::new(StringArray::from_iter_values(rows.iter().map(f)))
        };
        let ints = |f: &dyn Fn(&ItemRow<'_>) -> i64| {
            Arc::new(Int64Array::from_iter_values(rows.iter().map(f)))
        };
        RecordBatch::try_new(
            items_schema(),
            vec![
                Arc::new(StringArray::from_iter_values(std::iter::repeat_n(
                    self.id.as_str(),
                    n,
                ))),
                Arc::new(Int64Array::from_iter_values(std::iter::repeat_n(
                    self.seed as i64,
                    n,
                ))),
                ints(&|r| r.0 as i64),
                strs(&|r| r.2.trace_id.clone()),
                strs(&|r| r.2.env.clone()),
                ints(&|r| r.1 as i64),
                strs(&|r| self.conditions[r.1].clone()),
                strs(&|r| r.3.summariser.clone()),
                strs(&|r| r.3.library.clone()),
                ints(&|r| r.3.patterns),
                strs(&|r| r.3.text.clone()),
            ],
        )
    }
}

/// The surveys of a run, read back from `survey_items` batches (by survey id).
#[derive(Clone, Debug, Default)]
pub struct Design {
    surveys: BTreeMap<String, Survey>,
}

impl Design {
    /// From the batches of the run's `survey_items` files (`path` names the file in errors).
    pub fn add_batch(&mut self, path: &Path, b: &RecordBatch) -> Result<(), SurveyError> {
        let bad = |m: String| SurveyError::Items {
            path: path.to_path_buf(),
            message: m,
        };
        let col = |n: &str| {
            b.column_by_name(n)
                .ok_or_else(|| bad(format!("no column {n}")))
        };
        let s = |n: &str| -> Result<StringArray, SurveyError> {
            col(n)?
                .as_string_opt::<i32>()
                .cloned()
                .ok_or_else(|| bad(format!("column {n} is not Utf8")))
        };
        let i = |n: &str| -> Result<Int64Array, SurveyError> {
            col(n)?
                .as_primitive_opt::<Int64Type>()
                .cloned()
                .ok_or_else(|| bad(format!("column {n} is not Int64")))
        };
        let (survey, seed, item, trace, env) = (
            s("survey")?,
            i("seed")?,
            i("item")?,
            s("trace_id")?,
            s("env")?,
        );
        let (ci, cond, summariser, library, patterns, text) = (
            i("condition_index")?,
            s("condition")?,
            s("summariser")?,
            s("library")?,
            i("patterns")?,
            s("text")?,
        );
        for r in 0..b.num_rows() {
            if survey.is_null(r) || item.is_null(r) || ci.is_null(r) {
                return Err(bad(format!("row {r} has a null key")));
            }
            let sv = self
                .surveys
                .entry(survey.value(r).to_string())
                .or_insert_with(|| Survey {
                    id: survey.value(r).to_string(),
                    seed: seed.value(r) as u64,
                    conditions: Vec::new(),
                    items: Vec::new(),
                });
            let (k, c) = (item.value(r) as usize, ci.value(r) as usize);
            if sv.conditions.len() <= c {
                sv.conditions.resize(c + 1, String::new());
            }
            sv.conditions[c] = cond.value(r).to_string();
            if sv.items.len() <= k {
                sv.items.resize(
                    k + 1,
                    Item {
                        trace_id: String::new(),
                        env: String::new(),
                        summaries: Vec::new(),
                    },
                );
            }
            let it = &mut sv.items[k];
            it.trace_id = trace.value(r).to_string();
            it.env = env.value(r).to_string();
            let empty = SummaryRef {
                summariser: String::new(),
                library: String::new(),
                patterns: 0,
                text: String::new(),
            };
            if it.summaries.len() <= c {
                it.summaries.resize(c + 1, empty);
            }
            it.summaries[c] = SummaryRef {
                summariser: summariser.value(r).to_string(),
                library: library.value(r).to_string(),
                patterns: patterns.value(r),
                text: text.value(r).to_string(),
            };
        }
        Ok(())
    }

    /// Whether the run has no survey.
    pub fn is_empty(&self) -> bool {
        self.surveys.is_empty()
    }

    /// The survey with this id.
    pub fn get(&self, id: &str) -> Option<&Survey> {
        self.surveys.get(id)
    }

    /// Checks parsed rows against the surveys (see the module doc); also refuses the same participant
    /// rating the same position twice, across all files.
    pub fn check(&self, rows: &[Response]) -> Result<(), SurveyError> {
        let mut seen: HashMap<(&str, &str, i64), &Response> = HashMap::new();
        let ids: Vec<&str> = self.surveys.keys().map(String::as_str).collect();
        for r in rows {
            let err = |field: &'static str, message: String| SurveyError::Csv {
                file: r.file.clone(),
                line: r.line,
                field: Some(field),
                message,
            };
            let Some(s) = self.surveys.get(&r.survey) else {
                return Err(err(
                    "survey",
                    format!(
                        "{:?} is not a survey of this run (its surveys: {})",
                        r.survey,
                        if ids.is_empty() {
                            "none: run `annotrace survey` first".to_string()
                        } else {
                            ids.join(", ")
                        }
                    ),
                ));
            };
            if r.seed != s.seed {
                return Err(err(
                    "seed",
                    format!("{} is not survey {}'s seed {}", r.seed, s.id, s.seed),
                ));
            }
            let n = s.items.len();
            if r.position < 1 || r.position as usize > n {
                return Err(err(
                    "position",
                    format!(
                        "{} is outside 1..={n} (the survey has {n} items)",
                        r.position
                    ),
                ));
            }
            let shown =
                assignment(s.seed, &r.participant, n, s.conditions.len())[r.position as usize - 1];
            let item = &s.items[shown.item];
            if r.trace_id != item.trace_id {
                return Err(err(
                    "trace_id",
                    format!(
                        "participant {} saw trace {} at position {}, not {}",
                        r.participant, item.trace_id, r.position, r.trace_id
                    ),
                ));
            }
            if r.env != item.env {
                return Err(err(
                    "env",
                    format!(
                        "trace {} is a {} trace, not {}",
                        item.trace_id, item.env, r.env
                    ),
                ));
            }
            let condition = &s.conditions[shown.condition];
            if &r.condition != condition {
                return Err(err(
                    "condition",
                    format!(
                        "participant {} saw trace {} in condition {condition:?}, not {:?}",
                        r.participant, item.trace_id, r.condition
                    ),
                ));
            }
            if let Some(first) = seen.insert((&r.survey, &r.participant, r.position), r) {
                return Err(err(
                    "position",
                    format!(
                        "participant {} rated position {} twice (first at {}:{})",
                        r.participant,
                        r.position,
                        first.file.display(),
                        first.line
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// One rating, as read from a CSV.
#[derive(Clone, Debug, PartialEq)]
pub struct Response {
    /// The survey's id.
    pub survey: String,
    /// The participant.
    pub participant: String,
    /// The survey's seed, as the page recorded it.
    pub seed: u64,
    /// 1-based position in the participant's order.
    pub position: i64,
    /// The trace.
    pub trace_id: String,
    /// Its environment.
    pub env: String,
    /// The condition shown.
    pub condition: String,
    /// The rating, 1–7.
    pub rating: i64,
    /// When it was given (the browser's ISO time; may be empty).
    pub answered_at: String,
    /// The CSV file.
    pub file: PathBuf,
    /// Its line (1-based; the header is line 1).
    pub line: u64,
}

/// Reads one response CSV (its bytes, `file` for errors). The header must be [`CSV_COLUMNS`] exactly;
/// every value is checked for its type and range. A file with a header and no rows is valid (a
/// participant who answered nothing).
pub fn parse_csv(file: &Path, bytes: &[u8]) -> Result<Vec<Response>, SurveyError> {
    let csv_err = |line: u64, field: Option<&'static str>, message: String| SurveyError::Csv {
        file: file.to_path_buf(),
        line,
        field,
        message,
    };
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(false)
        .from_reader(bytes);
    let header = reader
        .headers()
        .map_err(|e| csv_err(1, None, e.to_string()))?
        .clone();
    let got: Vec<&str> = header.iter().map(str::trim).collect();
    if got != CSV_COLUMNS {
        let missing: Vec<&str> = CSV_COLUMNS
            .iter()
            .copied()
            .filter(|c| !got.contains(c))
            .collect();
        let unknown: Vec<&str> = got
            .iter()
            .copied()
            .filter(|c| !CSV_COLUMNS.contains(c))
            .collect();
        let detail = if missing.is_empty() && unknown.is_empty() {
            "the columns are in another order".to_string()
        } else {
            format!("missing {missing:?}, unknown {unknown:?}")
        };
        return Err(csv_err(
            1,
            None,
            format!("the header must be `{}` ({detail})", CSV_COLUMNS.join(",")),
        ));
    }
    let mut out = Vec::new();
    for rec in reader.records() {
        let rec = rec.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line());
            let message = match e.kind() {
                csv::ErrorKind::UnequalLengths {
                    expected_len, len, ..
                } => {
                    format!("{len} fields, expected {expected_len}")
                }
                _ => e.to_string(),
            };
            csv_err(line, None, message)
        })?;
        let line = rec.position().map_or(0, |p| p.line());
        let get = |i: usize| rec.get(i).unwrap_or("").trim();
        let int = |i: usize, what: &str| -> Result<i64, SurveyError> {
            get(i).parse::<i64>().map_err(|_| {
                csv_err(
                    line,
                    Some(CSV_COLUMNS[i]),
                    format!("{:?} is not {what}", get(i)),
                )
            })
        };
        let text = |i: usize| -> Result<String, SurveyError> {
            let v = get(i);
            if v.is_empty() {
                Err(csv_err(line, Some(CSV_COLUMNS[i]), "is empty".into()))
            } else {
                Ok(v.to_string())
            }
        };
        let participant = text(1)?;
        if !valid_participant(&participant) {
            return Err(csv_err(
                line,
                Some("participant"),
                format!("{participant:?} is not a participant id (1–64 of A–Z a–z 0–9 _ . -)"),
            ));
        }
        let seed = get(2).parse::<u64>().map_err(|_| {
            csv_err(
                line,
                Some("seed"),
                format!("{:?} is not a seed (an unsigned integer)", get(2)),
            )
        })?;
        let rating = int(7, "a rating (an integer 1–7)")?;
        if !(RATINGS.0..=RATINGS.1).contains(&rating) {
            return Err(csv_err(
                line,
                Some("rating"),
                format!("{rating} is outside the scale 1–7"),
            ));
        }
        out.push(Response {
            survey: text(0)?,
            participant,
            seed,
            position: int(3, "a position (an integer from 1)")?,
            trace_id: text(4)?,
            env: text(5)?,
            condition: text(6)?,
            rating,
            answered_at: get(8).to_string(),
            file: file.to_path_buf(),
            line,
        });
    }
    Ok(out)
}

/// The Arrow schema of `survey_responses`.
pub fn responses_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        field("survey", DataType::Utf8),
        field("participant", DataType::Utf8),
        field("seed", DataType::Int64),
        field("position", DataType::Int64),
        field("trace_id", DataType::Utf8),
        field("env", DataType::Utf8),
        field("condition", DataType::Utf8),
        field("rating", DataType::Int64),
        field("answered_at", DataType::Utf8),
        field("file", DataType::Utf8),
        field("line", DataType::Int64),
    ]))
}

/// `rows` as a `survey_responses` batch (`file` as its name only, so the table does not depend on
/// where the CSVs were kept).
pub fn responses_batch(rows: &[Response]) -> Result<RecordBatch, ArrowError> {
    let s = |f: &dyn Fn(&Response) -> String| {
        Arc::new(StringArray::from_iter_values(rows.iter().map(f)))
    };
    let i =
        |f: &dyn Fn(&Response) -> i64| Arc::new(Int64Array::from_iter_values(rows.iter().map(f)));
    RecordBatch::try_new(
        responses_schema(),
        vec![
            s(&|r| r.survey.clone()),
            s(&|r| r.participant.clone()),
            i(&|r| r.seed as i64),
            i(&|r| r.position),
            s(&|r| r.trace_id.clone()),
            s(&|r| r.env.clone()),
            s(&|r| r.condition.clone()),
            i(&|r| r.rating),
            s(&|r| r.answered_at.clone()),
            s(&|r| {
                r.file
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default()
            }),
            i(&|r| r.line as i64),
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn survey() -> Survey {
        let item = |t: &str| Item {
            trace_id: t.into(),
            env: "pooltool".into(),
            summaries: ["A", "B"]
                .iter()
                .map(|c| SummaryRef {
                    summariser: "offline".into(),
                    library: format!("lib{c}"),
                    patterns: 3,
                    text: format!("{t} in {c}"),
                })
                .collect(),
        };
        Survey {
            id: "abc123abc123".into(),
            seed: 5,
            conditions: vec!["a".into(), "b".into()],
            items: vec![item("t0"), item("t1"), item("t2")],
        }
    }

    /// The CSV the page would export for `participant`, rating every item `rating`.
    fn csv_for(s: &Survey, participant: &str, rating: i64) -> String {
        let mut out = CSV_COLUMNS.join(",") + "\n";
        for (k, sh) in assignment(s.seed, participant, s.items.len(), 2)
            .iter()
            .enumerate()
        {
            out += &format!(
                "{},{participant},{},{},{},pooltool,{},{rating},2026-11-24T05:00:00Z\n",
                s.id,
                s.seed,
                k + 1,
                s.items[sh.item].trace_id,
                s.conditions[sh.condition]
            );
        }
        out
    }

    fn design(s: &Survey) -> Design {
        let mut d = Design::default();
        d.add_batch(Path::new("items.parquet"), &s.items_batch().unwrap())
            .unwrap();
        d
    }

    #[test]
    fn a_survey_round_trips_through_its_items_table() {
        let s = survey();
        assert_eq!(design(&s).get(&s.id), Some(&s));
    }

    #[test]
    fn an_exported_csv_parses_and_checks() {
        let s = survey();
        let rows = parse_csv(Path::new("p1.csv"), csv_for(&s, "P1", 6).as_bytes()).unwrap();
        assert_eq!(rows.len(), 3);
        assert_eq!((rows[0].line, rows[2].line), (2, 4));
        design(&s).check(&rows).unwrap();
        let b = responses_batch(&rows).unwrap();
        assert_eq!(b.num_rows(), 3);
        assert_eq!(b.schema(), responses_schema());
    }

    fn parse_err(text: &str) -> String {
        parse_csv(Path::new("r.csv"), text.as_bytes())
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn bad_csv_names_file_line_and_field() {
        let s = survey();
        let good = csv_for(&s, "P1", 4);
        let e = parse_err("survey,participant\nx,y\n");
        assert!(e.starts_with("r.csv:1: the header must be"), "{e}");
        assert!(e.contains("missing [\"seed\""), "{e}");
        let e = parse_err(&good.replacen(",4,2026", ",9,2026", 1));
        assert_eq!(e, "r.csv:2: field `rating`: 9 is outside the scale 1–7");
        let e = parse_err(&good.replacen(",4,2026", ",four,2026", 1));
        assert!(
            e.starts_with("r.csv:2: field `rating`: \"four\" is not a rating"),
            "{e}"
        );
        let e = parse_err(&good.replacen(",P1,", ",P 1,", 2));
        assert!(e.starts_with("r.csv:2: field `participant`"), "{e}");
        let e = parse_err(&format!("{good}x,y\n"));
        assert!(e.starts_with("r.csv:5: 2 fields, expected 9"), "{e}");
        let e = parse_err(&good.replacen(",5,", ",-5,", 1));
        assert!(e.starts_with("r.csv:2: field `seed`"), "{e}");
    }

    #[test]
    fn rows_that_do_not_match_the_survey_are_refused() {
        let s = survey();
        let d = design(&s);
        let check = |text: String| {
            let rows = parse_csv(Path::new("r.csv"), text.as_bytes()).unwrap();
            d.check(&rows).unwrap_err().to_string()
        };
        let good = csv_for(&s, "P1", 4);
        let e = check(good.replace("abc123abc123", "ffffffffffff"));
        assert!(e.starts_with("r.csv:2: field `survey`"), "{e}");
        // Rows of P1 claimed by a participant whose order differs.
        let p1 = assignment(s.seed, "P1", 3, 2);
        let other_id = (2..100)
            .map(|k| format!("P{k}"))
            .find(|p| assignment(s.seed, p, 3, 2) != p1)
            .unwrap();
        let e = check(good.replace(",P1,", &format!(",{other_id},")));
        assert!(
            e.contains("field `trace_id`") || e.contains("field `condition`"),
            "{e}"
        );
        let other = csv_for(&s, &other_id, 4);
        // The same rows twice.
        let twice = format!("{good}{}", good.lines().nth(1).unwrap());
        let e = check(twice + "\n");
        assert!(
            e.contains("rated position 1 twice (first at r.csv:2)"),
            "{e}"
        );
        // Another participant's CSV is valid on its own.
        let rows = parse_csv(Path::new("o.csv"), other.as_bytes()).unwrap();
        d.check(&rows).unwrap();
        // Position out of range.
        let e = check(good.replacen(",1,t", ",4,t", 1));
        assert!(e.contains("field `position`: 4 is outside 1..=3"), "{e}");
    }
}
