//! A small software rasteriser for shaded pictures of triangle meshes, written as PNG: contact
//! sheets of generated hand poses (`crease handgen`) and strips of a mocap-driven hand, so a person
//! can check shapes by eye without a GPU.
//!
//! Layout (all in this file):
//! - [`View`] and [`Camera`]: orthographic cameras, fitted to a bounding box.
//! - [`RenderSettings`], [`Light`]: colours, lights fixed relative to the camera, supersampling.
//! - [`Renderer`]: z-buffered rasterisation into reusable buffers; [`render`] for one picture.
//! - [`Image`]: RGB8 pictures with [`Image::blit`], [`Image::fill_rect`], a built-in 5x7 bitmap
//!   font ([`Image::draw_text`]) and PNG output ([`Image::encode_png`], [`Image::write_png`]).
//! - [`contact_sheet`] and [`SheetLayout`]: poses x views in a labelled grid.
//! - [`image_stats`]: mean and variance of luminance (a "not blank" check).
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
use std::path::{Path, PathBuf};

use glam::Vec3;

use crease_core::mesh::{Mesh, compute_vertex_normals};

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

// ---------------------------------------------------------------------------------------------
// Views and cameras
// ---------------------------------------------------------------------------------------------

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

// ---------------------------------------------------------------------------------------------
// Settings
// ---------------------------------------------------------------------------------------------

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

// ---------------------------------------------------------------------------------------------
// Rasteriser
// ---------------------------------------------------------------------------------------------

/// Fixed-point subpixel resolution of vertex positions (8 bits, 1/256 pixel): edge functions are
/// exact integers, so a pixel centre on an edge shared by two triangles is drawn by exactly one
/// of them (no cracks, no double hits).
const SUBPIXEL_BITS: u32 = 8;
/// One pixel in fixed point.
const SUBPIXEL: i64 = 1 << SUBPIXEL_BITS;
/// Triangles with a vertex farther than this (in pixels) from the image origin are skipped: it
/// keeps the fixed-point edge functions (products of two 29-bit differences) inside `i64`.
const MAX_PIXEL_COORD: f32 = 1.0e6;
/// Largest supported [`RenderSettings::supersample`]: 4x4 already costs 16 samples a pixel.
const MAX_SUPERSAMPLE: u32 = 4;

/// Reusable rasteriser state: vertex normals, projected vertices, the depth buffer and the
/// per-sample normal buffer. After the first picture of a given size and vertex count,
/// [`Renderer::render_into`] allocates nothing (e.g. for the frames of an animation strip).
#[derive(Debug, Default)]
pub struct Renderer {
    /// Area-weighted vertex normals of the current mesh.
    normals: Vec<Vec3>,
    /// Projected vertices: pixel x, pixel y, depth.
    projected: Vec<Vec3>,
    /// Per sample: depth of the nearest surface, `INFINITY` where nothing was drawn.
    depth: Vec<f32>,
    /// Per sample: interpolated (unnormalised) normal of the nearest surface.
    sample_normals: Vec<Vec3>,
}

impl Renderer {
    /// An empty renderer; buffers grow on first use.
    pub fn new() -> Self {
        Self::default()
    }

