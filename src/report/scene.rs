//! A trace as a vector scene for the viewer's canvas: the static drawing (the billiards table), one
//! rigid shape per object in its body frame, and each object's pose at every timestep, in the
//! environment's own coordinates with the view transform to a 512-pixel square.
//!
//! **Owns:** the viewer's geometry and palette, which follow each environment's `render.rs` (pool: the
//! table layout, cloth, rails, pockets, ball colours and the tray of pocketed balls; PHYRE:
//! `WAD_COLORS` and the task's body outlines; I-PHYRE: gray, black and blue blocks, red balls, purple
//! joints). The tests render the same trace with `render` and compare pixel colours, so the two cannot
//! drift apart. **Does not:** draw (the page's JavaScript does), read run folders, or simulate.

use std::collections::BTreeMap;

use serde::Serialize;
use serde_json::{Value, json};

use crate::envs::iphyre::Games;
use crate::envs::phyre::TaskSet;
use crate::envs::phyre::{Color as PhyreColor, Shape, Task};
use crate::envs::pool::PoolConfig;
use crate::trace::{Body, Env, Trace};

/// The side of the viewer's square canvas, in CSS pixels.
pub const CANVAS: f64 = 512.0;

/// Pool: cushion and rail widths (m), as `envs::pool::render` draws them.
const CUSHION: f64 = 0.0508;
const RAIL: f64 = 0.045;
const OUTER: f64 = CUSHION + RAIL;

/// I-PHYRE's palette (`envs::iphyre::render`).
pub(crate) const IPHYRE_GRAY: [u8; 3] = [164, 164, 164];
pub(crate) const IPHYRE_BLACK: [u8; 3] = [0, 0, 0];
pub(crate) const IPHYRE_BLUE: [u8; 3] = [52, 152, 219];
pub(crate) const IPHYRE_RED: [u8; 3] = [220, 30, 30];
pub(crate) const IPHYRE_PURPLE: [u8; 3] = [150, 60, 190];
/// I-PHYRE's screen (px).
const IPHYRE_SCREEN: f64 = 600.0;

/// Pool cloth, cushion, rail, pocket and background colours (`envs::pool::render`).
pub(crate) const POOL_CLOTH: [u8; 3] = [36, 130, 74];
const POOL_CUSHION: [u8; 3] = [22, 96, 52];
const POOL_RAIL: [u8; 3] = [110, 64, 32];
const POOL_POCKET: [u8; 3] = [8, 8, 8];
const POOL_BACKGROUND: [u8; 3] = [236, 236, 232];
const POOL_NOSE: [u8; 3] = [150, 210, 170];
const POOL_DIAMOND: [u8; 3] = [235, 225, 200];
const POOL_WHITE: [u8; 3] = [250, 250, 245];

/// `#rrggbb`.
pub fn hex(c: [u8; 3]) -> String {
    format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2])
}

/// `v` rounded to 4 decimals (the payload's precision: 0.1 mm on the table, 0.0001 px in PHYRE).
pub(crate) fn r4(v: f64) -> f64 {
    if v.is_finite() {
        (v * 1e4).round() / 1e4
    } else {
        0.0
    }
}

/// One object of the scene: its id (as annotations name it), a description for hovering, and its
/// shape in the body frame.
#[derive(Debug, Clone, Serialize)]
pub struct SceneObject {
    /// The id annotations use (`cue`, `3`; PHYRE `object_index`; I-PHYRE `index`).
    pub id: String,
    /// What hovering shows (`ball 3`, `green ball`, `eliminable block`).
    pub name: String,
    /// Drawing primitives in the body frame (see the module doc of `viewer.js`).
    pub prims: Vec<Value>,
    /// Drawing order: lower layers first (I-PHYRE blocks 0, balls 1).
    pub layer: u8,
    /// Text drawn on the object (a ball's number), upright, at its centre.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub text: Option<Value>,
}

