//! An RGB raster with the few primitives the charts need: rectangles, thick (optionally dashed)
//! clipped lines, markers, bitmap text (horizontal and rotated), and PNG encoding.

use font8x8::legacy::{BASIC_LEGACY, GREEK_LEGACY, LATIN_LEGACY};
use std::io::{self, Write};
use std::path::Path;

/// An RGB colour.
pub type Rgb = [u8; 3];

pub const WHITE: Rgb = [255, 255, 255];
#[cfg(test)]
pub const BLACK: Rgb = [0, 0, 0];
pub const GRID: Rgb = [228, 228, 228];
pub const TEXT: Rgb = [30, 30, 30];
pub const FRAME: Rgb = [110, 110, 110];

/// Glyph cell of the bitmap font, in font pixels.
pub const GLYPH: i32 = 8;

/// A pixel rectangle `[x0, x1) × [y0, y1)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rect {
    pub x0: i32,
    pub y0: i32,
    pub x1: i32,
    pub y1: i32,
}

impl Rect {
    pub fn w(&self) -> i32 {
        self.x1 - self.x0
    }
    pub fn h(&self) -> i32 {
        self.y1 - self.y0
    }
}

/// Marker shapes, cycled through series so that colour is not the only cue.
#[derive(Clone, Copy, Debug)]
pub enum Shape {
    Circle,
    Square,
    Triangle,
    Diamond,
}

impl Shape {
    pub fn nth(i: usize) -> Shape {
        [
            Shape::Circle,
            Shape::Square,
            Shape::Triangle,
            Shape::Diamond,
        ][i % 4]
    }
}

/// An RGB image, row-major, 3 bytes per pixel.
pub struct Canvas {
    pub w: u32,
    pub h: u32,
    pub px: Vec<u8>,
}

impl Canvas {
    pub fn new(w: u32, h: u32, bg: Rgb) -> Canvas {
        let mut px = vec![0; w as usize * h as usize * 3];
        for p in px.chunks_exact_mut(3) {
            p.copy_from_slice(&bg);
        }
        Canvas { w, h, px }
    }

    /// Sets one pixel; outside the image it does nothing.
    pub fn set(&mut self, x: i32, y: i32, c: Rgb) {
        if x < 0 || y < 0 || x as u32 >= self.w || y as u32 >= self.h {
            return;
        }
        let i = (y as usize * self.w as usize + x as usize) * 3;
        self.px[i..i + 3].copy_from_slice(&c);
    }

    /// Fills `r` (clamped to the image).
    pub fn fill(&mut self, r: Rect, c: Rgb) {
        let x0 = r.x0.max(0);
        let x1 = r.x1.min(self.w as i32);
        let y0 = r.y0.max(0);
        let y1 = r.y1.min(self.h as i32);
        for y in y0..y1 {
            for x in x0..x1 {
                self.set(x, y, c);
            }
        }
    }

    /// Draws the outline of `r`, `t` pixels thick, inside `r`.
    pub fn outline(&mut self, r: Rect, t: i32, c: Rgb) {
        let t = t.max(1);
        self.fill(Rect { y1: r.y0 + t, ..r }, c);
        self.fill(Rect { y0: r.y1 - t, ..r }, c);
        self.fill(Rect { x1: r.x0 + t, ..r }, c);
        self.fill(Rect { x0: r.x1 - t, ..r }, c);
    }

    /// Draws a `width`-pixel square brush along the segment `a`–`b`, clipped to `clip`.
    /// `dash` = `(on, off, phase)` in pixels draws a dashed line; the phase (distance already
    /// drawn along the polyline) is advanced so consecutive segments continue the pattern.
    pub fn line(
        &mut self,
        a: (f64, f64),
        b: (f64, f64),
        width: i32,
        c: Rgb,
        clip: Rect,
        dash: Option<(f64, f64, &mut f64)>,
    ) {
        let full = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
        let Some((p, q, t0)) = clip_segment(a, b, clip) else {
            if let Some((_, _, phase)) = dash {
                *phase += full;
            }
            return;
        };
        let (dx, dy) = (q.0 - p.0, q.1 - p.1);
        let n = dx.abs().max(dy.abs()).ceil().max(1.0) as i64;
        let len = (dx * dx + dy * dy).sqrt();
        let lo = -(width - 1) / 2;
        let hi = lo + width.max(1);
        let (on, period, start) = match &dash {
            Some((on, off, phase)) => (*on, on + off, **phase + t0 * full),
            None => (f64::INFINITY, f64::INFINITY, 0.0),
        };
        for i in 0..=n {
            let f = i as f64 / n as f64;
            if period.is_finite() && (start + f * len).rem_euclid(period) >= on {
                continue;
            }
            let x = (p.0 + f * dx).round() as i32;
            let y = (p.1 + f * dy).round() as i32;
            for oy in lo..hi {
                for ox in lo..hi {
                    let (px, py) = (x + ox, y + oy);
                    if px >= clip.x0 && px < clip.x1 && py >= clip.y0 && py < clip.y1 {
                        self.set(px, py, c);
                    }
                }
            }
        }
        if let Some((_, _, phase)) = dash {
            *phase += full;
        }
    }

