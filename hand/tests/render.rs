//! The software rasteriser against independent computations: analytic coverage of squares,
//! triangles and discs, the Lambert formula evaluated here (with its own sRGB transfer
//! functions), depth order, a PNG round trip through the `png` decoder, and contact-sheet layout.

use std::f32::consts::PI;
use std::io::Cursor;
use std::time::Instant;

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_hand::render::{
    Camera, Image, Light, RenderError, RenderSettings, Renderer, SHEET_BACKGROUND, SHEET_GAP,
    SheetLayout, VIEW_GAP, View, contact_sheet, image_stats, render,
};

// --- independent helpers ----------------------------------------------------------------------

/// sRGB decode (IEC 61966-2-1), written out here rather than taken from the crate.
fn decode(v: u8) -> f64 {
    let c = f64::from(v) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// sRGB encode to 8 bits (IEC 61966-2-1).
fn encode(c: f64) -> u8 {
    let c = c.clamp(0.0, 1.0);
    let s = if c <= 0.0031308 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

/// Lambert plus ambient, one light, no specular: `albedo * (ambient + I * max(0, n.l))`.
fn lambert(base: [u8; 3], ambient: f64, intensity: f64, n_dot_l: f64) -> [u8; 3] {
    base.map(|c| encode(decode(c) * (ambient + intensity * n_dot_l.max(0.0))))
}

/// One light, no specular, exact coverage: the shading is the Lambert formula above.
fn flat_settings(base: [u8; 3], direction: Vec3, intensity: f32, ambient: f32) -> RenderSettings {
    RenderSettings {
        base_color: base,
        background: [10, 20, 30],
        ambient,
        lights: [
            Light {
                direction,
                intensity,
            },
            Light {
                direction: Vec3::Z,
                intensity: 0.0,
            },
        ],
        specular: 0.0,
        shininess: 1.0,
        supersample: 1,
    }
}

fn close(a: [u8; 3], b: [u8; 3], tol: i32) -> bool {
    a.iter()
        .zip(b)
        .all(|(&x, y)| (i32::from(x) - i32::from(y)).abs() <= tol)
}

/// An axis-aligned quad in the plane `z = z0 + slope * x`, two triangles.
fn quad(x: [f32; 2], y: [f32; 2], z0: f32, slope: f32) -> Mesh {
    let p = |x: f32, y: f32| Vec3::new(x, y, z0 + slope * x);
    Mesh {
        positions: vec![p(x[0], y[0]), p(x[1], y[0]), p(x[1], y[1]), p(x[0], y[1])],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
    }
}

fn concat(a: &Mesh, b: &Mesh) -> Mesh {
    let n = a.positions.len() as u32;
    Mesh {
        positions: a.positions.iter().chain(&b.positions).copied().collect(),
        triangles: a
            .triangles
            .iter()
            .copied()
            .chain(b.triangles.iter().map(|t| t.map(|i| i + n)))
            .collect(),
    }
}

/// A UV sphere, every triangle facing outward.
fn uv_sphere(center: Vec3, radius: f32, segments: u32, stacks: u32) -> Mesh {
    let mut positions = vec![center + Vec3::Y * radius];
    for i in 1..stacks {
        let theta = PI * i as f32 / stacks as f32;
        for j in 0..segments {
            let phi = 2.0 * PI * j as f32 / segments as f32;
            let d = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            positions.push(center + d * radius);
        }
    }
    positions.push(center - Vec3::Y * radius);
    let ring = |i: u32, j: u32| 1 + (i - 1) * segments + j % segments;
    let bottom = positions.len() as u32 - 1;
    let mut triangles = Vec::new();
    for j in 0..segments {
        triangles.push([0, ring(1, j), ring(1, j + 1)]);
        triangles.push([bottom, ring(stacks - 1, j + 1), ring(stacks - 1, j)]);
        for i in 1..stacks - 1 {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j),
                ring(i + 1, j + 1),
            );
            triangles.push([a, c, b]);
            triangles.push([b, c, d]);
        }
    }
    // Orient outward by construction-independent check.
    for t in &mut triangles {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        if (b - a).cross(c - a).dot((a + b + c) / 3.0 - center) < 0.0 {
            t.swap(1, 2);
        }
    }
    Mesh {
        positions,
        triangles,
    }
}

