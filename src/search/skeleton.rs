//! The skeleton program g₀ of Algorithm 1 for a label the library has no detector for: a small,
//! parametric detector (objects moving faster than a threshold, in scene units per second) with the
//! structure every detector needs, so that both an LLM and the offline `mutate` proposer have something
//! to change.

use crate::fitness::scene_scale;
use crate::trace::Env;

const SKELETON_PY: &str = include_str!("skeleton.py");

/// g₀ for `label` in `env`.
pub fn skeleton(env: Env, label: &str) -> String {
    let safe: String = label
        .chars()
        .filter(|c| !matches!(c, '"' | '\\' | '\n' | '\r' | '{' | '}'))
        .collect();
    SKELETON_PY
        .replace("{label}", &safe)
        .replace("{scale}", &format!("{:?}", scene_scale(env)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_skeleton_names_its_label_and_scale() {
        let s = skeleton(Env::Phyre, "ball \"falls\"");
        assert!(s.contains("LABEL = \"ball falls\""));
        assert!(s.contains("SCALE = 256.0"));
        assert!(s.contains("def find_pattern(trace)"));
    }
}
