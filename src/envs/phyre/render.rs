//! PNG pictures of PHYRE scenes: one instant of a trace, a strip of instants, or a task's initial scene,
//! in PHYRE's palette (`phyre.vis.WAD_COLORS`: white background, red user ball, green goal subject, blue
//! and purple targets, gray dynamic and black static bodies).
//!
//! The 256×256 scene fills the square picture (512×512 by default), y up as in PHYRE's images. Body
//! shapes come from the task (polygons and circles in the body frame), poses from the trace's timestep
//! nearest the requested time. With `grid` on, DeepPHY's 8×8 red grid is drawn with cells numbered 1–64
//! row by row from the top-left — the picture a VLM gets before answering `Cell: N, Radius: R`. The time
//! is printed in the top-left corner. Text uses a tiny built-in segment font (digits, `.`, `t`, `s`).

use tiny_skia::{Color as SkColor, LineCap, LineJoin, PathBuilder, Pixmap, Stroke, Transform};

use super::task::{Color, Shape, Task};
use crate::envs::EnvError;
use crate::envs::draw::{self, encode_png, fill_path, new_pixmap, paint};
use crate::envs::pool::render::timestep_at;
use crate::trace::{Body, Trace};

/// Picture options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderOptions {
    /// Width and height of one frame in pixels (default 512).
    pub size: u32,
    /// Draw DeepPHY's numbered 8×8 grid.
    pub grid: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            size: 512,
            grid: false,
        }
    }
}

/// A body to draw: index, colour, pose, user-ball radius.
struct Pose {
    index: usize,
    color: [u8; 3],
    x: f64,
    y: f64,
    angle: f64,
    /// For the user ball (not in the task): its radius (px).
    radius: Option<f64>,
    /// The trace's shape name (`ball`, `bar`, `jar`, `wall`, …).
    shape: String,
    /// The trace's diameter (px).
    diameter: f64,
}

/// A body's pieces in scene coordinates: the task's shapes when the task body matches the pose (same
/// shape type), else an outline from the pose's own features — a circle for a ball, a bar of the
/// diameter's length and PHYRE's bar thickness (256/50 px) otherwise — so traces imported from elsewhere
/// (whose bodies need not match the task file) still draw. Walls are not drawn (they lie outside).
fn pose_shapes(task: &Task, pose: &Pose) -> Vec<Shape> {
    if let Some(r) = pose.radius {
        return vec![Shape::Circle { radius: r }];
    }
    if pose.shape == "wall" {
        return Vec::new();
    }
    if let Some(b) = task.bodies.get(pose.index)
        && !b.is_wall
        && b.shape_type == pose.shape
    {
        return b.world_shapes([pose.x, pose.y], pose.angle);
    }
    if pose.shape == "ball" {
        return vec![Shape::Circle {
            radius: pose.diameter / 2.0,
        }];
    }
    let (hx, hy) = (pose.diameter / 2.0, task.height / 100.0);
    let (s, c) = pose.angle.sin_cos();
    let corner = |u: f64, v: f64| [pose.x + c * u - s * v, pose.y + s * u + c * v];
    vec![Shape::Polygon(vec![
        corner(-hx, -hy),
        corner(hx, -hy),
        corner(hx, hy),
        corner(-hx, hy),
    ])]
}

fn check_size(opts: &RenderOptions) -> Result<(), EnvError> {
    if !(64..=4096).contains(&opts.size) {
        return Err(EnvError::Render(format!(
            "frame size must be within 64..=4096 pixels, found {}",
            opts.size
        )));
    }
    Ok(())
}

/// Segments of the digit font on a 4 × 6 box (y down).
fn glyph(c: char) -> Vec<[(f32, f32); 2]> {
    const A: [(f32, f32); 2] = [(0., 0.), (4., 0.)];
    const B: [(f32, f32); 2] = [(4., 0.), (4., 3.)];
    const C: [(f32, f32); 2] = [(4., 3.), (4., 6.)];
    const D: [(f32, f32); 2] = [(0., 6.), (4., 6.)];
    const E: [(f32, f32); 2] = [(0., 3.), (0., 6.)];
    const F: [(f32, f32); 2] = [(0., 0.), (0., 3.)];
    const G: [(f32, f32); 2] = [(0., 3.), (4., 3.)];
    match c {
        '0' => vec![A, B, C, D, E, F],
        '1' => vec![[(2., 0.), (2., 6.)]],
        '2' => vec![A, B, G, E, D],
        '3' => vec![A, B, G, C, D],
        '4' => vec![F, G, B, C],
        '5' => vec![A, F, G, C, D],
        '6' => vec![A, F, G, E, C, D],
        '7' => vec![A, B, C],
        '8' => vec![A, B, C, D, E, F, G],
        '9' => vec![A, B, C, D, F, G],
        '.' => vec![[(1.6, 5.6), (2.4, 6.)]],
        't' => vec![
            [(1.5, 0.5), (1.5, 6.)],
            [(0., 2.), (3.5, 2.)],
            [(1.5, 6.), (3.5, 6.)],
        ],
        's' => vec![
            [(4., 2.5), (0., 2.5)],
            [(0., 2.5), (0., 4.2)],
            [(0., 4.2), (4., 4.2)],
            [(4., 4.2), (4., 6.)],
            [(4., 6.), (0., 6.)],
        ],
        '=' => vec![[(0., 2.2), (4., 2.2)], [(0., 4.), (4., 4.)]],
        _ => Vec::new(),
    }
}

