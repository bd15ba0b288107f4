//! Writing a grown library as a folder `Library::load` reads (and `annotate` uses directly): a
//! `library.toml` and one self-contained `.py` file per detector (preludes already inlined).
//!
//! The folder is written next to its target under a temporary name and renamed into place, so a reader
//! never sees half a library; an earlier folder at the target is replaced.

use std::path::Path;

use crate::detect::Detector;
use crate::trace::Env;

/// A file name for `label`: lower case, `[a-z0-9_]`, `_2`, `_3`… on collision.
fn file_name(label: &str, taken: &mut Vec<String>) -> String {
    let mut base: String = label
        .to_lowercase()
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    base = base.trim_matches('_').to_string();
    if base.is_empty() {
        base = "detector".into();
    }
    let mut name = format!("{base}.py");
    let mut k = 2;
    while taken.contains(&name) {
        name = format!("{base}_{k}.py");
        k += 1;
    }
    taken.push(name.clone());
    name
}

fn toml_str(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

/// Writes `detectors` as library `name` of `env` into `dir`.
pub fn write_library(
    dir: &Path,
    name: &str,
    env: Env,
    description: &str,
    detectors: &[Detector],
) -> std::io::Result<()> {
    crate::store::write_dir_atomic(dir, |tmp| {
        let mut manifest = format!(
            "# Written by annotrace evolve: the accepted detectors of the search plus the library it grew.\n\
             # Each .py file is self-contained (shared helpers inlined).\n\n\
             [library]\nname = {}\nenv = {}\ndescription = {}\n",
            toml_str(name),
            toml_str(env.as_str()),
            toml_str(description)
        );
        let mut taken = Vec::new();
        for d in detectors {
            let f = file_name(&d.label, &mut taken);
            std::fs::write(tmp.join(&f), &d.code)?;
            manifest.push_str(&format!(
                "\n# {}\n[[detector]]\nlabel = {}\nfile = {}\n",
                d.source.replace('\n', " "),
                toml_str(&d.label),
                toml_str(&f)
            ));
            if !d.aliases.is_empty() {
                let a: Vec<String> = d.aliases.iter().map(|a| toml_str(a)).collect();
                manifest.push_str(&format!("aliases = [{}]\n", a.join(", ")));
            }
            if d.weight != 1.0 {
                manifest.push_str(&format!("weight = {:?}\n", d.weight));
            }
        }
        std::fs::write(tmp.join("library.toml"), manifest)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::Library;

    #[test]
    fn a_written_library_loads_with_the_same_code() {
        let tmp = tempfile::tempdir().unwrap();
        let mut a = Detector::new(
            Env::Pooltool,
            "cue strike",
            "def find_pattern(trace):\n    return []\n",
            "x",
        );
        a.aliases = vec!["stick \"hit\"".into()];
        a.weight = 0.5;
        let b = Detector::new(
            Env::Pooltool,
            "cue-strike",
            "def find_pattern(trace):\n    return []\n\n",
            "y",
        );
        let dir = tmp.path().join("lib");
        write_library(
            &dir,
            "grown",
            Env::Pooltool,
            "test",
            &[a.clone(), b.clone()],
        )
        .unwrap();
        write_library(
            &dir,
            "grown",
            Env::Pooltool,
            "test",
            &[a.clone(), b.clone()],
        )
        .unwrap();
        let lib = Library::load(&dir).unwrap();
        assert_eq!(lib.detectors.len(), 2);
        assert_eq!(lib.detectors[0].id, a.id);
        assert_eq!(lib.detectors[0].aliases, a.aliases);
        assert_eq!(lib.detectors[0].weight, 0.5);
        assert_eq!(lib.detectors[1].code, b.code);
    }
}
