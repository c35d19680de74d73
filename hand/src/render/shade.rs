//! Shading: [`RenderSettings`] and [`Light`] (colours, camera-fixed lights, supersampling), the
//! per-picture Blinn-Phong shader in linear light, and the sRGB transfer functions
//! (IEC 61966-2-1) with a table encoder that skips the `powf` per pixel.

use glam::Vec3;

use super::Camera;

/// A directional light fixed relative to the camera, so every view of a sheet is lit alike.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    /// Direction towards the light in camera space: `+x` right, `+y` up, `+z` towards the viewer
    /// (need not be unit length; zero switches the light off).
    pub direction: Vec3,
    /// Linear intensity multiplying the diffuse and specular terms (0 switches it off).
    pub intensity: f32,
}

/// Colours, lights and sampling for [`Renderer`].
///
/// A pixel's linear colour is `albedo * (ambient + sum_k I_k max(0, n.l_k)) + specular * sum_k
/// I_k max(0, n.h_k)^shininess` (the specular term only where `n.l_k > 0`), clamped to `[0, 1]`
/// per channel and encoded to sRGB; `albedo` is [`RenderSettings::base_color`] decoded from sRGB,
/// `n` the interpolated unit normal turned towards the viewer, `l_k` the unit light direction and
/// `h_k` the unit half vector between `l_k` and the direction towards the viewer.
///
/// [`Renderer`]: super::Renderer
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Surface colour, 8-bit sRGB.
    pub base_color: [u8; 3],
    /// Colour where no triangle covers the pixel, 8-bit sRGB (written exactly).
    pub background: [u8; 3],
    /// Ambient term, a fraction of the albedo (linear).
    pub ambient: f32,
    /// Two lights: a key light and a fill light by default. Set an intensity to 0 to use one.
    pub lights: [Light; 2],
    /// Weight of the white Blinn-Phong highlight (0 switches it off).
    pub specular: f32,
    /// Blinn-Phong exponent: larger is a smaller, sharper highlight.
    pub shininess: f32,
    /// Samples per pixel along each axis (`s x s` box filter in linear light), clamped to
    /// `1..=4`. 1 is exact coverage (no anti-aliasing).
    pub supersample: u32,
}

/// Default surface colour: a neutral light skin tone (sRGB).
pub const SKIN: [u8; 3] = [224, 180, 152];
/// Default background: a light, slightly cool grey that the skin tone stands out from.
pub const LIGHT_GREY: [u8; 3] = [226, 228, 232];

impl Default for RenderSettings {
    /// Skin on light grey; a key light from the upper left in front and a weaker fill from the
    /// lower right, so the form reads and small normal changes (creases) show as shading steps;
    /// a faint highlight; 2x2 supersampling.
    fn default() -> Self {
        RenderSettings {
            base_color: SKIN,
            background: LIGHT_GREY,
            ambient: 0.12,
            lights: [
                Light {
                    direction: Vec3::new(-0.45, 0.55, 0.70),
                    intensity: 0.80,
                },
                Light {
                    direction: Vec3::new(0.60, -0.25, 0.45),
                    intensity: 0.25,
                },
            ],
            specular: 0.12,
            shininess: 24.0,
            supersample: 2,
        }
    }
}

/// A Blinn-Phong term `(n.h)^shininess` below this is left out (its `powf` skipped): it is under
/// a third of an 8-bit sRGB step even at black, where steps are finest (12.92 * 255 * 1e-4).
const NEGLIGIBLE_HIGHLIGHT: f32 = 1e-4;

/// Per-picture shading constants: lights in world space, albedo and background in linear light.
pub(super) struct Shader {
    /// Unit direction from the surface towards the viewer (`-forward`).
    to_viewer: Vec3,
    /// Unit light directions, unit half vectors, intensities.
    lights: [(Vec3, Vec3, f32); 2],
    albedo: Vec3,
    ambient: f32,
    specular: f32,
    shininess: f32,
    /// `n.h` below which the highlight is negligible ([`NEGLIGIBLE_HIGHLIGHT`]).
    highlight_cut: f32,
    pub(super) background: Vec3,
    /// `thresholds[v]`: the linear value from which encoding rounds up to `v + 1`, so encoding
    /// is a binary search instead of a `powf` (exactly [`linear_to_srgb8`] up to f32 rounding).
    thresholds: [f32; 255],
}

