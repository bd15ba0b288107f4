//! PNG pictures of a billiards trace: the table seen from above at one instant, or a strip of instants.
//!
//! The picture is what VLM prompts show, so it favours legibility at 512×512: the table stands upright
//! (x to the right, y up, as in the trace), wood rails, cushions, black pockets labelled with their ids
//! (`lb`, `lc`, `lt`, `rb`, `rc`, `rt`), balls in the standard pool colours (1 yellow, 2 blue, 3 red,
//! 4 purple, 5 orange, 6 green, 7 maroon, 8 black, 9–15 striped, cue white) with their numbers, the
//! time in the top-left corner and pocketed balls in a tray on the right. Ball states come from the
//! trace's timesteps (the step nearest to the requested time), so any trace in a run can be drawn.
//!
//! Drawing uses `tiny-skia` (anti-aliased paths, PNG encoding). Text is a built-in stroke font of the
//! few glyphs needed (digits, `t = . s`, pocket letters), so no font file ships with annotrace.

use tiny_skia::{
    Color, FillRule, LineCap, LineJoin, Mask, PathBuilder, Pixmap, Rect, Stroke, Transform,
};

use super::config::PoolConfig;
use crate::envs::EnvError;
use crate::envs::draw::{self, encode_png, fill_circle, fill_path, new_pixmap, paint};
use crate::trace::{Body, PoolBall, Timestep, Trace};

/// Picture options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderOptions {
    /// Width and height of one frame in pixels (default 512).
    pub size: u32,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions { size: 512 }
    }
}

/// The timestep of `trace` nearest to `t` (the first on a tie); `None` for a trace without timesteps.
pub fn timestep_at(trace: &Trace, t: f64) -> Option<&Timestep> {
    let steps = &trace.timesteps;
    let k = steps.partition_point(|s| s.t < t);
    match (k.checked_sub(1).and_then(|i| steps.get(i)), steps.get(k)) {
        (Some(a), Some(b)) => Some(if (t - a.t) <= (b.t - t) { a } else { b }),
        (a, b) => a.or(b),
    }
}

/// `k` instants spread evenly over the trace, first and last included.
pub fn strip_times(trace: &Trace, k: usize) -> Vec<f64> {
    let (t0, t1) = match (trace.timesteps.first(), trace.timesteps.last()) {
        (Some(a), Some(b)) => (a.t, b.t),
        _ => (0.0, 0.0),
    };
    match k {
        0 => Vec::new(),
        1 => vec![t0],
        _ => (0..k)
            .map(|i| t0 + (t1 - t0) * i as f64 / (k - 1) as f64)
            .collect(),
    }
}

/// One frame at time `t`, as PNG bytes.
pub fn render_png(
    trace: &Trace,
    config: &PoolConfig,
    t: f64,
    opts: &RenderOptions,
) -> Result<Vec<u8>, EnvError> {
    encode_png(&frame(trace, config, t, opts)?)
}

/// Frames at `times`, side by side left to right, as PNG bytes (`size·k` × `size` pixels).
pub fn render_strip_png(
    trace: &Trace,
    config: &PoolConfig,
    times: &[f64],
    opts: &RenderOptions,
) -> Result<Vec<u8>, EnvError> {
    let strip = draw::strip(times.len(), opts.size, |i| {
        frame(trace, config, times[i], opts)
    })?;
    encode_png(&strip)
}

/// Standard pool colours: (base colour, striped).
fn ball_colour(id: &str) -> ([u8; 3], bool) {
    let n: u32 = match id.parse() {
        Ok(n) => n,
        Err(_) => return ([250, 250, 245], false),
    };
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
    if n == 8 || n == 0 {
        ([15, 15, 15], false)
    } else {
        (base, n >= 9)
    }
}

fn luminance(c: [u8; 3]) -> f64 {
    0.299 * c[0] as f64 + 0.587 * c[1] as f64 + 0.114 * c[2] as f64
}

/// Maps table metres to pixels: x right, y up.
struct View {
    scale: f32,
    ox: f32,
    oy: f32,
}

impl View {
    fn px(&self, x: f64, y: f64) -> (f32, f32) {
        (
            self.ox + x as f32 * self.scale,
            self.oy - y as f32 * self.scale,
        )
    }
}

fn rect(p: &mut Pixmap, x0: f32, y0: f32, x1: f32, y1: f32, colour: [u8; 3]) {
    if let Some(r) = Rect::from_ltrb(x0.min(x1), y0.min(y1), x0.max(x1), y0.max(y1)) {
        p.fill_rect(r, &paint(colour), Transform::identity(), None);
    }
}

