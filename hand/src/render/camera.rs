//! Views and cameras: [`View`] (a viewing direction named for the hand skeleton frame) and the
//! orthographic [`Camera`] that projects world points to pixels, fitted to a bounding box.

use glam::Vec3;

/// A viewing direction with an up vector, named for the hand skeleton frame (see the module
/// docs): wrist at the origin, `+Y` towards the fingers, `+Z` dorsal, thumb towards `-X`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum View {
    /// From `+Z` looking along `-Z`, `+Y` up: the back of the hand; world `+X` to the right.
    Back,
    /// From `-Z` looking along `+Z`, `+Y` up: the palm; world `+X` to the left.
    Palm,
    /// From `-X` (the thumb side) looking along `+X`, `+Y` up; world `+Z` to the right.
    ThumbSide,
    /// From `+X` (the little-finger side) looking along `-X`, `+Y` up; world `+Z` to the left.
    LittleSide,
    /// Any direction. `forward` is where the camera looks, `up` what points up the picture
    /// (only its part perpendicular to `forward` counts). Zero or parallel vectors fall back to
    /// a valid basis (see [`View::basis`]).
    Custom {
        /// Viewing direction (need not be unit length).
        forward: Vec3,
        /// Up direction (need not be unit length or perpendicular to `forward`).
        up: Vec3,
    },
}

impl View {
    /// The four named views, in the order a contact sheet would show them.
    pub const NAMED: [View; 4] = [View::Back, View::Palm, View::ThumbSide, View::LittleSide];

    /// A short lower-case name: `back`, `palm`, `thumb-side`, `little-side`, `custom`.
    pub fn name(self) -> &'static str {
        match self {
            View::Back => "back",
            View::Palm => "palm",
            View::ThumbSide => "thumb-side",
            View::LittleSide => "little-side",
            View::Custom { .. } => "custom",
        }
    }

    /// The named view called `name` (as [`View::name`] writes it, case-insensitive; `side` is
    /// accepted for `thumb-side`), or `None`.
    pub fn from_name(name: &str) -> Option<View> {
        match name.to_ascii_lowercase().as_str() {
            "back" => Some(View::Back),
            "palm" => Some(View::Palm),
            "thumb-side" | "side" => Some(View::ThumbSide),
            "little-side" => Some(View::LittleSide),
            _ => None,
        }
    }

    /// The orthonormal camera basis `(right, up, forward)` with `right = forward x up`.
    ///
    /// A zero or non-finite `forward` becomes `-Z`; an `up` parallel to `forward` (or zero) is
    /// replaced by `+Y`, or `+Z` when `forward` is along `Y`.
    pub fn basis(self) -> (Vec3, Vec3, Vec3) {
        let (forward, up) = match self {
            View::Back => (Vec3::NEG_Z, Vec3::Y),
            View::Palm => (Vec3::Z, Vec3::Y),
            View::ThumbSide => (Vec3::X, Vec3::Y),
            View::LittleSide => (Vec3::NEG_X, Vec3::Y),
            View::Custom { forward, up } => (forward, up),
        };
        let forward = forward.try_normalize().unwrap_or(Vec3::NEG_Z);
        let right = forward.cross(up).try_normalize().unwrap_or_else(|| {
            let fallback = if forward.y.abs() > 0.9 {
                Vec3::Z
            } else {
                Vec3::Y
            };
            forward.cross(fallback).normalize()
        });
        let up = right.cross(forward);
        (right, up, forward)
    }
}

/// An orthographic camera: a view basis, the world point at the image centre, a scale and an
/// image size.
///
/// [`Camera::project`] maps a world point to pixel coordinates (x right, y down, origin at the
/// top-left corner of the image) and a depth along [`Camera::forward`] (smaller is nearer).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Unit vector pointing right in the picture (`forward x up`).
    pub right: Vec3,
    /// Unit vector pointing up in the picture.
    pub up: Vec3,
    /// Unit viewing direction (from the camera into the scene).
    pub forward: Vec3,
    /// The world point shown at the centre of the image.
    pub center: Vec3,
    /// Pixels per world unit.
    pub pixels_per_unit: f32,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

/// Fraction of the image left empty on each side by [`Camera::fit`] in [`contact_sheet`]: keeps
/// silhouettes off the tile edges and leaves a little room for the view label in the corner.
///
/// [`contact_sheet`]: super::contact_sheet
pub const TILE_MARGIN: f32 = 0.06;

