//! The annotation-examples figure (the paper's first figure): `k` frames of a trace side by side, in
//! the colours of `annotrace render`, above the trace's pattern timeline on the same time span (one
//! row per label, a bar per annotation, a marker under each frame's time).
//!
//! **Owns:** drawing the strip through each environment's renderer and composing it with the timeline,
//! as SVG (the strip embedded as a PNG image, the timeline and its labels as vectors) or PNG (no text).
//! **Does not:** choose the trace or read the run (the caller passes the trace and its annotations).

use std::fmt::Write as _;

use crate::detect::Annotation;
use crate::envs::EnvError;
use crate::envs::iphyre::Games;
use crate::envs::iphyre::render::{
    RenderOptions as IphyreOptions, render_strip_png as iphyre_strip,
};
use crate::envs::phyre::TaskSet;
use crate::envs::phyre::render::{RenderOptions as PhyreOptions, render_strip_png as phyre_strip};
use crate::envs::pool::PoolConfig;
use crate::envs::pool::render::{RenderOptions, render_strip_png, strip_times};
use crate::trace::{Env, Trace};

use super::figure::colour;

/// Pixels per frame of the strip.
pub const FRAME: u32 = 200;
/// Height of one timeline row (px).
const ROW: f64 = 18.0;
/// Width of the label column left of the timeline (px).
const LABELS: f64 = 150.0;

/// `frames` frames of `trace` evenly over its span, side by side, as PNG bytes, with the times drawn.
pub fn strip(trace: &Trace, frames: usize) -> Result<(Vec<u8>, Vec<f64>), EnvError> {
    let times = strip_times(trace, frames);
    let png = match trace.env {
        Env::Pooltool => render_strip_png(
            trace,
            &PoolConfig::default_7ft(),
            &times,
            &RenderOptions { size: FRAME },
        )?,
        Env::Phyre => {
            let tasks = TaskSet::default_tasks().map_err(|e| EnvError::Render(e.to_string()))?;
            let task = tasks
                .get(&trace.task_id)
                .map_err(|e| EnvError::Render(e.to_string()))?;
            phyre_strip(
                trace,
                &task,
                &times,
                &PhyreOptions {
                    size: FRAME,
                    grid: false,
                },
            )?
        }
        Env::Iphyre => {
            let games = Games::default_games().map_err(|e| EnvError::Render(e.to_string()))?;
            let game = games.get(&trace.task_id).ok();
            iphyre_strip(
                trace,
                game,
                &times,
                &IphyreOptions {
                    size: FRAME,
                    block_indices: false,
                    time_label: true,
                },
            )?
        }
    };
    Ok((png, times))
}

/// Standard base64 (RFC 4648, with padding).
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                out.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// The labels of `annotations`, in first-start order, each with its (t0, t1) spans.
fn rows(annotations: &[Annotation]) -> Vec<(String, Vec<(f64, f64)>)> {
    let mut anns: Vec<&Annotation> = annotations
        .iter()
        .filter(|a| a.t_start.is_finite() && a.t_end.is_finite())
        .collect();
    anns.sort_by(|a, b| a.t_start.total_cmp(&b.t_start));
    let mut out: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for a in anns {
        match out.iter_mut().find(|(l, _)| *l == a.label) {
            Some((_, v)) => v.push((a.t_start, a.t_end)),
            None => out.push((a.label.clone(), vec![(a.t_start, a.t_end)])),
        }
    }
    out
}

