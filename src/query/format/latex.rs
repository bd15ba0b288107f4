//! LaTeX `tabular` with booktabs rules (`\toprule`, `\midrule`, `\bottomrule`), ready for `\input`.
//!
//! Text columns are left-aligned and numeric ones right-aligned; the ten characters LaTeX treats
//! specially are escaped so labels such as `cushion_rebound` or `50%` print as written.

use std::io::{self, Write};

use super::{Cells, RenderOptions};

/// Escapes LaTeX's special characters.
pub(crate) fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '\\' => out.push_str("\\textbackslash{}"),
            '&' | '%' | '$' | '#' | '_' | '{' | '}' => {
                out.push('\\');
                out.push(c);
            }
            '~' => out.push_str("\\textasciitilde{}"),
            '^' => out.push_str("\\textasciicircum{}"),
            '\n' => out.push(' '),
            _ => out.push(c),
        }
    }
    out
}

pub(super) fn write(out: &mut dyn Write, cells: &Cells, opts: &RenderOptions) -> io::Result<()> {
    writeln!(out, "% requires \\usepackage{{booktabs}}")?;
    if let Some(title) = &opts.title {
        writeln!(out, "% {}", title.replace('\n', " "))?;
    }
    let spec: String = cells
        .numeric
        .iter()
        .map(|n| if *n { 'r' } else { 'l' })
        .collect();
    writeln!(out, "\\begin{{tabular}}{{{spec}}}")?;
    writeln!(out, "\\toprule")?;
    let header: Vec<String> = cells.headers.iter().map(|h| escape(h)).collect();
    writeln!(out, "{} \\\\", header.join(" & "))?;
    writeln!(out, "\\midrule")?;
    for row in &cells.rows {
        let line: Vec<String> = row
            .iter()
            .map(|c| escape(c.as_deref().unwrap_or("")))
            .collect();
        writeln!(out, "{} \\\\", line.join(" & "))?;
    }
    writeln!(out, "\\bottomrule")?;
    writeln!(out, "\\end{{tabular}}")
}

#[cfg(test)]
mod tests {
    #[test]
    fn escapes_every_special_character() {
        assert_eq!(
            super::escape(r"a_b&c%d$e#f{g}h~i^j\k"),
            r"a\_b\&c\%d\$e\#f\{g\}h\textasciitilde{}i\textasciicircum{}j\textbackslash{}k"
        );
    }
}