    /// Renders the triangles `triangles` over `positions` seen by `camera` into `out` (resized to
    /// the camera's size), shaded with smooth area-weighted vertex normals.
    ///
    /// Triangles are drawn in both windings (no culling) with a z-buffer (the nearest surface
    /// wins; at equal depth the first drawn). Triangles with a non-finite vertex, or a vertex
    /// absurdly far outside the image, are skipped. Where a vertex has no normal (it lies only on
    /// degenerate triangles) its triangle is shaded flat.
    ///
    /// # Panics
    /// If a triangle index is out of range (check in-memory meshes with [`Mesh::validate`]).
    pub fn render_into(
        &mut self,
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        camera: &Camera,
        settings: &RenderSettings,
        out: &mut Image,
    ) {
        let factor = settings.supersample.clamp(1, MAX_SUPERSAMPLE);
        let cam = camera.scaled(factor);
        let (width, height) = (cam.width as usize, cam.height as usize);

        compute_vertex_normals(positions, triangles, &mut self.normals);
        self.projected.clear();
        self.projected
            .extend(positions.iter().map(|&p| cam.project(p)));
        self.depth.clear();
        self.depth.resize(width * height, f32::INFINITY);
        self.sample_normals.resize(width * height, Vec3::ZERO);

        let mut target = Target {
            width,
            height,
            depth: &mut self.depth,
            normals: &mut self.sample_normals,
        };
        for t in triangles {
            rasterize_triangle(*t, positions, &self.projected, &self.normals, &mut target);
        }

        let shader = Shader::new(&cam, settings);
        out.resize(camera.width, camera.height);
        let f = factor as usize;
        let inv_samples = 1.0 / (f * f) as f32;
        for oy in 0..camera.height as usize {
            for ox in 0..camera.width as usize {
                let mut sum = Vec3::ZERO;
                let mut covered = 0;
                for sy in 0..f {
                    let row = (oy * f + sy) * width + ox * f;
                    for i in row..row + f {
                        if self.depth[i].is_finite() {
                            sum += shader.shade(self.sample_normals[i]);
                            covered += 1;
                        } else {
                            sum += shader.background;
                        }
                    }
                }
                let pixel = if covered == 0 {
                    settings.background
                } else {
                    (sum * inv_samples).to_array().map(|c| shader.encode(c))
                };
                out.pixels[oy * camera.width as usize + ox] = pixel;
            }
        }
    }
}

/// Renders `mesh` seen by `camera` into a new image. See [`Renderer::render_into`], which reuses
/// its buffers across pictures.
///
/// # Panics
/// If a triangle index is out of range.
pub fn render(mesh: &Mesh, camera: &Camera, settings: &RenderSettings) -> Image {
    let mut image = Image::new(camera.width, camera.height, settings.background);
    Renderer::new().render_into(
        &mesh.positions,
        &mesh.triangles,
        camera,
        settings,
        &mut image,
    );
    image
}

/// The sample buffers a triangle is drawn into.
struct Target<'a> {
    width: usize,
    height: usize,
    depth: &'a mut [f32],
    normals: &'a mut [Vec3],
}

/// One vertex of a triangle being drawn: fixed-point pixel position, depth, normal.
#[derive(Clone, Copy)]
struct Corner {
    x: i64,
    y: i64,
    z: f32,
    n: Vec3,
}

/// An edge function `E(p) = (b - a) x (p - a)` in fixed point, evaluated incrementally.
#[derive(Clone, Copy)]
struct Edge {
    /// Value at the current pixel centre.
    value: i64,
    /// Change per pixel step right.
    step_x: i64,
    /// Change per pixel step down.
    step_y: i64,
    /// 0 where a pixel centre exactly on the edge counts as inside, -1 where it does not.
    bias: i64,
}

impl Edge {
    /// The edge from `a` to `b`, evaluated at the fixed-point point `(px, py)`.
    fn new(a: Corner, b: Corner, px: i64, py: i64) -> Edge {
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        // Tie rule: of the two opposite directions an edge shared by two (consistently
        // oriented) triangles has, exactly one satisfies this, so exactly one triangle owns a
        // pixel centre lying on the edge. (The half-plane of directions plays the role of the
        // usual top-left rule.)
        let owned = dy > 0 || (dy == 0 && dx > 0);
        Edge {
            value: dx * (py - a.y) - dy * (px - a.x),
            step_x: -dy * SUBPIXEL,
            step_y: dx * SUBPIXEL,
            bias: if owned { 0 } else { -1 },
        }
    }
}

/// Fixed-point coordinate of a pixel coordinate (round to nearest 1/256).
fn to_fixed(v: f32) -> i64 {
    (v * SUBPIXEL as f32).round() as i64
}

