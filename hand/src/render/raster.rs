//! The rasteriser: [`Renderer`] draws triangles into a z-buffer with exact fixed-point edge
//! functions (no cracks, no double hits on shared edges), then shades and box-filters the
//! samples into an [`Image`]; [`render`] draws one picture.

use glam::Vec3;

use crease_core::mesh::{Mesh, compute_vertex_normals};

use super::shade::Shader;
use super::{Camera, Image, RenderSettings};

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
    /// Vertex colours in linear light ([`Renderer::render_colored_into`]).
    linear_colors: Vec<Vec3>,
    /// Per sample: interpolated linear albedo of the nearest surface (vertex colours only).
    sample_albedo: Vec<Vec3>,
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
        self.draw(positions, triangles, None, camera, settings, out);
    }

    /// [`Renderer::render_into`] with one sRGB colour per vertex instead of
    /// [`RenderSettings::base_color`]: the albedo is interpolated across each triangle in linear
    /// light and shaded as usual (e.g. an error heat map on the mesh).
    ///
    /// # Panics
    /// If a triangle index is out of range, or `colors` does not have one entry per position.
    pub fn render_colored_into(
        &mut self,
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        colors: &[[u8; 3]],
        camera: &Camera,
        settings: &RenderSettings,
        out: &mut Image,
    ) {
        assert_eq!(
            colors.len(),
            positions.len(),
            "one vertex colour per position"
        );
        let mut linear = std::mem::take(&mut self.linear_colors);
        linear.clear();
        linear.extend(
            colors
                .iter()
                .map(|c| Vec3::from_array(c.map(super::srgb8_to_linear))),
        );
        self.draw(positions, triangles, Some(&linear), camera, settings, out);
        self.linear_colors = linear;
    }

    fn draw(
        &mut self,
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        colors: Option<&[Vec3]>,
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
        if colors.is_some() {
            self.sample_albedo.resize(width * height, Vec3::ZERO);
        }

        let mut target = Target {
            width,
            height,
            depth: &mut self.depth,
            normals: &mut self.sample_normals,
            albedo: colors.map(|c| (c, &mut self.sample_albedo[..])),
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
                            sum += match colors {
                                Some(_) => shader
                                    .shade_albedo(self.sample_normals[i], self.sample_albedo[i]),
                                None => shader.shade(self.sample_normals[i]),
                            };
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
    /// Vertex colours (linear) and the per-sample albedo they are interpolated into.
    albedo: Option<(&'a [Vec3], &'a mut [Vec3])>,
}

/// One vertex of a triangle being drawn: fixed-point pixel position, depth, normal.
#[derive(Clone, Copy)]
struct Corner {
    x: i64,
    y: i64,
    z: f32,
    n: Vec3,
    /// Linear vertex colour (zero without vertex colours).
    c: Vec3,
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
    let color = |i: usize| target.albedo.as_ref().map_or(Vec3::ZERO, |(c, _)| c[i]);
    let corner = |p: Vec3, n: Vec3, c: Vec3| Corner {
        x: to_fixed(p.x),
        y: to_fixed(p.y),
        z: p.z,
        n,
        c,
    };
    let a = corner(p0, n0, color(i0));
    let mut b = corner(p1, n1, color(i1));
    let mut c = corner(p2, n2, color(i2));
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
                    if let Some((_, albedo)) = target.albedo.as_mut() {
                        albedo[i] = a.c * l0 + b.c * l1 + c.c * l2;
                    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::View;

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
    fn vertex_colours_are_interpolated_and_shaded() {
        // A square facing the camera, left edge red and right edge blue: the left of the
        // picture is red, the right blue, the middle a mix.
        let positions = vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ];
        let triangles = vec![[0, 1, 2], [0, 2, 3]];
        let colors = [[255, 0, 0], [0, 0, 255], [0, 0, 255], [255, 0, 0]];
        let camera = Camera::orthographic(View::Back, Vec3::ZERO, 20.0, 50, 50);
        let settings = RenderSettings {
            supersample: 1,
            specular: 0.0,
            ..RenderSettings::default()
        };
        let mut image = Image::default();
        Renderer::new().render_colored_into(
            &positions, &triangles, &colors, &camera, &settings, &mut image,
        );
        let (left, right, mid) = (image.pixel(6, 25), image.pixel(43, 25), image.pixel(25, 25));
        assert!(left[0] > 150 && left[1] == 0 && left[2] < 80, "{left:?}");
        assert!(
            right[2] > 150 && right[1] == 0 && right[0] < 80,
            "{right:?}"
        );
        assert!(mid[0] > 40 && mid[2] > 40, "{mid:?}");
        assert_eq!(image.pixel(1, 1), settings.background);
    }
}