/// A trace as the viewer draws it.
#[derive(Debug, Clone, Serialize)]
pub struct Scene {
    /// Canvas side (px).
    pub size: f64,
    /// `[ox, oy, sx, sy]`: canvas x = ox + sx·x, y = oy + sy·y.
    pub view: [f64; 4],
    /// Background colour.
    pub background: String,
    /// Primitives drawn first, in world coordinates (the table).
    pub statics: Vec<Value>,
    /// The objects, in first-appearance order.
    pub objects: Vec<SceneObject>,
    /// Lines between two objects' centres: `[i, j, colour, width]` (I-PHYRE joints and springs).
    pub links: Vec<Value>,
    /// Per timestep, per object: `[x, y, angle]`, or null when the object is absent.
    pub poses: Vec<Vec<Option<[f64; 3]>>>,
    /// Per timestep: its time (s).
    pub times: Vec<f64>,
}

/// Why a trace cannot be drawn.
#[derive(Debug, thiserror::Error)]
#[error("trace {trace}: {message}")]
pub struct SceneError {
    /// The trace.
    pub trace: String,
    /// What is wrong.
    pub message: String,
}

fn circle(x: f64, y: f64, r: f64, c: [u8; 3]) -> Value {
    json!({"k": "circle", "x": r4(x), "y": r4(y), "r": r4(r), "c": hex(c)})
}

fn rect(x0: f64, y0: f64, x1: f64, y1: f64, c: [u8; 3]) -> Value {
    json!({"k": "rect", "x0": r4(x0), "y0": r4(y0), "x1": r4(x1), "y1": r4(y1), "c": hex(c)})
}

/// Builds the scene of `trace`; `config` is the billiards table it was played on.
pub fn scene(trace: &Trace, config: &PoolConfig) -> Result<Scene, SceneError> {
    let err = |message: String| SceneError {
        trace: trace.trace_id.clone(),
        message,
    };
    if trace.timesteps.is_empty() {
        return Err(err("has no timesteps".into()));
    }
    match trace.env {
        Env::Pooltool => pool_scene(trace, config).map_err(err),
        Env::Phyre => phyre_scene(trace).map_err(err),
        Env::Iphyre => iphyre_scene(trace).map_err(err),
    }
}

/// Each object's pose `[x, y, angle]` per timestep, `None` where the object is absent.
type Poses = Vec<Vec<Option<[f64; 3]>>>;

/// Object ids in first-appearance order and the pose table filled by `pose`.
fn collect<F>(
    trace: &Trace,
    id_of: impl Fn(&Body) -> Result<String, String>,
    mut pose: F,
) -> Result<(Vec<String>, Poses), String>
where
    F: FnMut(usize, &Body) -> Option<[f64; 3]>,
{
    let mut ids: Vec<String> = Vec::new();
    let mut index: BTreeMap<String, usize> = BTreeMap::new();
    // Each object's position in `ids`, step by step in trace order: every id is made once.
    let mut slots: Vec<usize> = Vec::new();
    for ts in &trace.timesteps {
        for o in &ts.objects {
            let id = id_of(&o.body)?;
            let i = match index.get(&id) {
                Some(&i) => i,
                None => {
                    index.insert(id.clone(), ids.len());
                    ids.push(id);
                    ids.len() - 1
                }
            };
            slots.push(i);
        }
    }
    let mut slots = slots.into_iter();
    let mut poses = Vec::with_capacity(trace.timesteps.len());
    for ts in &trace.timesteps {
        let mut row = vec![None; ids.len()];
        for (o, i) in ts.objects.iter().zip(slots.by_ref()) {
            row[i] = pose(i, &o.body).map(|p| [r4(p[0]), r4(p[1]), r4(p[2])]);
        }
        poses.push(row);
    }
    Ok((ids, poses))
}

fn wrong_env(b: &Body, want: Env) -> String {
    format!("holds a {} object in a {want} trace", b.env())
}

