//! The report's pictures of meshes, drawn by the project's rasteriser (`crease_hand::render`):
//! error heat maps of a pose (the true shape, then the prediction coloured by per-vertex error,
//! front and side, over a colour bar) and the control-point layout on the rest mesh.

use std::path::Path;

use anyhow::Context;
use crease_core::glam::Vec3;
use crease_hand::render::{Camera, Image, RenderSettings, Renderer, View};

/// Side of one square view, pixels.
const TILE: u32 = 380;
/// Height of the title strip above the views.
const HEADER: u32 = 30;
/// Height of the colour-bar strip below the views.
const FOOTER: u32 = 56;
/// The page background of the pictures (the HTML page's, so they sit on it seamlessly).
pub(super) const BACKGROUND: [u8; 3] = [250, 250, 250];
/// Text colour.
const INK: [u8; 3] = [40, 40, 48];
/// The untouched mesh colour (truth, rest mesh).
const GREY: [u8; 3] = [200, 200, 204];
/// Fraction of a view left free on each side.
const MARGIN: f32 = 0.05;

/// The two views of every picture: `front` looks along `-Z` and `side` along `+X`, `+Y` up
/// (the hand skeleton frame's back and thumb-side views; a Y-up mesh's front and left side).
pub(super) const VIEWS: [(View, &str); 2] = [(View::Back, "front"), (View::ThumbSide, "side")];

/// The error colour map: light grey (no error) through yellow and orange to dark red (the
/// scale's top), interpolated in sRGB between five stops (ColorBrewer YlOrRd with a neutral
/// start, so small errors stay out of the way and large ones stand out).
pub(super) fn heat_color(t: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 5] = [
        [225.0, 225.0, 228.0],
        [254.0, 217.0, 118.0],
        [253.0, 141.0, 60.0],
        [227.0, 26.0, 28.0],
        [128.0, 0.0, 38.0],
    ];
    let t = if t.is_nan() { 1.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (STOPS.len() - 1) as f32;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - i as f32;
    std::array::from_fn(|c| (STOPS[i][c] * (1.0 - f) + STOPS[i + 1][c] * f).round() as u8)
}

/// A shaded picture's settings: 2x2 supersampling on the report background, no highlight
/// (it would read as a low error).
fn settings(base_color: [u8; 3]) -> RenderSettings {
    RenderSettings {
        base_color,
        background: BACKGROUND,
        specular: 0.0,
        ambient: 0.35,
        ..RenderSettings::default()
    }
}

/// The box around every point of `sets`.
fn bounds(sets: &[&[Vec3]]) -> (Vec3, Vec3) {
    sets.iter()
        .flat_map(|s| s.iter())
        .filter(|p| p.is_finite())
        .fold(
            (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        )
}

/// One view of a picture: positions, vertex colours, view, label.
type Tile<'a> = (&'a [Vec3], &'a [[u8; 3]], View, &'a str);

/// One pose's error heat map, written as PNG to `path`: three views in a row (the true shape
/// in grey from the front, the prediction coloured by `vertex_error` from the front and the
/// side), `title` above, a colour bar from 0 to `scale_max` below (errors as a fraction of the
/// rest mesh's largest bounding-box side). Every view of the row shares one scale.
#[allow(clippy::too_many_arguments)]
pub(super) fn heat_map(
    path: &Path,
    triangles: &[[u32; 3]],
    truth: &[Vec3],
    predicted: &[Vec3],
    vertex_error: &[f32],
    scale_max: f32,
    title: &str,
) -> anyhow::Result<()> {
    let colors: Vec<[u8; 3]> = vertex_error
        .iter()
        .map(|&e| heat_color(e / scale_max.max(f32::MIN_POSITIVE)))
        .collect();
    let grey = vec![GREY; truth.len()];
    let box_ = bounds(&[truth, predicted]);
    let tiles: [Tile<'_>; 3] = [
        (truth, &grey, VIEWS[0].0, "truth, front"),
        (predicted, &colors, VIEWS[0].0, "error, front"),
        (predicted, &colors, VIEWS[1].0, "error, side"),
    ];
    let mut sheet = Image::new(TILE * 3, HEADER + TILE + FOOTER, BACKGROUND);
    sheet.draw_text(8, 8, title, INK, 2);
    let mut renderer = Renderer::new();
    let mut tile = Image::default();
    for (k, (positions, colors, view, label)) in tiles.into_iter().enumerate() {
        let camera = Camera::fit(view, box_, TILE, TILE, MARGIN);
        renderer.render_colored_into(
            positions,
            triangles,
            colors,
            &camera,
            &settings(GREY),
            &mut tile,
        );
        tile.draw_text(6, 6, label, INK, 1);
        sheet.blit(&tile, k as u32 * TILE, HEADER);
    }
    color_bar(&mut sheet, HEADER + TILE + 8, scale_max);
    sheet
        .write_png(path)
        .with_context(|| format!("writing the heat map {}", path.display()))
}

