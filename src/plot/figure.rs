//! One small plotting module: a figure is axes (label and unit each) and series of points (a line
//! with an optional ±std band, points, or grouped bars over categories), written as SVG for papers
//! (all text) or PNG for quick looks (tiny-skia: the same marks, axes, ticks and legend swatches; the
//! PNG carries no text, since no font ships with annotrace — the SVG has the labels).
//!
//! **Owns:** layout (frame, ticks at 1-2-5 steps, legend), colours and both encodings. **Does not:**
//! aggregate data (each plot kind's query or caller does) or read run folders.

use std::fmt::Write as _;

/// An axis: what it measures and in which unit.
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    /// What the axis measures (`optimisation budget`).
    pub label: String,
    /// Its unit (`samples`, `%`), shown in parentheses; empty for none.
    pub unit: String,
    /// Lower end (default: 0, or the data's minimum when negative).
    pub min: Option<f64>,
    /// Upper end (default: the data's maximum, rounded up to a tick).
    pub max: Option<f64>,
}

impl Axis {
    /// An axis with a label and unit and automatic range.
    pub fn new(label: &str, unit: &str) -> Axis {
        Axis {
            label: label.into(),
            unit: unit.into(),
            min: None,
            max: None,
        }
    }

    /// The same axis with a fixed range.
    pub fn range(mut self, min: f64, max: f64) -> Axis {
        self.min = Some(min);
        self.max = Some(max);
        self
    }

    /// `label (unit)`.
    pub fn title(&self) -> String {
        if self.unit.is_empty() {
            self.label.clone()
        } else {
            format!("{} ({})", self.label, self.unit)
        }
    }
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mark {
    /// A line through the points, with a shaded band of ± `err` where given.
    Line,
    /// Dots.
    Points,
    /// Bars over the figure's categories (x = category index), grouped by series, with error whiskers.
    Bars,
}

/// One point: x, y and an optional spread (a standard deviation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// Position on the x axis (a category index for bars).
    pub x: f64,
    /// Value.
    pub y: f64,
    /// Spread drawn as a band or whisker (0: none).
    pub err: f64,
}

/// A named series.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// How it is drawn.
    pub mark: Mark,
    /// Its points, by increasing x.
    pub points: Vec<Point>,
}

/// A figure.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// Title line.
    pub title: String,
    /// Horizontal axis.
    pub x: Axis,
    /// Vertical axis.
    pub y: Axis,
    /// Category names for bar figures (x = 0, 1, …), empty otherwise.
    pub categories: Vec<String>,
    /// The series.
    pub series: Vec<Series>,
}

const W: f64 = 640.0;
const H: f64 = 420.0;
const LEFT: f64 = 74.0;
const RIGHT: f64 = 20.0;
const TOP: f64 = 40.0;
const BOTTOM: f64 = 60.0;

/// Series colours (matplotlib's tab10).
pub const PALETTE: [[u8; 3]; 10] = [
    [31, 119, 180],
    [214, 39, 40],
    [44, 160, 44],
    [148, 103, 189],
    [255, 127, 14],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
    [188, 189, 34],
    [23, 190, 207],
];

/// The colour of series `i`.
pub fn colour(i: usize) -> [u8; 3] {
    PALETTE[i % PALETTE.len()]
}

/// A "nice" tick step (1, 2 or 5 × 10^k) giving at most about `n` intervals over `span`.
fn nice_step(span: f64, n: f64) -> f64 {
    if !(span.is_finite() && span > 0.0) {
        return 1.0;
    }
    let raw = span / n;
    let mag = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag)
}

/// The plotting frame: data ranges mapped into the plot area.
struct Frame {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
    xstep: f64,
    ystep: f64,
    bars: bool,
}