impl Camera {
    /// A camera for `view` centred on `center` at `pixels_per_unit`.
    pub fn orthographic(
        view: View,
        center: Vec3,
        pixels_per_unit: f32,
        width: u32,
        height: u32,
    ) -> Camera {
        let (right, up, forward) = view.basis();
        Camera {
            right,
            up,
            forward,
            center,
            pixels_per_unit,
            width,
            height,
        }
    }

    /// A camera for `view` that shows the box `bounds = (min, max)` (e.g. from
    /// [`Mesh::bounding_box`]) as large as possible with `margin` (a fraction of the image width
    /// and height, clamped to `[0, 0.45]`) left free on every side, centred.
    ///
    /// The box's eight corners are projected, so the fit is exact for the box and conservative
    /// for what is inside it. A box that is flat in the picture in one direction is fitted by the
    /// other; a single point (or an empty mesh's `(ZERO, ZERO)`) gets one pixel per unit.
    ///
    /// [`Mesh::bounding_box`]: crease_core::mesh::Mesh::bounding_box
    pub fn fit(view: View, bounds: (Vec3, Vec3), width: u32, height: u32, margin: f32) -> Camera {
        let (lo, hi) = bounds;
        let mut camera = Camera::orthographic(view, (lo + hi) * 0.5, 1.0, width, height);
        let (mut extent_x, mut extent_y) = (0.0f32, 0.0f32);
        for corner in 0..8 {
            let p = Vec3::new(
                if corner & 1 == 0 { lo.x } else { hi.x },
                if corner & 2 == 0 { lo.y } else { hi.y },
                if corner & 4 == 0 { lo.z } else { hi.z },
            ) - camera.center;
            extent_x = extent_x.max(2.0 * p.dot(camera.right).abs());
            extent_y = extent_y.max(2.0 * p.dot(camera.up).abs());
        }
        let free = 1.0 - 2.0 * margin.clamp(0.0, 0.45);
        let scale_x = width as f32 * free / extent_x;
        let scale_y = height as f32 * free / extent_y;
        // A zero extent gives an infinite scale, which `min` then ignores in favour of the other.
        let scale = scale_x.min(scale_y);
        camera.pixels_per_unit = if scale.is_finite() && scale > 0.0 {
            scale
        } else {
            1.0
        };
        camera
    }

    /// `(x, y, depth)`: pixel coordinates of `p` (x right, y down, `(0, 0)` the top-left corner
    /// of the image, pixel centres at half-integers) and its depth along [`Camera::forward`]
    /// relative to [`Camera::center`] (smaller is nearer the viewer).
    pub fn project(&self, p: Vec3) -> Vec3 {
        let d = p - self.center;
        Vec3::new(
            0.5 * self.width as f32 + d.dot(self.right) * self.pixels_per_unit,
            0.5 * self.height as f32 - d.dot(self.up) * self.pixels_per_unit,
            d.dot(self.forward),
        )
    }

    /// The same view at `factor` times the resolution (for supersampling).
    pub fn scaled(&self, factor: u32) -> Camera {
        Camera {
            pixels_per_unit: self.pixels_per_unit * factor as f32,
            width: self.width * factor,
            height: self.height * factor,
            ..*self
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn view_bases_are_right_handed_and_unmirrored() {
        for view in View::NAMED {
            let (right, up, forward) = view.basis();
            assert!((right.cross(up) - (-forward)).length() < 1e-6, "{view:?}");
            assert_eq!(up, Vec3::Y, "{view:?}");
        }
        assert_eq!(View::Back.basis().0, Vec3::X);
        assert_eq!(View::Palm.basis().0, Vec3::NEG_X);
        assert_eq!(View::ThumbSide.basis().0, Vec3::Z);
    }

    #[test]
    fn degenerate_custom_views_get_a_basis() {
        for (forward, up) in [
            (Vec3::ZERO, Vec3::Y),
            (Vec3::Y, Vec3::Y),
            (Vec3::X, Vec3::ZERO),
            (Vec3::splat(f32::NAN), Vec3::Y),
        ] {
            let (r, u, f) = View::Custom { forward, up }.basis();
            for v in [r, u, f] {
                assert!((v.length() - 1.0).abs() < 1e-5, "{forward} {up}: {v}");
            }
            assert!(r.dot(u).abs() < 1e-5 && r.dot(f).abs() < 1e-5 && u.dot(f).abs() < 1e-5);
        }
    }
}