/// Pool colours: (base colour, striped), as `envs::pool::render` draws balls.
pub(crate) fn pool_ball_colour(id: &str) -> ([u8; 3], bool) {
    let n: u32 = match id.parse() {
        Ok(n) => n,
        Err(_) => return (POOL_WHITE, false),
    };
    if n == 0 || n == 8 {
        return ([15, 15, 15], false);
    }
    let base = match (n - 1) % 8 + 1 {
        1 => [250, 200, 20],
        2 => [25, 70, 200],
        3 => [220, 30, 30],
        4 => [110, 40, 160],
        5 => [250, 120, 20],
        6 => [20, 130, 60],
        7 => [130, 30, 30],
        _ => [15, 15, 15],
    };
    (base, n >= 9)
}

fn pool_scene(trace: &Trace, config: &PoolConfig) -> Result<Scene, String> {
    let table = &config.table;
    let size = CANVAS;
    // The layout of `envs::pool::render::Layout::of`.
    let margin = size * 0.02;
    let label_h = (size / 40.0).max(7.0);
    let title_h = 1.3 * label_h;
    let avail_h = size - 3.0 * margin - title_h;
    let avail_w = size - 2.0 * margin;
    let scale = (avail_h / (table.l + 2.0 * OUTER)).min(avail_w / (table.w + 2.0 * OUTER));
    let ox = size / 2.0 - table.w * scale / 2.0;
    let oy = (size + 2.0 * margin + title_h) / 2.0 + table.l * scale / 2.0;
    let mut statics = vec![
        rect(-OUTER, -OUTER, table.w + OUTER, table.l + OUTER, POOL_RAIL),
        rect(
            -CUSHION,
            -CUSHION,
            table.w + CUSHION,
            table.l + CUSHION,
            POOL_CUSHION,
        ),
        rect(0.0, 0.0, table.w, table.l, POOL_CLOTH),
    ];
    let dot = 1.6 / scale;
    for i in 1..4 {
        let x = table.w * i as f64 / 4.0;
        for y in [-CUSHION - RAIL / 2.0, table.l + CUSHION + RAIL / 2.0] {
            statics.push(circle(x, y, dot, POOL_DIAMOND));
        }
    }
    for i in 1..8 {
        let y = table.l * i as f64 / 8.0;
        for x in [-CUSHION - RAIL / 2.0, table.w + CUSHION + RAIL / 2.0] {
            statics.push(circle(x, y, dot, POOL_DIAMOND));
        }
    }
    let clip = [
        r4(-OUTER),
        r4(-OUTER),
        r4(table.w + OUTER),
        r4(table.l + OUTER),
    ];
    for pk in &table.pockets {
        let mut c = circle(pk.center[0], pk.center[1], pk.radius, POOL_POCKET);
        c["clip"] = json!(clip);
        statics.push(c);
    }
    for seg in &table.linear {
        statics.push(
            json!({"k": "line", "x1": r4(seg.p1[0]), "y1": r4(seg.p1[1]),
            "x2": r4(seg.p2[0]), "y2": r4(seg.p2[1]), "w": r4(1.2 / scale), "c": hex(POOL_NOSE)}),
        );
    }
    for jaw in &table.circular {
        statics.push(circle(
            jaw.center[0],
            jaw.center[1],
            jaw.radius,
            POOL_CUSHION,
        ));
    }
    for pk in &table.pockets {
        let right = pk.center[0] > table.w / 2.0;
        statics.push(json!({"k": "text", "s": pk.id, "size": label_h,
            "x": r4(if right { table.w + OUTER } else { -OUTER }), "y": r4(pk.center[1]),
            "align": if right { "left" } else { "right" }, "dx": if right { 0.4 * label_h } else { -0.4 * label_h },
            "c": hex([60, 60, 60])}));
    }
    // Pocketed balls go to a tray right of the table, top to bottom, in the order of each timestep.
    let r_px = config.ball.r * scale;
    let rail_right = ox + (table.w + OUTER) * scale;
    let tray_x = (rail_right + (size - rail_right) / 2.0 - ox) / scale;
    let mut radius: BTreeMap<usize, f64> = BTreeMap::new();
    let (ids, mut poses) = collect(
        trace,
        |b| match b {
            Body::Pool(b) => Ok(b.ball_id.to_string()),
            other => Err(wrong_env(other, Env::Pooltool)),
        },
        |i, b| {
            let Body::Pool(b) = b else { return None };
            radius.entry(i).or_insert(b.radius);
            // Pocketed balls get their tray position below.
            (b.motion_state_code != 4).then_some([b.position[0], b.position[1], 0.0])
        },
    )?;
    // The tray positions of pocketed balls: the n-th pocketed ball of a timestep in its n-th slot.
    let index: BTreeMap<&str, usize> = ids
        .iter()
        .enumerate()
        .map(|(i, s)| (s.as_str(), i))
        .collect();
    for (k, ts) in trace.timesteps.iter().enumerate() {
        let mut n = 0;
        for o in &ts.objects {
            if let Body::Pool(b) = &o.body
                && b.motion_state_code == 4
            {
                let py = size * 0.2 + n as f64 * 2.6 * r_px;
                let y = (oy - py) / scale;
                poses[k][index[b.ball_id.as_str()]] = Some([r4(tray_x), r4(y), 0.0]);
                n += 1;
            }
        }
    }
    let objects = ids
        .iter()
        .enumerate()
        .map(|(i, id)| {
            let r = radius.get(&i).copied().unwrap_or(config.ball.r);
            let (colour, striped) = pool_ball_colour(id);
            let mut prims = vec![circle(0.0, 0.0, r + 0.8 / scale, [20, 20, 20])];
            if striped {
                prims.push(circle(0.0, 0.0, r, POOL_WHITE));
                prims.push(json!({"k": "band", "r": r4(r), "h": r4(0.55 * r), "c": hex(colour)}));
            } else {
                prims.push(circle(0.0, 0.0, r, colour));
            }
            let text = id.parse::<u32>().is_ok().then(|| {
                let lum = 0.299 * colour[0] as f64 + 0.587 * colour[1] as f64 + 0.114 * colour[2] as f64;
                let (fg, halo) = if lum > 140.0 {
                    ([0, 0, 0], [255, 255, 255])
                } else {
                    ([255, 255, 255], [0, 0, 0])
                };
                json!({"s": id, "size": r4((1.25 * r * scale).max(6.0)), "c": hex(fg), "halo": hex(halo)})
            });
            SceneObject {
                id: id.clone(),
                name: format!("ball {id}"),
                prims,
                layer: 0,
                text,
            }
        })
        .collect();
    Ok(Scene {
        size,
        view: [r4(ox), r4(oy), r4(scale), r4(-scale)],
        background: hex(POOL_BACKGROUND),
        statics,
        objects,
        links: Vec::new(),
        poses,
        times: trace.timesteps.iter().map(|s| r4(s.t)).collect(),
    })
}

