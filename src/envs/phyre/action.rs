//! Actions: PHYRE's ball-tier action `(x, y, r) ∈ [0,1]³` ([`BallAction`]), its quantisation into the red
//! user ball ([`UserBall`]) and the validity rules ([`Placement`]); and DeepPHY's `Cell: 1–64, Radius: 1–8`
//! as an adapter ([`deepphy_action`]).
//!
//! As in PHYRE 0.2.2 (`SingleBallActionMapper`, docs/envs/phyre.md §R4): the centre is `(x·255, y·255)` px and the
//! radius `2 + r·30` px; the ball must lie inside the 256×256 scene (checked before quantisation, borders
//! allowed); then the radius is rounded (half to even, as Python's `round`) and the centre truncated to
//! whole pixels. A quantised ball that overlaps any scene body — walls included, touching allowed, with
//! PHYRE's 1e-5 px tolerance — is invalid too (`INVALID_INPUT`; the geometric test of PHYRE's C++
//! `mergeUserInputIntoScene`, not a raster test).

use super::error::{PhyreError, Result};
use super::task::{Shape, Task};

/// Smallest user-ball radius (px).
pub const MIN_RADIUS: f64 = 2.0;
/// Largest user-ball radius (px): 256 / 8.
pub const MAX_RADIUS: f64 = 32.0;
/// PHYRE's tolerance for "overlapping" (px).
const INSIDENESS_EPS: f64 = 1e-5;

/// A ball-tier action: where and how big the red ball is, each in [0, 1].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BallAction {
    /// Centre x as a fraction of the scene width.
    pub x: f64,
    /// Centre y (upwards) as a fraction of the scene height.
    pub y: f64,
    /// Radius: 0 → 2 px, 1 → 32 px.
    pub r: f64,
}

/// The red ball an action places, after quantisation (scene pixels).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UserBall {
    /// Centre x (whole px).
    pub x: f64,
    /// Centre y (whole px).
    pub y: f64,
    /// Radius (whole px).
    pub radius: f64,
}

/// Whether an action's ball can go into the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Placement {
    /// The ball fits: the episode runs with it.
    Valid(UserBall),
    /// The unquantised ball crosses the scene border (`INVALID_INPUT`).
    OutsideScene,
    /// The quantised ball overlaps scene body `body` (`INVALID_INPUT`).
    Occludes {
        /// The first overlapped body's index.
        body: usize,
    },
}

impl Placement {
    /// The ball, when valid.
    pub fn ball(&self) -> Option<UserBall> {
        match self {
            Placement::Valid(b) => Some(*b),
            _ => None,
        }
    }
}

impl BallAction {
    /// Checks each component is a finite number in [0, 1]; the error names the component.
    pub fn validate(&self) -> Result<()> {
        for (field, v) in [("x", self.x), ("y", self.y), ("r", self.r)] {
            if !v.is_finite() {
                return Err(PhyreError::InvalidAction {
                    field,
                    message: format!("{v} is not a finite number"),
                });
            }
            if !(0.0..=1.0).contains(&v) {
                return Err(PhyreError::InvalidAction {
                    field,
                    message: format!("{v} is outside [0, 1]"),
                });
            }
        }
        Ok(())
    }

    /// The unquantised centre and radius (px).
    pub fn scaled(&self, width: f64, height: f64) -> (f64, f64, f64) {
        (
            self.x * (width - 1.0),
            self.y * (height - 1.0),
            MIN_RADIUS + self.r * (MAX_RADIUS - MIN_RADIUS),
        )
    }

    /// Where the action puts the red ball in `task`, or why it cannot (after [`BallAction::validate`]).
    pub fn place(&self, task: &Task) -> Result<Placement> {
        self.validate()?;
        let (x, y, r) = self.scaled(task.width, task.height);
        if !(r <= x && x <= task.width - r && r <= y && y <= task.height - r) {
            return Ok(Placement::OutsideScene);
        }
        let ball = UserBall {
            x: x.trunc(),
            y: y.trunc(),
            radius: r.round_ties_even(),
        };
        for body in &task.bodies {
            if ball_overlaps_body(&ball, body.position, body.angle, &body.shapes) {
                return Ok(Placement::Occludes { body: body.id });
            }
        }
        Ok(Placement::Valid(ball))
    }