impl Frame {
    fn of(f: &Figure) -> Frame {
        let pts = || f.series.iter().flat_map(|s| s.points.iter());
        let bars = f.series.iter().any(|s| s.mark == Mark::Bars);
        let (dx0, dx1) = if bars {
            (-0.5, f.categories.len().max(1) as f64 - 0.5)
        } else {
            pts().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                (a.min(p.x), b.max(p.x))
            })
        };
        let (dy0, dy1) = pts().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.y - p.err), b.max(p.y + p.err))
        });
        let (dx0, dx1) = if dx0.is_finite() {
            (dx0, dx1)
        } else {
            (0.0, 1.0)
        };
        let (dy0, dy1) = if dy0.is_finite() {
            (dy0, dy1)
        } else {
            (0.0, 1.0)
        };
        let x0 = f.x.min.unwrap_or(if bars { dx0 } else { dx0.min(0.0) });
        let mut x1 = f.x.max.unwrap_or(dx1);
        if x1 <= x0 {
            x1 = x0 + 1.0;
        }
        let ystep = nice_step(
            f.y.max.unwrap_or(dy1) - f.y.min.unwrap_or(dy0.min(0.0)),
            5.0,
        );
        let y0 = f.y.min.unwrap_or(if dy0 < 0.0 {
            (dy0 / ystep).floor() * ystep
        } else {
            0.0
        });
        let mut y1 = f.y.max.unwrap_or((dy1 / ystep).ceil() * ystep);
        if y1 <= y0 {
            y1 = y0 + 1.0;
        }
        Frame {
            x0,
            x1,
            y0,
            y1,
            xstep: nice_step(x1 - x0, 8.0),
            ystep: nice_step(y1 - y0, 5.0),
            bars,
        }
    }
    fn x(&self, v: f64) -> f64 {
        LEFT + (v - self.x0) / (self.x1 - self.x0) * (W - LEFT - RIGHT)
    }
    fn y(&self, v: f64) -> f64 {
        H - BOTTOM - ((v - self.y0) / (self.y1 - self.y0)).clamp(0.0, 1.0) * (H - TOP - BOTTOM)
    }
    fn ticks(a: f64, b: f64, step: f64) -> Vec<f64> {
        let first = (a / step).ceil() as i64;
        let last = (b / step + 1e-9).floor() as i64;
        (first..=last.min(first + 50))
            .map(|k| k as f64 * step)
            .collect()
    }
    fn x_ticks(&self, f: &Figure) -> Vec<(f64, String)> {
        if self.bars {
            return f
                .categories
                .iter()
                .enumerate()
                .map(|(i, c)| (i as f64, c.clone()))
                .collect();
        }
        Self::ticks(self.x0, self.x1, self.xstep)
            .into_iter()
            .map(|t| (t, tick_text(t, self.xstep)))
            .collect()
    }
    fn y_ticks(&self) -> Vec<(f64, String)> {
        Self::ticks(self.y0, self.y1, self.ystep)
            .into_iter()
            .map(|t| (t, tick_text(t, self.ystep)))
            .collect()
    }
    /// Bar `j` of `n` series at category `x`: (left, width) in pixels.
    fn bar(&self, x: f64, j: usize, n: usize) -> (f64, f64) {
        let slot = (self.x(1.0) - self.x(0.0)) * 0.8;
        let w = slot / n.max(1) as f64;
        (self.x(x) - slot / 2.0 + j as f64 * w, w)
    }
}

/// [`nice_step`] for the other figures of the module.
pub(crate) fn nice_step_pub(span: f64, n: f64) -> f64 {
    nice_step(span, n)
}

/// [`tick_text`] for the other figures of the module.
pub(crate) fn tick_text_pub(v: f64, step: f64) -> String {
    tick_text(v, step)
}

fn tick_text(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10().floor()) as usize
    };
    format!("{v:.decimals$}")
}

