//! PNG pictures of I-PHYRE scenes and traces: the 600×600 screen scaled to the picture size, in the
//! original's colours (white screen, eliminable blocks gray (164,164,164), fixed blocks black, dynamic
//! blocks pymunk blue (52,152,219), balls red, pin joints and springs purple lines between body centres).
//!
//! **Owns:** drawing a game's initial scene ([`render_scene_png`]), one instant of a trace
//! ([`render_png`]) and a strip of instants ([`render_strip_png`]); optionally the eliminable blocks'
//! action indices 0…k−1 on the blocks, as DeepPHY shows them to a VLM (docs/envs/iphyre.md §R8).
//! **Does not:** read run folders (the CLI does) or simulate. Object states come from the trace's
//! timesteps (the step nearest to the requested time, `pool::render::timestep_at`), so any I-PHYRE
//! trace in a run can be drawn; removed blocks are simply absent from later steps.
//!
//! Text (indices, the time) uses a small stroke font of our own: seven-segment digits plus `t = . s`.

use tiny_skia::{Color, LineCap, LineJoin, PathBuilder, Pixmap, Stroke, Transform};

use super::action::SCREEN;
use super::game::{Game, ObjectKind};
use crate::envs::EnvError;
use crate::envs::draw::{self, encode_png, fill_circle, new_pixmap, paint};
use crate::envs::pool::render::timestep_at;
use crate::trace::{Body, Trace};

/// Picture options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderOptions {
    /// Width and height of one frame in pixels (default 512).
    pub size: u32,
    /// Draw each eliminable block's action index (0-based, in object order) on it.
    pub block_indices: bool,
    /// Draw the time in the top-left corner (trace frames only).
    pub time_label: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            size: 512,
            block_indices: false,
            time_label: true,
        }
    }
}

const GRAY: [u8; 3] = [164, 164, 164];
const BLACK: [u8; 3] = [0, 0, 0];
const BLUE: [u8; 3] = [52, 152, 219];
const RED: [u8; 3] = [220, 30, 30];
const PURPLE: [u8; 3] = [150, 60, 190];
const INDEX_BLUE: [u8; 3] = [20, 40, 230];

/// One object to draw, in screen pixels.
#[derive(Debug, Clone, Copy)]
struct Item {
    index: usize,
    ball: bool,
    p1: [f64; 2],
    p2: [f64; 2],
    radius: f64,
    eliminable: bool,
    dynamic: bool,
    joint: i64,
    spring: i64,
}

impl Item {
    fn centre(&self) -> [f64; 2] {
        [
            (self.p1[0] + self.p2[0]) / 2.0,
            (self.p1[1] + self.p2[1]) / 2.0,
        ]
    }
}

fn items_of_game(game: &Game) -> Vec<Item> {
    game.objects
        .iter()
        .map(|o| Item {
            index: o.index,
            ball: o.kind == ObjectKind::Ball,
            p1: o.p1,
            p2: o.p2,
            radius: o.radius,
            eliminable: o.eliminable,
            dynamic: o.dynamic,
            joint: o.joint,
            spring: o.spring,
        })
        .collect()
}

/// The initial scene of `game`, as PNG bytes.
pub fn render_scene_png(game: &Game, opts: &RenderOptions) -> Result<Vec<u8>, EnvError> {
    let order = eliminable_order(&items_of_game(game));
    let p = draw(&items_of_game(game), &order, None, opts)?;
    encode_png(&p)
}

/// The timestep of `trace` nearest to `t`, as PNG bytes. `game`, when given, supplies which objects
/// are balls and the eliminable blocks' action indices; without it a ball is an object whose two ends
/// coincide and indices follow the objects present at the first timestep.
pub fn render_png(
    trace: &Trace,
    game: Option<&Game>,
    t: f64,
    opts: &RenderOptions,
) -> Result<Vec<u8>, EnvError> {
    encode_png(&frame(trace, game, t, opts)?)
}