/// Draws one triangle into `target` with a depth test.
fn rasterize_triangle(
    t: [u32; 3],
    positions: &[Vec3],
    projected: &[Vec3],
    normals: &[Vec3],
    target: &mut Target<'_>,
) {
    let [i0, i1, i2] = t.map(|i| i as usize);
    let (p0, p1, p2) = (projected[i0], projected[i1], projected[i2]);
    let in_range =
        |p: Vec3| p.is_finite() && p.x.abs() <= MAX_PIXEL_COORD && p.y.abs() <= MAX_PIXEL_COORD;
    if !(in_range(p0) && in_range(p1) && in_range(p2)) {
        return;
    }
    let (mut n0, mut n1, mut n2) = (normals[i0], normals[i1], normals[i2]);
    // Vertex normals are unit length or zero (a vertex only on degenerate triangles).
    if n0.length_squared() < 0.5 || n1.length_squared() < 0.5 || n2.length_squared() < 0.5 {
        let face = (positions[i1] - positions[i0])
            .cross(positions[i2] - positions[i0])
            .normalize_or_zero();
        (n0, n1, n2) = (face, face, face);
    }
    let corner = |p: Vec3, n: Vec3| Corner {
        x: to_fixed(p.x),
        y: to_fixed(p.y),
        z: p.z,
        n,
    };
    let a = corner(p0, n0);
    let mut b = corner(p1, n1);
    let mut c = corner(p2, n2);
    let mut area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
    if area == 0 {
        return;
    }
    if area < 0 {
        // Seen from behind: draw it anyway (open meshes), with one orientation for the tests.
        std::mem::swap(&mut b, &mut c);
        area = -area;
    }

    // Pixel (i, j) has its centre at ((i + 1/2), (j + 1/2)) pixels; the range of pixels whose
    // centres can be inside the triangle's bounding box, clipped to the image.
    let half = SUBPIXEL / 2;
    let first = |lo: i64| (lo - half + SUBPIXEL - 1).div_euclid(SUBPIXEL).max(0);
    let last = |hi: i64, size: usize| (hi - half).div_euclid(SUBPIXEL).min(size as i64 - 1);
    let x0 = first(a.x.min(b.x).min(c.x));
    let x1 = last(a.x.max(b.x).max(c.x), target.width);
    let y0 = first(a.y.min(b.y).min(c.y));
    let y1 = last(a.y.max(b.y).max(c.y), target.height);
    if x0 > x1 || y0 > y1 {
        return;
    }

    let (px, py) = (x0 * SUBPIXEL + half, y0 * SUBPIXEL + half);
    // Edge k is opposite corner k, so its value divided by the area is corner k's barycentric.
    let mut e0 = Edge::new(b, c, px, py);
    let mut e1 = Edge::new(c, a, px, py);
    let mut e2 = Edge::new(a, b, px, py);
    let inv_area = 1.0 / area as f32;
    for y in y0 as usize..=y1 as usize {
        let (mut w0, mut w1, mut w2) = (e0.value, e1.value, e2.value);
        let row = y * target.width;
        for x in x0 as usize..=x1 as usize {
            // All three non-negative (after the tie bias) iff their bitwise OR is.
            if (w0 + e0.bias) | (w1 + e1.bias) | (w2 + e2.bias) >= 0 {
                let (l0, l1, l2) = (
                    w0 as f32 * inv_area,
                    w1 as f32 * inv_area,
                    w2 as f32 * inv_area,
                );
                let z = l0 * a.z + l1 * b.z + l2 * c.z;
                let i = row + x;
                if z < target.depth[i] {
                    target.depth[i] = z;
                    target.normals[i] = a.n * l0 + b.n * l1 + c.n * l2;
                }
            }
            w0 += e0.step_x;
            w1 += e1.step_x;
            w2 += e2.step_x;
        }
        e0.value += e0.step_y;
        e1.value += e1.step_y;
        e2.value += e2.step_y;
    }
}

/// A Blinn-Phong term `(n.h)^shininess` below this is left out (its `powf` skipped): it is under
/// a third of an 8-bit sRGB step even at black, where steps are finest (12.92 * 255 * 1e-4).
const NEGLIGIBLE_HIGHLIGHT: f32 = 1e-4;

