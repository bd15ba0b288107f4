//! The answer formats of the benchmark (DeepPHY's, `docs/benchmark.md` "Action formats") and their
//! strict, typed parsing.
//!
//! | format | answer text | action |
//! |---|---|---|
//! | [`Format::PhyreGrid`] | `Cell: 27, Radius: 4` | cell 1–64 of the numbered 8×8 grid (row-major from the top left), radius level 1–8 |
//! | [`Format::IphyreRemovals`] | `[{"time": 0.5, "index": 2}]` | eliminable block `index` (0-based) removed at `time` s (0–15, 10 fps) |
//! | [`Format::PoolDeepphy`] | `Speed: High, Strikespot: Top Left Spin` | V0 ∈ {2, 5, 8}, (a, b) from the strike spot, φ aimed at the lowest-numbered ball |
//! | [`Format::PoolFree`] | `V0: 3.5, phi: 87.0, theta: 0, a: 0.1, b: -0.2` | every shot parameter given |
//!
//! A parse either gives an [`Answer`] or an [`Invalid`] with its reason; the environment's own range and
//! placement checks happen when the answer is applied (`bench::task`). Nothing here panics on any text.

use serde::{Deserialize, Serialize};

use crate::envs::pool::Shot;
use crate::envs::pool::deepphy::DeepphyAction;

/// An answer format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Format {
    /// PHYRE: `Cell: N, Radius: R`.
    PhyreGrid,
    /// I-PHYRE: a JSON list of `{"time", "index"}` removals.
    IphyreRemovals,
    /// PoolTool as DeepPHY: speed level and strike spot, automatic aim.
    PoolDeepphy,
    /// PoolTool with every shot parameter free: V0, φ, θ, a, b.
    PoolFree,
}

impl Format {
    /// The format's name (`phyre-grid`, `iphyre-removals`, `pool-deepphy`, `pool-free`).
    pub fn as_str(self) -> &'static str {
        match self {
            Format::PhyreGrid => "phyre-grid",
            Format::IphyreRemovals => "iphyre-removals",
            Format::PoolDeepphy => "pool-deepphy",
            Format::PoolFree => "pool-free",
        }
    }
}

/// Largest removal time (s) of the I-PHYRE format: the episode's length.
pub const IPHYRE_MAX_TIME: f64 = 15.0;
/// I-PHYRE's frame rate in the benchmark (DeepPHY's).
pub const IPHYRE_FPS: f64 = 10.0;

/// One I-PHYRE removal.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Removal {
    /// When (s).
    pub time: f64,
    /// Which eliminable block (0-based, in the numbering drawn on the image).
    pub index: i64,
}

/// A parsed answer.
#[derive(Clone, Debug, PartialEq)]
pub enum Answer {
    /// PHYRE grid cell and radius level.
    Phyre {
        /// Cell 1–64.
        cell: u32,
        /// Radius level 1–8.
        radius: u32,
    },
    /// I-PHYRE removals, in the order given.
    Iphyre(Vec<Removal>),
    /// A DeepPHY billiards action.
    PoolDeepphy(DeepphyAction),
    /// A free billiards shot.
    PoolFree(Shot),
}

/// Why an answer is not a valid action. Every kind uses up an attempt.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Invalid {
    /// The text does not contain an action in the format.
    #[error("unparsable: {0}")]
    Unparsable(String),
    /// A value is outside its range.
    #[error("out of range: {0}")]
    OutOfRange(String),
    /// The PHYRE ball overlaps a body of the scene.
    #[error("occluding: {0}")]
    Occluding(String),
}

impl Invalid {
    /// The kind as a word (`unparsable`, `out_of_range`, `occluding`).
    pub fn kind(&self) -> &'static str {
        match self {
            Invalid::Unparsable(_) => "unparsable",
            Invalid::OutOfRange(_) => "out_of_range",
            Invalid::Occluding(_) => "occluding",
        }
    }
}