/// Frames at `times`, side by side left to right (`size·k` × `size` pixels), as PNG bytes.
pub fn render_strip_png(
    trace: &Trace,
    game: Option<&Game>,
    times: &[f64],
    opts: &RenderOptions,
) -> Result<Vec<u8>, EnvError> {
    let mut strip = draw::strip(times.len(), opts.size, |i| {
        frame(trace, game, times[i], opts)
    })?;
    // A thin separator between frames (frames are opaque, so no background shows elsewhere).
    for i in 1..times.len() {
        fill_rect(
            &mut strip,
            (i as u32 * opts.size) as f32 - 1.0,
            0.0,
            2.0,
            opts.size as f32,
            [90, 90, 90],
        );
    }
    encode_png(&strip)
}

/// Action index of each eliminable block: position among the eliminable objects in object order.
fn eliminable_order(items: &[Item]) -> Vec<(usize, usize)> {
    items
        .iter()
        .filter(|i| i.eliminable && !i.ball)
        .enumerate()
        .map(|(k, i)| (i.index, k))
        .collect()
}

fn frame(
    trace: &Trace,
    game: Option<&Game>,
    t: f64,
    opts: &RenderOptions,
) -> Result<Pixmap, EnvError> {
    if !t.is_finite() {
        return Err(EnvError::Render(format!("time {t} is not a finite number")));
    }
    let ts = timestep_at(trace, t)
        .ok_or_else(|| EnvError::Render(format!("trace {} has no timesteps", trace.trace_id)))?;
    let items_at = |objects: &[crate::trace::Object]| -> Result<Vec<Item>, EnvError> {
        objects
            .iter()
            .map(|o| match &o.body {
                Body::Iphyre(b) => {
                    let index = usize::try_from(b.index).map_err(|_| {
                        EnvError::Render(format!("object index {} is negative", b.index))
                    })?;
                    let ball = match game.and_then(|g| g.objects.get(index)) {
                        Some(go) => go.kind == ObjectKind::Ball,
                        None => b.x1 == b.x2 && b.y1 == b.y2,
                    };
                    Ok(Item {
                        index,
                        ball,
                        p1: [b.x1, b.y1],
                        p2: [b.x2, b.y2],
                        radius: b.radius,
                        eliminable: b.eliminable > 0.5,
                        dynamic: b.dynamic > 0.5,
                        joint: b.joint,
                        spring: b.spring,
                    })
                }
                _ => Err(EnvError::Render(format!(
                    "trace {} is not an I-PHYRE trace",
                    trace.trace_id
                ))),
            })
            .collect()
    };
    let items = items_at(&ts.objects)?;
    let order = match (game, trace.timesteps.first()) {
        (Some(g), _) => eliminable_order(&items_of_game(g)),
        (None, Some(first)) => eliminable_order(&items_at(&first.objects)?),
        (None, None) => Vec::new(),
    };
    draw(&items, &order, opts.time_label.then_some(ts.t), opts)
}

fn fill_rect(p: &mut Pixmap, x: f32, y: f32, w: f32, h: f32, c: [u8; 3]) {
    if let Some(r) = tiny_skia::Rect::from_xywh(x, y, w, h) {
        p.fill_rect(r, &paint(c), Transform::identity(), None);
    }
}

fn line(p: &mut Pixmap, a: (f32, f32), b: (f32, f32), width: f32, c: [u8; 3]) {
    let mut pb = PathBuilder::new();
    pb.move_to(a.0, a.1);
    pb.line_to(b.0, b.1);
    if let Some(path) = pb.finish() {
        let stroke = Stroke {
            width,
            line_cap: LineCap::Round,
            line_join: LineJoin::Round,
            ..Stroke::default()
        };
        p.stroke_path(&path, &paint(c), &stroke, Transform::identity(), None);
    }
}