fn esc(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Layout shared by both encodings: width, strip height, timeline top, time → x.
struct Layout {
    w: f64,
    top: f64,
    t0: f64,
    t1: f64,
    rows: usize,
}

impl Layout {
    fn of(trace: &Trace, frames: usize, rows: usize) -> Layout {
        let (t0, t1) = match (trace.timesteps.first(), trace.timesteps.last()) {
            (Some(a), Some(b)) => (a.t, b.t.max(a.t + 1e-9)),
            _ => (0.0, 1.0),
        };
        Layout {
            w: LABELS + (frames as f64) * FRAME as f64,
            top: FRAME as f64 + 34.0,
            t0,
            t1,
            rows,
        }
    }
    fn x(&self, t: f64) -> f64 {
        LABELS + (t - self.t0) / (self.t1 - self.t0) * (self.w - LABELS - 1.0)
    }
    fn h(&self) -> f64 {
        self.top + self.rows as f64 * ROW + 44.0
    }
}

/// The figure as SVG: `<image>` of the strip, `<g class="timeline">` with one `<g class="row">` per
/// label, the time axis (`<g class="axis x">`, "time (s)").
pub fn svg(trace: &Trace, annotations: &[Annotation], frames: usize) -> Result<String, EnvError> {
    let (png, times) = strip(trace, frames)?;
    let rows = rows(annotations);
    let l = Layout::of(trace, times.len(), rows.len());
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{:.0}" height="{:.0}" viewBox="0 0 {:.0} {:.0}" font-family="sans-serif" font-size="12">"#,
        l.w,
        l.h(),
        l.w,
        l.h()
    );
    let _ = writeln!(
        s,
        r#"<rect width="{:.0}" height="{:.0}" fill="white"/>"#,
        l.w,
        l.h()
    );
    let _ = writeln!(
        s,
        r#"<text class="title" x="4" y="14">{} ({}, task {})</text>"#,
        esc(&trace.trace_id),
        trace.env,
        esc(&trace.task_id)
    );
    let _ = writeln!(
        s,
        r#"<image x="{LABELS}" y="20" width="{}" height="{FRAME}" href="data:image/png;base64,{}"/>"#,
        times.len() as u32 * FRAME,
        base64(&png)
    );
    // Each frame's time, marked on the timeline.
    for (i, t) in times.iter().enumerate() {
        let fx = LABELS + (i as f64 + 0.5) * FRAME as f64;
        let _ = writeln!(
            s,
            r##"<line class="frame-time" x1="{fx:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="#999" stroke-dasharray="3 3"/>"##,
            20.0 + FRAME as f64,
            l.x(*t),
            l.top
        );
    }
    s.push_str("<g class=\"timeline\">\n");
    for (i, (label, spans)) in rows.iter().enumerate() {
        let y = l.top + i as f64 * ROW;
        let c = colour(i);
        let _ = writeln!(
            s,
            r#"<g class="row" data-label="{}"><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"#,
            esc(label),
            LABELS - 6.0,
            y + ROW - 5.0,
            esc(label)
        );
        for (a, b) in spans {
            let _ = writeln!(
                s,
                r#"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="rgb({},{},{})"/>"#,
                l.x(*a),
                y + 3.0,
                (l.x(*b) - l.x(*a)).max(2.0),
                ROW - 6.0,
                c[0],
                c[1],
                c[2]
            );
        }
        s.push_str("</g>\n");
    }
    s.push_str("</g>\n<g class=\"axis x\">\n");
    let axis_y = l.top + rows.len() as f64 * ROW + 4.0;
    let _ = writeln!(
        s,
        r##"<line x1="{LABELS}" y1="{axis_y:.1}" x2="{:.1}" y2="{axis_y:.1}" stroke="#333"/>"##,
        l.w - 1.0
    );
    let step = super::figure::nice_step_pub(l.t1 - l.t0, 10.0);
    let mut t = (l.t0 / step).ceil() * step;
    while t <= l.t1 + 1e-9 {
        let x = l.x(t);
        let _ = writeln!(
            s,
            r##"<line x1="{x:.1}" y1="{axis_y:.1}" x2="{x:.1}" y2="{:.1}" stroke="#333"/><text class="tick" x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
            axis_y + 4.0,
            axis_y + 16.0,
            super::figure::tick_text_pub(t, step)
        );
        t += step;
    }
    let _ = writeln!(
        s,
        r#"<text class="label" x="{:.1}" y="{:.1}" text-anchor="middle">time (s)</text>"#,
        (LABELS + l.w) / 2.0,
        axis_y + 34.0
    );
    s.push_str("</g>\n</svg>\n");
    Ok(s)
}

