//! Seeded 9-ball rack (docs/envs/pool.md §P4 "9-ball rack"; pooltool
//! `layouts.py`): a diamond with the 1-ball at the apex (table fraction (0.5, 0.75)), the
//! 9-ball in the middle, the other balls in random order, every ball jittered by up to
//! R·0.5e-3 per axis (pooltool: R·1e-3, which can overlap balls) around tight-packed positions; the cue ball behind the head string at (0.85, 0.23)
//! fractions. Draws come from the crate's [`SplitMix64`] (positions do not reproduce pooltool's
//! `random`-based racks bit for bit; replays read positions from traces).

use std::sync::Arc;

use super::params::{BallParams, CueSpecs};
use super::shot::Shot;
use super::state::{Ball, BallState};
use super::system::System;
use super::table::Table;
use crate::rng::{GOLDEN, SplitMix64, splitmix64};

/// Ball positions of a seeded 9-ball rack: ids "cue", "1".."9".
pub fn nine_ball_positions(table: &Table, r: f64, seed: u64) -> Vec<(String, f64, f64)> {
    let mut rng = SplitMix64::new(seed ^ 0x5EED_9BA1);
    let apex = (table.w * 0.5, table.l * 0.75);
    let gap = 2.0 * r * (1.0 + 1e-3); // spacing with pooltool's spacing_factor margin
    let dy = gap * (3f64).sqrt() / 2.0;
    // diamond rows 1-2-3-2-1
    let rows: [usize; 5] = [1, 2, 3, 2, 1];
    let mut spots = Vec::new();
    for (k, &cnt) in rows.iter().enumerate() {
        let y = apex.1 + k as f64 * dy;
        for c in 0..cnt {
            let x = apex.0 + (c as f64 - (cnt as f64 - 1.0) / 2.0) * gap;
            spots.push((x, y));
        }
    }
    // spot 0 = apex (1-ball), spot 4 = centre (9-ball)
    let mut others: Vec<&str> = vec!["2", "3", "4", "5", "6", "7", "8"];
    // Fisher–Yates
    for i in (1..others.len()).rev() {
        let j = rng.below(i + 1);
        others.swap(i, j);
    }
    let mut out = Vec::new();
    out.push(("cue".to_string(), table.w * 0.85, table.l * 0.23));
    let mut oi = 0;
    for (s, &(x, y)) in spots.iter().enumerate() {
        let id = match s {
            0 => "1".to_string(),
            4 => "9".to_string(),
            _ => {
                let id = others[oi].to_string();
                oi += 1;
                id
            }
        };
        // NOTE: pooltool jitters each axis by up to R·1e-3, which can close a 2R·1e-3 gap by
        // 2√2·R·1e-3 and overlap two balls by a micrometre; half that jitter never overlaps.
        let jx = rng.uniform(-1.0, 1.0) * r * 0.5e-3;
        let jy = rng.uniform(-1.0, 1.0) * r * 0.5e-3;
        out.push((id, x + jx, y + jy));
    }
    out
}

/// A ready-to-simulate 9-ball system on `table` with default pool parameters.
pub fn nine_ball_system(table: Arc<Table>, params: BallParams, cue: CueSpecs, seed: u64) -> System {
    let balls = nine_ball_positions(&table, params.r, seed)
        .into_iter()
        .map(|(id, x, y)| Ball {
            id,
            params,
            state: BallState::at_rest(x, y, params.r),
        })
        .collect();
    System::new(table, balls, cue)
}

/// A random shot like `tools/pooltool/gen_traces.py::random_shot` (uniform direction
/// variant): V0 ~ U(0.5, 6), (a, b) uniform on a disc of radius 0.6, θ ~ U(0, 5)° w.p. 0.8
/// else U(5, 30)°.
pub fn random_shot(rng: &mut SplitMix64) -> Shot {
    let phi = rng.uniform(0.0, 360.0);
    let rad = 0.6 * rng.next_f64().sqrt();
    let ang = rng.uniform(0.0, 2.0 * std::f64::consts::PI);
    let theta = if rng.next_f64() < 0.8 {
        rng.uniform(0.0, 5.0)
    } else {
        rng.uniform(5.0, 30.0)
    };
    let v0 = rng.uniform(0.5, 6.0);
    Shot {
        v0,
        phi,
        theta,
        a: rad * ang.cos(),
        b: rad * ang.sin(),
    }
}

