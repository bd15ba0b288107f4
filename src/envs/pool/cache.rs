//! Event-time caches (reference/pooltool-physics.md §2.6 step 5; pooltool
//! `evolution/event_based/cache.py`): absolute collision times per pair (ball–ball,
//! ball–linear cushion, ball–jaw, ball–pocket) and each ball's next transition. After an
//! event only the entries of the balls in that event are invalidated — the other
//! trajectories did not change, so their absolute times stay valid.
//!
//! pooltool keeps each cache in a Python dict: an invalidated key is deleted and
//! re-inserted at the end when recomputed, and `min` returns the first of several equal
//! times in dict order. Exact ties are common (overlapping balls after a `make_kiss` all
//! get t = now), so every entry carries the sequence number of its (re)computation and
//! ties are broken by it, reproducing pooltool's order.

use super::events::EventKind;

/// Marker for "not computed / invalidated".
const STALE: f64 = f64::NAN;

/// Cached absolute collision times; NaN = stale.
#[derive(Debug, Clone)]
pub struct CollisionCache {
    n: usize,
    n_lin: usize,
    n_circ: usize,
    n_pock: usize,
    /// row-major n×n, only i < j used
    pub ball_ball: Vec<f64>,
    pub linear: Vec<f64>,
    pub circular: Vec<f64>,
    pub pocket: Vec<f64>,
    /// insertion sequence numbers (pooltool dict order) of the entries above
    pub ball_ball_seq: Vec<u64>,
    pub linear_seq: Vec<u64>,
    pub circular_seq: Vec<u64>,
    pub pocket_seq: Vec<u64>,
    /// per ball: are its cushion/jaw/pocket rows up to date? (rows are invalidated whole)
    pub row_fresh: Vec<bool>,
    /// per ball: earliest (time, seq, index) of its jaw / linear / pocket row
    pub row_min_circular: Vec<(f64, u64, usize)>,
    pub row_min_linear: Vec<(f64, u64, usize)>,
    pub row_min_pocket: Vec<(f64, u64, usize)>,
    counter: u64,
}

impl CollisionCache {
    pub fn new(n: usize, n_lin: usize, n_circ: usize, n_pock: usize) -> Self {
        CollisionCache {
            n,
            n_lin,
            n_circ,
            n_pock,
            ball_ball: vec![STALE; n * n],
            linear: vec![STALE; n * n_lin],
            circular: vec![STALE; n * n_circ],
            pocket: vec![STALE; n * n_pock],
            ball_ball_seq: vec![0; n * n],
            linear_seq: vec![0; n * n_lin],
            circular_seq: vec![0; n * n_circ],
            pocket_seq: vec![0; n * n_pock],
            row_fresh: vec![false; n],
            row_min_circular: vec![(f64::INFINITY, u64::MAX, 0); n],
            row_min_linear: vec![(f64::INFINITY, u64::MAX, 0); n],
            row_min_pocket: vec![(f64::INFINITY, u64::MAX, 0); n],
            counter: 0,
        }
    }

    #[inline]
    pub fn bb_index(&self, i: usize, j: usize) -> usize {
        i * self.n + j
    }

    /// Delete every cached time involving ball `i`.
    pub fn invalidate_ball(&mut self, i: usize) {
        let n = self.n;
        for j in 0..n {
            self.ball_ball[i * n + j] = STALE;
            self.ball_ball[j * n + i] = STALE;
        }
        self.linear[i * self.n_lin..(i + 1) * self.n_lin].fill(STALE);
        self.circular[i * self.n_circ..(i + 1) * self.n_circ].fill(STALE);
        self.pocket[i * self.n_pock..(i + 1) * self.n_pock].fill(STALE);
        self.row_fresh[i] = false;
    }

    /// Next insertion sequence number.
    #[inline]
    pub fn next_seq(&mut self) -> u64 {
        self.counter += 1;
        self.counter
    }

    pub fn is_stale(t: f64) -> bool {
        t.is_nan()
    }
}

/// Each ball's next transition (absolute time, kind); `None` = never.
#[derive(Debug, Clone)]
pub struct TransitionCache {
    pub next: Vec<Option<(f64, EventKind)>>,
}

impl TransitionCache {
    /// Earliest transition: (ball, time, kind); first ball wins exact ties.
    pub fn earliest(&self) -> Option<(usize, f64, EventKind)> {
        let mut best: Option<(usize, f64, EventKind)> = None;
        for (i, t) in self.next.iter().enumerate() {
            if let Some((time, kind)) = t
                && best.is_none_or(|b| *time < b.1)
            {
                best = Some((i, *time, *kind));
            }
        }
        best
    }

    /// Absolute time of ball `i`'s next transition (∞ if none).
    pub fn time_of(&self, i: usize) -> f64 {
        self.next[i].map_or(f64::INFINITY, |x| x.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn invalidation_only_touches_the_ball() {
        let mut c = CollisionCache::new(3, 2, 1, 1);
        c.ball_ball.fill(1.0);
        c.linear.fill(1.0);
        c.circular.fill(1.0);
        c.pocket.fill(1.0);
        c.invalidate_ball(1);
        assert!(c.ball_ball[c.bb_index(0, 1)].is_nan());
        assert!(c.ball_ball[c.bb_index(1, 2)].is_nan());
        assert_eq!(c.ball_ball[c.bb_index(0, 2)], 1.0);
        assert!(
            c.linear[2].is_nan()
                && c.linear[3].is_nan()
                && c.linear[0] == 1.0
                && c.linear[5] == 1.0
        );
        assert!(c.circular[1].is_nan() && c.circular[0] == 1.0);
    }
}