/// Glyphs of the stroke font on a 4 × 6 grid (y down; lower-case letters use rows 2–6).
///
/// Long because it is the font: one arm per glyph, the strokes as data; split, the font would be
/// scattered for nothing.
fn glyph(c: char) -> &'static [&'static [(f32, f32)]] {
    match c {
        '0' => &[&[
            (1., 0.),
            (3., 0.),
            (4., 1.),
            (4., 5.),
            (3., 6.),
            (1., 6.),
            (0., 5.),
            (0., 1.),
            (1., 0.),
        ]],
        '1' => &[&[(1., 1.2), (2.3, 0.), (2.3, 6.)], &[(1., 6.), (3.6, 6.)]],
        '2' => &[&[
            (0., 1.2),
            (1., 0.),
            (3., 0.),
            (4., 1.),
            (4., 2.2),
            (0., 6.),
            (4., 6.),
        ]],
        '3' => &[&[
            (0., 0.),
            (4., 0.),
            (1.8, 2.6),
            (3., 2.6),
            (4., 3.6),
            (4., 5.),
            (3., 6.),
            (1., 6.),
            (0., 5.),
        ]],
        '4' => &[&[(3., 6.), (3., 0.), (0., 4.2), (4., 4.2)]],
        '5' => &[&[
            (4., 0.),
            (0.3, 0.),
            (0., 2.7),
            (3., 2.5),
            (4., 3.5),
            (4., 5.),
            (3., 6.),
            (0., 6.),
        ]],
        '6' => &[&[
            (3.6, 0.),
            (1.5, 0.),
            (0., 2.),
            (0., 5.),
            (1., 6.),
            (3., 6.),
            (4., 5.),
            (4., 3.5),
            (3., 2.6),
            (1., 2.6),
            (0., 3.6),
        ]],
        '7' => &[&[(0., 0.), (4., 0.), (1.4, 6.)]],
        '8' => &[
            &[
                (1., 0.),
                (3., 0.),
                (3.8, 0.8),
                (3.8, 2.),
                (3., 2.8),
                (1., 2.8),
                (0.2, 2.),
                (0.2, 0.8),
                (1., 0.),
            ],
            &[
                (1., 2.8),
                (0., 3.8),
                (0., 5.),
                (1., 6.),
                (3., 6.),
                (4., 5.),
                (4., 3.8),
                (3., 2.8),
            ],
        ],
        '9' => &[&[
            (0.4, 6.),
            (2.5, 6.),
            (4., 4.),
            (4., 1.),
            (3., 0.),
            (1., 0.),
            (0., 1.),
            (0., 2.4),
            (1., 3.4),
            (3., 3.4),
            (4., 2.4),
        ]],
        't' => &[
            &[(1.3, 0.5), (1.3, 5.3), (2., 6.), (3.2, 6.)],
            &[(0., 2.), (3., 2.)],
        ],
        's' => &[&[
            (4., 2.3),
            (3.4, 2.),
            (0.8, 2.),
            (0., 2.8),
            (0.8, 3.8),
            (3.2, 4.2),
            (4., 5.1),
            (3.2, 6.),
            (0., 6.),
        ]],
        '=' => &[&[(0., 2.6), (4., 2.6)], &[(0., 4.4), (4., 4.4)]],
        '.' => &[&[(1.7, 5.6), (2.3, 5.6), (2.3, 6.), (1.7, 6.), (1.7, 5.6)]],
        'l' => &[&[(1.5, 0.), (1.5, 5.3), (2.2, 6.), (2.8, 6.)]],
        'r' => &[&[(0.6, 2.), (0.6, 6.)], &[(0.6, 3.6), (2., 2.), (3.8, 2.)]],
        'b' => &[&[
            (0., 0.),
            (0., 6.),
            (3., 6.),
            (4., 5.),
            (4., 3.),
            (3., 2.),
            (0., 2.),
        ]],
        'c' => &[&[(4., 2.), (1., 2.), (0., 3.), (0., 5.), (1., 6.), (4., 6.)]],
        _ => &[],
    }
}

