//! The drawing plumbing the environments' renderers share (tiny-skia): solid anti-aliased paints, filled
//! discs, pixmaps and PNG encoding, and strips of frames side by side.
//!
//! **Owns:** making a pixmap or failing with a clear [`EnvError::Render`], encoding it as PNG, and
//! laying out a strip (at least one frame, at most [`MAX_STRIP_WIDTH`] pixels wide, frame `i` pasted at
//! `x = i·size`). **Does not:** know any scene, palette, font or layout: each environment's `render.rs`
//! (`pool`, `phyre`, `iphyre`) draws its own frames with these helpers.

use tiny_skia::{FillRule, Paint, Path, PathBuilder, Pixmap, PixmapPaint, Transform};

use super::EnvError;

/// The widest strip drawn, in pixels.
pub(crate) const MAX_STRIP_WIDTH: u32 = 16_384;

/// An opaque, anti-aliased paint of colour `c` (RGB).
pub(crate) fn paint(c: [u8; 3]) -> Paint<'static> {
    let mut p = Paint::default();
    p.set_color_rgba8(c[0], c[1], c[2], 255);
    p.anti_alias = true;
    p
}

/// A transparent `w`×`h` pixmap, or an error naming the size tiny-skia refused.
pub(crate) fn new_pixmap(w: u32, h: u32) -> Result<Pixmap, EnvError> {
    Pixmap::new(w, h).ok_or_else(|| EnvError::Render(format!("cannot make a {w}×{h} image")))
}

/// The pixmap as PNG bytes.
pub(crate) fn encode_png(p: &Pixmap) -> Result<Vec<u8>, EnvError> {
    p.encode_png().map_err(|e| EnvError::Render(e.to_string()))
}

/// Fills `path` (non-zero winding) with `colour`; nothing when the path could not be built.
pub(crate) fn fill_path(p: &mut Pixmap, path: Option<Path>, colour: [u8; 3]) {
    if let Some(path) = path {
        p.fill_path(
            &path,
            &paint(colour),
            FillRule::Winding,
            Transform::identity(),
            None,
        );
    }
}

/// Fills the disc of radius `r` around (`cx`, `cy`) with `colour` (nothing for a degenerate radius).
pub(crate) fn fill_circle(p: &mut Pixmap, cx: f32, cy: f32, r: f32, colour: [u8; 3]) {
    fill_path(p, PathBuilder::from_circle(cx, cy, r), colour);
}

/// `frames` frames of `size` pixels side by side, left to right (`size·frames` × `size` pixels): frame
/// `i` comes from `frame(i)` and is pasted at `x = i·size`. Fails on an empty or too wide strip, or
/// with the first frame's error.
pub(crate) fn strip(
    frames: usize,
    size: u32,
    mut frame: impl FnMut(usize) -> Result<Pixmap, EnvError>,
) -> Result<Pixmap, EnvError> {
    if frames == 0 {
        return Err(EnvError::Render("a strip needs at least one frame".into()));
    }
    let width = u32::try_from(frames)
        .ok()
        .and_then(|k| k.checked_mul(size))
        .filter(|w| *w <= MAX_STRIP_WIDTH)
        .ok_or_else(|| {
            EnvError::Render(format!(
                "a strip of {frames} frames of {size} px is too wide (at most {MAX_STRIP_WIDTH} px)"
            ))
        })?;
    let mut strip = new_pixmap(width, size)?;
    for i in 0..frames {
        let f = frame(i)?;
        strip.draw_pixmap(
            (i as u32 * size) as i32,
            0,
            f.as_ref(),
            &PixmapPaint::default(),
            Transform::identity(),
            None,
        );
    }
    Ok(strip)
}

/// The RGB colour of pixel (`x`, `y`) of a PNG: what the renderers' tests read back.
#[cfg(test)]
pub(crate) fn png_pixel(png: &[u8], x: u32, y: u32) -> [u8; 3] {
    let p = Pixmap::decode_png(png).unwrap();
    let c = p.pixel(x, y).unwrap();
    [c.red(), c.green(), c.blue()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_paste_frames_left_to_right_and_refuse_bad_sizes() {
        let colours = [[255, 0, 0], [0, 0, 255]];
        let s = strip(2, 4, |i| {
            let mut f = new_pixmap(4, 4)?;
            let [r, g, b] = colours[i];
            f.fill(tiny_skia::Color::from_rgba8(r, g, b, 255));
            Ok(f)
        })
        .unwrap();
        assert_eq!((s.width(), s.height()), (8, 4));
        for (x, c) in [
            (0, colours[0]),
            (3, colours[0]),
            (4, colours[1]),
            (7, colours[1]),
        ] {
            let p = s.pixel(x, 2).unwrap();
            assert_eq!([p.red(), p.green(), p.blue()], c, "x = {x}");
        }
        let none = strip(0, 4, |_| new_pixmap(4, 4)).unwrap_err();
        assert!(none.to_string().contains("at least one frame"), "{none}");
        let wide = strip(5, 4000, |_| new_pixmap(4000, 4000)).unwrap_err();
        assert!(wide.to_string().contains("too wide"), "{wide}");
        let failing = strip(2, 4, |i| match i {
            0 => new_pixmap(4, 4),
            _ => Err(EnvError::Render("frame 1 failed".into())),
        });
        assert!(failing.is_err());
        assert!(new_pixmap(0, 4).is_err());
        assert_eq!(&encode_png(&s).unwrap()[1..4], b"PNG");
    }
}
