//! [`Image`]: an 8-bit sRGB picture with pixel access, rectangles, blits and PNG output, and
//! [`image_stats`], the luminance statistics the tests use as a "not blank" check.

use std::path::Path;

use super::RenderError;

/// An 8-bit sRGB picture, rows top to bottom, `width * height` pixels.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Image {
    width: u32,
    height: u32,
    pub(super) pixels: Vec<[u8; 3]>,
}

impl Image {
    /// A `width x height` image filled with `color`.
    pub fn new(width: u32, height: u32, color: [u8; 3]) -> Image {
        Image {
            width,
            height,
            pixels: vec![color; width as usize * height as usize],
        }
    }

    /// An image from its pixels (rows top to bottom), or `None` if there are not exactly
    /// `width * height` of them.
    pub fn from_pixels(width: u32, height: u32, pixels: Vec<[u8; 3]>) -> Option<Image> {
        (pixels.len() == width as usize * height as usize).then_some(Image {
            width,
            height,
            pixels,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// All pixels, rows top to bottom.
    pub fn pixels(&self) -> &[[u8; 3]] {
        &self.pixels
    }

    /// The pixel at column `x`, row `y` (0 at the top).
    ///
    /// # Panics
    /// If `(x, y)` is outside the image.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) outside image"
        );
        self.pixels[y as usize * self.width as usize + x as usize]
    }

    /// Sets the pixel at `(x, y)`; does nothing outside the image.
    pub fn set_pixel(&mut self, x: u32, y: u32, color: [u8; 3]) {
        if x < self.width && y < self.height {
            self.pixels[y as usize * self.width as usize + x as usize] = color;
        }
    }

    /// Changes the size to `width x height`, keeping the allocation where it can; the contents
    /// are unspecified until overwritten.
    pub fn resize(&mut self, width: u32, height: u32) {
        self.width = width;
        self.height = height;
        self.pixels
            .resize(width as usize * height as usize, [0, 0, 0]);
    }

    /// Sets every pixel to `color`.
    pub fn fill(&mut self, color: [u8; 3]) {
        self.pixels.fill(color);
    }

    /// Fills the rectangle with top-left corner `(x, y)` and size `w x h`, clipped to the image.
    pub fn fill_rect(&mut self, x: u32, y: u32, w: u32, h: u32, color: [u8; 3]) {
        let x_end = x.saturating_add(w).min(self.width);
        let y_end = y.saturating_add(h).min(self.height);
        if x >= x_end {
            // Wholly right of the image (a label drawn past its edge): nothing to fill.
            return;
        }
        for row in y..y_end {
            let start = row as usize * self.width as usize;
            self.pixels[start + x as usize..start + x_end as usize].fill(color);
        }
    }

    /// Copies `other` with its top-left corner at `(x, y)`, clipped to this image.
    pub fn blit(&mut self, other: &Image, x: u32, y: u32) {
        if x >= self.width || y >= self.height {
            return;
        }
        let w = other.width.min(self.width - x) as usize;
        let h = other.height.min(self.height - y) as usize;
        for row in 0..h {
            let src = row * other.width as usize;
            let dst = (y as usize + row) * self.width as usize + x as usize;
            self.pixels[dst..dst + w].copy_from_slice(&other.pixels[src..src + w]);
        }
    }

    /// The image as a PNG file (8-bit RGB, no alpha).
    ///
    /// # Errors
    /// [`RenderError::Encode`] if the encoder refuses it (a zero width or height).
    pub fn encode_png(&self) -> Result<Vec<u8>, RenderError> {
        let encode_error = |source| RenderError::Encode {
            width: self.width,
            height: self.height,
            source,
        };
        let mut bytes = Vec::new();
        let mut encoder = png::Encoder::new(&mut bytes, self.width, self.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut writer = encoder.write_header().map_err(encode_error)?;
        writer
            .write_image_data(bytemuck::cast_slice(&self.pixels))
            .map_err(encode_error)?;
        writer.finish().map_err(encode_error)?;
        Ok(bytes)
    }

    /// Writes the image as a PNG file at `path`, atomically (a temporary file renamed into
    /// place).
    ///
    /// # Errors
    /// [`RenderError::Encode`] as for [`Image::encode_png`]; [`RenderError::Io`], naming `path`,
    /// if the file cannot be written.
    pub fn write_png(&self, path: impl AsRef<Path>) -> Result<(), RenderError> {
        let path = path.as_ref();
        let bytes = self.encode_png()?;
        crease_core::atomic::write_atomic_with(path, |out| out.write_all(&bytes)).map_err(
            |source| RenderError::Io {
                path: path.to_path_buf(),
                source,
            },
        )
    }
}

/// Mean and variance of the luminance of `image`'s pixels, in 8-bit units (so the variance is in
/// units squared): Rec. 709 luma weights applied to the sRGB values as stored. A blank picture has
/// variance 0. `(0, 0)` for an empty image.
pub fn image_stats(image: &Image) -> (f64, f64) {
    let n = image.pixels.len();
    if n == 0 {
        return (0.0, 0.0);
    }
    let luma = |p: &[u8; 3]| {
        0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2])
    };
    let mean = image.pixels.iter().map(luma).sum::<f64>() / n as f64;
    let variance = image
        .pixels
        .iter()
        .map(|p| (luma(p) - mean).powi(2))
        .sum::<f64>()
        / n as f64;
    (mean, variance)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fills_and_text_past_the_right_edge_are_clipped_not_a_panic() {
        // A report's control-point label can start right of its tile (found on the generated
        // hand's report: a point near the tile's right edge).
        let (bg, ink) = ([255, 255, 255], [0, 0, 0]);
        let mut image = Image::new(10, 6, bg);
        image.fill_rect(12, 1, 3, 2, ink);
        image.fill_rect(10, 0, 1, 1, ink);
        image.draw_text(11, 0, "label", ink, 2);
        assert!(image.pixels().iter().all(|&p| p == bg));
        // Straddling the edge: only the inside is filled.
        image.fill_rect(8, 2, 5, 1, ink);
        for x in 0..10 {
            assert_eq!(image.pixel(x, 2), if x >= 8 { ink } else { bg }, "x {x}");
        }
        assert!((0..10).all(|x| image.pixel(x, 1) == bg && image.pixel(x, 3) == bg));
    }
}