fn shape_prim(s: &Shape, c: [u8; 3]) -> Value {
    match s {
        Shape::Circle { radius } => circle(0.0, 0.0, *radius, c),
        Shape::Polygon(vs) => {
            let p: Vec<f64> = vs.iter().flat_map(|v| [r4(v[0]), r4(v[1])]).collect();
            json!({"k": "poly", "p": p, "c": hex(c)})
        }
    }
}

fn phyre_scene(trace: &Trace) -> Result<Scene, String> {
    let task: Option<Task> = TaskSet::default_tasks()
        .ok()
        .and_then(|t| t.get(&trace.task_id).ok());
    let (width, height) = task
        .as_ref()
        .map_or((256.0, 256.0), |t| (t.width, t.height));
    let mut shapes: BTreeMap<usize, (Vec<Value>, String)> = BTreeMap::new();
    let (ids, poses) = collect(
        trace,
        |b| match b {
            Body::Phyre(p) => Ok(p.object_index.to_string()),
            other => Err(wrong_env(other, Env::Phyre)),
        },
        |i, b| {
            let Body::Phyre(p) = b else { return None };
            shapes.entry(i).or_insert_with(|| {
                let c = PhyreColor::from_name(&p.color)
                    .unwrap_or(PhyreColor::Black)
                    .rgb();
                // The outline rule of `envs::phyre::render::pose_shapes`, in the body frame.
                let prims: Vec<Value> = if p.is_user_input {
                    vec![circle(0.0, 0.0, p.diameter / 2.0, c)]
                } else if p.shape == "wall" {
                    Vec::new()
                } else if let Some(b) = task.as_ref().and_then(|t| {
                    usize::try_from(p.object_index)
                        .ok()
                        .and_then(|k| t.bodies.get(k))
                        .filter(|b| !b.is_wall && b.shape_type == p.shape)
                }) {
                    b.shapes.iter().map(|s| shape_prim(s, c)).collect()
                } else if p.shape == "ball" {
                    vec![circle(0.0, 0.0, p.diameter / 2.0, c)]
                } else {
                    let (hx, hy) = (p.diameter / 2.0, height / 100.0);
                    vec![shape_prim(
                        &Shape::Polygon(vec![[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]]),
                        c,
                    )]
                };
                let name = format!(
                    "{} {}{}",
                    p.color,
                    p.shape,
                    if p.is_user_input { " (placed)" } else { "" }
                );
                (prims, name)
            });
            Some([p.x, p.y, p.angle])
        },
    )?;
    let k = CANVAS / width;
    let objects = ids
        .iter()
        .enumerate()
        .map(|(i, id)| {
            let (prims, name) = shapes.remove(&i).unwrap_or_default();
            SceneObject {
                id: id.clone(),
                name: format!("{id}: {name}"),
                prims,
                layer: 0,
                text: None,
            }
        })
        .collect();
    Ok(Scene {
        size: CANVAS,
        view: [0.0, r4(height * k), r4(k), r4(-k)],
        background: hex([255, 255, 255]),
        statics: Vec::new(),
        objects,
        links: Vec::new(),
        poses,
        times: trace.timesteps.iter().map(|s| r4(s.t)).collect(),
    })
}