/// Pixels differing from `background`.
fn covered(image: &Image, background: [u8; 3]) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    for y in 0..image.height() {
        for x in 0..image.width() {
            if image.pixel(x, y) != background {
                out.push((x, y));
            }
        }
    }
    out
}

fn crop(image: &Image, x: u32, y: u32, w: u32, h: u32) -> Image {
    let mut pixels = Vec::new();
    for row in y..y + h {
        for col in x..x + w {
            pixels.push(image.pixel(col, row));
        }
    }
    Image::from_pixels(w, h, pixels).unwrap()
}

// --- coverage and shading -----------------------------------------------------------------------

#[test]
fn square_facing_the_camera_covers_its_area_with_the_lambert_shade() {
    let base = [200, 150, 100];
    // Light 36.87 degrees off the view axis: n.l = 0.8 for the normal +Z facing the camera.
    let settings = flat_settings(base, Vec3::new(0.6, 0.0, 0.8), 0.7, 0.1);
    let camera = Camera::orthographic(View::Back, Vec3::ZERO, 100.0, 200, 200);
    let image = render(
        &quad([-0.5, 0.5], [-0.5, 0.5], 0.0, 0.0),
        &camera,
        &settings,
    );

    // The square spans pixels [50, 150) both ways: exactly 100 x 100 pixel centres inside,
    // including the diagonal shared by its two triangles, whose centres lie exactly on it.
    let hit = covered(&image, settings.background);
    assert_eq!(hit.len(), 100 * 100);
    assert!(
        hit.iter()
            .all(|&(x, y)| (50..150).contains(&x) && (50..150).contains(&y))
    );
    let expected = lambert(base, 0.1, 0.7, 0.8);
    for &(x, y) in &hit {
        let p = image.pixel(x, y);
        assert!(close(p, expected, 1), "({x}, {y}): {p:?} vs {expected:?}");
    }
}

#[test]
fn shared_diagonal_is_drawn_exactly_once() {
    let settings = flat_settings([200, 200, 200], Vec3::Z, 1.0, 0.0);
    let camera = Camera::orthographic(View::Back, Vec3::ZERO, 100.0, 200, 200);
    let square = quad([-0.5, 0.5], [-0.5, 0.5], 0.0, 0.0);
    let count = |triangles: Vec<[u32; 3]>| {
        let mesh = Mesh {
            positions: square.positions.clone(),
            triangles,
        };
        covered(&render(&mesh, &camera, &settings), settings.background).len()
    };
    let (first, second) = (count(vec![[0, 1, 2]]), count(vec![[0, 2, 3]]));
    // The 100 centres on the diagonal go to one triangle or the other, not both, not neither.
    assert_eq!(first + second, 100 * 100);
    assert_eq!(first.abs_diff(second), 100);
}

#[test]
fn off_grid_triangle_covers_its_analytic_area_in_either_winding() {
    let settings = flat_settings([200, 200, 200], Vec3::Z, 1.0, 0.0);
    let ppu = 100.0;
    let camera = Camera::orthographic(View::Back, Vec3::ZERO, ppu, 200, 200);
    let [a, b, c] = [
        Vec3::new(-0.63, -0.41, 0.2),
        Vec3::new(0.52, -0.37, -0.1),
        Vec3::new(-0.05, 0.58, 0.0),
    ];
    let area_px = 0.5 * ((b - a).truncate().perp_dot((c - a).truncate())).abs() * ppu * ppu;
    let perimeter_px =
        ((b - a).truncate().length() + (c - b).truncate().length() + (a - c).truncate().length())
            * ppu;
    for triangles in [vec![[0, 1, 2]], vec![[0, 2, 1]]] {
        let mesh = Mesh {
            positions: vec![a, b, c],
            triangles,
        };
        let n = covered(&render(&mesh, &camera, &settings), settings.background).len() as f32;
        // Each pixel the boundary crosses is either in or out: at most ~perimeter/2 of error,
        // and in practice far less since the misses and extras cancel.
        assert!(
            (n - area_px).abs() < 0.1 * perimeter_px,
            "covered {n} vs area {area_px}"
        );
    }
}

