//! Aligned text for a terminal: numbers right-aligned, a row count under the table.

use std::io::{self, Write};

use super::Cells;

pub(super) fn write(out: &mut dyn Write, cells: &Cells) -> io::Result<()> {
    let width = |s: &str| s.chars().count();
    let mut widths: Vec<usize> = cells.headers.iter().map(|h| width(h)).collect();
    for row in &cells.rows {
        for (w, c) in widths.iter_mut().zip(row) {
            *w = (*w).max(c.as_deref().map_or(0, width));
        }
    }
    let rule: String = widths
        .iter()
        .map(|w| format!("+{}", "-".repeat(w + 2)))
        .collect::<String>()
        + "+";
    writeln!(out, "{rule}")?;
    let header: String = cells
        .headers
        .iter()
        .zip(&widths)
        .map(|(h, w)| format!("| {h:<w$} "))
        .collect::<String>();
    writeln!(out, "{header}|")?;
    writeln!(out, "{rule}")?;
    for row in &cells.rows {
        let mut line = String::new();
        for ((c, w), numeric) in row.iter().zip(&widths).zip(&cells.numeric) {
            let c = c.as_deref().unwrap_or("");
            // Pad by characters, not bytes, so non-ASCII labels stay aligned.
            let pad = w - width(c);
            if *numeric {
                line.push_str(&format!("| {}{c} ", " ".repeat(pad)));
            } else {
                line.push_str(&format!("| {c}{} ", " ".repeat(pad)));
            }
        }
        writeln!(out, "{line}|")?;
    }
    writeln!(out, "{rule}")?;
    let n = cells.rows.len();
    writeln!(out, "{n} row{}", if n == 1 { "" } else { "s" })
}