    /// Draws a filled marker of radius `r` centred at `(cx, cy)`, clipped to `clip`.
    pub fn marker(&mut self, cx: f64, cy: f64, shape: Shape, r: i32, c: Rgb, clip: Rect) {
        let (x0, y0) = (cx.round() as i32, cy.round() as i32);
        let rf = r as f64 + 0.5;
        for oy in -r..=r {
            for ox in -r..=r {
                let (fx, fy) = (ox as f64, oy as f64);
                let inside = match shape {
                    Shape::Circle => fx * fx + fy * fy <= rf * rf,
                    Shape::Square => true,
                    Shape::Diamond => fx.abs() + fy.abs() <= rf,
                    // Apex up: the half width grows from the top row to the bottom one.
                    Shape::Triangle => fx.abs() <= (fy + r as f64) * 0.5 + 0.5,
                };
                let (px, py) = (x0 + ox, y0 + oy);
                if inside && px >= clip.x0 && px < clip.x1 && py >= clip.y0 && py < clip.y1 {
                    self.set(px, py, c);
                }
            }
        }
    }

    /// Draws `s` with its top-left corner at `(x, y)`, each font pixel `scale` pixels wide.
    pub fn text(&mut self, x: i32, y: i32, s: &str, scale: i32, c: Rgb) {
        let scale = scale.max(1);
        for (k, ch) in s.chars().enumerate() {
            let g = glyph(ch);
            let gx = x + k as i32 * GLYPH * scale;
            for (row, bits) in g.iter().enumerate() {
                for col in 0..8 {
                    if bits & (1 << col) != 0 {
                        let r = Rect {
                            x0: gx + col * scale,
                            y0: y + row as i32 * scale,
                            x1: gx + (col + 1) * scale,
                            y1: y + (row as i32 + 1) * scale,
                        };
                        self.fill(r, c);
                    }
                }
            }
        }
    }

    /// Draws `s` rotated a quarter turn anticlockwise (reading bottom to top), the bottom-left
    /// of its first glyph at `(x, y)`: for a y-axis label.
    pub fn text_up(&mut self, x: i32, y: i32, s: &str, scale: i32, c: Rgb) {
        let scale = scale.max(1);
        for (k, ch) in s.chars().enumerate() {
            let g = glyph(ch);
            let base = y - k as i32 * GLYPH * scale;
            for (row, bits) in g.iter().enumerate() {
                for col in 0..8 {
                    if bits & (1 << col) != 0 {
                        // Glyph (col, row) → image (x + row, base - col).
                        let px = x + row as i32 * scale;
                        let py = base - (col + 1) * scale;
                        self.fill(
                            Rect {
                                x0: px,
                                y0: py,
                                x1: px + scale,
                                y1: py + scale,
                            },
                            c,
                        );
                    }
                }
            }
        }
    }

    /// PNG bytes of the image.
    pub fn encode_png(&self) -> io::Result<Vec<u8>> {
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, self.w, self.h);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            let mut w = enc.write_header().map_err(io::Error::other)?;
            w.write_image_data(&self.px).map_err(io::Error::other)?;
            w.finish().map_err(io::Error::other)?;
        }
        Ok(out)
    }

    /// Writes the image as PNG to `path` atomically: a temporary file in the same folder,
    /// then a rename, so a reader never sees a half-written image.
    pub fn write_png(&self, path: &Path) -> io::Result<()> {
        write_atomic(path, &self.encode_png()?)
    }
}