fn esc(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn rgb(c: [u8; 3]) -> String {
    format!("rgb({},{},{})", c[0], c[1], c[2])
}

/// The figure as SVG text. Structure (relied on by tests): one `<g class="axis x">` and one
/// `<g class="axis y">` with their ticks and titles, one `<g class="series">` per series with its
/// `data-name`, one `<g class="legend">`.
pub fn svg(f: &Figure) -> String {
    let fr = Frame::of(f);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="{W}" height="{H}" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text class="title" x="{}" y="22" text-anchor="middle" font-size="14">{}</text>"#,
        W / 2.0,
        esc(&f.title)
    );
    s.push_str("<g class=\"axis y\">\n");
    for (t, text) in fr.y_ticks() {
        let y = fr.y(t);
        let _ = writeln!(
            s,
            r##"<line x1="{LEFT}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text class="tick" x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
            W - RIGHT,
            LEFT - 6.0,
            y + 4.0,
            esc(&text)
        );
    }
    let _ = writeln!(
        s,
        r#"<text class="label" transform="translate(18 {:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
        (TOP + H - BOTTOM) / 2.0,
        esc(&f.y.title())
    );
    s.push_str("</g>\n<g class=\"axis x\">\n");
    for (t, text) in fr.x_ticks(f) {
        let x = fr.x(t);
        let _ = writeln!(
            s,
            r##"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#333"/><text class="tick" x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
            H - BOTTOM,
            H - BOTTOM + 5.0,
            H - BOTTOM + 18.0,
            esc(&text)
        );
    }
    let _ = writeln!(
        s,
        r#"<text class="label" x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
        (LEFT + W - RIGHT) / 2.0,
        H - 18.0,
        esc(&f.x.title())
    );
    s.push_str("</g>\n");
    let _ = writeln!(
        s,
        r##"<rect x="{LEFT}" y="{TOP}" width="{:.1}" height="{:.1}" fill="none" stroke="#333"/>"##,
        W - LEFT - RIGHT,
        H - TOP - BOTTOM
    );
    let n_bars = f.series.iter().filter(|s| s.mark == Mark::Bars).count();
    let mut bar_j = 0;
    for (i, se) in f.series.iter().enumerate() {
        let c = rgb(colour(i));
        let _ = writeln!(s, r#"<g class="series" data-name="{}">"#, esc(&se.name));
        match se.mark {
            Mark::Line => {
                if se.points.iter().any(|p| p.err > 0.0) {
                    let upper = se
                        .points
                        .iter()
                        .map(|p| format!("{:.1},{:.1}", fr.x(p.x), fr.y(p.y + p.err)));
                    let lower = se
                        .points
                        .iter()
                        .rev()
                        .map(|p| format!("{:.1},{:.1}", fr.x(p.x), fr.y(p.y - p.err)));
                    let pts: Vec<String> = upper.chain(lower).collect();
                    let _ = writeln!(
                        s,
                        r#"<polygon class="band" points="{}" fill="{c}" fill-opacity="0.2" stroke="none"/>"#,
                        pts.join(" ")
                    );
                }
                let line: Vec<String> = se
                    .points
                    .iter()
                    .map(|p| format!("{:.1},{:.1}", fr.x(p.x), fr.y(p.y)))
                    .collect();
                let _ = writeln!(
                    s,
                    r#"<polyline points="{}" fill="none" stroke="{c}" stroke-width="2"/>"#,
                    line.join(" ")
                );
            }
            Mark::Points => {
                for p in &se.points {
                    let _ = writeln!(
                        s,
                        r#"<circle cx="{:.1}" cy="{:.1}" r="2.5" fill="{c}"/>"#,
                        fr.x(p.x),
                        fr.y(p.y)
                    );
                }
            }
            Mark::Bars => {
                for p in &se.points {
                    let (x, w) = fr.bar(p.x, bar_j, n_bars);
                    let (y, base) = (fr.y(p.y.max(fr.y0)), fr.y(fr.y0.max(0.0)));
                    let _ = writeln!(
                        s,
                        r#"<rect x="{x:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="{c}"/>"#,
                        y.min(base),
                        w * 0.92,
                        (base - y).abs()
                    );
                    if p.err > 0.0 {
                        let cx = x + w * 0.46;
                        let _ = writeln!(
                            s,
                            r##"<line x1="{cx:.1}" y1="{:.1}" x2="{cx:.1}" y2="{:.1}" stroke="#222"/>"##,
                            fr.y(p.y - p.err),
                            fr.y(p.y + p.err)
                        );
                    }
                }
                bar_j += 1;
            }
        }
        s.push_str("</g>\n");
    }
    s.push_str("<g class=\"legend\">\n");
    for (i, se) in f.series.iter().enumerate() {
        let ly = TOP + 14.0 + 16.0 * i as f64;
        let _ = writeln!(
            s,
            r#"<rect x="{:.1}" y="{:.1}" width="18" height="6" fill="{}"/><text x="{:.1}" y="{:.1}">{}</text>"#,
            LEFT + 10.0,
            ly - 3.0,
            rgb(colour(i)),
            LEFT + 34.0,
            ly + 4.0,
            esc(&se.name)
        );
    }
    s.push_str("</g>\n</svg>\n");
    s
}

/// The figure as PNG bytes: the same marks, frame, grid, ticks and legend swatches as [`svg`], without
/// text.
pub fn png(f: &Figure) -> Result<Vec<u8>, String> {
    use tiny_skia::{Color, FillRule, Paint, PathBuilder, Pixmap, Rect, Stroke, Transform};
    let fr = Frame::of(f);
    let mut pm = Pixmap::new(W as u32, H as u32).ok_or("cannot allocate the image")?;
    pm.fill(Color::WHITE);
    let paint = |c: [u8; 3], a: u8| {
        let mut p = Paint::default();
        p.set_color_rgba8(c[0], c[1], c[2], a);
        p.anti_alias = true;
        p
    };
    let poly = |pts: &[(f64, f64)], close: bool| {
        let mut pb = PathBuilder::new();
        for (k, (x, y)) in pts.iter().enumerate() {
            if k == 0 {
                pb.move_to(*x as f32, *y as f32);
            } else {
                pb.line_to(*x as f32, *y as f32);
            }
        }
        if close {
            pb.close();
        }
        pb.finish()
    };
    let stroke = |pm: &mut Pixmap, pts: &[(f64, f64)], c: [u8; 3], width: f32| {
        if let Some(path) = poly(pts, false) {
            let st = Stroke {
                width,
                ..Stroke::default()
            };
            pm.stroke_path(&path, &paint(c, 255), &st, Transform::identity(), None);
        }
    };
    let rect = |pm: &mut Pixmap, x: f64, y: f64, w: f64, h: f64, c: [u8; 3], a: u8| {
        if let Some(r) = Rect::from_xywh(x as f32, y as f32, w as f32, h as f32) {
            // Axis-aligned: no anti-aliasing (tiny-skia's hairline path asserts on some thin ones).
            let mut p = paint(c, a);
            p.anti_alias = false;
            pm.fill_rect(r, &p, Transform::identity(), None);
        }
    };
    for (t, _) in fr.y_ticks() {
        stroke(
            &mut pm,
            &[(LEFT, fr.y(t)), (W - RIGHT, fr.y(t))],
            [221, 221, 221],
            1.0,
        );
    }
    for (t, _) in fr.x_ticks(f) {
        let x = fr.x(t);
        stroke(
            &mut pm,
            &[(x, H - BOTTOM), (x, H - BOTTOM + 5.0)],
            [51, 51, 51],
            1.0,
        );
    }
    let n_bars = f.series.iter().filter(|s| s.mark == Mark::Bars).count();
    let mut bar_j = 0;
    for (i, se) in f.series.iter().enumerate() {
        let c = colour(i);
        match se.mark {
            Mark::Line => {
                if se.points.iter().any(|p| p.err > 0.0) {
                    let mut pts: Vec<(f64, f64)> = se
                        .points
                        .iter()
                        .map(|p| (fr.x(p.x), fr.y(p.y + p.err)))
                        .collect();
                    pts.extend(
                        se.points
                            .iter()
                            .rev()
                            .map(|p| (fr.x(p.x), fr.y(p.y - p.err))),
                    );
                    if let Some(path) = poly(&pts, true) {
                        pm.fill_path(
                            &path,
                            &paint(c, 51),
                            FillRule::Winding,
                            Transform::identity(),
                            None,
                        );
                    }
                }
                let pts: Vec<(f64, f64)> =
                    se.points.iter().map(|p| (fr.x(p.x), fr.y(p.y))).collect();
                stroke(&mut pm, &pts, c, 2.0);
            }
            Mark::Points => {
                for p in &se.points {
                    if let Some(path) =
                        PathBuilder::from_circle(fr.x(p.x) as f32, fr.y(p.y) as f32, 2.5)
                    {
                        pm.fill_path(
                            &path,
                            &paint(c, 255),
                            FillRule::Winding,
                            Transform::identity(),
                            None,
                        );
                    }
                }
            }
            Mark::Bars => {
                for p in &se.points {
                    let (x, w) = fr.bar(p.x, bar_j, n_bars);
                    let (y, base) = (fr.y(p.y.max(fr.y0)), fr.y(fr.y0.max(0.0)));
                    rect(&mut pm, x, y.min(base), w * 0.92, (base - y).abs(), c, 255);
                    if p.err > 0.0 {
                        let cx = x + w * 0.46;
                        stroke(
                            &mut pm,
                            &[(cx, fr.y(p.y - p.err)), (cx, fr.y(p.y + p.err))],
                            [34, 34, 34],
                            1.0,
                        );
                    }
                }
                bar_j += 1;
            }
        }
        let ly = TOP + 14.0 + 16.0 * i as f64;
        rect(&mut pm, LEFT + 10.0, ly - 3.0, 18.0, 6.0, c, 255);
    }
    stroke(
        &mut pm,
        &[
            (LEFT, TOP),
            (W - RIGHT, TOP),
            (W - RIGHT, H - BOTTOM),
            (LEFT, H - BOTTOM),
            (LEFT, TOP),
        ],
        [51, 51, 51],
        1.0,
    );
    pm.encode_png().map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_cover_the_data() {
        assert_eq!(nice_step(1.0, 5.0), 0.2);
        assert_eq!(nice_step(430.0, 8.0), 100.0);
        assert_eq!(nice_step(0.0, 5.0), 1.0);
        let f = Figure {
            title: "t".into(),
            x: Axis::new("budget", "samples"),
            y: Axis::new("success rate", ""),
            categories: vec![],
            series: vec![Series {
                name: "a".into(),
                mark: Mark::Line,
                points: vec![
                    Point {
                        x: 0.0,
                        y: 0.1,
                        err: 0.0,
                    },
                    Point {
                        x: 430.0,
                        y: 0.73,
                        err: 0.1,
                    },
                ],
            }],
        };
        let fr = Frame::of(&f);
        assert_eq!((fr.y0, fr.y1), (0.0, 1.0));
        assert_eq!(fr.x_ticks(&f).last().unwrap().1, "400");
        assert_eq!(fr.y_ticks()[1].1, "0.2");
    }
}