fn draw(
    items: &[Item],
    order: &[(usize, usize)],
    time: Option<f64>,
    opts: &RenderOptions,
) -> Result<Pixmap, EnvError> {
    let size = opts.size.max(64);
    let mut p = new_pixmap(size, size)?;
    p.fill(Color::WHITE);
    let k = size as f32 / SCREEN as f32;
    let px = |q: [f64; 2]| (q[0] as f32 * k, q[1] as f32 * k);
    for it in items.iter().filter(|i| !i.ball) {
        let colour = if it.dynamic {
            BLUE
        } else if it.eliminable {
            GRAY
        } else {
            BLACK
        };
        line(
            &mut p,
            px(it.p1),
            px(it.p2),
            (2.0 * it.radius) as f32 * k,
            colour,
        );
    }
    for it in items.iter().filter(|i| i.ball) {
        let (cx, cy) = px(it.p1);
        fill_circle(&mut p, cx, cy, it.radius as f32 * k, RED);
    }
    // Constraints: the two objects sharing a joint (spring) number, centre to centre.
    let picks: [fn(&Item) -> i64; 2] = [|i| i.joint, |i| i.spring];
    for pick in picks {
        let mut ends: Vec<(i64, [f64; 2])> = items
            .iter()
            .filter(|i| pick(i) > 0)
            .map(|i| (pick(i), i.centre()))
            .collect();
        ends.sort_by_key(|e| e.0);
        for w in ends.windows(2) {
            if w[0].0 == w[1].0 {
                line(&mut p, px(w[0].1), px(w[1].1), (2.0 * k).max(1.0), PURPLE);
            }
        }
    }
    if opts.block_indices {
        for it in items.iter().filter(|i| i.eliminable && !i.ball) {
            if let Some(&(_, n)) = order.iter().find(|(index, _)| *index == it.index) {
                let label = n.to_string();
                let h = (26.0 * k).max(9.0);
                let (cx, cy) = px(it.centre());
                let w = text_width(&label, h);
                text(&mut p, cx - w / 2.0, cy - h / 2.0, h, &label, INDEX_BLUE);
            }
        }
    }
    if let Some(t) = time {
        let h = (22.0 * k).max(9.0);
        text(&mut p, 8.0 * k, 8.0 * k, h, &format!("t = {t:.2} s"), BLACK);
    }
    Ok(p)
}

/// Seven-segment layout on a 4 × 6 grid: a top, b top right, c bottom right, d bottom, e bottom left,
/// f top left, g middle.
const SEGMENTS: [[(f32, f32); 2]; 7] = [
    [(0., 0.), (4., 0.)],
    [(4., 0.), (4., 3.)],
    [(4., 3.), (4., 6.)],
    [(0., 6.), (4., 6.)],
    [(0., 3.), (0., 6.)],
    [(0., 0.), (0., 3.)],
    [(0., 3.), (4., 3.)],
];

/// Which segments each digit lights (bits a…g from the lowest).
const DIGITS: [u8; 10] = [
    0b0111111, 0b0000110, 0b1011011, 0b1001111, 0b1100110, 0b1101101, 0b1111101, 0b0000111,
    0b1111111, 0b1101111,
];

/// Strokes of one character on the 4 × 6 grid.
fn strokes(c: char) -> Vec<Vec<(f32, f32)>> {
    if let Some(d) = c.to_digit(10) {
        return SEGMENTS
            .iter()
            .enumerate()
            .filter(|(i, _)| DIGITS[d as usize] >> i & 1 == 1)
            .map(|(_, s)| s.to_vec())
            .collect();
    }
    match c {
        '.' => vec![vec![(1.8, 5.8), (2.2, 5.8)]],
        '=' => vec![vec![(0., 2.3), (4., 2.3)], vec![(0., 4.2), (4., 4.2)]],
        't' => vec![
            vec![(1.5, 0.5), (1.5, 6.), (3.5, 6.)],
            vec![(0., 2.2), (3.5, 2.2)],
        ],
        's' => vec![vec![
            (4., 2.),
            (0., 2.),
            (0., 4.),
            (4., 4.),
            (4., 6.),
            (0., 6.),
        ]],
        _ => Vec::new(),
    }
}