fn text_width(s: &str, h: f32) -> f32 {
    (s.chars().count() as f32 * 6.0 - 2.0) * h / 6.0
}

/// Draws `s` with its top-left corner at (x, y), glyphs `h` pixels high, with a halo for contrast.
fn text(p: &mut Pixmap, x: f32, y: f32, h: f32, s: &str, colour: [u8; 3], halo: [u8; 3]) {
    let k = h / 6.0;
    let mut pb = PathBuilder::new();
    for (i, c) in s.chars().enumerate() {
        let gx = x + i as f32 * 6.0 * k;
        for [(u0, v0), (u1, v1)] in glyph(c) {
            pb.move_to(gx + u0 * k, y + v0 * k);
            pb.line_to(gx + u1 * k, y + v1 * k);
        }
    }
    let Some(path) = pb.finish() else { return };
    let width = (h / 7.0).max(1.2);
    for (w, c) in [(width + 2.0, halo), (width, colour)] {
        let stroke = Stroke {
            width: w,
            line_cap: LineCap::Round,
            line_join: LineJoin::Round,
            ..Stroke::default()
        };
        p.stroke_path(&path, &paint(c), &stroke, Transform::identity(), None);
    }
}

/// One frame: the bodies at their poses, the grid, the time label.
fn draw(
    task: &Task,
    poses: &[Pose],
    t: Option<f64>,
    opts: &RenderOptions,
) -> Result<Pixmap, EnvError> {
    check_size(opts)?;
    let size = opts.size as f32;
    let k = size / task.width as f32;
    let h = task.height as f32;
    let to_px = |x: f64, y: f64| (x as f32 * k, (h - y as f32) * k);
    let mut p = new_pixmap(opts.size, opts.size)?;
    p.fill(SkColor::WHITE);
    for pose in poses {
        for shape in pose_shapes(task, pose) {
            let path = match shape {
                Shape::Circle { radius } => {
                    let (cx, cy) = to_px(pose.x, pose.y);
                    PathBuilder::from_circle(cx, cy, (radius as f32 * k).max(0.5))
                }
                Shape::Polygon(vs) => {
                    let mut pb = PathBuilder::new();
                    for (i, v) in vs.iter().enumerate() {
                        let (x, y) = to_px(v[0], v[1]);
                        if i == 0 {
                            pb.move_to(x, y);
                        } else {
                            pb.line_to(x, y);
                        }
                    }
                    pb.close();
                    pb.finish()
                }
            };
            fill_path(&mut p, path, pose.color);
        }
    }
    if opts.grid {
        let red = [255, 0, 0];
        let mut pb = PathBuilder::new();
        for i in 1..8 {
            let c = size * i as f32 / 8.0;
            pb.move_to(c, 0.0);
            pb.line_to(c, size);
            pb.move_to(0.0, c);
            pb.line_to(size, c);
        }
        if let Some(path) = pb.finish() {
            let stroke = Stroke {
                width: (size / 340.0).max(1.0),
                ..Stroke::default()
            };
            p.stroke_path(&path, &paint(red), &stroke, Transform::identity(), None);
        }
        let cell = size / 8.0;
        let th = (cell * 0.28).max(6.0);
        for n in 1..=64u32 {
            let (row, col) = ((n - 1) / 8, (n - 1) % 8);
            let s = n.to_string();
            let (cx, cy) = ((col as f32 + 0.5) * cell, (row as f32 + 0.5) * cell);
            text(
                &mut p,
                cx - text_width(&s, th) / 2.0,
                cy - th / 2.0,
                th,
                &s,
                red,
                [255, 255, 255],
            );
        }
    }
    if let Some(t) = t {
        let label = format!("t={t:.2}s");
        let th = (size / 28.0).max(7.0);
        text(
            &mut p,
            th * 0.5,
            th * 0.5,
            th,
            &label,
            [60, 60, 60],
            [255, 255, 255],
        );
    }
    Ok(p)
}