/// Writes `bytes` to `path` through a temporary sibling file and a rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let name = path
        .file_name()
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "path has no file name"))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".tmp{}", std::process::id()));
    let tmp = path.with_file_name(tmp_name);
    let res = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if res.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    res
}

/// Width in pixels of `s` drawn at `scale`.
pub fn text_width(s: &str, scale: i32) -> i32 {
    s.chars().count() as i32 * GLYPH * scale.max(1)
}

/// `s` cut to at most `max_px` pixels at `scale` ("..": cut).
pub fn fit_text(s: &str, scale: i32, max_px: i32) -> String {
    let max_chars = (max_px / (GLYPH * scale.max(1))).max(0) as usize;
    if s.chars().count() <= max_chars {
        return s.to_string();
    }
    if max_chars <= 2 {
        return s.chars().take(max_chars).collect();
    }
    let mut t: String = s.chars().take(max_chars - 2).collect();
    t.push_str("..");
    t
}

/// The 8×8 bitmap of `c` (row bytes, bit 0 = leftmost pixel); `?` when the font lacks it.
fn glyph(c: char) -> [u8; 8] {
    let u = c as u32;
    match u {
        0x20..=0x7e => BASIC_LEGACY[u as usize],
        0xa0..=0xff => LATIN_LEGACY[(u - 0xa0) as usize],
        0x390..=0x3c9 => GREEK_LEGACY[(u - 0x390) as usize],
        // Typographic dashes and the minus sign as a hyphen.
        0x2010..=0x2015 | 0x2212 => BASIC_LEGACY[b'-' as usize],
        0x2019 => BASIC_LEGACY[b'\'' as usize],
        0x2026 => BASIC_LEGACY[b':' as usize],
        0x22c5 | 0x2219 => LATIN_LEGACY[0xb7 - 0xa0],
        _ => BASIC_LEGACY[b'?' as usize],
    }
}

/// A point in pixel coordinates.
type Pt = (f64, f64);

/// The part of segment `a`–`b` inside `r` (Liang–Barsky), with the parameter of its start
/// along `a`–`b`; `None` when it misses `r` or is not finite.
fn clip_segment(a: Pt, b: Pt, r: Rect) -> Option<(Pt, Pt, f64)> {
    if ![a.0, a.1, b.0, b.1].iter().all(|v| v.is_finite()) {
        return None;
    }
    // A brush pixel may reach one past the edge: clip one pixel wider, the stamp clips exactly.
    let (xmin, xmax) = (r.x0 as f64 - 1.0, r.x1 as f64);
    let (ymin, ymax) = (r.y0 as f64 - 1.0, r.y1 as f64);
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, a.0 - xmin),
        (dx, xmax - a.0),
        (-dy, a.1 - ymin),
        (dy, ymax - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    if t0 > t1 {
        return None;
    }
    Some((
        (a.0 + t0 * dx, a.1 + t0 * dy),
        (a.0 + t1 * dx, a.1 + t1 * dy),
        t0,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipping_keeps_inside_parts_only() {
        let r = Rect {
            x0: 0,
            y0: 0,
            x1: 10,
            y1: 10,
        };
        assert!(clip_segment((-5.0, -5.0), (-1.0, -9.0), r).is_none());
        let (p, q, _) = clip_segment((-10.0, 5.0), (20.0, 5.0), r).unwrap();
        assert!(p.0 >= -1.0 && q.0 <= 10.0);
        assert!(clip_segment((f64::NAN, 0.0), (1.0, 1.0), r).is_none());
        // A huge segment is clipped, not walked pixel by pixel.
        let mut c = Canvas::new(10, 10, WHITE);
        c.line((-1e15, 5.0), (1e15, 5.0), 2, BLACK, r, None);
        assert!(c.px.chunks(3).any(|p| p == BLACK));
    }

    #[test]
    fn text_draws_pixels_and_fits() {
        let mut c = Canvas::new(40, 40, WHITE);
        c.text(0, 0, "A", 2, BLACK);
        c.text_up(20, 39, "µ°", 1, BLACK);
        assert!(c.px.chunks(3).filter(|p| *p == BLACK).count() > 20);
        assert_eq!(text_width("abc", 2), 48);
        assert_eq!(fit_text("compacity", 1, 48), "comp..");
        assert_eq!(fit_text("abc", 1, 48), "abc");
    }
}