impl Answer {
    /// The answer in its format's canonical text (what the table's `action` column holds).
    pub fn text(&self) -> String {
        match self {
            Answer::Phyre { cell, radius } => format!("Cell: {cell}, Radius: {radius}"),
            Answer::Iphyre(rs) => {
                let items: Vec<String> = rs
                    .iter()
                    .map(|r| format!("{{\"time\": {}, \"index\": {}}}", fmt_num(r.time), r.index))
                    .collect();
                format!("[{}]", items.join(", "))
            }
            Answer::PoolDeepphy(a) => a.text(),
            Answer::PoolFree(s) => format!(
                "V0: {}, phi: {}, theta: {}, a: {}, b: {}",
                fmt_num(s.v0),
                fmt_num(s.phi),
                fmt_num(s.theta),
                fmt_num(s.a),
                fmt_num(s.b)
            ),
        }
    }
}

/// A number with at most 3 decimals and no trailing zeros.
pub(crate) fn fmt_num(v: f64) -> String {
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.to_string() }
}

/// The values written after `key:` in `text` (case-insensitive; `key` must start a word), each the
/// run of characters up to the next comma, semicolon, newline or closing bracket.
fn values_after(text: &str, key: &str) -> Vec<String> {
    let lower = text.to_ascii_lowercase();
    let key = key.to_ascii_lowercase();
    let bytes = lower.as_bytes();
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(pos) = lower[from..].find(&key) {
        let start = from + pos;
        from = start + key.len();
        let word_start =
            start == 0 || !(bytes[start - 1].is_ascii_alphanumeric() || bytes[start - 1] == b'_');
        if !word_start {
            continue;
        }
        let rest = lower[from..].trim_start_matches([' ', '\t', '*', '"']);
        let Some(rest) = rest.strip_prefix(':') else {
            continue;
        };
        let value: String = rest
            .trim_start_matches([' ', '\t', '*', '"'])
            .chars()
            .take_while(|c| !matches!(c, ',' | ';' | '\n' | ')' | ']' | '}'))
            .collect();
        // A value is one token: `2. So …` is `2`.
        let token = value.split_whitespace().next().unwrap_or("");
        out.push(token.trim_end_matches(['.', '*', '"']).to_string());
    }
    out
}

/// The one value of `key` in `text`: absent or given twice with different values is unparsable.
fn one_value(text: &str, key: &str, example: &str) -> Result<String, Invalid> {
    let mut vals = values_after(text, key);
    vals.dedup();
    match vals.as_slice() {
        [v] => Ok(v.clone()),
        [] => Err(Invalid::Unparsable(format!(
            "no `{key}:` in the answer (expected {example})"
        ))),
        _ => Err(Invalid::Unparsable(format!(
            "`{key}:` is given {} times with different values ({}); give one action",
            vals.len(),
            vals.join(" / ")
        ))),
    }
}

fn integer(key: &str, v: &str) -> Result<i64, Invalid> {
    v.parse::<i64>()
        .map_err(|_| Invalid::Unparsable(format!("{key} {v:?} is not a whole number")))
}

fn number(key: &str, v: &str) -> Result<f64, Invalid> {
    match v.parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(x),
        _ => Err(Invalid::Unparsable(format!("{key} {v:?} is not a number"))),
    }
}

/// Parses `text` in `format`. `blocks` is the number of eliminable I-PHYRE blocks (ignored otherwise).
pub fn parse(format: Format, text: &str, blocks: usize) -> Result<Answer, Invalid> {
    let text = crate::llm::strip_think(text);
    match format {
        Format::PhyreGrid => parse_phyre(&text),
        Format::IphyreRemovals => parse_iphyre(&text, blocks),
        Format::PoolDeepphy => DeepphyAction::parse(&text)
            .map(Answer::PoolDeepphy)
            .map_err(|e| Invalid::Unparsable(e.to_string())),
        Format::PoolFree => parse_pool_free(&text),
    }
}