#[test]
fn pictures_are_not_mirrored() {
    // A small triangle in the world's upper-left (x < 0, y > 0), facing +Z.
    let mesh = Mesh {
        positions: vec![
            Vec3::new(-0.8, 0.5, 0.0),
            Vec3::new(-0.5, 0.5, 0.0),
            Vec3::new(-0.8, 0.8, 0.0),
        ],
        triangles: vec![[0, 1, 2]],
    };
    let settings = flat_settings([200, 200, 200], Vec3::Z, 1.0, 0.2);
    let centroid = |view: View| {
        let camera = Camera::orthographic(view, Vec3::ZERO, 100.0, 200, 200);
        let hit = covered(&render(&mesh, &camera, &settings), settings.background);
        assert!(!hit.is_empty(), "{view:?}");
        let n = hit.len() as f32;
        let sx = hit.iter().map(|p| p.0 as f32).sum::<f32>() / n;
        let sy = hit.iter().map(|p| p.1 as f32).sum::<f32>() / n;
        (sx, sy)
    };
    // Looking along -Z with +Y up: world +X is image right, world +Y is image up (small rows).
    let (x, y) = centroid(View::Back);
    assert!(x < 50.0 && y < 50.0, "back view centroid ({x}, {y})");
    // From behind (the palm view) world +X is image left.
    let (x, y) = centroid(View::Palm);
    assert!(x > 150.0 && y < 50.0, "palm view centroid ({x}, {y})");
}

#[test]
fn nearer_quad_wins_the_overlap_in_any_draw_order() {
    let base = [180, 180, 180];
    // Headlight: the shade reads the normal's component towards the camera.
    let settings = flat_settings(base, Vec3::Z, 1.0, 0.05);
    let camera = Camera::orthographic(View::Back, Vec3::ZERO, 100.0, 200, 200);
    let bright = lambert(base, 0.05, 1.0, 1.0);
    // Slope 1: normal (-1, 0, 1)/sqrt(2), so n.l = 0.7071.
    let dark = lambert(base, 0.05, 1.0, std::f64::consts::FRAC_1_SQRT_2);
    assert_ne!(bright, dark);

    let flat = quad([-0.5, 0.3], [-0.5, 0.5], 0.0, 0.0);
    for (tilted_z, overlap_colour) in [(-2.0, bright), (2.0, dark)] {
        // Camera looks along -Z, so larger z is nearer.
        let tilted = quad([-0.3, 0.5], [-0.4, 0.4], tilted_z, 1.0);
        for mesh in [concat(&flat, &tilted), concat(&tilted, &flat)] {
            let image = render(&mesh, &camera, &settings);
            // Overlap: x in [-0.3, 0.3], y in [-0.4, 0.4] -> pixels [70, 130) x [60, 140).
            for y in 62..138 {
                for x in 72..128 {
                    let p = image.pixel(x, y);
                    assert!(close(p, overlap_colour, 1), "z {tilted_z} ({x},{y}) {p:?}");
                }
            }
            // Outside the overlap each quad shows its own shade.
            assert!(close(image.pixel(60, 100), bright, 1));
            assert!(close(image.pixel(140, 100), dark, 1));
        }
    }
}

#[test]
fn sphere_silhouette_is_a_disk_of_the_fitted_radius_and_shaded() {
    let sphere = uv_sphere(Vec3::new(0.3, -0.2, 0.1), 1.0, 64, 32);
    let size = 200;
    let margin = 0.05;
    let camera = Camera::fit(View::Back, sphere.bounding_box(), size, size, margin);
    let settings = RenderSettings {
        supersample: 1,
        ..RenderSettings::default()
    };
    let image = render(&sphere, &camera, &settings);

    // Fitting the box [-1, 1]^3 (+ offset) into 200 px with 5% margins: radius 90 px, centred.
    let r = size as f32 * (1.0 - 2.0 * margin) / 2.0;
    let hit = covered(&image, settings.background);
    let n = hit.len() as f32;
    let disk = PI * r * r;
    assert!(
        (n / disk - 1.0).abs() < 0.02,
        "covered {n} vs pi r^2 {disk}"
    );
    let cx = hit.iter().map(|p| p.0 as f32 + 0.5).sum::<f32>() / n;
    let cy = hit.iter().map(|p| p.1 as f32 + 0.5).sum::<f32>() / n;
    assert!(
        (cx - 100.0).abs() < 0.5 && (cy - 100.0).abs() < 0.5,
        "({cx}, {cy})"
    );
    // Every covered pixel lies within the disk (plus one pixel).
    for &(x, y) in &hit {
        let d = Vec3::new(x as f32 + 0.5 - 100.0, y as f32 + 0.5 - 100.0, 0.0).length();
        assert!(d <= r + 1.0, "({x}, {y}) at {d}");
    }

    let (_, variance) = image_stats(&image);
    assert!(variance > 300.0, "luminance variance {variance}");
    let (_, inside_variance) = image_stats(&crop(&image, 60, 60, 80, 80));
    assert!(inside_variance > 20.0, "shading variance {inside_variance}");
    // The default key light comes from the upper left: that side of the sphere is brighter.
    let luma = |p: [u8; 3]| p.iter().map(|&c| u32::from(c)).sum::<u32>();
    let upper_left = luma(image.pixel(100 - 40, 100 - 40));
    let lower_right = luma(image.pixel(100 + 40, 100 + 40));
    assert!(
        upper_left > lower_right + 60,
        "{upper_left} vs {lower_right}"
    );
}

