//! [`Task`]: one PHYRE ball-tier task scene as exported from PHYRE 0.2.2 (`export_ball_tasks.py`): bodies with
//! their shapes, colours and roles, and the goal (body1 touching body2).
//!
//! Units are scene pixels, origin bottom-left, y up, angles in radians (CCW). Polygon vertices are in the
//! body's local frame; circles sit on the body origin. Bodies 0–3 are the four static black walls just
//! outside the 256×256 frame.

use serde::Deserialize;

use super::error::{PhyreError, Result};

/// PHYRE's colour codes (`shared.thrift` `Color`), which also encode each body's role.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Color {
    /// 0: background.
    White,
    /// 1: the user's ball.
    Red,
    /// 2: the goal subject (always dynamic).
    Green,
    /// 3: a dynamic goal target.
    Blue,
    /// 4: a static goal target.
    Purple,
    /// 5: other dynamic bodies.
    Gray,
    /// 6: other static bodies, the walls included.
    Black,
    /// 7: auxiliary.
    LightRed,
}

impl Color {
    /// Every colour in code order.
    pub const ALL: [Color; 8] = [
        Color::White,
        Color::Red,
        Color::Green,
        Color::Blue,
        Color::Purple,
        Color::Gray,
        Color::Black,
        Color::LightRed,
    ];

    /// PHYRE's name, lower case (`green`, `light_red`).
    pub fn name(self) -> &'static str {
        match self {
            Color::White => "white",
            Color::Red => "red",
            Color::Green => "green",
            Color::Blue => "blue",
            Color::Purple => "purple",
            Color::Gray => "gray",
            Color::Black => "black",
            Color::LightRed => "light_red",
        }
    }

    /// The colour of a name as PHYRE spells it.
    pub fn from_name(name: &str) -> Option<Color> {
        Color::ALL.into_iter().find(|c| c.name() == name)
    }

    /// The RGB colour PHYRE draws it with (`phyre.vis.WAD_COLORS`).
    pub fn rgb(self) -> [u8; 3] {
        match self {
            Color::White => [255, 255, 255],
            Color::Red => [0xf3, 0x4f, 0x46],
            Color::Green => [0x6b, 0xce, 0xbb],
            Color::Blue => [0x18, 0x77, 0xf2],
            Color::Purple => [0x4b, 0x4a, 0xa4],
            Color::Gray => [0xb9, 0xca, 0xd2],
            Color::Black => [0, 0, 0],
            Color::LightRed => [0xfc, 0xdf, 0xe3],
        }
    }
}

/// One convex piece of a body, in the body's frame (px).
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// A circle centred on the body origin.
    Circle {
        /// Radius (px).
        radius: f64,
    },
    /// A convex polygon, counter-clockwise.
    Polygon(Vec<[f64; 2]>),
}

/// One body of a task scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Body {
    /// Index in the scene (the trace's `object_index`; the goal refers to it).
    pub id: usize,
    /// One of the four bounding walls (bodies 0–3).
    pub is_wall: bool,
    /// PHYRE's shape type: `ball`, `bar`, `jar`, `standingsticks`, or `undefined` (walls).
    pub shape_type: String,
    /// Colour and role.
    pub color: Color,
    /// Moves under gravity.
    pub dynamic: bool,
    /// Body origin (px). For jars this is not the centre of mass.
    pub position: [f64; 2],
    /// Rotation (rad, CCW).
    pub angle: f64,
    /// PHYRE's size feature (px).
    pub diameter: f64,
    /// The convex pieces (a jar has three).
    pub shapes: Vec<Shape>,
}

impl Body {
    /// The body's pieces with vertices in scene coordinates (circles: centre and radius).
    pub fn world_shapes(&self, position: [f64; 2], angle: f64) -> Vec<Shape> {
        let (s, c) = angle.sin_cos();
        self.shapes
            .iter()
            .map(|sh| match sh {
                Shape::Circle { radius } => Shape::Circle { radius: *radius },
                Shape::Polygon(vs) => Shape::Polygon(
                    vs.iter()
                        .map(|v| {
                            [
                                position[0] + c * v[0] - s * v[1],
                                position[1] + s * v[0] + c * v[1],
                            ]
                        })
                        .collect(),
                ),
            })
            .collect()
    }
}

/// A PHYRE task: the scene and its goal.
#[derive(Debug, Clone, PartialEq)]
pub struct Task {
    /// `TTTTT:VVV` (template:variant).
    pub task_id: String,
    /// `TTTTT`.
    pub template_id: String,
    /// The goal in words (`Make sure the green ball is touching the blue ball.`).
    pub description: String,
    /// Scene width (px): 256.
    pub width: f64,
    /// Scene height (px): 256.
    pub height: f64,
    /// The goal subject (green) body index.
    pub body1: usize,
    /// The goal target (blue or purple) body index.
    pub body2: usize,
    /// The goal relationships (`TOUCHING` for every ball-tier task).
    pub relationships: Vec<String>,
    /// Every body, walls first, indexed by `id`.
    pub bodies: Vec<Body>,
}