fn parse_phyre(text: &str) -> Result<Answer, Invalid> {
    const EX: &str = "`Cell: 27, Radius: 4`";
    let cell = integer("Cell", &one_value(text, "cell", EX)?)?;
    let radius = integer("Radius", &one_value(text, "radius", EX)?)?;
    if !(1..=64).contains(&cell) {
        return Err(Invalid::OutOfRange(format!("cell {cell} is outside 1..64")));
    }
    if !(1..=8).contains(&radius) {
        return Err(Invalid::OutOfRange(format!(
            "radius {radius} is outside 1..8"
        )));
    }
    Ok(Answer::Phyre {
        cell: cell as u32,
        radius: radius as u32,
    })
}

fn parse_iphyre(text: &str, blocks: usize) -> Result<Answer, Invalid> {
    let (Some(a), Some(b)) = (text.find('['), text.rfind(']')) else {
        return Err(Invalid::Unparsable(
            "no JSON list in the answer (expected e.g. [{\"time\": 0.5, \"index\": 2}])".into(),
        ));
    };
    if b < a {
        return Err(Invalid::Unparsable("no JSON list in the answer".into()));
    }
    let removals: Vec<Removal> = serde_json::from_str(&text[a..=b]).map_err(|e| {
        Invalid::Unparsable(format!(
            "the list is not [{{\"time\": seconds, \"index\": block}}, …]: {e}"
        ))
    })?;
    for (i, r) in removals.iter().enumerate() {
        if !r.time.is_finite() || !(0.0..=IPHYRE_MAX_TIME).contains(&r.time) {
            return Err(Invalid::OutOfRange(format!(
                "removal {i}: time {} is outside 0..{IPHYRE_MAX_TIME} s",
                r.time
            )));
        }
        if r.index < 0 || r.index as usize >= blocks {
            return Err(Invalid::OutOfRange(format!(
                "removal {i}: block index {} is outside 0..{} (the scene has {blocks} removable blocks)",
                r.index,
                blocks.saturating_sub(1)
            )));
        }
    }
    Ok(Answer::Iphyre(removals))
}