    /// Parses `[x, y, r]`, `{"x": …, "y": …, "r": …}` or DeepPHY's `{"cell": 1–64, "radius": 1–8}`, then
    /// validates it.
    pub fn from_json(value: &serde_json::Value) -> Result<BallAction> {
        use serde_json::Value;
        let num = |v: Option<&Value>, field: &'static str| -> Result<f64> {
            v.and_then(Value::as_f64)
                .ok_or_else(|| PhyreError::InvalidAction {
                    field,
                    message: "expected a number".into(),
                })
        };
        let action = match value {
            Value::Array(a) if a.len() == 3 => BallAction {
                x: num(a.first(), "x")?,
                y: num(a.get(1), "y")?,
                r: num(a.get(2), "r")?,
            },
            Value::Object(m) if m.contains_key("cell") || m.contains_key("radius") => {
                if let Some(k) = m.keys().find(|k| !matches!(k.as_str(), "cell" | "radius")) {
                    return Err(PhyreError::InvalidAction {
                        field: "action",
                        message: format!(
                            "unknown key {k:?} in a DeepPHY action {{\"cell\", \"radius\"}}"
                        ),
                    });
                }
                let int = |field: &'static str| -> Result<u32> {
                    let v = num(m.get(field), field)?;
                    if v.fract() != 0.0 || !(0.0..=u32::MAX as f64).contains(&v) {
                        return Err(PhyreError::InvalidAction {
                            field,
                            message: format!("{v} is not a whole number"),
                        });
                    }
                    Ok(v as u32)
                };
                deepphy_action(int("cell")?, int("radius")?)?
            }
            Value::Object(m) => {
                if let Some(k) = m.keys().find(|k| !matches!(k.as_str(), "x" | "y" | "r")) {
                    return Err(PhyreError::InvalidAction {
                        field: "action",
                        message: format!("unknown key {k:?} (expected x, y, r)"),
                    });
                }
                BallAction {
                    x: num(m.get("x"), "x")?,
                    y: num(m.get("y"), "y")?,
                    r: num(m.get("r"), "r")?,
                }
            }
            _ => {
                return Err(PhyreError::InvalidAction {
                    field: "action",
                    message: "expected [x, y, r], {\"x\", \"y\", \"r\"} or {\"cell\", \"radius\"}"
                        .into(),
                });
            }
        };
        action.validate()?;
        Ok(action)
    }

    /// Parses the JSON text of [`BallAction::from_json`].
    pub fn from_json_str(text: &str) -> Result<BallAction> {
        let v: serde_json::Value =
            serde_json::from_str(text).map_err(|e| PhyreError::InvalidAction {
                field: "action",
                message: format!("{text:?} is not JSON: {e}"),
            })?;
        BallAction::from_json(&v)
    }
}

/// DeepPHY's PHYRE action: `cell` 1–64 numbers an 8×8 grid row by row from the top-left and gives the
/// ball centre (the cell centre, y flipped to PHYRE's bottom-left origin); `radius` 1–8 maps linearly onto
/// r = 0.0625 … 1.0 (about 4 to 32 px).
pub fn deepphy_action(cell: u32, radius: u32) -> Result<BallAction> {
    if !(1..=64).contains(&cell) {
        return Err(PhyreError::InvalidAction {
            field: "cell",
            message: format!("{cell} is outside 1..=64"),
        });
    }
    if !(1..=8).contains(&radius) {
        return Err(PhyreError::InvalidAction {
            field: "radius",
            message: format!("{radius} is outside 1..=8"),
        });
    }
    let index = cell - 1;
    let (row, col) = (f64::from(index / 8), f64::from(index % 8));
    Ok(BallAction {
        x: (col + 0.5) / 8.0,
        y: (7.0 - row + 0.5) / 8.0,
        r: 0.0625 + f64::from(radius - 1) / 7.0 * (1.0 - 0.0625),
    })
}

fn cross(o: [f64; 2], a: [f64; 2], p: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (p[1] - o[1]) - (a[1] - o[1]) * (p[0] - o[0])
}

