//! Writing ensemble libraries as folders people can read (and `detect::Library` loads): per label an
//! `[[ensemble]]` table (γ, ε_s, ε_t, K) and one `.py` file per member with its weight, training reward
//! and provenance (run or stage, candidate id, cluster); and the single-program ablation "-SP" beside
//! it, a plain library of the best candidate per label with the same provenance as comments.
//!
//! A folder is written under a temporary name and renamed into place, so a reader never sees half of it.
//!
//! **Owns:** the folder layout of both. **Does not:** parse it (`detect::Library`).

use std::path::Path;

use crate::trace::Env;

/// One member as written.
#[derive(Clone, Debug, PartialEq)]
pub struct MemberFile {
    /// The label.
    pub label: String,
    /// The code (self-contained).
    pub code: String,
    /// Reliability weight w.
    pub weight: f64,
    /// Training reward t (ν).
    pub reward: f64,
    /// Provenance: run folder / stage.
    pub run: String,
    /// Provenance: candidate id (code hash).
    pub candidate: String,
    /// The cluster it represents.
    pub cluster: u32,
}

/// One label as written: its settings and members (an empty `members` list writes nothing).
#[derive(Clone, Debug, PartialEq)]
pub struct LabelFile {
    /// The label.
    pub label: String,
    /// γ.
    pub gamma: f64,
    /// ε_s (the environment's NEARBY_AT unit).
    pub eps_s: f64,
    /// ε_t (timesteps).
    pub eps_t: f64,
    /// Members.
    pub members: Vec<MemberFile>,
}

fn toml_str(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

fn file_stem(label: &str) -> String {
    let s: String = label
        .to_lowercase()
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    let s = s.trim_matches('_').to_string();
    if s.is_empty() { "label".into() } else { s }
}

/// Writes the labels into `dir` as library `name`: an ensemble library when `ensemble`, else a plain
/// library of every member (for "-SP", one per label).
pub fn write(
    dir: &Path,
    name: &str,
    env: Env,
    description: &str,
    labels: &[LabelFile],
    ensemble: bool,
) -> std::io::Result<()> {
    crate::store::write_dir_atomic(dir, |tmp| {
        let mut m = format!(
            "# Written by annotrace ensemble ({}). Each .py file is self-contained.\n\n\
             [library]\nname = {}\nenv = {}\ndescription = {}\n",
            if ensemble {
                "ensemble library: paper section 3.3; docs/ensemble.md"
            } else {
                "single-program ablation -SP: the best candidate per label over every run"
            },
            toml_str(name),
            toml_str(env.as_str()),
            toml_str(description)
        );
        let mut taken: Vec<String> = Vec::new();
        for l in labels.iter().filter(|l| !l.members.is_empty()) {
            if ensemble {
                m.push_str(&format!(
                    "\n[[ensemble]]\nlabel = {}\ngamma = {:?}\neps_s = {:?}\neps_t = {:?}\nk = {}\n",
                    toml_str(&l.label),
                    l.gamma,
                    l.eps_s,
                    l.eps_t,
                    l.members.len()
                ));
            }
            for mem in &l.members {
                let mut f = format!("{}_c{}.py", file_stem(&l.label), mem.cluster);
                let mut k = 2;
                while taken.contains(&f) {
                    f = format!("{}_c{}_{k}.py", file_stem(&l.label), mem.cluster);
                    k += 1;
                }
                taken.push(f.clone());
                std::fs::write(tmp.join(&f), &mem.code)?;
                m.push_str(&format!(
                    "\n[[detector]]\nlabel = {}\nfile = {}\n",
                    toml_str(&mem.label),
                    toml_str(&f)
                ));
                if ensemble {
                    m.push_str(&format!(
                        "weight = {:?}\nreward = {:?}\nrun = {}\ncandidate = {}\ncluster = {}\n",
                        mem.weight,
                        mem.reward,
                        toml_str(&mem.run),
                        toml_str(&mem.candidate),
                        mem.cluster
                    ));
                } else {
                    m.push_str(&format!(
                        "# from {} candidate {} (ν {:?})\n",
                        mem.run.replace('\n', " "),
                        mem.candidate,
                        mem.reward
                    ));
                }
            }
        }
        std::fs::write(tmp.join("library.toml"), m)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::Library;

    #[test]
    fn an_ensemble_library_round_trips_through_library_loading() {
        let tmp = tempfile::tempdir().unwrap();
        let code = |n: u32| format!("def find_pattern(trace):\n    return []  # {n}\n");
        let mem = |c: u32, w: f64| MemberFile {
            label: "cue strike".into(),
            code: code(c),
            weight: w,
            reward: 0.5 + f64::from(c),
            run: "evolve_s1".into(),
            candidate: format!("hash{c}"),
            cluster: c,
        };
        let labels = vec![LabelFile {
            label: "cue strike".into(),
            gamma: 0.4,
            eps_s: 0.005,
            eps_t: 1.0,
            members: vec![mem(0, 1.0), mem(1, 0.25)],
        }];
        let dir = tmp.path().join("lib");
        write(&dir, "ens", Env::Pooltool, "test", &labels, true).unwrap();
        let lib = Library::load(&dir).unwrap();
        assert!(lib.is_ensemble());
        assert_eq!(lib.detectors.len(), 2);
        let m = lib.detectors[1].ensemble.as_ref().unwrap();
        assert_eq!(
            (m.reward, m.cluster, m.candidate.as_str()),
            (1.5, 1, "hash1")
        );
        assert_eq!(lib.detectors[1].weight, 0.25);
        let s = &m.settings;
        assert_eq!((s.gamma, s.eps_s, s.eps_t, s.k), (0.4, 0.005, 1.0, 2));
        assert_eq!(
            s.members,
            vec![lib.detectors[0].id.clone(), lib.detectors[1].id.clone()]
        );
        // The -SP form is a plain library.
        let sp = tmp.path().join("sp");
        write(&sp, "sp", Env::Pooltool, "test", &labels, false).unwrap();
        let plain = Library::load(&sp).unwrap();
        assert!(!plain.is_ensemble());
        assert_ne!(plain.fingerprint(), lib.fingerprint());
        // A hand edit that breaks k is refused with the file named.
        let text = std::fs::read_to_string(dir.join("library.toml")).unwrap();
        std::fs::write(dir.join("library.toml"), text.replace("k = 2", "k = 3")).unwrap();
        let e = Library::load(&dir).unwrap_err().to_string();
        assert!(e.contains("library.toml") && e.contains("k = 3"), "{e}");
    }
}