/// Draws `text` with its top-left corner at (x, y); `h` is the glyph height in pixels. A halo in
/// `halo` colour keeps it legible on any background.
fn text(p: &mut Pixmap, x: f32, y: f32, h: f32, s: &str, colour: [u8; 3], halo: Option<[u8; 3]>) {
    let k = h / 6.0;
    let advance = 5.2 * k;
    let width = (h / 7.0).max(1.1);
    let mut pb = PathBuilder::new();
    for (i, c) in s.chars().enumerate() {
        let gx = x + i as f32 * advance;
        for line in glyph(c) {
            for (j, &(u, v)) in line.iter().enumerate() {
                let (px, py) = (gx + u * k, y + v * k);
                if j == 0 {
                    pb.move_to(px, py);
                } else {
                    pb.line_to(px, py);
                }
            }
        }
    }
    let Some(path) = pb.finish() else { return };
    let stroke = |w: f32| Stroke {
        width: w,
        line_cap: LineCap::Round,
        line_join: LineJoin::Round,
        ..Stroke::default()
    };
    if let Some(halo) = halo {
        p.stroke_path(
            &path,
            &paint(halo),
            &stroke(width + 1.6),
            Transform::identity(),
            None,
        );
    }
    p.stroke_path(
        &path,
        &paint(colour),
        &stroke(width),
        Transform::identity(),
        None,
    );
}

fn text_width(s: &str, h: f32) -> f32 {
    let n = s.chars().count() as f32;
    (n * 5.2 - 1.2) * h / 6.0
}

/// One ball: coloured disc (a band for stripes), outline, number.
fn draw_ball(p: &mut Pixmap, cx: f32, cy: f32, r: f32, id: &str) {
    let (colour, striped) = ball_colour(id);
    fill_circle(p, cx, cy, r + 0.8, [20, 20, 20]);
    if striped {
        fill_circle(p, cx, cy, r, [250, 250, 245]);
        // The band is the disc clipped to |dy| ≤ 0.55 r: clamping the circle's y traces exactly that.
        let band = 0.55 * r;
        let mut pb = PathBuilder::new();
        for i in 0..=48 {
            let a = i as f32 / 48.0 * std::f32::consts::TAU;
            let (px, py) = (cx + r * a.cos(), cy + (r * a.sin()).clamp(-band, band));
            if i == 0 {
                pb.move_to(px, py);
            } else {
                pb.line_to(px, py);
            }
        }
        pb.close();
        fill_path(p, pb.finish(), colour);
    } else {
        fill_circle(p, cx, cy, r, colour);
    }
    if id.parse::<u32>().is_ok() {
        let h = (1.25 * r).max(6.0);
        let w = text_width(id, h);
        let (fg, halo) = if luminance(colour) > 140.0 {
            ([0, 0, 0], [255, 255, 255])
        } else {
            ([255, 255, 255], [0, 0, 0])
        };
        text(p, cx - w / 2.0, cy - h / 2.0, h, id, fg, Some(halo));
    }
}

/// Cushion width (m) drawn around the playing surface.
const CUSHION: f64 = 0.0508;
/// Wooden rail width (m) drawn around the cushions.
const RAIL: f64 = 0.045;
/// Cushion plus rail: the table's outer edge beyond the playing surface (m).
const OUTER: f64 = CUSHION + RAIL;

/// Where things go in a frame of `size` pixels: the view of the table and the text heights.
struct Layout {
    view: View,
    margin: f32,
    /// Height of pocket labels.
    label_h: f32,
    /// Height of the time line above the table.
    title_h: f32,
}

impl Layout {
    /// Fits the outer rail box (w + 2·outer) × (l + 2·outer) into the frame below a title line.
    fn of(size: u32, config: &PoolConfig) -> Layout {
        let table = &config.table;
        let margin = size as f32 * 0.02;
        let label_h = (size as f32 / 40.0).max(7.0);
        let title_h = 1.3 * label_h;
        let avail_h = size as f32 - 3.0 * margin - title_h;
        let avail_w = size as f32 - 2.0 * margin;
        let scale = (avail_h / (table.l + 2.0 * OUTER) as f32)
            .min(avail_w / (table.w + 2.0 * OUTER) as f32);
        let view = View {
            scale,
            ox: size as f32 / 2.0 - table.w as f32 * scale / 2.0,
            oy: (size as f32 + 2.0 * margin + title_h) / 2.0 + table.l as f32 * scale / 2.0,
        };
        Layout {
            view,
            margin,
            label_h,
            title_h,
        }
    }
}