impl Task {
    /// True when both goal bodies are single circles: PHYRE then judges "touching" by centre distance
    /// (< r1 + r2 + 0.1 px) instead of by contacts.
    pub fn two_ball_goal(&self) -> bool {
        let circle = |b: &Body| matches!(b.shapes.as_slice(), [Shape::Circle { .. }]);
        self.relationships == ["TOUCHING"]
            && circle(&self.bodies[self.body1])
            && circle(&self.bodies[self.body2])
    }
}

#[derive(Deserialize)]
struct RawTask {
    task_id: String,
    template_id: String,
    #[serde(default)]
    description: String,
    scene: RawScene,
    goal: RawGoal,
    bodies: Vec<RawBody>,
}

#[derive(Deserialize)]
struct RawScene {
    width: f64,
    height: f64,
}

#[derive(Deserialize)]
struct RawGoal {
    body1: usize,
    body2: usize,
    relationships: Vec<String>,
}

#[derive(Deserialize)]
struct RawBody {
    id: usize,
    #[serde(default)]
    is_wall: bool,
    shape_type: String,
    color: String,
    dynamic: bool,
    position: [f64; 2],
    #[serde(default)]
    angle: Option<f64>,
    #[serde(default)]
    diameter: Option<f64>,
    shapes: Vec<RawShape>,
}

#[derive(Deserialize)]
struct RawShape {
    #[serde(default)]
    circle: Option<RawCircle>,
    #[serde(default)]
    polygon: Option<Vec<[f64; 2]>>,
}

#[derive(Deserialize)]
struct RawCircle {
    radius: f64,
}

fn bad(field: String, message: impl Into<String>) -> PhyreError {
    PhyreError::InvalidTask {
        field,
        message: message.into(),
    }
}

impl Task {
    /// Parses and checks one line of the task file (`where_` names the line in errors).
    pub fn from_json_line(line: &str, where_: &str) -> Result<Task> {
        let raw: RawTask =
            serde_json::from_str(line).map_err(|e| bad(where_.to_string(), e.to_string()))?;
        let at = |f: &str| format!("{where_} ({}) {f}", raw.task_id);
        if !(raw.scene.width > 0.0 && raw.scene.height > 0.0) {
            return Err(bad(at("scene"), "width and height must be positive"));
        }
        let mut bodies = Vec::with_capacity(raw.bodies.len());
        for (i, b) in raw.bodies.into_iter().enumerate() {
            let f = |s: &str| at(&format!("bodies[{i}].{s}"));
            if b.id != i {
                return Err(bad(f("id"), format!("expected {i}, found {}", b.id)));
            }
            let color = Color::from_name(&b.color)
                .ok_or_else(|| bad(f("color"), format!("unknown colour {:?}", b.color)))?;
            let angle = b.angle.unwrap_or(0.0);
            if !(b.position.iter().all(|v| v.is_finite()) && angle.is_finite()) {
                return Err(bad(f("position"), "not finite"));
            }
            let mut shapes = Vec::with_capacity(b.shapes.len());
            for (k, s) in b.shapes.into_iter().enumerate() {
                let fs = || f(&format!("shapes[{k}]"));
                shapes.push(match (s.circle, s.polygon) {
                    (Some(c), None) if c.radius.is_finite() && c.radius > 0.0 => {
                        Shape::Circle { radius: c.radius }
                    }
                    (None, Some(p))
                        if p.len() >= 3 && p.iter().flatten().all(|v| v.is_finite()) =>
                    {
                        Shape::Polygon(p)
                    }
                    _ => {
                        return Err(bad(
                            fs(),
                            "expected a circle with a positive radius or a polygon of 3+ finite vertices",
                        ));
                    }
                });
            }
            if shapes.is_empty() {
                return Err(bad(f("shapes"), "a body needs at least one shape"));
            }
            bodies.push(Body {
                id: i,
                is_wall: b.is_wall,
                shape_type: b.shape_type,
                color,
                dynamic: b.dynamic,
                position: b.position,
                angle,
                diameter: b.diameter.unwrap_or(0.0),
                shapes,
            });
        }
        for (name, id) in [
            ("goal.body1", raw.goal.body1),
            ("goal.body2", raw.goal.body2),
        ] {
            if id >= bodies.len() {
                return Err(bad(
                    at(name),
                    format!("body {id} does not exist ({} bodies)", bodies.len()),
                ));
            }
        }
        Ok(Task {
            template_id: raw.template_id,
            description: raw.description,
            width: raw.scene.width,
            height: raw.scene.height,
            body1: raw.goal.body1,
            body2: raw.goal.body2,
            relationships: raw.goal.relationships,
            bodies,
            task_id: raw.task_id,
        })
    }
}
