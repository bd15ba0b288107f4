//! The success-versus-budget figure: for each reward type and budget, the success rate averaged over
//! goals and scenes for each seed, then the mean over seeds (line) and its standard deviation
//! (shaded band). Written as SVG (text, by hand) and PNG (tiny-skia, no text: axes, grid and legend
//! swatches only; the SVG carries the labels).

use std::collections::BTreeMap;
use std::fmt::Write as _;

/// One point of a curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// Samples spent.
    pub budget: f64,
    /// Mean success over seeds.
    pub mean: f64,
    /// Standard deviation over seeds (0 with one seed).
    pub std: f64,
}

/// One reward type's curve.
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    /// The reward type (`dense`, `sparse`).
    pub name: String,
    /// Points by increasing budget.
    pub points: Vec<Point>,
}

/// Curves from `(reward type, budget, seed, success)` rows (one per goal × scene × seed × budget).
pub fn curves<'a>(rows: impl IntoIterator<Item = (&'a str, u64, u64, bool)>) -> Vec<Curve> {
    // (type, budget) -> seed -> (successes, total)
    let mut acc: BTreeMap<(String, u64), BTreeMap<u64, (f64, f64)>> = BTreeMap::new();
    for (kind, budget, seed, success) in rows {
        let e = acc
            .entry((kind.to_string(), budget))
            .or_default()
            .entry(seed)
            .or_insert((0.0, 0.0));
        e.0 += if success { 1.0 } else { 0.0 };
        e.1 += 1.0;
    }
    let mut out: BTreeMap<String, Vec<Point>> = BTreeMap::new();
    for ((kind, budget), seeds) in acc {
        let rates: Vec<f64> = seeds.values().map(|(s, n)| s / n).collect();
        let n = rates.len() as f64;
        let mean = rates.iter().sum::<f64>() / n;
        let std = (rates.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
        out.entry(kind).or_default().push(Point {
            budget: budget as f64,
            mean,
            std,
        });
    }
    out.into_iter()
        .map(|(name, points)| Curve { name, points })
        .collect()
}

const W: f64 = 640.0;
const H: f64 = 420.0;
const LEFT: f64 = 70.0;
const RIGHT: f64 = 20.0;
const TOP: f64 = 40.0;
const BOTTOM: f64 = 60.0;

fn colour(i: usize) -> [u8; 3] {
    [
        [31, 119, 180],
        [214, 39, 40],
        [44, 160, 44],
        [148, 103, 189],
    ][i % 4]
}

struct Frame {
    x_max: f64,
    y_max: f64,
}

impl Frame {
    fn of(curves: &[Curve]) -> Frame {
        let x_max = curves
            .iter()
            .flat_map(|c| c.points.iter().map(|p| p.budget))
            .fold(1.0_f64, f64::max);
        let y_top = curves
            .iter()
            .flat_map(|c| c.points.iter().map(|p| p.mean + p.std))
            .fold(0.0_f64, f64::max);
        let y_max = if y_top <= 0.0 {
            0.1
        } else {
            ((y_top * 10.0).ceil() / 10.0).clamp(0.1, 1.0)
        };
        Frame { x_max, y_max }
    }
    fn x(&self, b: f64) -> f64 {
        LEFT + b / self.x_max * (W - LEFT - RIGHT)
    }
    fn y(&self, v: f64) -> f64 {
        H - BOTTOM - (v / self.y_max).clamp(0.0, 1.0) * (H - TOP - BOTTOM)
    }
    fn x_ticks(&self) -> Vec<f64> {
        let step = [50.0, 100.0, 200.0, 250.0, 500.0, 1000.0]
            .into_iter()
            .find(|s| self.x_max / s <= 10.0)
            .unwrap_or(1000.0);
        (0..=((self.x_max / step) as usize))
            .map(|i| i as f64 * step)
            .collect()
    }
    fn y_ticks(&self) -> Vec<f64> {
        (0..=5).map(|i| self.y_max * i as f64 / 5.0).collect()
    }
}

/// The figure as SVG text.
pub fn svg(curves: &[Curve], title: &str) -> String {
    let f = Frame::of(curves);
    let mut s = String::new();
    let esc = |t: &str| {
        t.replace('&', "&amp;")
            .replace('<', "&lt;")
            .replace('>', "&gt;")
    };
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="{W}" height="{H}" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="22" text-anchor="middle" font-size="14">{}</text>"#,
        W / 2.0,
        esc(title)
    );
    for t in f.y_ticks() {
        let y = f.y(t);
        let _ = writeln!(
            s,
            r##"<line x1="{LEFT}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">{t:.2}</text>"##,
            W - RIGHT,
            LEFT - 6.0,
            y + 4.0
        );
    }
    for t in f.x_ticks() {
        let x = f.x(t);
        let _ = writeln!(
            s,
            r##"<line x1="{x:.1}" y1="{TOP}" x2="{x:.1}" y2="{:.1}" stroke="#eee"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{t}</text>"##,
            H - BOTTOM,
            H - BOTTOM + 18.0
        );
    }
    let _ = writeln!(
        s,
        r##"<rect x="{LEFT}" y="{TOP}" width="{:.1}" height="{:.1}" fill="none" stroke="#333"/>"##,
        W - LEFT - RIGHT,
        H - TOP - BOTTOM
    );
    let _ = writeln!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">optimisation budget (samples)</text>"#,
        (LEFT + W - RIGHT) / 2.0,
        H - 18.0
    );
    let _ = writeln!(
        s,
        r#"<text transform="translate(18 {:.1}) rotate(-90)" text-anchor="middle">success rate</text>"#,
        (TOP + H - BOTTOM) / 2.0
    );
    for (i, c) in curves.iter().enumerate() {
        let [r, g, b] = colour(i);
        let upper: Vec<String> = c
            .points
            .iter()
            .map(|p| format!("{:.1},{:.1}", f.x(p.budget), f.y(p.mean + p.std)))
            .collect();
        let lower: Vec<String> = c
            .points
            .iter()
            .rev()
            .map(|p| format!("{:.1},{:.1}", f.x(p.budget), f.y((p.mean - p.std).max(0.0))))
            .collect();
        let _ = writeln!(
            s,
            r#"<polygon points="{} {}" fill="rgb({r},{g},{b})" fill-opacity="0.2" stroke="none"/>"#,
            upper.join(" "),
            lower.join(" ")
        );
        let line: Vec<String> = c
            .points
            .iter()
            .map(|p| format!("{:.1},{:.1}", f.x(p.budget), f.y(p.mean)))
            .collect();
        let _ = writeln!(
            s,
            r#"<polyline points="{}" fill="none" stroke="rgb({r},{g},{b})" stroke-width="2"/>"#,
            line.join(" ")
        );
        let ly = TOP + 16.0 + 18.0 * i as f64;
        let _ = writeln!(
            s,
            r#"<line x1="{:.1}" y1="{ly:.1}" x2="{:.1}" y2="{ly:.1}" stroke="rgb({r},{g},{b})" stroke-width="3"/><text x="{:.1}" y="{:.1}">{}</text>"#,
            LEFT + 12.0,
            LEFT + 36.0,
            LEFT + 42.0,
            ly + 4.0,
            esc(&c.name)
        );
    }
    s.push_str("</svg>\n");
    s
}