/// The colour bar: 0 on the left, `scale_max` on the right, labelled.
fn color_bar(sheet: &mut Image, y: u32, scale_max: f32) {
    let (x0, width, height) = (60, sheet.width() - 120, 16);
    for i in 0..width {
        let t = i as f32 / (width - 1) as f32;
        sheet.fill_rect(x0 + i, y, 1, height, heat_color(t));
    }
    let label_y = y + height + 6;
    sheet.draw_text(x0, label_y, "0", INK, 2);
    let max = format!("{scale_max:.2e}");
    let w = Image::text_width(&max, 2);
    sheet.draw_text(x0 + width - w, label_y, &max, INK, 2);
    let mid = "vertex error / largest side of the rest box";
    let w = Image::text_width(mid, 1);
    sheet.draw_text(x0 + (width - w) / 2, label_y + 4, mid, INK, 1);
}

/// What [`rest_views`] draws on a view: its tile, camera and the mesh's box.
type Marks<'a> = dyn FnMut(&mut Image, &Camera, (Vec3, Vec3)) + 'a;

/// The rest mesh front and side, side by side, written as PNG to `path` (`what` names it in
/// an error): grey, or in per-vertex `colors`; `mark` draws on each view's tile before its
/// name (the view's camera and the mesh's box given).
fn rest_views(
    path: &Path,
    what: &str,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    colors: Option<&[[u8; 3]]>,
    mark: &mut Marks<'_>,
) -> anyhow::Result<()> {
    let box_ = bounds(&[positions]);
    let tile_size = TILE + 60;
    let mut sheet = Image::new(tile_size * 2, tile_size, BACKGROUND);
    let mut renderer = Renderer::new();
    let mut tile = Image::default();
    for (k, (view, name)) in VIEWS.into_iter().enumerate() {
        let camera = Camera::fit(view, box_, tile_size, tile_size, MARGIN + 0.03);
        match colors {
            Some(colors) => renderer.render_colored_into(
                positions,
                triangles,
                colors,
                &camera,
                &settings(GREY),
                &mut tile,
            ),
            None => renderer.render_into(positions, triangles, &camera, &settings(GREY), &mut tile),
        }
        mark(&mut tile, &camera, box_);
        tile.draw_text(6, 6, name, INK, 2);
        sheet.blit(&tile, k as u32 * tile_size, 0);
    }
    sheet
        .write_png(path)
        .with_context(|| format!("writing the {what} {}", path.display()))
}