fn text_width(s: &str, h: f32) -> f32 {
    let n = s.chars().count() as f32;
    (n * 5.5 - 1.5) * h / 6.0
}

/// Draws `s` with its top-left corner at (x, y), glyph height `h`, on a white halo.
fn text(p: &mut Pixmap, x: f32, y: f32, h: f32, s: &str, colour: [u8; 3]) {
    let k = h / 6.0;
    let mut pb = PathBuilder::new();
    for (i, c) in s.chars().enumerate() {
        let gx = x + i as f32 * 5.5 * k;
        for stroke in strokes(c) {
            for (j, &(u, v)) in stroke.iter().enumerate() {
                if j == 0 {
                    pb.move_to(gx + u * k, y + v * k);
                } else {
                    pb.line_to(gx + u * k, y + v * k);
                }
            }
        }
    }
    let Some(path) = pb.finish() else { return };
    let width = (h / 6.5).max(1.2);
    for (w, c) in [(width + 2.5, [255, 255, 255]), (width, colour)] {
        let stroke = Stroke {
            width: w,
            line_cap: LineCap::Round,
            line_join: LineJoin::Round,
            ..Stroke::default()
        };
        p.stroke_path(&path, &paint(c), &stroke, Transform::identity(), None);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::draw::png_pixel as pixel;
    use crate::envs::iphyre::Games;
    use crate::envs::iphyre::to_trace::support_episode;

    #[test]
    fn scene_has_the_original_colours_where_the_objects_are() {
        let games = Games::default_games().unwrap();
        let g = games.get("support").unwrap(); // blocks (200,400)-(300,400), (200,500)-(300,500) eliminable; ball (250,340) r 20
        let opts = RenderOptions {
            size: 600,
            block_indices: false,
            time_label: false,
        };
        let png = render_scene_png(g, &opts).unwrap();
        assert_eq!(pixel(&png, 230, 400), GRAY);
        assert_eq!(pixel(&png, 250, 340), RED);
        assert_eq!(pixel(&png, 50, 50), [255, 255, 255]);
        let with = render_scene_png(
            g,
            &RenderOptions {
                block_indices: true,
                ..opts
            },
        )
        .unwrap();
        assert_ne!(png, with, "indices must change the picture");
        // The index "0" sits on block 0's centre: its strokes are blue, not gray.
        let p = Pixmap::decode_png(&with).unwrap();
        let blue = (235..265)
            .flat_map(|x| (385..415).map(move |y| (x, y)))
            .filter(|&(x, y)| {
                let c = p.pixel(x, y).unwrap();
                c.blue() > 200 && c.red() < 60
            })
            .count();
        assert!(blue > 20, "{blue} blue pixels");
    }

    #[test]
    fn trace_frames_follow_the_motion_and_strips_are_wide() {
        let (game, _, tr) = support_episode("support-render");
        let g = &game;
        let opts = RenderOptions {
            size: 600,
            block_indices: true,
            time_label: false,
        };
        let start = render_png(&tr, Some(g), 0.0, &opts).unwrap();
        let end = render_png(&tr, Some(g), 100.0, &opts).unwrap();
        assert_eq!(pixel(&start, 250, 340), RED);
        assert_eq!(
            pixel(&end, 230, 400),
            [255, 255, 255],
            "block 0 was removed"
        );
        assert_ne!(pixel(&end, 250, 340), RED, "the ball fell");
        let strip = render_strip_png(&tr, None, &[0.0, 1.0, 2.0], &opts).unwrap();
        let p = Pixmap::decode_png(&strip).unwrap();
        assert_eq!((p.width(), p.height()), (1800, 600));
        assert!(render_png(&tr, Some(g), f64::NAN, &opts).is_err());
        assert!(render_strip_png(&tr, None, &[], &opts).is_err());
    }
}
