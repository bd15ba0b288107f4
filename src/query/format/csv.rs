//! RFC 4180 CSV: a header row, fields quoted when they hold a comma, quote or line break.

use std::io::{self, Write};

use super::Cells;

fn field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

pub(super) fn write(out: &mut dyn Write, cells: &Cells) -> io::Result<()> {
    let header: Vec<String> = cells.headers.iter().map(|h| field(h)).collect();
    writeln!(out, "{}", header.join(","))?;
    for row in &cells.rows {
        let line: Vec<String> = row
            .iter()
            .map(|c| c.as_deref().map(field).unwrap_or_default())
            .collect();
        writeln!(out, "{}", line.join(","))?;
    }
    Ok(())
}
