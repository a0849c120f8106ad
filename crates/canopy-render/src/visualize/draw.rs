//! Drawing on a film: lines, rectangles and text in sRGB colours (converted to linear so
//! that the written image shows exactly the colour asked for).

use super::font::draw_text;
use crate::film::Film;
use glam::Vec3;

/// The inverse of the sRGB transfer function.
fn srgb_to_linear(c: Vec3) -> Vec3 {
    c.map(crate::film::srgb_to_linear)
}

pub struct Canvas<'a> {
    film: &'a mut Film,
}

impl<'a> Canvas<'a> {
    pub fn new(film: &'a mut Film) -> Self {
        Self { film }
    }

    pub fn width(&self) -> i32 {
        self.film.width as i32
    }

    pub fn height(&self) -> i32 {
        self.film.height as i32
    }

    /// Mixes `srgb` into pixel (x, y) with opacity `alpha`; off-image pixels are ignored.
    pub fn blend(&mut self, x: i32, y: i32, srgb: Vec3, alpha: f32) {
        if x < 0 || y < 0 || x >= self.width() || y >= self.height() {
            return;
        }
        let pixel = &mut self.film.pixels[y as usize * self.film.width as usize + x as usize];
        // Blend in display space, which is what the eye compares.
        let shown = Vec3::from(pixel.to_array().map(crate::film::linear_to_srgb));
        *pixel = srgb_to_linear(shown.lerp(srgb, alpha));
    }

    pub fn fill_rect(&mut self, x: i32, y: i32, w: i32, h: i32, srgb: Vec3, alpha: f32) {
        for py in y..y + h {
            for px in x..x + w {
                self.blend(px, py, srgb, alpha);
            }
        }
    }

    pub fn text(&mut self, text: &str, x: i32, y: i32, scale: u32, srgb: Vec3) {
        draw_text(text, x, y, scale, |px, py| self.blend(px, py, srgb, 1.0));
    }

    /// A one-pixel line from (x0, y0) to (x1, y1), clipped to the image first so that
    /// far off-screen endpoints cost nothing.
    pub fn line(&mut self, (x0, y0): (f32, f32), (x1, y1): (f32, f32), srgb: Vec3, alpha: f32) {
        let Some(((x0, y0), (x1, y1))) = clip_to_rect(
            (x0, y0),
            (x1, y1),
            self.width() as f32,
            self.height() as f32,
        ) else {
            return;
        };
        let steps = (x1 - x0).abs().max((y1 - y0).abs()).ceil().max(1.0) as i32;
        for i in 0..=steps {
            let t = i as f32 / steps as f32;
            let (x, y) = (x0 + t * (x1 - x0), y0 + t * (y1 - y0));
            self.blend(x.floor() as i32, y.floor() as i32, srgb, alpha);
        }
    }
}

/// Liang–Barsky clipping of a segment to `[0, w) x [0, h)`.
fn clip_to_rect(a: (f32, f32), b: (f32, f32), w: f32, h: f32) -> Option<((f32, f32), (f32, f32))> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f32, 1.0f32);
    for (p, q) in [
        (-dx, a.0),
        (dx, w - 1e-3 - a.0),
        (-dy, a.1),
        (dy, h - 1e-3 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t0 <= t1).then_some((
        (a.0 + t0 * dx, a.1 + t0 * dy),
        (a.0 + t1 * dx, a.1 + t1 * dy),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blending_fully_gives_the_exact_srgb_colour() {
        let mut film = Film::new(2, 2);
        let colour = Vec3::new(0.2, 0.6, 1.0);
        Canvas::new(&mut film).blend(1, 1, colour, 1.0);
        let back = film.pixel(1, 1).to_array().map(crate::film::linear_to_srgb);
        assert!((Vec3::from(back) - colour).abs().max_element() < 1e-4);
    }

    #[test]
    fn horizontal_line_lights_its_row_only() {
        let mut film = Film::new(10, 5);
        Canvas::new(&mut film).line((-5.0, 2.5), (50.0, 2.5), Vec3::ONE, 1.0);
        for y in 0..5 {
            for x in 0..10 {
                assert_eq!(film.pixel(x, y) != Vec3::ZERO, y == 2, "({x}, {y})");
            }
        }
    }

    #[test]
    fn segment_entirely_outside_is_dropped() {
        assert_eq!(clip_to_rect((-5.0, -5.0), (-1.0, 20.0), 10.0, 10.0), None);
    }
}
