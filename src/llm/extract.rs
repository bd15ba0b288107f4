//! Getting a detector program out of a model's answer.
//!
//! Models wrap code in prose, in fences (```` ```python ````, ```` ```py ````, bare ```` ``` ````), in
//! several blocks (a first attempt, then a fix; helpers in one block and `find_pattern` in another), in
//! `<think>` sections, or forget to close the last fence when they run out of tokens. [`extract_code`]
//! handles all of these and returns [`ExtractError`] for an answer with no usable code. It checks only
//! that `def find_pattern(` is there; syntax and the sandbox's rules are the validator's job.

use std::fmt;

/// No usable code in an answer.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ExtractError {
    /// The answer is empty (or only a `<think>` section).
    #[error("the answer is empty")]
    Empty,
    /// There is code, but no block defines `find_pattern`.
    #[error("no code block defines find_pattern(trace); the answer starts: {excerpt}")]
    NoFindPattern {
        /// The start of the answer.
        excerpt: String,
    },
    /// Nothing in the answer looks like Python.
    #[error("no Python code in the answer; it starts: {excerpt}")]
    NoCode {
        /// The start of the answer.
        excerpt: String,
    },
}

/// A fenced block: its info string (language) and body.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Fence<'a> {
    /// The language tag after the opening fence, lower-cased (`python`, `json`, `dsl`, or empty).
    pub lang: String,
    /// The text between the fences.
    pub body: &'a str,
}

impl fmt::Display for Fence<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "```{}\n{}```", self.lang, self.body)
    }
}

/// Removes `<think>…</think>` sections (and an unclosed trailing `<think>`), which reasoning models put
/// before their answer.
pub fn strip_think(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    loop {
        match rest.find("<think>") {
            Some(i) => {
                out.push_str(&rest[..i]);
                match rest[i..].find("</think>") {
                    Some(j) => rest = &rest[i + j + "</think>".len()..],
                    None => break,
                }
            }
            None => {
                out.push_str(rest);
                break;
            }
        }
    }
    // A model that only closes the section (the template opened it) leaves a lone `</think>`.
    match out.rfind("</think>") {
        Some(i) => out[i + "</think>".len()..].to_string(),
        None => out,
    }
}

/// Every fenced block of `text`, in order. An opening fence without a closing one runs to the end.
pub fn fences(text: &str) -> Vec<Fence<'_>> {
    let mut out = Vec::new();
    let mut pos = 0;
    while let Some(i) = text[pos..].find("```") {
        let open = pos + i;
        let after = open + 3;
        let line_end = text[after..].find('\n').map_or(text.len(), |j| after + j);
        let lang = text[after..line_end].trim().to_ascii_lowercase();
        let body_start = (line_end + 1).min(text.len());
        match text[body_start..].find("```") {
            Some(j) => {
                out.push(Fence {
                    lang,
                    body: &text[body_start..body_start + j],
                });
                pos = body_start + j + 3;
            }
            None => {
                out.push(Fence {
                    lang,
                    body: &text[body_start..],
                });
                break;
            }
        }
    }
    out
}

fn is_python_lang(lang: &str) -> bool {
    matches!(lang, "" | "python" | "python3" | "py")
}

fn defines_find_pattern(code: &str) -> bool {
    code.lines().any(|l| {
        l.trim_start().starts_with("def find_pattern(")
            || l.trim_start().starts_with("def find_pattern (")
    })
}

/// The detector program in a model's answer: the last Python block defining `find_pattern` (with the
/// Python blocks before it that define helpers it may call prepended); failing fences, the code found
/// in prose (from the first top-level `def`, `class`, assignment or comment to the last code line).
pub fn extract_code(answer: &str) -> Result<String, ExtractError> {
    let text = strip_think(answer);
    if text.trim().is_empty() {
        return Err(ExtractError::Empty);
    }
    let blocks: Vec<Fence<'_>> = fences(&text)
        .into_iter()
        .filter(|f| is_python_lang(&f.lang) && !f.body.trim().is_empty())
        .collect();
    if let Some(k) = blocks.iter().rposition(|f| defines_find_pattern(f.body)) {
        // Helper blocks before the chosen one that define functions and do not themselves define
        // find_pattern (an earlier attempt) are kept: the chosen block may call them.
        let mut code = String::new();
        for f in &blocks[..k] {
            if !defines_find_pattern(f.body) && f.body.lines().any(|l| l.starts_with("def ")) {
                code.push_str(f.body.trim_end());
                code.push_str("\n\n\n");
            }
        }
        code.push_str(blocks[k].body.trim_end());
        code.push('\n');
        return Ok(code);
    }
    if !blocks.is_empty() && blocks.iter().any(|f| looks_like_python(f.body)) {
        return Err(ExtractError::NoFindPattern {
            excerpt: excerpt(&text),
        });
    }
    // No fences: code in prose.
    if let Some(code) = code_in_prose(&text) {
        if defines_find_pattern(&code) {
            return Ok(code);
        }
        return Err(ExtractError::NoFindPattern {
            excerpt: excerpt(&text),
        });
    }
    Err(ExtractError::NoCode {
        excerpt: excerpt(&text),
    })
}

fn excerpt(text: &str) -> String {
    let t = text.trim();
    let mut out: String = t.chars().take(120).collect();
    if t.chars().nth(120).is_some() {
        out.push('…');
    }
    out
}

fn looks_like_python(body: &str) -> bool {
    body.lines().any(is_code_start)
}

