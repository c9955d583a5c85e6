//! Text of the figures: one layout for both formats, and glyph-exact rasterisation.
//!
//! [`Typeset`] wraps a plotters backend. Both formats get the text extents from the shipped
//! font's advances and kerning (so the SVG and the PNG are laid out alike), and the raster
//! one draws each glyph at its pen position with its side bearing: plotters 0.3.7's own
//! `ab_glyph` text drops the bearings and rounds the pen to whole pixels, which spaces
//! letters unevenly ("iterat ions"). Sizes follow the SVG backend: a plotters font size `z`
//! is an em of `z / 1.24`, and the vertical anchors are the SVG's `dy` (top: baseline 0.76 em
//! below the anchor; centre: 0.5 ex; bottom: 0.5 ex above).

use ab_glyph::{point, Font, FontRef, PxScale, ScaleFont};
use plotters_backend::text_anchor::{HPos, VPos};
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingBackend, DrawingErrorKind,
};
use std::sync::OnceLock;

/// The shipped font, parsed once.
fn font() -> &'static FontRef<'static> {
    static FONT: OnceLock<FontRef<'static>> = OnceLock::new();
    FONT.get_or_init(|| {
        // Part of the binary: a font that does not parse is a build defect.
        FontRef::try_from_slice(super::FONT).expect("assets/fonts/DejaVuSans.ttf parses")
    })
}

/// Em size in pixels of plotters font size `size` (what the SVG backend writes).
fn em(size: f64) -> f32 {
    (size / 1.24) as f32
}

/// Pixel scale giving an em of `em` pixels.
fn scale(em: f32) -> PxScale {
    let f = font();
    let upem = f.units_per_em().unwrap_or(2048.0);
    PxScale::from(em * f.height_unscaled() / upem)
}

/// Width in pixels of `text` at em `em`: advances and kerning.
fn width(text: &str, em: f32) -> f32 {
    let f = font().as_scaled(scale(em));
    let mut w = 0.0;
    let mut prev = None;
    for c in text.chars() {
        let id = f.glyph_id(c);
        if let Some(p) = prev {
            w += f.kern(p, id);
        }
        w += f.h_advance(id);
        prev = Some(id);
    }
    w
}

/// Baseline offset below the anchor for a vertical anchor, in pixels at em `em`.
fn baseline(v: VPos, em: f32) -> f32 {
    // DejaVu Sans' x-height is 1120/2048 em; SVG's `ex` is that.
    let half_ex = 0.5 * 1120.0 / 2048.0 * em;
    match v {
        VPos::Top => 0.76 * em,
        VPos::Center => half_ex,
        VPos::Bottom => -half_ex,
    }
}

/// A plotters backend whose text is measured (and, when `raster`, drawn) with the shipped
/// font; everything else is passed through.
pub struct Typeset<B> {
    /// The backend drawn on.
    pub inner: B,
    /// Draw text as pixels here (bitmap); otherwise the inner backend writes it (SVG text).
    pub raster: bool,
}

impl<B: DrawingBackend> DrawingBackend for Typeset<B> {
    type ErrorType = B::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.inner.get_size()
    }

    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.ensure_prepared()
    }

    fn present(&mut self) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.present()
    }

    fn draw_pixel(
        &mut self,
        point: BackendCoord,
        color: BackendColor,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_pixel(point, color)
    }

    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_line(from, to, style)
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_rect(upper_left, bottom_right, style, fill)
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_path(path, style)
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.draw_circle(center, radius, style, fill)
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.fill_polygon(vert, style)
    }

    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        size: (u32, u32),
        src: &[u8],
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        self.inner.blit_bitmap(pos, size, src)
    }

    fn estimate_text_size<S: BackendTextStyle>(
        &self,
        text: &str,
        style: &S,
    ) -> Result<(u32, u32), DrawingErrorKind<B::ErrorType>> {
        let em = em(style.size());
        Ok((width(text, em).ceil() as u32, em.ceil() as u32))
    }

    fn draw_text<S: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &S,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<B::ErrorType>> {
        if !self.raster {
            return self.inner.draw_text(text, style, pos);
        }
        let color = style.color();
        if color.alpha == 0.0 {
            return Ok(());
        }
        let em = em(style.size());
        let f = font().as_scaled(scale(em));
        let anchor = style.anchor();
        let w = width(text, em);
        // Pen start and baseline in the text's own frame, the anchor at the origin.
        let mut x = match anchor.h_pos {
            HPos::Left => 0.0,
            HPos::Center => -0.5 * w,
            HPos::Right => -w,
        };
        let y = baseline(anchor.v_pos, em);
        let trans = style.transform();
        let mut prev = None;
        for c in text.chars() {
            let id = f.glyph_id(c);
            if let Some(p) = prev {
                x += f.kern(p, id);
            }
            prev = Some(id);
            let glyph = id.with_scale_and_position(f.scale(), point(x, y));
            x += f.h_advance(id);
            let Some(outline) = f.outline_glyph(glyph) else {
                continue;
            };
            let b = outline.px_bounds();
            let mut pixels = Vec::new();
            outline.draw(|gx, gy, cov| {
                if cov > 0.0 {
                    pixels.push((b.min.x as i32 + gx as i32, b.min.y as i32 + gy as i32, cov));
                }
            });
            for (tx, ty, cov) in pixels {
                let (dx, dy) = trans.transform(tx, ty);
                let alpha = color.alpha * f64::from(cov.min(1.0));
                self.inner.draw_pixel(
                    (pos.0 + dx, pos.1 + dy),
                    BackendColor {
                        alpha,
                        rgb: color.rgb,
                    },
                )?;
            }
        }
        Ok(())
    }
}