/// Per-picture shading constants: lights in world space, albedo and background in linear light.
struct Shader {
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
    background: Vec3,
    /// `thresholds[v]`: the linear value from which encoding rounds up to `v + 1`, so encoding
    /// is a binary search instead of a `powf` (exactly [`linear_to_srgb8`] up to f32 rounding).
    thresholds: [f32; 255],
}

impl Shader {
    fn new(camera: &Camera, settings: &RenderSettings) -> Shader {
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
    fn encode(&self, c: f32) -> u8 {
        // At most 255 thresholds lie below any value, so the count fits a u8.
        self.thresholds.partition_point(|&t| t <= c) as u8
    }

    /// Linear colour of a surface sample with (unnormalised) normal `n`, clamped to `[0, 1]`.
    fn shade(&self, n: Vec3) -> Vec3 {
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
        (self.albedo * diffuse + Vec3::splat(self.specular * highlight))
            .clamp(Vec3::ZERO, Vec3::ONE)
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

// ---------------------------------------------------------------------------------------------
// Images
// ---------------------------------------------------------------------------------------------

/// An 8-bit sRGB picture, rows top to bottom, `width * height` pixels.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Image {
    width: u32,
    height: u32,
    pixels: Vec<[u8; 3]>,
}

/// Width of a glyph of the built-in font, in font pixels.
pub const GLYPH_WIDTH: u32 = 5;
/// Height of a glyph of the built-in font, in font pixels.
pub const GLYPH_HEIGHT: u32 = 7;
/// Horizontal advance per character: the glyph and one column of space.
pub const GLYPH_ADVANCE: u32 = GLYPH_WIDTH + 1;

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

    /// Width in pixels of `text` drawn by [`Image::draw_text`] at `scale`.
    pub fn text_width(text: &str, scale: u32) -> u32 {
        let n = text.chars().count() as u32;
        (n * GLYPH_ADVANCE).saturating_sub(1) * scale
    }

    /// Draws `text` in the built-in 5x7 font with its top-left corner at `(x, y)`, each font
    /// pixel a `scale x scale` square, clipped to the image. Letters are drawn as capitals;
    /// digits, space and `-_.:/()+,` have glyphs; anything else is drawn as `?`.
    pub fn draw_text(&mut self, x: u32, y: u32, text: &str, color: [u8; 3], scale: u32) {
        let scale = scale.max(1);
        let mut pen = x;
        for ch in text.chars() {
            let rows = glyph(ch);
            for (gy, bits) in rows.iter().enumerate() {
                for gx in 0..GLYPH_WIDTH {
                    if bits & (1 << (GLYPH_WIDTH - 1 - gx)) != 0 {
                        self.fill_rect(
                            pen.saturating_add(gx * scale),
                            y.saturating_add(gy as u32 * scale),
                            scale,
                            scale,
                            color,
                        );
                    }
                }
            }
            pen = pen.saturating_add(GLYPH_ADVANCE * scale);
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

// ---------------------------------------------------------------------------------------------
// Contact sheets
// ---------------------------------------------------------------------------------------------

/// Pixels between cells and around the border of a contact sheet.
pub const SHEET_GAP: u32 = 8;
/// Pixels between the view tiles of one pose: enough to see where one tile ends.
pub const VIEW_GAP: u32 = 2;
/// Background of a contact sheet outside the tiles (white, so the grey tiles stand out).
pub const SHEET_BACKGROUND: [u8; 3] = [255, 255, 255];
/// Colour of pose labels.
pub const LABEL_COLOR: [u8; 3] = [30, 30, 30];
/// Colour of the view name in a tile's corner (quiet, so it does not compete with the mesh).
pub const VIEW_LABEL_COLOR: [u8; 3] = [120, 122, 128];

/// Where things go on a contact sheet: one cell per pose, holding its view tiles side by side
/// (separated by [`VIEW_GAP`]) with the pose label under them, cells in a grid
/// of `columns` cells per row, [`SHEET_GAP`] between cells and around the border.
///
/// `width = gap + columns * (cell_width + gap)` with `cell_width = views * tile_size + (views - 1)
/// * VIEW_GAP`, and `height = gap + rows * (tile_size + label_height + gap)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SheetLayout {
    /// Number of poses (cells).
    pub poses: u32,
    /// Number of views (tiles per cell).
    pub views: u32,
    /// Side of a square tile in pixels.
    pub tile_size: u32,
    /// Cells per row: the requested number, at least 1 and at most `poses` (when there are any).
    pub columns: u32,
    /// Rows of cells.
    pub rows: u32,
    /// Font scale of the labels: 1 up to 399-pixel tiles, 2 from 400, and so on.
    pub label_scale: u32,
    /// Height of the label strip under each cell.
    pub label_height: u32,
}

impl SheetLayout {
    /// The layout of `poses` poses x `views` views in tiles of `tile_size` pixels, `columns`
    /// cells per row.
    pub fn new(poses: usize, views: usize, tile_size: u32, columns: u32) -> SheetLayout {
        let poses = poses as u32;
        let columns = columns.clamp(1, poses.max(1));
        let label_scale = (tile_size / 200).max(1);
        SheetLayout {
            poses,
            views: views as u32,
            tile_size,
            columns,
            rows: poses.div_ceil(columns),
            label_scale,
            label_height: (GLYPH_HEIGHT + 4) * label_scale,
        }
    }

    /// Width of one cell: its tiles and the gaps between them.
    pub fn cell_width(&self) -> u32 {
        self.views * self.tile_size + self.views.saturating_sub(1) * VIEW_GAP
    }

    /// Width of the sheet.
    pub fn width(&self) -> u32 {
        SHEET_GAP + self.columns * (self.cell_width() + SHEET_GAP)
    }

    /// Height of the sheet.
    pub fn height(&self) -> u32 {
        SHEET_GAP + self.rows * (self.tile_size + self.label_height + SHEET_GAP)
    }

    /// Top-left corner of the cell of pose `pose` (row-major).
    pub fn cell_origin(&self, pose: usize) -> (u32, u32) {
        let (col, row) = (pose as u32 % self.columns, pose as u32 / self.columns);
        (
            SHEET_GAP + col * (self.cell_width() + SHEET_GAP),
            SHEET_GAP + row * (self.tile_size + self.label_height + SHEET_GAP),
        )
    }

    /// Top-left corner of the tile of pose `pose`, view `view`.
    pub fn tile_origin(&self, pose: usize, view: usize) -> (u32, u32) {
        let (x, y) = self.cell_origin(pose);
        (x + view as u32 * (self.tile_size + VIEW_GAP), y)
    }
}

/// A contact sheet with [`RenderSettings::default`]. See [`contact_sheet_with`].
pub fn contact_sheet<S: AsRef<str>>(
    tiles: &[(S, &Mesh)],
    views: &[View],
    tile_size: u32,
    columns: u32,
) -> Image {
    contact_sheet_with(tiles, views, tile_size, columns, &RenderSettings::default())
}

/// Renders each `(label, mesh)` of `tiles` in every view of `views` into square tiles of
/// `tile_size` pixels laid out by [`SheetLayout::new`]`(tiles.len(), views.len(), tile_size,
/// columns)`: one cell per mesh with its views side by side, the label under the cell (cut to the
/// cell width) and the view name in each tile's top-left corner.
///
/// All tiles of a view share one camera, fitted ([`Camera::fit`], [`TILE_MARGIN`]) to the
/// bounding box of all the meshes together, so sizes and positions compare across poses.
///
/// # Panics
/// If a mesh has a triangle index out of range.
pub fn contact_sheet_with<S: AsRef<str>>(
    tiles: &[(S, &Mesh)],
    views: &[View],
    tile_size: u32,
    columns: u32,
    settings: &RenderSettings,
) -> Image {
    let layout = SheetLayout::new(tiles.len(), views.len(), tile_size, columns);
    let mut sheet = Image::new(layout.width(), layout.height(), SHEET_BACKGROUND);
    let bounds = tiles
        .iter()
        .filter(|(_, mesh)| !mesh.positions.is_empty())
        .map(|(_, mesh)| mesh.bounding_box())
        .reduce(|(lo, hi), (l, h)| (lo.min(l), hi.max(h)))
        .unwrap_or((Vec3::ZERO, Vec3::ZERO));
    let cameras: Vec<Camera> = views
        .iter()
        .map(|&view| Camera::fit(view, bounds, tile_size, tile_size, TILE_MARGIN))
        .collect();

    let mut renderer = Renderer::new();
    let mut tile = Image::default();
    let view_pad = 3;
    let max_label_chars = (layout.cell_width() / (GLYPH_ADVANCE * layout.label_scale)) as usize;
    for (pose, (label, mesh)) in tiles.iter().enumerate() {
        for (v, (camera, view)) in cameras.iter().zip(views).enumerate() {
            renderer.render_into(
                &mesh.positions,
                &mesh.triangles,
                camera,
                settings,
                &mut tile,
            );
            tile.draw_text(view_pad, view_pad, view.name(), VIEW_LABEL_COLOR, 1);
            let (x, y) = layout.tile_origin(pose, v);
            sheet.blit(&tile, x, y);
        }
        let text: String = label.as_ref().chars().take(max_label_chars).collect();
        let (x, y) = layout.cell_origin(pose);
        let text_y = y + tile_size + 2 * layout.label_scale;
        sheet.draw_text(x, text_y, &text, LABEL_COLOR, layout.label_scale);
    }
    sheet
}

// ---------------------------------------------------------------------------------------------
// Font
// ---------------------------------------------------------------------------------------------

/// The 5x7 glyph of `ch`: seven rows, top first, bit 4 the leftmost column. Lower-case letters
/// share the capitals; characters without a glyph get `?`.
fn glyph(ch: char) -> [u8; 7] {
    match ch.to_ascii_uppercase() {
        ' ' => [0, 0, 0, 0, 0, 0, 0],
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        '-' => [0, 0, 0, 0x1F, 0, 0, 0],
        '_' => [0, 0, 0, 0, 0, 0, 0x1F],
        '.' => [0, 0, 0, 0, 0, 0x0C, 0x0C],
        ',' => [0, 0, 0, 0, 0x0C, 0x04, 0x08],
        ':' => [0, 0x0C, 0x0C, 0, 0x0C, 0x0C, 0],
        '/' => [0, 0x01, 0x02, 0x04, 0x08, 0x10, 0],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '+' => [0, 0x04, 0x04, 0x1F, 0x04, 0x04, 0],
        '=' => [0, 0, 0x1F, 0, 0x1F, 0, 0],
        _ => [0x0E, 0x11, 0x01, 0x02, 0x04, 0, 0x04],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn degenerate_and_non_finite_triangles_draw_nothing() {
        let positions = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(f32::NAN, 0.0, 0.0),
            Vec3::new(1e30, 0.0, 0.0),
            Vec3::Y,
        ];
        let triangles = vec![[0, 1, 2], [0, 0, 5], [0, 3, 5], [0, 4, 5]];
        let camera = Camera::orthographic(View::Back, Vec3::ZERO, 10.0, 40, 40);
        let settings = RenderSettings {
            supersample: 1,
            ..RenderSettings::default()
        };
        let mut image = Image::default();
        Renderer::new().render_into(&positions, &triangles, &camera, &settings, &mut image);
        assert!(image.pixels().iter().all(|&p| p == settings.background));
    }

    #[test]
    fn text_is_drawn_inside_its_box() {
        let mut image = Image::new(40, 12, [0, 0, 0]);
        image.draw_text(1, 2, "Ab9", [255, 255, 255], 1);
        let width = Image::text_width("Ab9", 1);
        assert_eq!(width, 17);
        let mut lit = 0;
        for y in 0..12 {
            for x in 0..40 {
                if image.pixel(x, y) != [0, 0, 0] {
                    lit += 1;
                    assert!(
                        (1..1 + width).contains(&x) && (2..9).contains(&y),
                        "({x}, {y})"
                    );
                }
            }
        }
        assert!(lit > 20);
    }
}