/// A line at column 0 that starts Python code (not prose).
fn is_code_start(line: &str) -> bool {
    let l = line.trim_end();
    if l.is_empty() || l.starts_with(char::is_whitespace) {
        return false;
    }
    let kw = [
        "def ", "class ", "@", "if ", "for ", "while ", "try:", "with ", "return", "import ",
        "from ",
    ];
    if kw.iter().any(|k| l.starts_with(k)) {
        return true;
    }
    // `NAME = …`, `NAME: type = …`, `NAME.attr(…)`, `NAME(…)` with a Python identifier.
    let ident_end = l
        .char_indices()
        .find(|(_, c)| !(c.is_ascii_alphanumeric() || *c == '_'))
        .map_or(l.len(), |(i, _)| i);
    if ident_end == 0 || l.as_bytes()[0].is_ascii_digit() {
        return false;
    }
    let rest = l[ident_end..].trim_start();
    (rest.starts_with('=') && !rest.starts_with("=="))
        || (rest.starts_with(':') && rest.contains('='))
        || rest.starts_with('(') && l.ends_with(')')
        || rest.starts_with('[') && rest.contains("] =")
        || rest.starts_with('.') && l.ends_with(')')
}

/// A top-level line that continues code already started (a comment, an `else:`/`except`, a closing
/// bracket, or a code start).
fn continues_code(line: &str) -> bool {
    let l = line.trim_end();
    is_code_start(l)
        || l.starts_with('#')
        || l.starts_with(')')
        || l.starts_with(']')
        || l.starts_with('}')
        || ["else:", "elif ", "except", "finally:"]
            .iter()
            .any(|k| l.starts_with(k))
}

/// The span of code in unfenced text: from the first code-start line to the last line that is
/// indented or continues code, stopping at the first top-level prose line after code began.
fn code_in_prose(text: &str) -> Option<String> {
    let lines: Vec<&str> = text.lines().collect();
    let first = lines.iter().position(|l| is_code_start(l))?;
    let mut last = first;
    for (i, l) in lines.iter().enumerate().skip(first + 1) {
        if l.trim().is_empty() {
            continue;
        }
        if l.starts_with(char::is_whitespace) || continues_code(l) {
            last = i;
        } else {
            break;
        }
    }
    let code = lines[first..=last].join("\n");
    Some(format!("{}\n", code.trim_end()))
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "def find_pattern(trace):\n    return []\n";

    #[test]
    fn a_python_fence_is_taken_verbatim() {
        let a = format!("Here it is:\n```python\n{GOOD}```\nIt returns nothing.");
        assert_eq!(extract_code(&a).unwrap(), GOOD);
        let bare = format!("```\n{GOOD}```");
        assert_eq!(extract_code(&bare).unwrap(), GOOD);
    }

    #[test]
    fn the_block_defining_find_pattern_wins_and_helpers_come_along() {
        let a = format!(
            "First a helper:\n```python\ndef dist(a, b):\n    return abs(a - b)\n```\nExample output:\n```json\n[{{\"label\": \"x\"}}]\n```\nThe detector:\n```py\n{GOOD}```\n"
        );
        let code = extract_code(&a).unwrap();
        assert!(code.starts_with("def dist(a, b):"), "{code}");
        assert!(code.ends_with(GOOD), "{code}");
        // Two attempts: the later one is taken, the earlier one dropped.
        let two = "```python\ndef find_pattern(trace):\n    return None\n```\nBetter:\n```python\ndef find_pattern(trace):\n    return []\n```";
        assert_eq!(extract_code(two).unwrap(), GOOD);
    }

    #[test]
    fn prose_wrapped_code_without_fences_is_cut_out() {
        let a = "Sure! Here is a detector.\n\nTHRESHOLD = 0.5\n\ndef find_pattern(trace):\n    out = []\n\n    for ts in trace[\"timesteps\"]:\n        pass\n    return out\n\nThis works by scanning timesteps.";
        assert_eq!(
            extract_code(a).unwrap(),
            "THRESHOLD = 0.5\n\ndef find_pattern(trace):\n    out = []\n\n    for ts in trace[\"timesteps\"]:\n        pass\n    return out\n"
        );
    }

    #[test]
    fn think_sections_and_unclosed_fences_are_handled() {
        let a = format!(
            "<think>maybe ```python\ndef find_pattern(t): pass\n```</think>\n```python\n{GOOD}"
        );
        assert_eq!(extract_code(&a).unwrap(), GOOD);
        assert_eq!(strip_think("a</think>b"), "b");
    }

    #[test]
    fn garbage_is_a_typed_error() {
        assert_eq!(extract_code("  "), Err(ExtractError::Empty));
        assert!(matches!(
            extract_code("I cannot help with that, sorry."),
            Err(ExtractError::NoCode { .. })
        ));
        assert!(matches!(
            extract_code("```python\ndef helper(x):\n    return x\n```"),
            Err(ExtractError::NoFindPattern { .. })
        ));
        assert!(matches!(
            extract_code("<think>only thinking</think>"),
            Err(ExtractError::Empty)
        ));
        // Binary-ish noise never panics.
        for s in [
            "```",
            "``````",
            "```python",
            "\u{0}\u{1}```py\n",
            "def",
            "x =",
        ] {
            let _ = extract_code(s);
        }
    }

    #[test]
    fn fences_report_their_language() {
        let f = fences("a\n```JSON\n[1]\n```\n```dsl\nAND()\n```");
        assert_eq!(f.len(), 2);
        assert_eq!((f[0].lang.as_str(), f[0].body), ("json", "[1]\n"));
        assert_eq!((f[1].lang.as_str(), f[1].body), ("dsl", "AND()\n"));
    }
}
