//! Side-by-side comparison sheets with labels, and image-difference statistics: the one PSNR
//! of pomkit, which `pomkit render --compare`, the renderers' agreement tests and the viewer's
//! export check all use.

use crate::render::RenderOutput;

/// An sRGB8 image.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pixels, row-major.
    pub pixels: Vec<[u8; 3]>,
}

impl From<&RenderOutput> for Image {
    /// The render as the PNG would store it ([`RenderOutput::to_srgb8`]).
    fn from(out: &RenderOutput) -> Self {
        Self { width: out.width, height: out.height, pixels: out.to_srgb8() }
    }
}

impl Image {
    /// A blank image of one colour.
    #[must_use]
    pub fn filled(width: u32, height: u32, c: [u8; 3]) -> Self {
        Self { width, height, pixels: vec![c; width as usize * height as usize] }
    }

    /// Copies `src` with its top-left corner at `(x, y)` (clipped).
    pub fn blit(&mut self, src: &Image, x: u32, y: u32) {
        for sy in 0..src.height {
            for sx in 0..src.width {
                let (dx, dy) = (x + sx, y + sy);
                if dx < self.width && dy < self.height {
                    self.pixels[(dy * self.width + dx) as usize] = src.pixels[(sy * src.width + sx) as usize];
                }
            }
        }
    }

