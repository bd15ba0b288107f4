//! `annotrace stages`: the stage kinds with their documentation and parameters.

use annotrace::pipeline::STAGE_KINDS;

use super::CliResult;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Show only this kind.
    kind: Option<String>,
}

pub fn run(args: Args) -> CliResult {
    for kind in STAGE_KINDS
        .iter()
        .filter(|k| args.kind.as_deref().is_none_or(|n| n == k.name))
    {
        println!("{} — {}", kind.name, kind.summary);
        println!("  writes: {}", kind.writes);
        println!("  {}", kind.doc);
        println!("  parameters:");
        for p in kind.params {
            let req = if p.required {
                "required".to_string()
            } else if let Some(d) = p.default {
                format!("default {d}")
            } else {
                "optional".to_string()
            };
            println!("    {:<18} {} ({req}): {}", p.name, p.ty.describe(), p.doc);
        }
        println!();
    }
    Ok(0)
}
