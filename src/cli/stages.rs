//! `annotrace stages`: the stage kinds with their documentation and parameters, read off each kind's
//! typed parameter struct (`pipeline::ParamsOf`).

use annotrace::pipeline::{ParamDoc, ParamDocs, STAGE_KINDS};

use super::CliResult;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Show only this kind.
    kind: Option<String>,
}

fn print_params(docs: &[ParamDoc], indent: &str) {
    for p in docs {
        println!(
            "{indent}{:<18} {} ({}): {}",
            p.name,
            p.ty.describe(),
            p.default_text(),
            p.doc
        );
    }
}

pub fn run(args: Args) -> CliResult {
    if let Some(k) = &args.kind
        && !STAGE_KINDS.iter().any(|s| s.name == k)
    {
        return Err(super::CliError::input(anyhow::anyhow!(
            "unknown stage kind {k:?} (known: {})",
            annotrace::pipeline::kind_names().join(", ")
        )));
    }
    for kind in STAGE_KINDS
        .iter()
        .filter(|k| args.kind.as_deref().is_none_or(|n| n == k.name))
    {
        println!("{} — {}", kind.name, kind.summary);
        println!("  writes: {}", kind.writes);
        println!("  {}", kind.doc);
        match kind.params.docs() {
            ParamDocs::Flat(docs) => {
                println!("  parameters:");
                print_params(&docs, "    ");
            }
            ParamDocs::ByTag {
                tag,
                default,
                variants,
            } => {
                for (value, docs) in variants {
                    let dflt = if value == default {
                        ", the default"
                    } else {
                        ""
                    };
                    println!("  parameters with {tag} = \"{value}\"{dflt}:");
                    print_params(&docs, "    ");
                }
            }
        }
        println!();
    }
    Ok(0)
}
