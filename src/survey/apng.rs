//! Animated PNG (APNG) encoding of equally sized RGBA frames, through the `png` crate's APNG writer.
//!
//! Every browser in use plays APNG in an `<img>`, and it needs no codec beyond what annotrace already
//! builds (`png` comes with `tiny-skia`). Rollouts are mostly a still scene with a few moving objects,
//! so each frame after the first stores only the rectangle that changed since the previous one
//! (`fcTL` offset and size, blend `Source`, dispose `None`): a 9-ball shot of 60 frames takes a few
//! times the bytes of one frame rather than sixty.
//!
//! **Owns:** the byte layout of the animation (frame rectangles, delays, loop count). **Does not:** draw
//! frames (the environments' renderers do, `super::video`).

use png::{BitDepth, BlendOp, ColorType, DisposeOp, Encoder};

/// Encoding an animation failed.
#[derive(Debug, thiserror::Error)]
pub enum ApngError {
    /// No frames, a zero size, or a frame whose byte length is not `width · height · 4`.
    #[error("animation: {0}")]
    Shape(String),
    /// The PNG writer refused (an annotrace bug if it happens).
    #[error("animation: PNG encoder: {0}")]
    Encode(#[from] png::EncodingError),
}

/// An animation: frames of `width × height` RGBA pixels (row-major, 4 bytes a pixel), each shown for
/// `delay_ms`, looping forever.
#[derive(Debug, Clone)]
pub struct Animation {
    /// Width (px).
    pub width: u32,
    /// Height (px).
    pub height: u32,
    /// How long each frame is shown (ms, at most 65 535).
    pub delay_ms: u16,
    /// The frames, each `width · height · 4` bytes.
    pub frames: Vec<Vec<u8>>,
}

/// The smallest rectangle `(x, y, w, h)` holding every pixel where `a` and `b` differ, or `None` when
/// they are equal.
fn changed_rect(a: &[u8], b: &[u8], width: u32, height: u32) -> Option<(u32, u32, u32, u32)> {
    let (w, h) = (width as usize, height as usize);
    let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0usize, 0usize);
    for y in 0..h {
        let row = y * w * 4..(y + 1) * w * 4;
        let (ra, rb) = (&a[row.clone()], &b[row]);
        if ra == rb {
            continue;
        }
        let first = (0..w).find(|&x| ra[x * 4..x * 4 + 4] != rb[x * 4..x * 4 + 4]);
        let last = (0..w)
            .rev()
            .find(|&x| ra[x * 4..x * 4 + 4] != rb[x * 4..x * 4 + 4]);
        if let (Some(f), Some(l)) = (first, last) {
            x0 = x0.min(f);
            x1 = x1.max(l);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    (x0 <= x1).then(|| {
        (
            x0 as u32,
            y0 as u32,
            (x1 - x0 + 1) as u32,
            (y1 - y0 + 1) as u32,
        )
    })
}

/// The pixels of rectangle `(x, y, w, h)` of a frame `width` pixels wide.
fn crop(frame: &[u8], width: u32, (x, y, w, h): (u32, u32, u32, u32)) -> Vec<u8> {
    let mut out = Vec::with_capacity(w as usize * h as usize * 4);
    for row in y..y + h {
        let start = (row as usize * width as usize + x as usize) * 4;
        out.extend_from_slice(&frame[start..start + w as usize * 4]);
    }
    out
}

impl Animation {
    /// The animation as APNG bytes. The first frame is the PNG's default image, so a viewer without
    /// APNG support shows the initial scene.
    pub fn encode(&self) -> Result<Vec<u8>, ApngError> {
        let (w, h) = (self.width, self.height);
        let size = w as usize * h as usize * 4;
        if w == 0 || h == 0 || self.frames.is_empty() {
            return Err(ApngError::Shape(format!(
                "{} frame(s) of {w}×{h} pixels: needs at least one frame of at least 1×1",
                self.frames.len()
            )));
        }
        if let Some((i, f)) = self
            .frames
            .iter()
            .enumerate()
            .find(|(_, f)| f.len() != size)
        {
            return Err(ApngError::Shape(format!(
                "frame {i} holds {} bytes, expected {size} ({w}×{h} RGBA)",
                f.len()
            )));
        }
        let mut out = Vec::new();
        {
            let mut enc = Encoder::new(&mut out, w, h);
            enc.set_color(ColorType::Rgba);
            enc.set_depth(BitDepth::Eight);
            enc.set_compression(png::Compression::Default);
            enc.set_animated(self.frames.len() as u32, 0)?;
            enc.set_frame_delay(self.delay_ms, 1000)?;
            enc.set_blend_op(BlendOp::Source)?;
            enc.set_dispose_op(DisposeOp::None)?;
            let mut writer = enc.write_header()?;
            writer.write_image_data(&self.frames[0])?;
            for k in 1..self.frames.len() {
                let (prev, cur) = (&self.frames[k - 1], &self.frames[k]);
                // An unchanged frame still needs a rectangle: one pixel, rewritten as it was.
                let rect = changed_rect(prev, cur, w, h).unwrap_or((0, 0, 1, 1));
                writer.reset_frame_position()?;
                writer.set_frame_dimension(rect.2, rect.3)?;
                writer.set_frame_position(rect.0, rect.1)?;
                writer.write_image_data(&crop(cur, w, rect))?;
            }
            writer.finish()?;
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 16×12 frame: grey, with a red 3×3 square at (k, 2).
    fn frame(k: u32) -> Vec<u8> {
        let (w, h) = (16u32, 12u32);
        let mut f = vec![128u8; (w * h * 4) as usize];
        for y in 2..5 {
            for x in k..k + 3 {
                let i = ((y * w + x) * 4) as usize;
                f[i..i + 4].copy_from_slice(&[220, 30, 30, 255]);
            }
        }
        for px in f.chunks_exact_mut(4) {
            px[3] = 255;
        }
        f
    }

    /// Decodes every frame of an APNG, composing sub-frames over the previous one (blend Source,
    /// dispose None, the only ops `encode` writes). Returns (frames, delay numerators, plays).
    fn decode(bytes: &[u8]) -> (Vec<Vec<u8>>, Vec<u16>, u32) {
        let dec = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = dec.read_info().unwrap();
        let info = reader.info();
        let (w, h) = (info.width, info.height);
        let actl = info.animation_control.expect("an acTL chunk");
        let mut canvas = vec![0u8; (w * h * 4) as usize];
        let mut frames = Vec::new();
        let mut delays = Vec::new();
        for _ in 0..actl.num_frames {
            let mut buf = vec![0u8; reader.output_buffer_size()];
            let out = reader.next_frame(&mut buf).unwrap();
            let fc = reader.info().frame_control.expect("an fcTL per frame");
            assert_eq!((out.width, out.height), (fc.width, fc.height));
            for row in 0..fc.height {
                let src = &buf[(row * fc.width * 4) as usize..((row + 1) * fc.width * 4) as usize];
                let at = (((fc.y_offset + row) * w + fc.x_offset) * 4) as usize;
                canvas[at..at + src.len()].copy_from_slice(src);
            }
            frames.push(canvas.clone());
            delays.push(fc.delay_num);
        }
        (frames, delays, actl.num_plays)
    }

    #[test]
    fn frames_decode_back_exactly_with_their_count_and_delay() {
        let frames: Vec<Vec<u8>> = (0..6).map(|k| frame(k * 2)).chain([frame(10)]).collect();
        let anim = Animation {
            width: 16,
            height: 12,
            delay_ms: 125,
            frames: frames.clone(),
        };
        let bytes = anim.encode().unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        let (decoded, delays, plays) = decode(&bytes);
        assert_eq!(decoded.len(), 7, "one frame per input frame");
        assert_eq!(decoded, frames, "sub-frames compose back to the frames");
        assert!(delays.iter().all(|&d| d == 125));
        assert_eq!(plays, 0, "loops forever");
    }

    #[test]
    fn only_the_changed_rectangle_is_stored() {
        let (a, b) = (frame(0), frame(4));
        assert_eq!(changed_rect(&a, &b, 16, 12), Some((0, 2, 7, 3)));
        assert_eq!(changed_rect(&a, &a, 16, 12), None);
        // On a noisy (incompressible) 64×64 background, sixty frames of a moving square cost little
        // more than the first frame: only the square's rectangle is stored after it.
        let mut rng = crate::rng::SplitMix64::new(1);
        let noise: Vec<u8> = (0..64 * 64)
            .flat_map(|_| {
                let v = rng.next_u64().to_le_bytes();
                [v[0], v[1], v[2], 255]
            })
            .collect();
        let at = |k: u32| {
            let mut f = noise.clone();
            for y in 10..14 {
                for x in k..k + 4 {
                    let i = ((y * 64 + x) * 4) as usize;
                    f[i..i + 4].copy_from_slice(&[220, 30, 30, 255]);
                }
            }
            f
        };
        let anim = |frames: Vec<Vec<u8>>| Animation {
            width: 64,
            height: 64,
            delay_ms: 40,
            frames,
        };
        let moving = anim((0..60).map(|k| at(k % 50)).collect())
            .encode()
            .unwrap();
        let still = anim(vec![at(0)]).encode().unwrap();
        assert!(
            moving.len() < 2 * still.len(),
            "{} vs {}",
            moving.len(),
            still.len()
        );
    }

    #[test]
    fn bad_shapes_are_refused() {
        let none = Animation {
            width: 4,
            height: 4,
            delay_ms: 10,
            frames: vec![],
        };
        assert!(matches!(none.encode(), Err(ApngError::Shape(_))));
        let short = Animation {
            width: 4,
            height: 4,
            delay_ms: 10,
            frames: vec![vec![0; 64], vec![0; 60]],
        };
        let e = short.encode().unwrap_err().to_string();
        assert!(e.contains("frame 1 holds 60 bytes, expected 64"), "{e}");
    }
}