/// The control points on the rest mesh, front and side, written as PNG to `path`: the mesh in
/// grey, each point a dot with its name beside it (dots the mesh hides drawn hollow).
pub(super) fn control_layout(
    path: &Path,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    controls: &[(u32, String)],
) -> anyhow::Result<()> {
    rest_views(
        path,
        "control-point layout",
        positions,
        triangles,
        None,
        &mut |tile, camera, box_| {
            // Visibility: the point is in front when no triangle projects nearer at its pixel,
            // which the depth of the rendered picture does not expose; use the nearest vertex
            // depth among the mesh's points projecting within two pixels instead.
            let projected: Vec<Vec3> = positions.iter().map(|&p| camera.project(p)).collect();
            for (i, (vertex, label)) in controls.iter().enumerate() {
                let Some(&p) = projected.get(*vertex as usize) else {
                    continue;
                };
                let hidden = projected.iter().any(|q| {
                    (q.x - p.x).abs() < 2.5
                        && (q.y - p.y).abs() < 2.5
                        && q.z < p.z - 0.02 * box_size(box_)
                });
                let color = marker_color(i);
                dot(tile, p.x, p.y, 6.0, color, hidden);
                let (x, y) = (p.x as u32 + 9, (p.y as u32).saturating_sub(7));
                for (dx, dy) in [(0, 1), (2, 1), (1, 0), (1, 2)] {
                    tile.draw_text(x + dx, y + dy, label, BACKGROUND, 2);
                }
                tile.draw_text(x + 1, y + 1, label, INK, 2);
            }
        },
    )
}

/// The regions the control points leave undetermined (issue 42) on the rest mesh, front and
/// side, written as PNG to `path`: the mesh in grey, each region's vertices in its marker
/// colour (region `k` in `marker_color(k)`, as the page's legend says), the control points
/// as black dots.
pub(super) fn undetermined_regions(
    path: &Path,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    regions: &[&[u32]],
    controls: &[u32],
) -> anyhow::Result<()> {
    let mut colors = vec![GREY; positions.len()];
    for (k, vertices) in regions.iter().enumerate() {
        for &v in *vertices {
            if let Some(c) = colors.get_mut(v as usize) {
                *c = marker_color(k);
            }
        }
    }
    rest_views(
        path,
        "undetermined regions",
        positions,
        triangles,
        Some(&colors),
        &mut |tile, camera, _| {
            for &v in controls {
                if let Some(&p) = positions.get(v as usize) {
                    let p = camera.project(p);
                    dot(tile, p.x, p.y, 5.0, INK, false);
                }
            }
        },
    )
}

/// The largest side of a box.
fn box_size((lo, hi): (Vec3, Vec3)) -> f32 {
    (hi - lo).max_element()
}

/// Distinct marker colours, cycling.
pub(super) fn marker_color(i: usize) -> [u8; 3] {
    const COLORS: [[u8; 3]; 6] = [
        [31, 119, 180],
        [214, 39, 40],
        [44, 160, 44],
        [148, 103, 189],
        [255, 127, 14],
        [23, 190, 207],
    ];
    COLORS[i % COLORS.len()]
}

/// A filled (or, `hollow`, ringed) disc of radius `r` at pixel `(cx, cy)`, with a dark rim.
fn dot(image: &mut Image, cx: f32, cy: f32, r: f32, color: [u8; 3], hollow: bool) {
    let (w, h) = (image.width() as i64, image.height() as i64);
    let reach = r.ceil() as i64 + 1;
    for y in (cy as i64 - reach)..=(cy as i64 + reach) {
        for x in (cx as i64 - reach)..=(cx as i64 + reach) {
            if x < 0 || y < 0 || x >= w || y >= h {
                continue;
            }
            let d = ((x as f32 + 0.5 - cx).powi(2) + (y as f32 + 0.5 - cy).powi(2)).sqrt();
            let pixel = if d > r {
                continue;
            } else if d > r - 1.5 {
                INK
            } else if hollow && d < r - 3.0 {
                continue;
            } else {
                color
            };
            image.set_pixel(x as u32, y as u32, pixel);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_colour_map_runs_from_grey_to_dark_red() {
        assert_eq!(heat_color(0.0), [225, 225, 228]);
        assert_eq!(heat_color(1.0), [128, 0, 38]);
        assert_eq!(heat_color(7.0), heat_color(1.0));
        assert_eq!(heat_color(-1.0), heat_color(0.0));
        // Redder as the error grows: the green channel falls monotonically after the grey.
        let greens: Vec<u8> = (0..=20).map(|i| heat_color(i as f32 / 20.0)[1]).collect();
        assert!(
            greens.windows(2).skip(5).all(|w| w[1] <= w[0]),
            "{greens:?}"
        );
    }
}
