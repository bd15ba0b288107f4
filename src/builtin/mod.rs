//! The built-in data compiled into the binary, so every command works from any folder and from a copied
//! or `cargo install`ed binary: the detector libraries (`data/libraries/<env>/`: `library.toml` and
//! its `.py` files), the goal files (`data/goals/<env>.toml`), the billiards table, the I-PHYRE games
//! and the PHYRE tasks.
//!
//! Each file is found by its path in the repository ([`get`], [`text`]), e.g.
//! `data/libraries/pooltool/library.toml`. The table, games and tasks are embedded once, by the
//! environment that reads them (`envs::pool::DEFAULT_TABLE_JSON`, `envs::iphyre::DEFAULT_GAMES_JSON`,
//! `envs::phyre::DEFAULT_TASKS_ZST`); this index refers to those constants instead of embedding them
//! again.
//! The prompt templates are embedded by `llm::prompt`, and the detector worker and mutation scripts by
//! their modules; they are not listed here.
//!
//! The index is written by hand (plain `include_bytes!`, no build script or dependency); a test walks
//! `data/` and fails when a file a library or goal set needs is missing from it or differs from the
//! disk. Which file a user's path means — a folder on disk first, then a built-in — is decided in
//! [`location`], not here.

pub mod location;

pub use location::Location;

use crate::trace::Env;

/// One embedded file: its path in the repository and its bytes.
#[derive(Clone, Copy, Debug)]
pub struct File {
    /// The path in the repository, `/`-separated, e.g. `data/goals/pooltool.toml`.
    pub path: &'static str,
    /// The file's bytes, as committed.
    pub bytes: &'static [u8],
}

/// `File { path, bytes: include_bytes!(<repository>/path) }` for each path.
macro_rules! embed {
    ($($path:literal),* $(,)?) => {
        &[$(File { path: $path, bytes: include_bytes!(concat!("../../", $path)) }),*]
    };
}

/// The libraries and goal files: the files this index embeds itself.
const OWN: &[File] = embed![
    "data/goals/iphyre.toml",
    "data/goals/phyre.toml",
    "data/goals/pooltool.toml",
    "data/libraries/iphyre/_common.py",
    "data/libraries/iphyre/_contacts.py",
    "data/libraries/iphyre/_motion.py",
    "data/libraries/iphyre/_springs.py",
    "data/libraries/iphyre/airborne_motion.py",
    "data/libraries/iphyre/bounce.py",
    "data/libraries/iphyre/chain_movement.py",
    "data/libraries/iphyre/collision.py",
    "data/libraries/iphyre/falling_object.py",
    "data/libraries/iphyre/lever_launch.py",
    "data/libraries/iphyre/library.toml",
    "data/libraries/iphyre/object_removal.py",
    "data/libraries/iphyre/sliding_contact.py",
    "data/libraries/iphyre/spring_pull_towards.py",
    "data/libraries/iphyre/spring_resist_movement.py",
    "data/libraries/iphyre/support_contact.py",
    "data/libraries/iphyre/swinging_object.py",
    "data/libraries/phyre/_common.py",
    "data/libraries/phyre/_contacts.py",
    "data/libraries/phyre/airborne_motion.py",
    "data/libraries/phyre/bounce.py",
    "data/libraries/phyre/falling_object.py",
    "data/libraries/phyre/grid_cell_transition.py",
    "data/libraries/phyre/library.toml",
    "data/libraries/phyre/lose_support.py",
    "data/libraries/phyre/moving_object_hits_stationary_object.py",
    "data/libraries/phyre/near_collision.py",
    "data/libraries/phyre/rolling_object.py",
    "data/libraries/phyre/sliding_contact.py",
    "data/libraries/phyre/support_relationship.py",
    "data/libraries/phyre/tip_over.py",
    "data/libraries/phyre/wedged.py",
    "data/libraries/pooltool/_common.py",
    "data/libraries/pooltool/_contacts.py",
    "data/libraries/pooltool/_episodes.py",
    "data/libraries/pooltool/_merge.py",
    "data/libraries/pooltool/ball_collision.py",
    "data/libraries/pooltool/ball_curves_around_ball.py",
    "data/libraries/pooltool/ball_pocketed.py",
    "data/libraries/pooltool/ball_slowing.py",
    "data/libraries/pooltool/cue_strike.py",
    "data/libraries/pooltool/cushion_rebound.py",
    "data/libraries/pooltool/gentle_touch.py",
    "data/libraries/pooltool/high_angle_collision.py",
    "data/libraries/pooltool/library.toml",
    "data/libraries/pooltool/rolling_ball.py",
    "data/libraries/pooltool/sliding_ball.py",
    "data/libraries/pooltool/spin_shot.py",
    "data/libraries/pooltool/spinning_ball.py",
];