/// The picture of `trace` at time `t`: the table, the balls of the nearest timestep, the tray of
/// pocketed balls and the time.
fn frame(
    trace: &Trace,
    config: &PoolConfig,
    t: f64,
    opts: &RenderOptions,
) -> Result<Pixmap, EnvError> {
    if !t.is_finite() {
        return Err(EnvError::Render(format!("time {t} is not a finite number")));
    }
    let size = opts.size.max(64);
    let mut p = new_pixmap(size, size)?;
    p.fill(Color::from_rgba8(236, 236, 232, 255));
    let layout = Layout::of(size, config);
    draw_rails(&mut p, &layout.view, config);
    draw_pockets(&mut p, &layout.view, config, size)?;
    draw_cushions(&mut p, &layout.view, config);
    draw_pocket_labels(&mut p, &layout, config);
    let step = timestep_at(trace, t)
        .ok_or_else(|| EnvError::Render(format!("trace {} has no timesteps", trace.trace_id)))?;
    draw_balls(&mut p, &layout.view, trace, step, config, size)?;
    let label = format!("t={:.2}s", step.t);
    let w = text_width(&label, layout.title_h);
    text(
        &mut p,
        (size as f32 - w) / 2.0,
        layout.margin,
        layout.title_h,
        &label,
        [20, 20, 20],
        None,
    );
    Ok(p)
}

/// Wood, cushion and cloth rectangles, and the diamonds on the rails (quarters of the width,
/// eighths of the length).
fn draw_rails(p: &mut Pixmap, view: &View, config: &PoolConfig) {
    let table = &config.table;
    let (x0, y0) = view.px(-OUTER, -OUTER);
    let (x1, y1) = view.px(table.w + OUTER, table.l + OUTER);
    rect(p, x0, y0, x1, y1, [110, 64, 32]);
    let (x0, y0) = view.px(-CUSHION, -CUSHION);
    let (x1, y1) = view.px(table.w + CUSHION, table.l + CUSHION);
    rect(p, x0, y0, x1, y1, [22, 96, 52]);
    let (x0, y0) = view.px(0.0, 0.0);
    let (x1, y1) = view.px(table.w, table.l);
    rect(p, x0, y0, x1, y1, [36, 130, 74]);
    for i in 1..4 {
        let x = table.w * i as f64 / 4.0;
        for y in [-CUSHION - RAIL / 2.0, table.l + CUSHION + RAIL / 2.0] {
            let (cx, cy) = view.px(x, y);
            fill_circle(p, cx, cy, 1.6, [235, 225, 200]);
        }
    }
    for i in 1..8 {
        let y = table.l * i as f64 / 8.0;
        for x in [-CUSHION - RAIL / 2.0, table.w + CUSHION + RAIL / 2.0] {
            let (cx, cy) = view.px(x, y);
            fill_circle(p, cx, cy, 1.6, [235, 225, 200]);
        }
    }
}

/// Pockets, clipped to the rail box (pooltool's pocket circles reach past the rails).
fn draw_pockets(
    p: &mut Pixmap,
    view: &View,
    config: &PoolConfig,
    size: u32,
) -> Result<(), EnvError> {
    let table = &config.table;
    let (x0, y0) = view.px(-OUTER, -OUTER);
    let (x1, y1) = view.px(table.w + OUTER, table.l + OUTER);
    let mut clip = Mask::new(size, size)
        .ok_or_else(|| EnvError::Render(format!("cannot make a {size}×{size} mask")))?;
    if let Some(r) = Rect::from_ltrb(x0.min(x1), y0.min(y1), x0.max(x1), y0.max(y1)) {
        clip.fill_path(
            &PathBuilder::from_rect(r),
            FillRule::Winding,
            false,
            Transform::identity(),
        );
    }
    for pk in &table.pockets {
        let (cx, cy) = view.px(pk.center[0], pk.center[1]);
        if let Some(path) = PathBuilder::from_circle(cx, cy, pk.radius as f32 * view.scale) {
            p.fill_path(
                &path,
                &paint([8, 8, 8]),
                FillRule::Winding,
                Transform::identity(),
                Some(&clip),
            );
        }
    }
    Ok(())
}

