//! Actions: clicks `(x, y, t)` that remove the eliminable block under the point, the discrete adapter
//! "remove eliminable block k at time t", and click validation (docs/envs/iphyre.md §R3).
//!
//! I-PHYRE's quirks are kept, each where it happens: a click whose time is exactly 0 is dropped
//! ([`ClickSchedule::due`]), at most one click is applied per physics step, and the time compared
//! against the click times is a float counter that accumulates `dt` (`step.rs`). A click hits a block
//! only inside its segment core ([`hits_block`]): the rounded end caps do not count.

use serde::{Deserialize, Serialize};

use super::error::{IphyreError, Result};
use super::game::{Game, GameObject};

/// Screen width and height (px).
pub const SCREEN: f64 = 600.0;

/// One click: at time `t` (s), remove the eliminable block under `(x, y)` (px, y down), if any.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Click {
    /// Screen x (px), in [0, 600].
    pub x: f64,
    /// Screen y (px, down), in [0, 600].
    pub y: f64,
    /// Time (s), in [0, max_time]; a click at exactly 0 is dropped, as I-PHYRE does.
    pub t: f64,
}

/// Checks every click: finite, on the 600×600 screen, and not after the episode's end `max_time`.
pub fn validate_clicks(clicks: &[Click], max_time: f64) -> Result<()> {
    for (index, c) in clicks.iter().enumerate() {
        let bad = |message: String| IphyreError::InvalidClick { index, message };
        if !(c.x.is_finite() && c.y.is_finite() && c.t.is_finite()) {
            return Err(bad(format!("({}, {}, {}) is not finite", c.x, c.y, c.t)));
        }
        if !(0.0..=SCREEN).contains(&c.x) || !(0.0..=SCREEN).contains(&c.y) {
            return Err(bad(format!("({}, {}) is off the 600×600 screen", c.x, c.y)));
        }
        if c.t < 0.0 {
            return Err(bad(format!("t = {} is negative", c.t)));
        }
        if c.t > max_time {
            return Err(bad(format!(
                "t = {} is after the episode's end ({max_time} s)",
                c.t
            )));
        }
    }
    Ok(())
}

/// The discrete action "remove eliminable block `block` (0-based, in object order) at time `t`": a click
/// on that block's centre, as I-PHYRE's `get_action_space()` lists them.
pub fn click_block(game: &Game, block: usize, t: f64) -> Result<Click> {
    let count = game.eliminable().count();
    let o = game
        .eliminable()
        .nth(block)
        .ok_or(IphyreError::InvalidBlock { block, count })?;
    let [x, y] = o.centre();
    Ok(Click { x, y, t })
}

/// Whether `p` lies in the segment core of block `o` whose body centre is now at `centre`:
/// `|projection on the segment| < length/2` and `|perpendicular distance| < radius`. As in I-PHYRE's
/// `eliminate`, the end caps are excluded and the unrotated segment direction is used.
pub fn hits_block(o: &GameObject, centre: [f64; 2], radius: f64, p: [f64; 2]) -> bool {
    let length = o.length();
    if length <= 0.0 {
        return false;
    }
    let (ux, uy) = ((o.p2[0] - o.p1[0]) / length, (o.p2[1] - o.p1[1]) / length);
    let (dx, dy) = (p[0] - centre[0], p[1] - centre[1]);
    let along = dx * ux + dy * uy;
    let across = -dx * uy + dy * ux;
    along.abs() < length / 2.0 && across.abs() < radius
}

/// Clicks sorted by time with a pointer to the next one, as I-PHYRE's `simulate` walks them.
#[derive(Debug, Clone, PartialEq)]
pub struct ClickSchedule {
    clicks: Vec<Click>,
    next: usize,
}

/// What the schedule yields at one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Due {
    /// No click is due yet (or none is left).
    Nothing,
    /// A click at exactly t = 0: I-PHYRE drops it without applying it.
    DroppedAtZero(Click),
    /// A click to apply before this step.
    Apply(Click),
}

impl ClickSchedule {
    /// The clicks, stably sorted by time.
    pub fn new(clicks: &[Click]) -> ClickSchedule {
        let mut clicks = clicks.to_vec();
        clicks.sort_by(|a, b| a.t.total_cmp(&b.t));
        ClickSchedule { clicks, next: 0 }
    }

    /// The sorted clicks.
    pub fn clicks(&self) -> &[Click] {
        &self.clicks
    }

    /// At most one click per step: the next click if the time counter has reached its time.
    pub fn due(&mut self, time_count: f64) -> Due {
        let Some(&click) = self.clicks.get(self.next) else {
            return Due::Nothing;
        };
        if time_count < click.t {
            return Due::Nothing;
        }
        self.next += 1;
        // NOTE: I-PHYRE's `simulate` skips actions whose time is exactly 0 (docs/envs/iphyre.md §R3).
        if click.t == 0.0 {
            Due::DroppedAtZero(click)
        } else {
            Due::Apply(click)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::iphyre::game::Games;

    #[test]
    fn validation_names_the_bad_click() {
        let ok = Click {
            x: 10.0,
            y: 10.0,
            t: 1.0,
        };
        validate_clicks(&[ok], 15.0).unwrap();
        for (bad, what) in [
            (Click { x: f64::NAN, ..ok }, "not finite"),
            (Click { x: 601.0, ..ok }, "off the"),
            (Click { y: -1.0, ..ok }, "off the"),
            (Click { t: -0.5, ..ok }, "negative"),
            (Click { t: 15.5, ..ok }, "after the episode"),
        ] {
            let err = validate_clicks(&[ok, bad], 15.0).unwrap_err().to_string();
            assert!(err.contains("actions[1]") && err.contains(what), "{err}");
        }
    }

    #[test]
    fn discrete_action_clicks_the_block_centre() {
        let games = Games::default_games().unwrap();
        let g = games.get("support").unwrap();
        assert_eq!(
            click_block(g, 1, 2.0).unwrap(),
            Click {
                x: 250.0,
                y: 500.0,
                t: 2.0
            }
        );
        let err = click_block(g, 2, 2.0).unwrap_err().to_string();
        assert!(
            err.contains("block 2") && err.contains("2 eliminable"),
            "{err}"
        );
    }

    #[test]
    fn clicks_hit_the_segment_core_only() {
        let games = Games::default_games().unwrap();
        let block = &games.get("support").unwrap().objects[0]; // (200,400)–(300,400)
        let c = block.centre();
        assert!(hits_block(block, c, 10.0, [250.0, 400.0]));
        assert!(hits_block(block, c, 10.0, [201.0, 409.0]));
        assert!(!hits_block(block, c, 10.0, [250.0, 411.0]));
        assert!(
            !hits_block(block, c, 10.0, [195.0, 400.0]),
            "end caps do not count"
        );
    }

    #[test]
    fn schedule_drops_t0_and_yields_one_click_per_call() {
        let a = Click {
            x: 1.0,
            y: 1.0,
            t: 0.5,
        };
        let b = Click {
            x: 2.0,
            y: 2.0,
            t: 0.5,
        };
        let z = Click {
            x: 3.0,
            y: 3.0,
            t: 0.0,
        };
        let mut s = ClickSchedule::new(&[a, b, z]);
        assert_eq!(s.due(0.0), Due::DroppedAtZero(z));
        assert_eq!(s.due(0.1), Due::Nothing);
        assert_eq!(s.due(0.5), Due::Apply(a));
        assert_eq!(s.due(0.5), Due::Apply(b));
        assert_eq!(s.due(9.0), Due::Nothing);
    }
}
