//! GitHub-flavoured Markdown tables: numbers right-aligned, pipes escaped.

use std::io::{self, Write};

use super::{Cells, RenderOptions};

fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

pub(super) fn write(out: &mut dyn Write, cells: &Cells, opts: &RenderOptions) -> io::Result<()> {
    if let Some(title) = &opts.title {
        writeln!(out, "**{}**\n", cell(title))?;
    }
    let header: Vec<String> = cells.headers.iter().map(|h| cell(h)).collect();
    writeln!(out, "| {} |", header.join(" | "))?;
    let align: Vec<&str> = cells
        .numeric
        .iter()
        .map(|n| if *n { "---:" } else { ":---" })
        .collect();
    writeln!(out, "| {} |", align.join(" | "))?;
    for row in &cells.rows {
        let line: Vec<String> = row
            .iter()
            .map(|c| cell(c.as_deref().unwrap_or("")))
            .collect();
        writeln!(out, "| {} |", line.join(" | "))?;
    }
    Ok(())
}
