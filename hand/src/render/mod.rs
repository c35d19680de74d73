//! A small software rasteriser for shaded pictures of triangle meshes, written as PNG: contact
//! sheets of generated hand poses (`crease handgen`) and strips of a mocap-driven hand, so a person
//! can check shapes by eye without a GPU.
//!
//! Layout:
//! - `camera`: [`View`] and [`Camera`]: orthographic cameras, fitted to a bounding box.
//! - `shade`: [`RenderSettings`], [`Light`]: colours, lights fixed relative to the camera,
//!   supersampling; the Blinn-Phong shader and the sRGB transfer functions.
//! - `raster`: [`Renderer`]: z-buffered rasterisation into reusable buffers, in the settings'
//!   colour or with per-vertex colours ([`Renderer::render_colored_into`], e.g. error heat maps);
//!   [`render`] for one picture.
//! - `image`: [`Image`]: RGB8 pictures with [`Image::blit`], [`Image::fill_rect`] and PNG output
//!   ([`Image::encode_png`], [`Image::write_png`]); [`image_stats`]: mean and variance of
//!   luminance (a "not blank" check).
//! - `font`: the built-in 5x7 bitmap font ([`Image::draw_text`]).
//! - `sheet`: [`contact_sheet`] and [`SheetLayout`]: poses x views in a labelled grid.
//!
//! # Conventions
//!
//! The camera looks along [`Camera::forward`] with [`Camera::up`] pointing up the picture and
//! [`Camera::right`] `= forward x up` pointing right, so nothing is mirrored: a camera looking
//! along `-Z` with `+Y` up shows world `+X` to the right and `+Y` up. Image rows run top to
//! bottom, pixel `(x, y)` covers `[x, x + 1) x [y, y + 1)` and is sampled at its centre.
//!
//! In the hand skeleton frame ([`crate`]: wrist at the origin, `+Y` towards the fingers,
//! `+Z` out of the back of the hand, thumb towards `-X` for the right hand) this gives, with the
//! fingers pointing up the picture:
//! - [`View::Back`] (from `+Z`): the back of the hand, the thumb of a right hand on the **left**
//!   (as you see the back of your own right hand held up in front of you);
//! - [`View::Palm`] (from `-Z`): the palm, the thumb of a right hand on the **right**;
//! - [`View::ThumbSide`] (from `-X`): the radial side, the palm on the left and the back on the
//!   right;
//! - [`View::LittleSide`] (from `+X`): the ulnar side, the back on the left.
//!
//! Shading is Lambert plus ambient plus Blinn-Phong specular (Blinn 1977, "Models of light
//! reflection for computer synthesized pictures"), computed in linear light from interpolated
//! area-weighted vertex normals and encoded to 8-bit sRGB (IEC 61966-2-1). Back faces are neither
//! culled nor darkened: meshes may be open, so a face seen from behind is lit as if it faced the
//! camera.

use std::io;
use std::path::PathBuf;

mod camera;
mod font;
mod image;
mod raster;
mod shade;
mod sheet;

pub use camera::{Camera, TILE_MARGIN, View};
pub use font::{GLYPH_ADVANCE, GLYPH_HEIGHT, GLYPH_WIDTH};
pub use image::{Image, image_stats};
pub use raster::{Renderer, render};
pub use shade::{LIGHT_GREY, Light, RenderSettings, SKIN, linear_to_srgb8, srgb8_to_linear};
pub use sheet::{
    LABEL_COLOR, SHEET_BACKGROUND, SHEET_GAP, SheetLayout, VIEW_GAP, VIEW_LABEL_COLOR,
    contact_sheet, contact_sheet_with,
};

/// An error from this module. Messages name the file.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The PNG encoder refused the image (e.g. a zero width or height).
    #[error("encoding a {width}x{height} PNG: {source}")]
    Encode {
        /// Image width in pixels.
        width: u32,
        /// Image height in pixels.
        height: u32,
        /// The encoder's error.
        #[source]
        source: png::EncodingError,
    },
    /// The PNG file could not be written.
    #[error("writing PNG {}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: io::Error,
    },
}