    /// Draws `text` with the built-in 5x7 font, each font pixel `scale` pixels, top-left at
    /// `(x, y)`, on a dark band for legibility. Characters without a glyph draw as a box.
    pub fn label(&mut self, text: &str, x: u32, y: u32, scale: u32, color: [u8; 3]) {
        let scale = scale.max(1);
        let advance = 6 * scale;
        let w = text.chars().count() as u32 * advance + 2 * scale;
        let h = 9 * scale;
        for py in y..(y + h).min(self.height) {
            for px in x..(x + w).min(self.width) {
                let p = &mut self.pixels[(py * self.width + px) as usize];
                *p = p.map(|c| c / 3);
            }
        }
        for (k, ch) in text.chars().enumerate() {
            let rows = glyph(ch);
            let gx = x + scale + k as u32 * advance;
            for (r, bits) in rows.iter().enumerate() {
                for c in 0..5u32 {
                    if bits & (0x10 >> c) != 0 {
                        for yy in 0..scale {
                            for xx in 0..scale {
                                let (px, py) = (gx + c * scale + xx, y + scale + r as u32 * scale + yy);
                                if px < self.width && py < self.height {
                                    self.pixels[(py * self.width + px) as usize] = color;
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}

/// Lays `panels` out left to right in rows of at most `columns`, each labelled, on a dark sheet
/// with `gap` pixels between panels.
#[must_use]
pub fn sheet(panels: &[(String, Image)], columns: usize, gap: u32) -> Image {
    let columns = columns.max(1);
    let (pw, ph) = panels.iter().fold((1, 1), |(w, h), (_, p)| (w.max(p.width), h.max(p.height)));
    let cols = columns.min(panels.len().max(1)) as u32;
    let rows = (panels.len() as u32).div_ceil(cols).max(1);
    let mut out = Image::filled(cols * pw + (cols + 1) * gap, rows * ph + (rows + 1) * gap, [18, 18, 22]);
    let scale = (pw / 220).clamp(1, 4);
    for (i, (name, img)) in panels.iter().enumerate() {
        let (c, r) = (i as u32 % cols, i as u32 / cols);
        let (x, y) = (gap + c * (pw + gap), gap + r * (ph + gap));
        out.blit(img, x, y);
        out.label(name, x + 2 * scale, y + 2 * scale, scale, [255, 240, 200]);
    }
    out
}

/// How different two images are.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Difference {
    /// Peak signal-to-noise ratio in dB over the sRGB8 values (infinite when identical).
    pub psnr_db: f64,
    /// Share of pixels whose largest channel difference exceeds the threshold.
    pub share_over: f64,
    /// The threshold used, in 8-bit steps.
    pub threshold: u8,
}

/// Compares two images of the same size; `mask` (if given) selects the pixels that count.
///
/// # Panics
/// If the sizes differ (a programming error).
#[must_use]
pub fn difference(a: &Image, b: &Image, threshold: u8, mask: Option<&[bool]>) -> Difference {
    assert_eq!((a.width, a.height), (b.width, b.height), "images must have the same size");
    let (mut se, mut n, mut over) = (0.0f64, 0usize, 0usize);
    for (i, (p, q)) in a.pixels.iter().zip(&b.pixels).enumerate() {
        if mask.is_some_and(|m| !m[i]) {
            continue;
        }
        let mut worst = 0u8;
        for c in 0..3 {
            let d = (i32::from(p[c]) - i32::from(q[c])).unsigned_abs() as u8;
            worst = worst.max(d);
            se += f64::from(d) * f64::from(d);
        }
        over += usize::from(worst > threshold);
        n += 1;
    }
    let mse = if n > 0 { se / (3 * n) as f64 } else { 0.0 };
    let psnr_db = psnr_of_mse(mse, 255.0);
    Difference { psnr_db, share_over: if n > 0 { over as f64 / n as f64 } else { 0.0 }, threshold }
}

/// 5x7 glyphs, one byte per row, the top bit of the low five bits is the leftmost column.
fn glyph(c: char) -> [u8; 7] {
    match c.to_ascii_lowercase() {
        'a' => [0x0e, 0x11, 0x11, 0x1f, 0x11, 0x11, 0x11],
        'b' => [0x1e, 0x11, 0x11, 0x1e, 0x11, 0x11, 0x1e],
        'c' => [0x0e, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0e],
        'd' => [0x1e, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1e],
        'e' => [0x1f, 0x10, 0x10, 0x1e, 0x10, 0x10, 0x1f],
        'f' => [0x1f, 0x10, 0x10, 0x1e, 0x10, 0x10, 0x10],
        'g' => [0x0e, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0f],
        'h' => [0x11, 0x11, 0x11, 0x1f, 0x11, 0x11, 0x11],
        'i' => [0x0e, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0e],
        'j' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0c],
        'k' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'l' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1f],
        'm' => [0x11, 0x1b, 0x15, 0x15, 0x11, 0x11, 0x11],
        'n' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'o' => [0x0e, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0e],
        'p' => [0x1e, 0x11, 0x11, 0x1e, 0x10, 0x10, 0x10],
        'q' => [0x0e, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0d],
        'r' => [0x1e, 0x11, 0x11, 0x1e, 0x14, 0x12, 0x11],
        's' => [0x0f, 0x10, 0x10, 0x0e, 0x01, 0x01, 0x1e],
        't' => [0x1f, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'u' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0e],
        'v' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0a, 0x04],
        'w' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0a],
        'x' => [0x11, 0x11, 0x0a, 0x04, 0x0a, 0x11, 0x11],
        'y' => [0x11, 0x11, 0x0a, 0x04, 0x04, 0x04, 0x04],
        'z' => [0x1f, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1f],
        '0' => [0x0e, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0e],
        '1' => [0x04, 0x0c, 0x04, 0x04, 0x04, 0x04, 0x0e],
        '2' => [0x0e, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1f],
        '3' => [0x1f, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0e],
        '4' => [0x02, 0x06, 0x0a, 0x12, 0x1f, 0x02, 0x02],
        '5' => [0x1f, 0x10, 0x1e, 0x01, 0x01, 0x11, 0x0e],
        '6' => [0x06, 0x08, 0x10, 0x1e, 0x11, 0x11, 0x0e],
        '7' => [0x1f, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0e, 0x11, 0x11, 0x0e, 0x11, 0x11, 0x0e],
        '9' => [0x0e, 0x11, 0x11, 0x0f, 0x01, 0x02, 0x0c],
        '-' => [0x00, 0x00, 0x00, 0x1f, 0x00, 0x00, 0x00],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0c, 0x0c],
        ',' => [0x00, 0x00, 0x00, 0x00, 0x0c, 0x04, 0x08],
        ':' => [0x00, 0x0c, 0x0c, 0x00, 0x0c, 0x0c, 0x00],
        '%' => [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '/' => [0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00],
        '=' => [0x00, 0x00, 0x1f, 0x00, 0x1f, 0x00, 0x00],
        '>' => [0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08],
        ' ' => [0; 7],
        _ => [0x1f, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1f],
    }
}

/// Peak signal-to-noise ratio in dB of `a` against `b`, values whose full range is `peak` (255
/// for 8-bit channels, 1 for colours in `[0, 1]`): `10 log10(peak^2 / MSE)`, infinite when the
/// two are equal. Any channel layout: the slices are compared element by element.
///
/// # Panics
/// If the lengths differ (a programming error).
#[must_use]
pub fn psnr<T: Copy + Into<f64>>(a: &[T], b: &[T], peak: f64) -> f64 {
    assert_eq!(a.len(), b.len(), "PSNR of slices of different lengths");
    let se: f64 = a.iter().zip(b).map(|(&x, &y)| (x.into() - y.into()).powi(2)).sum();
    psnr_of_mse(if a.is_empty() { 0.0 } else { se / a.len() as f64 }, peak)
}

fn psnr_of_mse(mse: f64, peak: f64) -> f64 {
    if mse > 0.0 { 10.0 * (peak * peak / mse).log10() } else { f64::INFINITY }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_of_identical_images_is_infinite_and_finite_otherwise() {
        let a = Image::filled(4, 4, [100, 100, 100]);
        let mut b = a.clone();
        assert!(difference(&a, &b, 8, None).psnr_db.is_infinite());
        b.pixels[0] = [110, 100, 100];
        let d = difference(&a, &b, 8, None);
        // MSE = 100 / (3 * 16); PSNR = 10 log10(255^2 / MSE).
        let expect = 10.0 * (255.0f64 * 255.0 / (100.0 / 48.0)).log10();
        assert!((d.psnr_db - expect).abs() < 1e-9);
        assert!((d.share_over - 1.0 / 16.0).abs() < 1e-12);
        let mask: Vec<bool> = (0..16).map(|i| i != 0).collect();
        assert!(difference(&a, &b, 8, Some(&mask)).psnr_db.is_infinite());
        // The slice form agrees, on bytes and on unit floats.
        let flat = |i: &Image| i.pixels.concat();
        assert!((psnr(&flat(&a), &flat(&b), 255.0) - expect).abs() < 1e-9);
        let unit = |i: &Image| i.pixels.concat().iter().map(|&c| f32::from(c) / 255.0).collect::<Vec<f32>>();
        assert!((psnr(&unit(&a), &unit(&b), 1.0) - expect).abs() < 1e-4);
        assert!(psnr::<u8>(&[], &[], 255.0).is_infinite());
    }

    #[test]
    fn sheet_places_panels_and_labels_them() {
        let red = Image::filled(10, 30, [200, 0, 0]);
        let blue = Image::filled(10, 30, [0, 0, 200]);
        let s = sheet(&[("a".into(), red), ("b".into(), blue)], 2, 2);
        assert_eq!((s.width, s.height), (26, 34));
        // Below the label band each panel keeps its colour; the label band darkens its top.
        assert_eq!(s.pixels[(25 * 26 + 10) as usize], [200, 0, 0]);
        assert_eq!(s.pixels[(25 * 26 + 22) as usize], [0, 0, 200]);
        assert_ne!(s.pixels[(5 * 26 + 10) as usize], [200, 0, 0]);
        let mut img = Image::filled(40, 12, [0, 0, 0]);
        img.label("pom", 0, 0, 1, [255, 255, 255]);
        assert!(img.pixels.contains(&[255, 255, 255]));
    }
}