fn parse_pool_free(text: &str) -> Result<Answer, Invalid> {
    const EX: &str = "`V0: 3.5, phi: 87.0, theta: 0, a: 0.1, b: -0.2`";
    let get = |k: &str| -> Result<f64, Invalid> { number(k, &one_value(text, k, EX)?) };
    let shot = Shot {
        v0: get("V0")?,
        phi: get("phi")?,
        theta: get("theta")?,
        a: get("a")?,
        b: get("b")?,
    };
    let checks = [
        ("V0", shot.v0, 0.0, 10.0, "m/s"),
        ("phi", shot.phi, 0.0, 360.0, "deg"),
        ("theta", shot.theta, 0.0, 90.0, "deg"),
        ("a", shot.a, -1.0, 1.0, "ball radii"),
        ("b", shot.b, -1.0, 1.0, "ball radii"),
    ];
    for (k, v, lo, hi, unit) in checks {
        let ok = if k == "V0" {
            v > lo && v <= hi
        } else {
            v >= lo && v < hi || (k != "phi" && v == hi)
        };
        if !ok {
            return Err(Invalid::OutOfRange(format!(
                "{k} = {v} is outside [{lo}, {hi}] {unit}"
            )));
        }
    }
    Ok(Answer::PoolFree(shot))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phyre_answers_parse_strictly() {
        assert_eq!(
            parse(
                Format::PhyreGrid,
                "I will drop it there.\nCell: 27, Radius: 4",
                0
            ),
            Ok(Answer::Phyre {
                cell: 27,
                radius: 4
            })
        );
        assert_eq!(
            parse(Format::PhyreGrid, "**Cell:** 3, **Radius:** 8.", 0),
            Ok(Answer::Phyre { cell: 3, radius: 8 })
        );
        let e = parse(Format::PhyreGrid, "Cell: 70, Radius: 2", 0).unwrap_err();
        assert_eq!(e.kind(), "out_of_range");
        let e = parse(Format::PhyreGrid, "Cell: 2, Radius: 9", 0).unwrap_err();
        assert_eq!(e.kind(), "out_of_range");
        for bad in [
            "Cell: two, Radius: 2",
            "Radius: 2",
            "Cell: 1, Radius: 2\nCell: 5, Radius: 2",
            "Cell: 2.5, Radius: 1",
            "",
        ] {
            assert_eq!(
                parse(Format::PhyreGrid, bad, 0).unwrap_err().kind(),
                "unparsable",
                "{bad}"
            );
        }
        // The same action repeated is one action; a <think> block is ignored.
        assert!(
            parse(
                Format::PhyreGrid,
                "<think>Cell: 9, Radius: 1?</think>Cell: 5, Radius: 2. So Cell: 5, Radius: 2",
                0
            )
            .is_ok()
        );
        assert_eq!(
            Answer::Phyre { cell: 5, radius: 2 }.text(),
            "Cell: 5, Radius: 2"
        );
    }

    #[test]
    fn iphyre_answers_parse_strictly() {
        let a = parse(
            Format::IphyreRemovals,
            "Remove: [{\"time\": 0.5, \"index\": 1}, {\"time\": 2, \"index\": 0}]",
            2,
        )
        .unwrap();
        assert_eq!(
            a.text(),
            "[{\"time\": 0.5, \"index\": 1}, {\"time\": 2, \"index\": 0}]"
        );
        assert_eq!(
            parse(Format::IphyreRemovals, "[]", 2),
            Ok(Answer::Iphyre(vec![]))
        );
        assert_eq!(
            parse(Format::IphyreRemovals, "[{\"time\": 1, \"index\": 2}]", 2)
                .unwrap_err()
                .kind(),
            "out_of_range"
        );
        assert_eq!(
            parse(Format::IphyreRemovals, "[{\"time\": 16, \"index\": 0}]", 2)
                .unwrap_err()
                .kind(),
            "out_of_range"
        );
        assert_eq!(
            parse(Format::IphyreRemovals, "[{\"t\": 1, \"index\": 0}]", 2)
                .unwrap_err()
                .kind(),
            "unparsable"
        );
        assert_eq!(
            parse(Format::IphyreRemovals, "remove block 1", 2)
                .unwrap_err()
                .kind(),
            "unparsable"
        );
        assert_eq!(
            parse(Format::IphyreRemovals, "] oops [", 2)
                .unwrap_err()
                .kind(),
            "unparsable"
        );
    }

    #[test]
    fn pool_answers_parse_strictly() {
        let a = parse(
            Format::PoolFree,
            "V0: 3.5, phi: 87, theta: 0, a: 0.1, b: -0.2",
            0,
        )
        .unwrap();
        assert_eq!(a.text(), "V0: 3.5, phi: 87, theta: 0, a: 0.1, b: -0.2");
        assert_eq!(
            parse(
                Format::PoolFree,
                "V0: 30, phi: 87, theta: 0, a: 0.1, b: -0.2",
                0
            )
            .unwrap_err()
            .kind(),
            "out_of_range"
        );
        assert_eq!(
            parse(Format::PoolFree, "V0: 3, phi: 87, theta: 0, b: -0.2", 0)
                .unwrap_err()
                .kind(),
            "unparsable"
        );
        assert!(
            parse(
                Format::PoolDeepphy,
                "Speed: Low, Strikespot: Middle Spin",
                0
            )
            .is_ok()
        );
        assert_eq!(
            parse(Format::PoolDeepphy, "Speed: warp", 0)
                .unwrap_err()
                .kind(),
            "unparsable"
        );
    }
}