fn iphyre_scene(trace: &Trace) -> Result<Scene, String> {
    let games = Games::default_games().ok();
    let game = games.as_ref().and_then(|g| g.get(&trace.task_id).ok());
    // (prims, name, joint, spring)
    let mut first: BTreeMap<usize, (Vec<Value>, String, i64, i64)> = BTreeMap::new();
    let (ids, poses) = collect(
        trace,
        |b| match b {
            Body::Iphyre(p) => Ok(p.index.to_string()),
            other => Err(wrong_env(other, Env::Iphyre)),
        },
        |i, b| {
            let Body::Iphyre(p) = b else { return None };
            let ball = match game
                .and_then(|g| usize::try_from(p.index).ok().and_then(|k| g.objects.get(k)))
            {
                Some(go) => go.kind == crate::envs::iphyre::ObjectKind::Ball,
                None => p.x1 == p.x2 && p.y1 == p.y2,
            };
            let (dx, dy) = (p.x2 - p.x1, p.y2 - p.y1);
            first.entry(i).or_insert_with(|| {
                if ball {
                    (
                        vec![circle(0.0, 0.0, p.radius, IPHYRE_RED)],
                        "ball".into(),
                        p.joint,
                        p.spring,
                    )
                } else {
                    let (colour, name) = if p.dynamic > 0.5 {
                        (IPHYRE_BLUE, "dynamic block")
                    } else if p.eliminable > 0.5 {
                        (IPHYRE_GRAY, "eliminable block")
                    } else {
                        (IPHYRE_BLACK, "fixed block")
                    };
                    let half = (dx * dx + dy * dy).sqrt() / 2.0;
                    (
                        vec![json!({"k": "capsule", "x1": r4(-half), "y1": 0.0, "x2": r4(half), "y2": 0.0,
                            "r": r4(p.radius), "c": hex(colour)})],
                        name.into(),
                        p.joint,
                        p.spring,
                    )
                }
            });
            let angle = if ball { 0.0 } else { dy.atan2(dx) };
            Some([(p.x1 + p.x2) / 2.0, (p.y1 + p.y2) / 2.0, angle])
        },
    )?;
    let k = CANVAS / IPHYRE_SCREEN;
    let mut links = Vec::new();
    type Pick = fn(&(Vec<Value>, String, i64, i64)) -> i64;
    let picks: [Pick; 2] = [|f| f.2, |f| f.3];
    for pick in picks {
        let mut ends: Vec<(i64, usize)> = first
            .iter()
            .filter(|(_, f)| pick(f) > 0)
            .map(|(i, f)| (pick(f), *i))
            .collect();
        ends.sort();
        for w in ends.windows(2) {
            if w[0].0 == w[1].0 {
                links.push(json!([
                    w[0].1,
                    w[1].1,
                    hex(IPHYRE_PURPLE),
                    r4((2.0 * k).max(1.0) / k)
                ]));
            }
        }
    }
    // Blocks first, balls on top, as `envs::iphyre::render` draws them.
    let objects: Vec<SceneObject> = ids
        .iter()
        .enumerate()
        .map(|(i, id)| {
            let (prims, name, _, _) = first.remove(&i).unwrap_or_default();
            SceneObject {
                id: id.clone(),
                layer: u8::from(name == "ball"),
                name: format!("{id}: {name}"),
                prims,
                text: None,
            }
        })
        .collect();
    Ok(Scene {
        size: CANVAS,
        view: [0.0, 0.0, r4(k), r4(k)],
        background: hex([255, 255, 255]),
        statics: Vec::new(),
        objects,
        links,
        poses,
        times: trace.timesteps.iter().map(|s| r4(s.t)).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::Environment;

    /// The RGB colour of pixel (`x`, `y`) of a PNG.
    fn png_pixel(png: &[u8], x: u32, y: u32) -> [u8; 3] {
        let p = tiny_skia::Pixmap::decode_png(png).unwrap();
        let c = p.pixel(x, y).unwrap();
        [c.red(), c.green(), c.blue()]
    }

    /// Bounding radius of an object's shape (body frame).
    fn reach(o: &SceneObject) -> f64 {
        o.prims
            .iter()
            .map(|q| match q["k"].as_str() {
                Some("circle") => q["r"].as_f64().unwrap(),
                Some("capsule") => q["x2"].as_f64().unwrap().abs() + q["r"].as_f64().unwrap(),
                Some("poly") => q["p"]
                    .as_array()
                    .unwrap()
                    .chunks(2)
                    .map(|c| c[0].as_f64().unwrap().hypot(c[1].as_f64().unwrap()))
                    .fold(0.0, f64::max),
                _ => 0.0,
            })
            .fold(0.0, f64::max)
    }

    /// At step 0, the pixel `render` draws at each object's centre (pool: 0.72 r right of it, clear of
    /// the number) has the colour the viewer fills the object with; objects another object may cover
    /// there are skipped. `zoom` is the render's size over the canvas's. Returns how many were checked.
    fn same_colours(trace: &Trace, png: &[u8], zoom: f64) -> usize {
        let sc = scene(trace, &PoolConfig::default_7ft()).unwrap();
        let [ox, oy, sx, sy] = sc.view;
        let poses = &sc.poses[0];
        let mut order: Vec<usize> = (0..sc.objects.len()).collect();
        order.sort_by_key(|&i| (sc.objects[i].layer, i));
        let mut checked = 0;
        for (rank, &i) in order.iter().enumerate() {
            let (o, Some(p)) = (&sc.objects[i], poses[i]) else {
                continue;
            };
            let Some(fill) = o.prims.last() else { continue };
            let dx = if trace.env == Env::Pooltool {
                if o.id.len() > 1 && o.id != "cue" {
                    continue;
                }
                0.72 * fill["r"].as_f64().unwrap()
            } else {
                0.0
            };
            let (x, y) = (p[0] + dx, p[1]);
            let covered = order[rank + 1..]
                .iter()
                .chain(order[..rank].iter())
                .any(|&j| {
                    poses[j].is_some_and(|q| {
                        (q[0] - x).hypot(q[1] - y) < reach(&sc.objects[j]) + 3.0 / sx.abs()
                    })
                });
            if covered {
                continue;
            }
            let (px, py) = ((ox + sx * x) * zoom, (oy + sy * y) * zoom);
            let want = fill["c"].as_str().unwrap().to_string();
            let got = hex(png_pixel(png, px as u32, py as u32));
            assert_eq!(
                got, want,
                "{}: object {} at ({px:.0}, {py:.0})",
                trace.env, o.id
            );
            checked += 1;
        }
        checked
    }

    #[test]
    fn the_viewer_draws_every_environment_in_the_colours_of_render() {
        let pool = crate::envs::pool::PoolEnv::default();
        let shot = crate::envs::pool::Shot {
            v0: 1.0,
            phi: 80.0,
            theta: 0.0,
            a: 0.0,
            b: 0.0,
        };
        let tr = pool
            .simulate(&pool.scenes(1, 3).unwrap()[0], &shot)
            .unwrap();
        let png = crate::envs::pool::render::render_png(
            &tr,
            &PoolConfig::default_7ft(),
            0.0,
            &crate::envs::pool::render::RenderOptions { size: 1024 },
        )
        .unwrap();
        assert!(same_colours(&tr, &png, 2.0) >= 5);
        // The cloth.
        let sc = scene(&tr, &PoolConfig::default_7ft()).unwrap();
        assert_eq!(sc.statics[2]["c"], hex(POOL_CLOTH));

        let phyre = crate::envs::phyre::PhyreEnv::default();
        let task = TaskSet::default_tasks().unwrap().get("00000:000").unwrap();
        let a = crate::envs::phyre::BallAction {
            x: 0.3,
            y: 0.8,
            r: 0.4,
        };
        let tr = phyre.simulate(&task, &a).unwrap();
        let png = phyre.render(&tr, 0.0).unwrap();
        assert!(same_colours(&tr, &png, 1.0) >= 3);

        let iphyre = crate::envs::iphyre::IphyreEnv::new().unwrap();
        let game = iphyre.scenes(1, 0).unwrap().remove(0);
        let tr = iphyre.simulate(&game, &Vec::new()).unwrap();
        let png = iphyre.render(&tr, 0.0).unwrap();
        assert!(same_colours(&tr, &png, 1.0) >= 2);
    }

    #[test]
    fn poses_follow_objects_and_pocketed_balls_go_to_the_tray() {
        let tr = crate::testutil::synthetic_trace(Env::Pooltool, 0, 4, 3);
        let sc = scene(&tr, &PoolConfig::default_7ft()).unwrap();
        assert_eq!(sc.poses.len(), 4);
        assert_eq!(sc.objects.len(), 3);
        assert_eq!(sc.times, [0.0, 0.01, 0.02, 0.03]);
        let mut pocketed = tr.clone();
        if let Body::Pool(b) = &mut pocketed.timesteps[3].objects[1].body {
            b.motion_state_code = 4;
        }
        let sc2 = scene(&pocketed, &PoolConfig::default_7ft()).unwrap();
        let tray = sc2.poses[3][1].unwrap();
        assert!(tray[0] > PoolConfig::default_7ft().table.w, "{tray:?}");
        let mut empty = tr.clone();
        empty.timesteps.clear();
        assert!(scene(&empty, &PoolConfig::default_7ft()).is_err());
    }
}