/// The figure as PNG bytes (no text; see the module docs).
pub fn png(curves: &[Curve]) -> Result<Vec<u8>, String> {
    use tiny_skia::{Color, FillRule, Paint, PathBuilder, Pixmap, Rect, Stroke, Transform};
    let f = Frame::of(curves);
    let mut pm = Pixmap::new(W as u32, H as u32).ok_or("cannot allocate the image")?;
    pm.fill(Color::WHITE);
    let paint = |rgb: [u8; 3], a: u8| {
        let mut p = Paint::default();
        p.set_color_rgba8(rgb[0], rgb[1], rgb[2], a);
        p.anti_alias = true;
        p
    };
    let line = |pm: &mut Pixmap, pts: &[(f64, f64)], rgb: [u8; 3], width: f32| {
        let mut pb = PathBuilder::new();
        for (k, (x, y)) in pts.iter().enumerate() {
            if k == 0 {
                pb.move_to(*x as f32, *y as f32);
            } else {
                pb.line_to(*x as f32, *y as f32);
            }
        }
        if let Some(path) = pb.finish() {
            let stroke = Stroke {
                width,
                ..Stroke::default()
            };
            pm.stroke_path(
                &path,
                &paint(rgb, 255),
                &stroke,
                Transform::identity(),
                None,
            );
        }
    };
    for t in f.y_ticks() {
        line(
            &mut pm,
            &[(LEFT, f.y(t)), (W - RIGHT, f.y(t))],
            [221, 221, 221],
            1.0,
        );
    }
    for t in f.x_ticks() {
        line(
            &mut pm,
            &[(f.x(t), TOP), (f.x(t), H - BOTTOM)],
            [238, 238, 238],
            1.0,
        );
        line(
            &mut pm,
            &[(f.x(t), H - BOTTOM), (f.x(t), H - BOTTOM + 6.0)],
            [51, 51, 51],
            1.0,
        );
    }
    for (i, c) in curves.iter().enumerate() {
        let rgb = colour(i);
        let mut pb = PathBuilder::new();
        for (k, p) in c.points.iter().enumerate() {
            let (x, y) = (f.x(p.budget) as f32, f.y(p.mean + p.std) as f32);
            if k == 0 {
                pb.move_to(x, y);
            } else {
                pb.line_to(x, y);
            }
        }
        for p in c.points.iter().rev() {
            pb.line_to(f.x(p.budget) as f32, f.y((p.mean - p.std).max(0.0)) as f32);
        }
        pb.close();
        if let Some(path) = pb.finish() {
            pm.fill_path(
                &path,
                &paint(rgb, 51),
                FillRule::Winding,
                Transform::identity(),
                None,
            );
        }
        let pts: Vec<(f64, f64)> = c
            .points
            .iter()
            .map(|p| (f.x(p.budget), f.y(p.mean)))
            .collect();
        line(&mut pm, &pts, rgb, 2.0);
        let ly = TOP + 16.0 + 18.0 * i as f64;
        if let Some(r) = Rect::from_xywh((LEFT + 12.0) as f32, (ly - 2.0) as f32, 24.0, 4.0) {
            pm.fill_rect(r, &paint(rgb, 255), Transform::identity(), None);
        }
    }
    line(
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
    fn curves_average_over_items_then_seeds() {
        let rows = vec![
            ("dense", 50, 1, true),
            ("dense", 50, 1, false),
            ("dense", 50, 2, true),
            ("dense", 50, 2, true),
            ("sparse", 50, 1, false),
        ];
        let c = curves(rows);
        assert_eq!(c[0].name, "dense");
        assert!((c[0].points[0].mean - 0.75).abs() < 1e-12);
        assert!((c[0].points[0].std - 0.25).abs() < 1e-12);
        assert_eq!(c[1].points[0].mean, 0.0);
        let s = svg(&c, "t");
        assert!(s.starts_with("<svg") && s.contains("dense") && s.contains("<polygon"));
        let p = png(&c).unwrap();
        assert_eq!(&p[1..4], b"PNG");
    }
}
