//! Replay every pooltool reference trace in a directory and report the agreement rate.
//!
//! `cargo run --example pool_agreement -- DIR [--verbose]`, where DIR holds the output of
//! `tools/pooltool/gen_traces.py` (e.g. `--n 120 --seed 12345`). A shot agrees when its ordered
//! ball–ball / cushion / pocket events (kinds and ids) are identical and every final position is within
//! 1 mm; each disagreeing shot is listed with where it diverged and whether inside a chatter burst.

use annotrace::envs::pool::reference::{RefTrace, compare};
use annotrace::envs::pool::{EventKind, SimOptions, simulate};

/// Ball–ball contacts of the reference that repeat the same pair within 50 ms
/// ("chatter", docs/envs/pool.md §P9), and whether `t` falls inside such a burst.
fn chatter(r: &RefTrace, t: Option<f64>) -> (usize, bool) {
    let mut last: std::collections::HashMap<Vec<String>, f64> = Default::default();
    let mut n = 0;
    let mut during = false;
    for e in &r.events {
        if e.kind != EventKind::BallBall {
            continue;
        }
        let mut key = e.ids.clone();
        key.sort();
        if let Some(&prev) = last.get(&key)
            && e.time - prev < 0.05
        {
            n += 1;
            if let Some(t) = t
                && (e.time - t).abs() < 0.05
            {
                during = true;
            }
        }
        last.insert(key, e.time);
    }
    (n, during)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let dir = args.get(1).cloned().unwrap_or_else(|| "traces".to_string());
    let verbose = args.iter().any(|a| a == "--verbose");
    let mut paths: Vec<_> = std::fs::read_dir(&dir)
        .expect("read dir")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("shot_"))
        })
        .collect();
    paths.sort();
    let (mut n, mut agree, mut seq_eq, mut final_ok) = (0, 0, 0, 0);
    let mut prefix_sum = 0usize;
    let mut all_eq = 0usize;
    let mut worst_dt_agree: f64 = 0.0;
    let mut worst_final_agree: f64 = 0.0;
    let mut finals: Vec<f64> = Vec::new();
    let mut ref_sum = 0usize;
    for p in &paths {
        let s = std::fs::read_to_string(p).expect("read");
        let r = match RefTrace::from_json_str(&s) {
            Ok(r) => r,
            Err(e) => {
                println!("{}: parse error {e}", p.display());
                continue;
            }
        };
        let sim = match simulate(&r.system, &r.shot, &SimOptions::default()) {
            Ok(x) => x,
            Err(e) => {
                println!("{}: simulate error {e}", p.display());
                continue;
            }
        };
        let c = compare(&r, &sim);
        n += 1;
        prefix_sum += c.common_prefix;
        ref_sum += c.n_ref;
        if c.sequence_equal {
            seq_eq += 1;
        }
        if c.max_final_dist <= 1e-3 {
            final_ok += 1;
        }
        let ok = c.agrees(1e-3);
        if ok {
            agree += 1;
            worst_dt_agree = worst_dt_agree.max(c.max_dt);
            worst_final_agree = worst_final_agree.max(c.max_final_dist);
        }
        if c.all_sequence_equal {
            all_eq += 1;
        }
        finals.push(c.max_final_dist);
        let (n_chat, in_chat) = chatter(&r, c.diverge_time);
        if verbose || !ok {
            println!(
                "{} {}: collisions ref {} sim {} prefix {} | all events ref {} sim {} | max|dt| {:.2e} | final {:.2e} m | diverge at {:?} | chatter contacts {} (divergence inside a chatter burst: {})",
                p.file_name().unwrap().to_string_lossy(),
                if ok { "OK  " } else { "DIFF" },
                c.n_ref,
                c.n_sim,
                c.common_prefix,
                c.n_all_ref,
                c.n_all_sim,
                c.max_dt,
                c.max_final_dist,
                c.diverge_time,
                n_chat,
                in_chat
            );
        }
    }
    println!(
        "shots {n}: agree {agree} ({:.1}%), identical collision/pocket sequence {seq_eq}, final positions within 1 mm {final_ok}, matched prefix {prefix_sum}/{ref_sum} collision events",
        100.0 * agree as f64 / n.max(1) as f64
    );
    finals.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let q = |f: f64| {
        finals
            .get(((finals.len() as f64 - 1.0) * f).round() as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    println!(
        "all events incl. transitions identical (kinds+ids, in order): {all_eq}/{n}; among agreeing shots: max |Δt| {worst_dt_agree:.2e} s, max final Δ {worst_final_agree:.2e} m; final Δ percentiles p50 {:.1e} p90 {:.1e} p99 {:.1e} max {:.1e} m",
        q(0.5),
        q(0.9),
        q(0.99),
        q(1.0)
    );
}
