//! The optimised-action figure (the paper's reward-program figures): for one goal, the rollout of the
//! best action found as a strip of frames, with the goal sentence above and the reward program
//! beneath. Written as SVG (the strip embedded as a PNG data URL, the text as text); the strip alone is
//! the PNG.
//!
//! **Owns:** laying the figure out. **Does not:** render frames (`problem::Problem::strip`, `envs`).

use std::fmt::Write as _;

/// Width and height of a PNG from its IHDR chunk, when `png` is one.
pub fn png_size(png: &[u8]) -> Option<(u32, u32)> {
    if png.len() < 24 || &png[1..4] != b"PNG" || &png[12..16] != b"IHDR" {
        return None;
    }
    let w = u32::from_be_bytes(png[16..20].try_into().ok()?);
    let h = u32::from_be_bytes(png[20..24].try_into().ok()?);
    Some((w, h))
}

fn esc(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// What the figure shows.
#[derive(Debug, Clone)]
pub struct ActionFigure<'a> {
    /// The goal sentence.
    pub goal: &'a str,
    /// A line under the goal (scene, action, reward, whether it verifies).
    pub caption: &'a str,
    /// The reward program's text.
    pub program: &'a str,
    /// The rollout's frame strip (PNG).
    pub strip: &'a [u8],
}

/// The figure as SVG text: the goal, the strip (scaled to at most 960 px wide), the caption and the
/// program in a monospace block.
pub fn action_svg(f: &ActionFigure<'_>) -> Result<String, String> {
    let (pw, ph) = png_size(f.strip).ok_or("the frame strip is not a PNG")?;
    let width = (pw as f64).min(960.0);
    let scale = width / pw as f64;
    let strip_h = ph as f64 * scale;
    let lines: Vec<&str> = f
        .program
        .lines()
        .map(str::trim_end)
        .filter(|l| !l.trim().is_empty())
        .collect();
    let line_h = 15.0;
    let top = 30.0;
    let height = top + strip_h + 30.0 + line_h * lines.len() as f64 + 16.0;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="13">"#
    );
    let _ = writeln!(
        s,
        r#"<rect width="{width}" height="{height}" fill="white"/>"#
    );
    let _ = writeln!(
        s,
        r#"<text x="6" y="20" font-weight="bold">{}</text>"#,
        esc(f.goal)
    );
    let _ = writeln!(
        s,
        r#"<image x="0" y="{top}" width="{width}" height="{strip_h}" href="data:image/png;base64,{}"/>"#,
        crate::llm::base64(f.strip)
    );
    let cap_y = top + strip_h + 18.0;
    let _ = writeln!(
        s,
        r##"<text x="6" y="{cap_y}" fill="#444">{}</text>"##,
        esc(f.caption)
    );
    for (i, l) in lines.iter().enumerate() {
        let y = cap_y + 6.0 + line_h * (i + 1) as f64;
        let _ = writeln!(
            s,
            r#"<text x="6" y="{y}" font-family="monospace" font-size="12" xml:space="preserve">{}</text>"#,
            esc(l)
        );
    }
    s.push_str("</svg>\n");
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lays_out_goal_strip_and_program() {
        let env = crate::envs::pool::PoolEnv::default();
        use crate::envs::Environment;
        let scene = &env.scenes(1, 3).unwrap()[0];
        let tr = env
            .simulate(scene, &crate::envs::pool::Shot::default())
            .unwrap();
        let strip = crate::envs::pool::render::render_strip_png(
            &tr,
            &env.config,
            &[0.0, 0.5],
            &crate::envs::pool::render::RenderOptions::default(),
        )
        .unwrap();
        let (w, h) = png_size(&strip).unwrap();
        assert!(w > h && h > 0);
        let svg = action_svg(&ActionFigure {
            goal: "Pot <the> ball",
            caption: "scene 1",
            program: "AND(\n  CUE_HIT(\"8\")\n)",
            strip: &strip,
        })
        .unwrap();
        assert!(svg.contains("Pot &lt;the&gt; ball"));
        assert!(svg.contains("data:image/png;base64,"));
        assert_eq!(svg.matches("font-family=\"monospace\"").count(), 3);
        assert!(
            action_svg(&ActionFigure {
                strip: b"nope",
                ..ActionFigure {
                    goal: "",
                    caption: "",
                    program: "",
                    strip: &[]
                }
            })
            .is_err()
        );
    }
}