/// The rack seed of scene `index` of a dataset seeded with `seed`; depends on nothing else, so a
/// dataset is the same whatever the sharding or thread count.
pub fn scene_seed(seed: u64, index: u64) -> u64 {
    splitmix64(splitmix64(seed) ^ index.wrapping_mul(GOLDEN))
}

/// The RNG of shot `shot` on scene `index` of a dataset seeded with `seed`.
pub fn shot_rng(seed: u64, index: u64, shot: u64) -> SplitMix64 {
    SplitMix64::new(splitmix64(
        scene_seed(seed, index) ^ splitmix64(shot.wrapping_add(0x5407)),
    ))
}

/// A random shot for datasets, like `tools/pooltool/gen_traces.py`: half aimed at a random object ball
/// of the scene (±4°), half in a uniform direction; V0 ~ U(0.5, 6) m/s, (a, b) uniform on a disc of
/// radius 0.6, θ ~ U(0, 5)° with probability 0.8, else U(5, 30)°.
pub fn dataset_shot(scene: &super::scene::Scene, rng: &mut SplitMix64) -> Shot {
    let mut shot = random_shot(rng);
    let objects: Vec<&super::scene::SceneBall> = scene
        .balls
        .iter()
        .filter(|b| b.id != scene.cue_ball)
        .collect();
    if rng.next_f64() < 0.5 && !objects.is_empty() {
        let target = objects[rng.below(objects.len())];
        if let Some(c) = scene.ball(&scene.cue_ball) {
            let phi = super::aim::at_pos((c.x, c.y), (target.x, target.y));
            shot.phi = (phi + rng.uniform(-4.0, 4.0)).rem_euclid(360.0);
        }
    }
    shot
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::pool::{PoolConfig, Scene};

    /// Rack sanity: 10 balls, no overlaps, 1 at the apex, 9 in the middle, cue behind the
    /// head string (y < l/4), deterministic per seed.
    #[test]
    fn rack_layout() {
        let t = Table::default_7ft();
        let r = 0.028575;
        for seed in 0..2000 {
            let c = PoolConfig::default_7ft();
            assert!(
                Scene::nine_ball(&c, seed).validate(&c).is_ok(),
                "rack {seed} overlaps"
            );
        }
        let a = nine_ball_positions(&t, r, 7);
        let b = nine_ball_positions(&t, r, 7);
        assert_eq!(a, b);
        assert_eq!(a.len(), 10);
        for i in 0..a.len() {
            for j in (i + 1)..a.len() {
                let d = ((a[i].1 - a[j].1).powi(2) + (a[i].2 - a[j].2).powi(2)).sqrt();
                assert!(d >= 2.0 * r, "{} {} overlap", a[i].0, a[j].0);
            }
        }
        let one = a.iter().find(|x| x.0 == "1").unwrap();
        assert!((one.1 - t.w / 2.0).abs() < 1e-4 && (one.2 - 0.75 * t.l).abs() < 1e-4);
        let nine = a.iter().find(|x| x.0 == "9").unwrap();
        let ys: Vec<f64> = a.iter().filter(|x| x.0 != "cue").map(|x| x.2).collect();
        let mid = (ys.iter().cloned().fold(f64::INFINITY, f64::min)
            + ys.iter().cloned().fold(f64::NEG_INFINITY, f64::max))
            / 2.0;
        assert!((nine.2 - mid).abs() < 1e-4 && (nine.1 - t.w / 2.0).abs() < 1e-4);
        let cue = a.iter().find(|x| x.0 == "cue").unwrap();
        assert!(cue.2 < t.l / 4.0);
        assert_ne!(
            nine_ball_positions(&t, r, 8)
                .iter()
                .map(|x| x.0.clone())
                .collect::<Vec<_>>(),
            vec![String::new(); 10]
        );
    }
}