#[test]
fn supersampling_keeps_the_shape_and_softens_the_edge() {
    let sphere = uv_sphere(Vec3::ZERO, 1.0, 48, 24);
    let camera = Camera::fit(View::ThumbSide, sphere.bounding_box(), 120, 120, 0.1);
    let exact = RenderSettings {
        supersample: 1,
        ..RenderSettings::default()
    };
    let smooth = RenderSettings {
        supersample: 3,
        ..RenderSettings::default()
    };
    let a = render(&sphere, &camera, &exact);
    let b = render(&sphere, &camera, &smooth);
    let (na, nb) = (
        covered(&a, exact.background).len() as f32,
        covered(&b, exact.background).len() as f32,
    );
    // Anti-aliased edge pixels count as covered, so b is a little larger, by about a perimeter.
    let perimeter = 2.0 * PI * 48.0;
    assert!(nb >= na && nb - na < perimeter, "{na} vs {nb}");
    // Interior pixels agree closely (same normals, averaged over 9 samples).
    assert!(close(a.pixel(60, 60), b.pixel(60, 60), 3));
}

// --- images and PNG ------------------------------------------------------------------------------

#[test]
fn png_round_trip_keeps_size_and_pixels() {
    let sphere = uv_sphere(Vec3::ZERO, 1.0, 32, 16);
    let camera = Camera::fit(View::Back, sphere.bounding_box(), 97, 61, 0.1);
    let mut image = render(&sphere, &camera, &RenderSettings::default());
    image.draw_text(2, 2, "Pose 7_a.b", [0, 0, 255], 1);
    let bytes = image.encode_png().unwrap();

    let mut reader = png::Decoder::new(Cursor::new(&bytes)).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height), (97, 61));
    assert_eq!(info.color_type, png::ColorType::Rgb);
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    let decoded: Vec<[u8; 3]> = buf[..info.buffer_size()]
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    assert_eq!(decoded, image.pixels());

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sphere.png");
    image.write_png(&path).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
}

#[test]
fn png_errors_name_the_path_or_the_size() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("no-such-folder").join("x.png");
    let err = Image::new(4, 4, [1, 2, 3]).write_png(&path).unwrap_err();
    assert!(matches!(err, RenderError::Io { .. }));
    assert!(err.to_string().contains("x.png"), "{err}");

    let err = Image::new(0, 4, [1, 2, 3]).encode_png().unwrap_err();
    assert!(matches!(err, RenderError::Encode { .. }), "{err}");
    assert!(err.to_string().contains("0x4"), "{err}");
}

#[test]
fn blit_and_fill_rect_clip_to_the_image() {
    let mut big = Image::new(10, 8, [0, 0, 0]);
    let small = Image::new(4, 3, [9, 9, 9]);
    big.blit(&small, 8, 6);
    big.fill_rect(0, 0, 2, 100, [5, 5, 5]);
    big.blit(&small, 20, 20);
    let count = |c: [u8; 3]| big.pixels().iter().filter(|&&p| p == c).count();
    assert_eq!(count([9, 9, 9]), 2 * 2);
    assert_eq!(count([5, 5, 5]), 2 * 8);
    assert_eq!(big.pixel(9, 7), [9, 9, 9]);
    assert_eq!(big.pixel(7, 7), [0, 0, 0]);
}

// --- contact sheets ------------------------------------------------------------------------------