fn poses_at(trace: &Trace, t: f64) -> Result<(Vec<Pose>, f64), EnvError> {
    let ts = timestep_at(trace, t)
        .ok_or_else(|| EnvError::Render(format!("trace {} has no timesteps", trace.trace_id)))?;
    let mut poses = Vec::with_capacity(ts.objects.len());
    for o in &ts.objects {
        let Body::Phyre(b) = &o.body else {
            return Err(EnvError::Render(format!(
                "trace {} is a {} trace, not PHYRE",
                trace.trace_id,
                o.body.env()
            )));
        };
        let color = Color::from_name(&b.color).unwrap_or(Color::Black).rgb();
        poses.push(Pose {
            index: usize::try_from(b.object_index).unwrap_or(usize::MAX),
            color,
            x: b.x,
            y: b.y,
            angle: b.angle,
            radius: b.is_user_input.then_some(b.diameter / 2.0),
            shape: b.shape.clone(),
            diameter: b.diameter,
        });
    }
    Ok((poses, ts.t))
}

/// One frame of `trace` (played on `task`) at the timestep nearest `t`, as PNG bytes.
pub fn render_png(
    trace: &Trace,
    task: &Task,
    t: f64,
    opts: &RenderOptions,
) -> Result<Vec<u8>, EnvError> {
    let (poses, at) = poses_at(trace, t)?;
    encode_png(&draw(task, &poses, Some(at), opts)?)
}

/// Frames at `times`, left to right, as PNG bytes (`size·k` × `size` pixels).
pub fn render_strip_png(
    trace: &Trace,
    task: &Task,
    times: &[f64],
    opts: &RenderOptions,
) -> Result<Vec<u8>, EnvError> {
    check_size(opts)?;
    let strip = draw::strip(times.len(), opts.size, |i| {
        let (poses, at) = poses_at(trace, times[i])?;
        draw(task, &poses, Some(at), opts)
    })?;
    encode_png(&strip)
}

/// A task's initial scene without a user ball (what an agent sees before acting), as PNG bytes.
pub fn render_task_png(task: &Task, opts: &RenderOptions) -> Result<Vec<u8>, EnvError> {
    let poses: Vec<Pose> = task
        .bodies
        .iter()
        .map(|b| Pose {
            index: b.id,
            color: b.color.rgb(),
            x: b.position[0],
            y: b.position[1],
            angle: b.angle,
            radius: None,
            shape: if b.is_wall {
                "wall".to_string()
            } else {
                b.shape_type.clone()
            },
            diameter: b.diameter,
        })
        .collect();
    encode_png(&draw(task, &poses, None, opts)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::draw::png_pixel as pixel;
    use crate::envs::phyre::action::BallAction;
    use crate::envs::phyre::episode::{RecordOptions, run};
    use crate::envs::phyre::params::PhysicsParams;
    use crate::envs::phyre::tasks::TaskSet;
    use crate::envs::phyre::to_trace::trace_of;

    #[test]
    fn scene_colours_grid_and_strip() {
        let task = TaskSet::default_tasks().unwrap().get("00000:000").unwrap();
        let png = render_task_png(&task, &RenderOptions::default()).unwrap();
        // Green ball centre (89.6, 58.7) → (179, 395) at 512 px; blue ball (192, 66.7) → (384, 379).
        assert_eq!(pixel(&png, 179, 395), Color::Green.rgb());
        assert_eq!(pixel(&png, 384, 379), Color::Blue.rgb());
        assert_eq!(pixel(&png, 10, 10), [255, 255, 255]);
        let grid = render_task_png(
            &task,
            &RenderOptions {
                size: 512,
                grid: true,
            },
        )
        .unwrap();
        let line = pixel(&grid, 64, 300);
        assert!(line[0] > 200 && line[1] < 120 && line[2] < 120, "{line:?}");
        let a = BallAction {
            x: 0.3,
            y: 0.8,
            r: 0.4,
        };
        let r = run(
            &task,
            &a,
            &PhysicsParams::default(),
            &RecordOptions::default(),
        )
        .unwrap();
        let tr = trace_of(&r, &task, "t");
        let png = render_png(&tr, &task, 0.0, &RenderOptions::default()).unwrap();
        let ball = r.placement.ball().unwrap();
        assert_eq!(
            pixel(&png, (ball.x * 2.0) as u32, (512.0 - ball.y * 2.0) as u32),
            Color::Red.rgb()
        );
        let strip = render_strip_png(
            &tr,
            &task,
            &[0.0, 1.0, 2.0],
            &RenderOptions {
                size: 128,
                grid: false,
            },
        )
        .unwrap();
        let p = Pixmap::decode_png(&strip).unwrap();
        assert_eq!((p.width(), p.height()), (384, 128));
        assert!(render_strip_png(&tr, &task, &[], &RenderOptions::default()).is_err());
        assert!(
            render_task_png(
                &task,
                &RenderOptions {
                    size: 8,
                    grid: false
                }
            )
            .is_err()
        );
    }
}