/// Cushion noses: the linear segments and the jaws, as thin light lines.
fn draw_cushions(p: &mut Pixmap, view: &View, config: &PoolConfig) {
    let table = &config.table;
    let mut pb = PathBuilder::new();
    for seg in &table.linear {
        let (ax, ay) = view.px(seg.p1[0], seg.p1[1]);
        let (bx, by) = view.px(seg.p2[0], seg.p2[1]);
        pb.move_to(ax, ay);
        pb.line_to(bx, by);
    }
    if let Some(path) = pb.finish() {
        let s = Stroke {
            width: 1.2,
            line_cap: LineCap::Round,
            ..Stroke::default()
        };
        p.stroke_path(
            &path,
            &paint([150, 210, 170]),
            &s,
            Transform::identity(),
            None,
        );
    }
    for jaw in &table.circular {
        let (cx, cy) = view.px(jaw.center[0], jaw.center[1]);
        fill_circle(p, cx, cy, jaw.radius as f32 * view.scale, [22, 96, 52]);
    }
}

/// Pocket labels outside the rails, on the side of the pocket.
fn draw_pocket_labels(p: &mut Pixmap, layout: &Layout, config: &PoolConfig) {
    let (table, view, label_h) = (&config.table, &layout.view, layout.label_h);
    for pk in &table.pockets {
        let (_, cy) = view.px(pk.center[0], pk.center[1]);
        let w = text_width(&pk.id, label_h);
        let right = pk.center[0] > table.w / 2.0;
        let lx = if right {
            view.px(table.w + OUTER, 0.0).0 + 0.4 * label_h
        } else {
            view.px(-OUTER, 0.0).0 - 0.4 * label_h - w
        };
        text(
            p,
            lx,
            cy - label_h / 2.0,
            label_h,
            &pk.id,
            [60, 60, 60],
            None,
        );
    }
}

/// The balls of `step` on the table, and the pocketed ones in a tray right of the table, top to
/// bottom.
fn draw_balls(
    p: &mut Pixmap,
    view: &View,
    trace: &Trace,
    step: &Timestep,
    config: &PoolConfig,
    size: u32,
) -> Result<(), EnvError> {
    let table = &config.table;
    let mut pocketed: Vec<&PoolBall> = Vec::new();
    for obj in &step.objects {
        let Body::Pool(b) = &obj.body else {
            return Err(EnvError::Render(format!(
                "trace {} is not a billiards trace",
                trace.trace_id
            )));
        };
        if b.motion_state_code == 4 {
            pocketed.push(b);
            continue;
        }
        let (cx, cy) = view.px(b.position[0], b.position[1]);
        draw_ball(p, cx, cy, b.radius as f32 * view.scale, &b.ball_id);
    }
    let r = config.ball.r as f32 * view.scale;
    let tray_x =
        view.px(table.w + OUTER, 0.0).0 + (size as f32 - view.px(table.w + OUTER, 0.0).0) / 2.0;
    for (i, b) in pocketed.iter().enumerate() {
        let cy = size as f32 * 0.2 + i as f32 * 2.6 * r;
        draw_ball(p, tray_x, cy, r, &b.ball_id);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::Environment;
    use crate::envs::pool::{PoolEnv, Shot};

    /// A slow shot on the first seeded rack (seed 3).
    fn gentle_shot() -> (PoolEnv, Trace) {
        let env = PoolEnv::default();
        let scene = &env.scenes(1, 3).unwrap()[0];
        let shot = Shot {
            v0: 1.0,
            phi: 80.0,
            theta: 0.0,
            a: 0.0,
            b: 0.0,
        };
        let tr = env.simulate(scene, &shot).unwrap();
        (env, tr)
    }

    #[test]
    fn renders_a_512_png_and_a_strip() {
        let (env, tr) = gentle_shot();
        let png = render_png(&tr, &env.config, 0.0, &RenderOptions::default()).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        let img = Pixmap::decode_png(&png).unwrap();
        assert_eq!((img.width(), img.height()), (512, 512));
        let strip = render_strip_png(
            &tr,
            &env.config,
            &strip_times(&tr, 3),
            &RenderOptions::default(),
        )
        .unwrap();
        let img = Pixmap::decode_png(&strip).unwrap();
        assert_eq!((img.width(), img.height()), (1536, 512));
        assert!(render_png(&tr, &env.config, f64::NAN, &RenderOptions::default()).is_err());
    }

    #[test]
    fn nearest_timestep() {
        let (_, tr) = gentle_shot();
        assert_eq!(timestep_at(&tr, -1.0).unwrap().index, 0);
        assert_eq!(timestep_at(&tr, 0.026).unwrap().index, 3);
        assert_eq!(
            timestep_at(&tr, 1e9).unwrap().index,
            tr.timesteps.last().unwrap().index
        );
    }
}