fn dist2_to_segment(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> f64 {
    let ab = [b[0] - a[0], b[1] - a[1]];
    let ap = [p[0] - a[0], p[1] - a[1]];
    let len2 = ab[0] * ab[0] + ab[1] * ab[1];
    let t = if len2 < 1e-12 {
        0.0
    } else {
        ((ab[0] * ap[0] + ab[1] * ap[1]) / len2).clamp(0.0, 1.0)
    };
    let d = [ap[0] - t * ab[0], ap[1] - t * ab[1]];
    d[0] * d[0] + d[1] * d[1]
}

/// PHYRE's overlap test between a ball and a body's shapes (touching is allowed).
fn ball_overlaps_body(ball: &UserBall, position: [f64; 2], angle: f64, shapes: &[Shape]) -> bool {
    let (s, c) = angle.sin_cos();
    let (dx, dy) = (ball.x - position[0], ball.y - position[1]);
    // The ball centre in the body's frame.
    let local = [c * dx + s * dy, -s * dx + c * dy];
    shapes.iter().any(|shape| match shape {
        Shape::Circle { radius } => dx.hypot(dy) + INSIDENESS_EPS < ball.radius + radius,
        Shape::Polygon(vs) => {
            let n = vs.len();
            let inside = (0..n).all(|i| cross(vs[(i + n - 1) % n], vs[i], local) > 0.0);
            inside
                || (0..n)
                    .map(|i| dist2_to_segment(vs[(i + n - 1) % n], vs[i], local))
                    .fold(f64::INFINITY, f64::min)
                    .sqrt()
                    + INSIDENESS_EPS
                    < ball.radius
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::phyre::tasks::TaskSet;

    #[test]
    fn quantisation_and_validity_follow_phyre() {
        let task = TaskSet::default_tasks().unwrap().get("00000:000").unwrap();
        // Centre (127.5, 229.5) → (127, 229); radius 2 + 0.5·30 = 17.
        let p = BallAction {
            x: 0.5,
            y: 0.9,
            r: 0.5,
        }
        .place(&task)
        .unwrap();
        assert_eq!(
            p,
            Placement::Valid(UserBall {
                x: 127.0,
                y: 229.0,
                radius: 17.0
            })
        );
        // Radius 2.5 rounds half to even → 2.
        let p = BallAction {
            x: 0.5,
            y: 0.9,
            r: 0.5 / 30.0,
        }
        .place(&task)
        .unwrap();
        assert_eq!(p.ball().unwrap().radius, 2.0);
        // Crossing the border is invalid, before quantisation.
        let p = BallAction {
            x: 0.0,
            y: 0.5,
            r: 0.5,
        }
        .place(&task)
        .unwrap();
        assert_eq!(p, Placement::OutsideScene);
        // On top of the green ball (89.6, 58.7).
        let p = BallAction {
            x: 89.6 / 255.0,
            y: 58.7 / 255.0,
            r: 0.1,
        }
        .place(&task)
        .unwrap();
        assert_eq!(p, Placement::Occludes { body: 4 });
        let e = BallAction {
            x: 1.5,
            y: 0.0,
            r: 0.0,
        }
        .place(&task)
        .unwrap_err();
        assert!(e.to_string().contains("x: 1.5 is outside"), "{e}");
        let e = BallAction {
            x: 0.5,
            y: f64::NAN,
            r: 0.0,
        }
        .validate()
        .unwrap_err();
        assert!(e.to_string().contains("y: NaN"), "{e}");
    }

    #[test]
    fn a_ball_on_a_bar_is_occluding_and_beside_it_is_not() {
        let task = TaskSet::default_tasks().unwrap().get("00002:007").unwrap();
        let bar = task.bodies.iter().find(|b| b.shape_type == "bar").unwrap();
        let on = BallAction {
            x: bar.position[0] / 255.0,
            y: bar.position[1] / 255.0,
            r: 0.0,
        };
        assert!(matches!(
            on.place(&task).unwrap(),
            Placement::Occludes { .. }
        ));
    }

    #[test]
    fn deepphy_cells_map_to_cell_centres() {
        let a = deepphy_action(1, 1).unwrap();
        assert_eq!((a.x, a.y, a.r), (0.0625, 0.9375, 0.0625));
        let a = deepphy_action(64, 8).unwrap();
        assert_eq!((a.x, a.y, a.r), (0.9375, 0.0625, 1.0));
        assert!(
            deepphy_action(0, 1)
                .unwrap_err()
                .to_string()
                .contains("cell")
        );
        assert!(
            deepphy_action(3, 9)
                .unwrap_err()
                .to_string()
                .contains("radius")
        );
        let j = BallAction::from_json_str(r#"{"cell": 12, "radius": 3}"#).unwrap();
        assert_eq!(j, deepphy_action(12, 3).unwrap());
        assert_eq!(
            BallAction::from_json_str("[0.1, 0.2, 0.3]").unwrap(),
            BallAction {
                x: 0.1,
                y: 0.2,
                r: 0.3
            }
        );
        assert!(BallAction::from_json_str(r#"{"x": 0.1, "y": 0.2}"#).is_err());
        assert!(
            BallAction::from_json_str("[0.1, 0.2, 2]")
                .unwrap_err()
                .to_string()
                .contains("r: 2")
        );
        assert!(BallAction::from_json_str(r#"{"cell": 1.5, "radius": 3}"#).is_err());
    }
}
