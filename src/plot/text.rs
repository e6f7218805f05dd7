//! The charts' text: the embedded font, registered with plotters (which measures text with it
//! to lay a chart out), and [`Canvas`], plotters' bitmap backend with the glyphs drawn by
//! `ab_glyph` at their true positions. plotters 0.3.7's own `ab_glyph` drawing drops each
//! glyph's left side bearing, so that "histogram" reads "hist ogram".

use ab_glyph::{Font, FontRef, ScaleFont};
use plotters::prelude::{BitMapBackend, DrawingBackend, FontStyle};
use plotters_backend::text_anchor::{HPos, VPos};
use plotters_backend::{BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingErrorKind};
use std::sync::OnceLock;

/// The font of every chart's text: Liberation Sans Regular 2.1.5 (SIL Open Font License 1.1,
/// the licence is `data/fonts/OFL.txt`), embedded in the binary.
pub const FONT_TTF: &[u8] = include_bytes!("../../data/fonts/LiberationSans-Regular.ttf");

/// [`FONT_TTF`], parsed, and registered once per process as plotters' "sans-serif" family (the
/// family of every text style used here and of plotters' defaults).
pub(super) fn font() -> &'static FontRef<'static> {
    static FONT: OnceLock<FontRef<'static>> = OnceLock::new();
    FONT.get_or_init(|| {
        let parsed = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT_TTF).is_ok();
        assert!(parsed, "the embedded data/fonts/LiberationSans-Regular.ttf does not parse as a font");
        FontRef::try_from_slice(FONT_TTF).expect("parsed just above")
    })
}

type Drawn<'a> = Result<(), DrawingErrorKind<<BitMapBackend<'a> as DrawingBackend>::ErrorType>>;

/// A [`BitMapBackend`] whose text is drawn with [`font`]; everything else is the bitmap's.
pub(super) struct Canvas<'a>(pub BitMapBackend<'a>);

impl<'a> DrawingBackend for Canvas<'a> {
    type ErrorType = <BitMapBackend<'a> as DrawingBackend>::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.0.get_size()
    }
    fn ensure_prepared(&mut self) -> Drawn<'a> {
        self.0.ensure_prepared()
    }
    fn present(&mut self) -> Drawn<'a> {
        self.0.present()
    }
    fn draw_pixel(&mut self, p: BackendCoord, c: BackendColor) -> Drawn<'a> {
        self.0.draw_pixel(p, c)
    }
    fn draw_line<S: BackendStyle>(&mut self, a: BackendCoord, b: BackendCoord, s: &S) -> Drawn<'a> {
        self.0.draw_line(a, b, s)
    }
    fn draw_rect<S: BackendStyle>(&mut self, a: BackendCoord, b: BackendCoord, s: &S, fill: bool) -> Drawn<'a> {
        self.0.draw_rect(a, b, s, fill)
    }
    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(&mut self, path: I, s: &S) -> Drawn<'a> {
        self.0.draw_path(path, s)
    }
    fn draw_circle<S: BackendStyle>(&mut self, c: BackendCoord, r: u32, s: &S, fill: bool) -> Drawn<'a> {
        self.0.draw_circle(c, r, s, fill)
    }
    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(&mut self, vert: I, s: &S) -> Drawn<'a> {
        self.0.fill_polygon(vert, s)
    }
    fn blit_bitmap(&mut self, pos: BackendCoord, size: (u32, u32), src: &[u8]) -> Drawn<'a> {
        self.0.blit_bitmap(pos, size, src)
    }

    /// `text` in the box plotters laid out for it (advances and kerning wide, size / 1.24
    /// high, anchored at `pos`), its capitals centred in the box's height.
    fn draw_text<S: BackendTextStyle>(&mut self, text: &str, style: &S, pos: BackendCoord) -> Drawn<'a> {
        let colour = style.color();
        let size = style.size() as f32;
        if colour.alpha == 0.0 || size.is_nan() || size <= 0.0 {
            return Ok(());
        }
        let scaled = font().as_scaled(size);
        let ids: Vec<_> = text.chars().map(|c| scaled.glyph_id(c)).collect();
        let kern = |k: usize| if k == 0 { 0.0 } else { scaled.kern(ids[k - 1], ids[k]) };
        let width: f32 = (0..ids.len()).map(|k| kern(k) + scaled.h_advance(ids[k])).sum();
        let (w, h) = (width as i32, (size / 1.24) as i32);
        let dx = match style.anchor().h_pos {
            HPos::Left => 0,
            HPos::Center => -w / 2,
            HPos::Right => -w,
        };
        let dy = match style.anchor().v_pos {
            VPos::Top => 0,
            VPos::Center => -h / 2,
            VPos::Bottom => -h,
        };
        let baseline = 0.75 * size;
        let transform = style.transform();
        let mut caret = 0.0f32;
        for (k, &id) in ids.iter().enumerate() {
            caret += kern(k);
            if let Some(outline) = scaled.outline_glyph(id.with_scale_and_position(size, ab_glyph::point(caret, baseline))) {
                let min = outline.px_bounds().min;
                let mut pixels = Vec::new();
                outline.draw(|x, y, cover| pixels.push((min.x as i32 + x as i32, min.y as i32 + y as i32, cover)));
                for (x, y, cover) in pixels {
                    let (x, y) = transform.transform(x + dx, y + dy);
                    self.0.draw_pixel((pos.0 + x, pos.1 + y), BackendColor { alpha: colour.alpha * cover.min(1.0) as f64, rgb: colour.rgb })?;
                }
            }
            caret += scaled.h_advance(id);
        }
        Ok(())
    }
}