/// The figure as PNG: the strip above the timeline bars (no text).
pub fn png(trace: &Trace, annotations: &[Annotation], frames: usize) -> Result<Vec<u8>, EnvError> {
    use tiny_skia::{Color, Paint, Pixmap, PixmapPaint, Rect, Transform};
    let (strip_png, times) = strip(trace, frames)?;
    let rows = rows(annotations);
    let l = Layout::of(trace, times.len(), rows.len());
    let mut pm = Pixmap::new(l.w as u32, l.h() as u32)
        .ok_or_else(|| EnvError::Render("cannot allocate the figure".into()))?;
    pm.fill(Color::WHITE);
    let strip = Pixmap::decode_png(&strip_png).map_err(|e| EnvError::Render(e.to_string()))?;
    pm.draw_pixmap(
        LABELS as i32,
        20,
        strip.as_ref(),
        &PixmapPaint::default(),
        Transform::identity(),
        None,
    );
    let fill = |pm: &mut Pixmap, x: f64, y: f64, w: f64, h: f64, c: [u8; 3]| {
        let mut p = Paint::default();
        p.set_color_rgba8(c[0], c[1], c[2], 255);
        // Axis-aligned rectangles need no anti-aliasing (and tiny-skia's hairline path asserts on
        // some sub-pixel ones).
        p.anti_alias = false;
        if let Some(r) = Rect::from_xywh(x as f32, y as f32, w as f32, h as f32) {
            pm.fill_rect(r, &p, Transform::identity(), None);
        }
    };
    for (i, (_, spans)) in rows.iter().enumerate() {
        let y = l.top + i as f64 * ROW;
        for (a, b) in spans {
            fill(
                &mut pm,
                l.x(*a),
                y + 3.0,
                (l.x(*b) - l.x(*a)).max(2.0),
                ROW - 6.0,
                colour(i),
            );
        }
    }
    let axis_y = l.top + rows.len() as f64 * ROW + 4.0;
    fill(
        &mut pm,
        LABELS,
        axis_y,
        l.w - LABELS - 1.0,
        1.0,
        [51, 51, 51],
    );
    for t in &times {
        fill(&mut pm, l.x(*t) - 0.5, axis_y - 4.0, 1.0, 8.0, [51, 51, 51]);
    }
    pm.encode_png().map_err(|e| EnvError::Render(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foo"), "Zm9v");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
    }
}

#[cfg(test)]
mod figure_tests {
    use super::*;
    use crate::detect::DetectorId;

    fn ann(label: &str, t0: f64, t1: f64) -> Annotation {
        Annotation {
            detector_id: DetectorId("d".into()),
            trace_id: "t".into(),
            label: label.into(),
            seq: 0,
            start_step: 0,
            end_step: 1,
            t_start: t0,
            t_end: t1,
            objects: vec!["cue".into()],
            parameters: Default::default(),
            provenance: None,
            metadata: None,
            activation: 1.0,
        }
    }

    #[test]
    fn the_examples_figure_has_frames_above_one_row_per_label_and_a_time_axis() {
        let env = crate::envs::pool::PoolEnv::default();
        use crate::envs::Environment;
        let scene = &env.scenes(1, 3).unwrap()[0];
        let shot = crate::envs::pool::Shot {
            v0: 2.0,
            phi: 80.0,
            theta: 0.0,
            a: 0.0,
            b: 0.0,
        };
        let trace = env.simulate(scene, &shot).unwrap();
        let t1 = trace.timesteps.last().unwrap().t;
        let anns = [
            ann("cue strike", 0.0, 0.0),
            ann("rolling ball", 0.2, t1 / 2.0),
            ann("rolling ball", t1 / 2.0 + 0.1, t1),
        ];
        let s = svg(&trace, &anns, 3).unwrap();
        assert_eq!(s.matches("<image ").count(), 1);
        assert!(s.contains("href=\"data:image/png;base64,iVBORw0KGgo"));
        assert_eq!(
            s.matches("<g class=\"row\"").count(),
            2,
            "one row per label"
        );
        assert_eq!(s.matches("class=\"frame-time\"").count(), 3);
        assert_eq!(s.matches("<g class=\"axis x\">").count(), 1);
        assert!(s.contains(">time (s)</text>"));
        let p = png(&trace, &anns, 3).unwrap();
        let pm = tiny_skia::Pixmap::decode_png(&p).unwrap();
        assert_eq!(pm.width(), LABELS as u32 + 3 * FRAME);
    }
}