impl Shader {
    pub(super) fn new(camera: &Camera, settings: &RenderSettings) -> Shader {
        let to_viewer = -camera.forward;
        let lights = settings.lights.map(|light| {
            let d = light.direction;
            let l = (camera.right * d.x + camera.up * d.y + to_viewer * d.z).normalize_or_zero();
            let h = (l + to_viewer).normalize_or_zero();
            let intensity = if l == Vec3::ZERO {
                0.0
            } else {
                light.intensity
            };
            (l, h, intensity)
        });
        let linear = |c: [u8; 3]| Vec3::from_array(c.map(srgb8_to_linear));
        Shader {
            to_viewer,
            lights,
            albedo: linear(settings.base_color),
            ambient: settings.ambient,
            specular: settings.specular,
            shininess: settings.shininess,
            highlight_cut: if settings.shininess > 0.0 {
                NEGLIGIBLE_HIGHLIGHT.powf(1.0 / settings.shininess)
            } else {
                f32::NEG_INFINITY
            },
            background: linear(settings.background),
            thresholds: std::array::from_fn(|v| srgb_to_linear((v as f32 + 0.5) / 255.0)),
        }
    }

    /// 8-bit sRGB of a linear value in `[0, 1]`.
    pub(super) fn encode(&self, c: f32) -> u8 {
        // At most 255 thresholds lie below any value, so the count fits a u8.
        self.thresholds.partition_point(|&t| t <= c) as u8
    }

    /// Linear colour of a surface sample with (unnormalised) normal `n`, clamped to `[0, 1]`.
    pub(super) fn shade(&self, n: Vec3) -> Vec3 {
        self.shade_albedo(n, self.albedo)
    }

    /// [`Shader::shade`] with a linear `albedo` instead of the settings' base colour.
    pub(super) fn shade_albedo(&self, n: Vec3, albedo: Vec3) -> Vec3 {
        let mut n = n.normalize_or(self.to_viewer);
        if n.dot(self.to_viewer) < 0.0 {
            n = -n;
        }
        let mut diffuse = self.ambient;
        let mut highlight = 0.0;
        for &(l, h, intensity) in &self.lights {
            let n_dot_l = n.dot(l);
            if n_dot_l > 0.0 && intensity != 0.0 {
                diffuse += intensity * n_dot_l;
                let n_dot_h = n.dot(h);
                if self.specular != 0.0 && n_dot_h > self.highlight_cut {
                    highlight += intensity * n_dot_h.max(0.0).powf(self.shininess);
                }
            }
        }
        (albedo * diffuse + Vec3::splat(self.specular * highlight)).clamp(Vec3::ZERO, Vec3::ONE)
    }
}

/// sRGB decoding of an 8-bit value to linear light in `[0, 1]` (IEC 61966-2-1).
pub fn srgb8_to_linear(v: u8) -> f32 {
    srgb_to_linear(f32::from(v) / 255.0)
}

/// sRGB decoding of an encoded value in `[0, 1]` to linear light (IEC 61966-2-1).
fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// sRGB encoding of linear light (clamped to `[0, 1]`) to 8 bits, rounded (IEC 61966-2-1).
pub fn linear_to_srgb8(c: f32) -> u8 {
    let c = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
    let s = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    // In [0, 255.5) after clamping, so the cast neither wraps nor saturates.
    (s * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::View;

    #[test]
    fn srgb_round_trips_every_byte() {
        for v in 0..=255u8 {
            assert_eq!(linear_to_srgb8(srgb8_to_linear(v)), v);
        }
        assert_eq!(linear_to_srgb8(f32::NAN), 0);
        assert_eq!(linear_to_srgb8(-1.0), 0);
        assert_eq!(linear_to_srgb8(2.0), 255);
    }

    #[test]
    fn table_encoding_matches_the_formula() {
        let shader = Shader::new(
            &Camera::orthographic(View::Back, Vec3::ZERO, 1.0, 1, 1),
            &RenderSettings::default(),
        );
        for i in 0..=100_000 {
            let c = i as f32 / 100_000.0;
            let (table, formula) = (shader.encode(c), linear_to_srgb8(c));
            assert!(table.abs_diff(formula) <= 1, "{c}: {table} vs {formula}");
        }
        for v in 0..=255u8 {
            assert_eq!(shader.encode(srgb8_to_linear(v)), v);
        }
    }
}
