//! Event-time caches (docs/envs/pool.md §P6 step 5; pooltool
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

/// One of a ball's rows of cushion-like obstacles, each cached whole.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Row {
    /// Ball–jaw (circular cushion) times.
    Circular,
    /// Ball–linear-cushion times.
    Linear,
    /// Ball–pocket times.
    Pocket,
}

/// The earliest entry of a row: (time, sequence number, obstacle index); ties go to the lower
/// sequence number.
pub type RowMin = (f64, u64, usize);

/// No entry: later than every time.
const NO_MIN: RowMin = (f64::INFINITY, u64::MAX, 0);

/// Cached absolute collision times; NaN = stale.
#[derive(Debug, Clone)]
pub struct CollisionCache {
    n: usize,
    n_lin: usize,
    n_circ: usize,
    n_pock: usize,
    /// row-major n×n, only i < j used
    pub ball_ball: Vec<f64>,
    linear: Vec<f64>,
    circular: Vec<f64>,
    pocket: Vec<f64>,
    /// insertion sequence numbers (pooltool dict order) of the entries above
    pub ball_ball_seq: Vec<u64>,
    linear_seq: Vec<u64>,
    circular_seq: Vec<u64>,
    pocket_seq: Vec<u64>,
    /// per ball: are its cushion/jaw/pocket rows up to date? (rows are invalidated whole)
    pub row_fresh: Vec<bool>,
    /// per ball: earliest (time, seq, index) of its jaw / linear / pocket row
    row_min_circular: Vec<RowMin>,
    row_min_linear: Vec<RowMin>,
    row_min_pocket: Vec<RowMin>,
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
            row_min_circular: vec![NO_MIN; n],
            row_min_linear: vec![NO_MIN; n],
            row_min_pocket: vec![NO_MIN; n],
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

    /// Stores ball `i`'s recomputed row `row`: obstacle `c` collides at `t0 + dts[c]`, each entry
    /// takes the next sequence number in obstacle order, and the row's earliest entry is kept
    /// for [`CollisionCache::row_min`]. Marks nothing fresh (a ball has three rows).
    pub fn store_row(&mut self, row: Row, i: usize, t0: f64, dts: impl IntoIterator<Item = f64>) {
        let mut m = NO_MIN;
        for (c, dt) in dts.into_iter().enumerate() {
            let (t, q) = (t0 + dt, self.next_seq());
            let (times, seqs, width) = match row {
                Row::Circular => (&mut self.circular, &mut self.circular_seq, self.n_circ),
                Row::Linear => (&mut self.linear, &mut self.linear_seq, self.n_lin),
                Row::Pocket => (&mut self.pocket, &mut self.pocket_seq, self.n_pock),
            };
            times[i * width + c] = t;
            seqs[i * width + c] = q;
            if t < m.0 || (t == m.0 && q < m.1) {
                m = (t, q, c);
            }
        }
        match row {
            Row::Circular => self.row_min_circular[i] = m,
            Row::Linear => self.row_min_linear[i] = m,
            Row::Pocket => self.row_min_pocket[i] = m,
        }
    }

    /// Every ball's earliest entry of row `row`, by ball.
    pub fn row_min(&self, row: Row) -> &[RowMin] {
        match row {
            Row::Circular => &self.row_min_circular,
            Row::Linear => &self.row_min_linear,
            Row::Pocket => &self.row_min_pocket,
        }
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