/// The files the environments embed, under their repository paths.
const ENVS: &[File] = &[
    File {
        path: "data/games/iphyre_games.json",
        bytes: crate::envs::iphyre::DEFAULT_GAMES_JSON.as_bytes(),
    },
    File {
        path: "data/tables/pooltool_7ft.json",
        bytes: crate::envs::pool::DEFAULT_TABLE_JSON.as_bytes(),
    },
    File {
        path: "data/tasks/phyre_ball_tasks.jsonl.zst",
        bytes: crate::envs::phyre::DEFAULT_TASKS_ZST,
    },
];

/// Every built-in file.
pub fn files() -> impl Iterator<Item = &'static File> {
    OWN.iter().chain(ENVS)
}

/// `path` with `\` read as `/`, `.` segments and empty segments dropped (`./data//goals/` →
/// `data/goals`); `None` when it is absolute or climbs with `..`.
pub(crate) fn normalise(path: &str) -> Option<String> {
    let path = path.replace('\\', "/");
    if path.starts_with('/') {
        return None;
    }
    let mut parts = Vec::new();
    for part in path.split('/') {
        match part {
            "" | "." => {}
            ".." => return None,
            p => parts.push(p),
        }
    }
    Some(parts.join("/"))
}

/// The bytes of the built-in file at repository path `path`, if there is one.
pub fn get(path: &str) -> Option<&'static [u8]> {
    let path = normalise(path)?;
    files().find(|f| f.path == path).map(|f| f.bytes)
}

/// The built-in file at `path` as text, if there is one and it is UTF-8.
pub fn text(path: &str) -> Option<&'static str> {
    get(path).and_then(|b| std::str::from_utf8(b).ok())
}

/// Whether `path` is a built-in library folder (it has a `library.toml`).
pub fn is_library(path: &str) -> bool {
    normalise(path).is_some_and(|p| get(&format!("{p}/library.toml")).is_some())
}

/// The repository path of `env`'s built-in library: `data/libraries/<env>`.
pub fn library_path(env: Env) -> String {
    format!("data/libraries/{}", env.as_str())
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    /// The files under `data/<sub>` whose name ends with one of `exts`, as repository paths.
    fn on_disk(sub: &str, exts: &[&str]) -> Vec<String> {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut out = Vec::new();
        let mut stack = vec![root.join("data").join(sub)];
        while let Some(dir) = stack.pop() {
            for e in std::fs::read_dir(&dir).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                } else if exts.iter().any(|x| p.to_string_lossy().ends_with(x)) {
                    let rel = p.strip_prefix(root).unwrap().to_string_lossy();
                    out.push(rel.replace('\\', "/"));
                }
            }
        }
        out.sort();
        out
    }

    #[test]
    fn every_library_goal_table_game_and_task_file_is_embedded_as_committed() {
        let mut want = on_disk("libraries", &[".py", "library.toml"]);
        want.extend(on_disk("goals", &[".toml"]));
        want.extend(on_disk("tables", &[".json"]));
        want.extend(on_disk("games", &[".json"]));
        want.extend(on_disk("tasks", &[".zst"]));
        want.sort();
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        for path in &want {
            let bytes = get(path).unwrap_or_else(|| panic!("{path} is not in builtin::OWN"));
            assert_eq!(bytes, std::fs::read(root.join(path)).unwrap(), "{path}");
        }
        let mut have: Vec<&str> = files().map(|f| f.path).collect();
        have.sort();
        assert_eq!(have, want, "the index lists a file that is not on disk");
    }

    #[test]
    fn paths_are_found_however_they_are_spelled_but_never_outside_the_repository() {
        assert!(get("data/goals/pooltool.toml").is_some());
        assert!(get("./data//goals/pooltool.toml").is_some());
        assert!(get("data\\goals\\pooltool.toml").is_some());
        assert!(get("/data/goals/pooltool.toml").is_none());
        assert!(get("data/../data/goals/pooltool.toml").is_none());
        assert!(get("data/goals/nope.toml").is_none());
        for env in Env::ALL {
            assert!(is_library(&library_path(env)), "{env}");
            assert!(is_library(&format!("./{}/", library_path(env))), "{env}");
        }
        assert!(!is_library("data/libraries"));
        assert!(!is_library("data/goals"));
    }
}