#[test]
fn contact_sheet_of_three_meshes_in_two_views() {
    let big = uv_sphere(Vec3::ZERO, 1.0, 40, 20);
    let small = uv_sphere(Vec3::new(0.3, 0.2, 0.0), 0.5, 40, 20);
    let slab = concat(
        &quad([-0.9, 0.9], [-0.6, 0.6], 0.2, 0.3),
        &quad([-0.2, 0.2], [-1.0, 1.0], -0.4, -0.5),
    );
    let tiles = [
        ("big".to_string(), &big),
        ("small".to_string(), &small),
        ("slab".to_string(), &slab),
    ];
    let views = [View::Back, View::ThumbSide];
    let (tile, columns) = (96, 2);
    let sheet = contact_sheet(&tiles, &views, tile, columns);

    // Two cells a row, two rows; each cell two tiles wide plus the label strip.
    let layout = SheetLayout::new(3, 2, tile, columns);
    let cell_width = 2 * tile + VIEW_GAP;
    assert_eq!((layout.columns, layout.rows), (2, 2));
    assert_eq!(sheet.width(), SHEET_GAP + 2 * (cell_width + SHEET_GAP));
    assert_eq!(
        sheet.height(),
        SHEET_GAP + 2 * (tile + layout.label_height + SHEET_GAP)
    );

    let background = RenderSettings::default().background;
    let mut coverage = Vec::new();
    for pose in 0..3 {
        for view in 0..2 {
            let (x, y) = layout.tile_origin(pose, view);
            assert!(x + tile <= sheet.width() && y + tile <= sheet.height());
            let t = crop(&sheet, x, y, tile, tile);
            let (_, variance) = image_stats(&t);
            assert!(
                variance > 100.0,
                "pose {pose} view {view}: variance {variance}"
            );
            coverage.push(covered(&t, background).len() as f32);
        }
        // The label strip under the cell has dark text in it.
        let (x, y) = layout.cell_origin(pose);
        let strip = crop(&sheet, x, y + tile, cell_width, layout.label_height);
        assert!(strip.pixels().iter().any(|p| p.iter().all(|&c| c < 100)));
    }
    // One framing for all poses: the half-radius sphere covers a quarter of the big one's area
    // (the view labels add a few pixels to both).
    let ratio = coverage[2] / coverage[0];
    assert!((ratio - 0.25).abs() < 0.04, "area ratio {ratio}");
    // The unused fourth cell stays sheet background.
    let (x, y) = layout.cell_origin(3);
    let empty = crop(&sheet, x, y, cell_width, tile + layout.label_height);
    assert!(empty.pixels().iter().all(|&p| p == SHEET_BACKGROUND));
}

#[test]
fn renderer_reuse_gives_identical_pictures() {
    let a = uv_sphere(Vec3::ZERO, 1.0, 24, 12);
    let b = quad([-0.5, 0.5], [-0.5, 0.5], 0.0, 0.0);
    let camera = Camera::fit(View::Palm, a.bounding_box(), 64, 64, 0.1);
    let settings = RenderSettings::default();
    let mut renderer = Renderer::new();
    let mut image = Image::default();
    renderer.render_into(&b.positions, &b.triangles, &camera, &settings, &mut image);
    renderer.render_into(&a.positions, &a.triangles, &camera, &settings, &mut image);
    assert_eq!(image, render(&a, &camera, &settings));
}

/// `cargo test -p crease-hand --release --test all -- --ignored --nocapture render::timing`
#[test]
#[ignore = "timing report, not a check"]
fn timing_of_large_meshes_at_400_pixels() {
    for (segments, stacks) in [(388, 194), (600, 300)] {
        let sphere = uv_sphere(Vec3::ZERO, 1.0, segments, stacks);
        let camera = Camera::fit(View::Back, sphere.bounding_box(), 400, 400, 0.05);
        let mut renderer = Renderer::new();
        let mut image = Image::default();
        for supersample in [1, 2] {
            let settings = RenderSettings {
                supersample,
                ..RenderSettings::default()
            };
            renderer.render_into(
                &sphere.positions,
                &sphere.triangles,
                &camera,
                &settings,
                &mut image,
            );
            // The fastest of ten: the least disturbed by other processes on a shared machine.
            let mut ms = f64::INFINITY;
            for _ in 0..10 {
                let start = Instant::now();
                renderer.render_into(
                    &sphere.positions,
                    &sphere.triangles,
                    &camera,
                    &settings,
                    &mut image,
                );
                ms = ms.min(start.elapsed().as_secs_f64() * 1e3);
            }
            println!(
                "{} vertices, {} triangles, 400x400, supersample {supersample}: {ms:.1} ms",
                sphere.positions.len(),
                sphere.triangles.len()
            );
        }
    }
}
