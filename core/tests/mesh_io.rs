//! Mesh file formats end to end: round trips through real files, the shared data sets, and the
//! error messages a user sees.

use crease_core::glam::Vec3;
use crease_core::mesh::{Mesh, MeshError, PlyFormat, gltf, obj, ply};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::common;
/// A path below the shared data folder, or `None` (with a note) when it is not there.
use common::shared_data as data;

/// A random mesh whose coordinates span many magnitudes, subnormals and signed zeros included,
/// with random (possibly degenerate) triangles.
fn random_mesh(seed: u64, vertices: usize, triangles: usize) -> Mesh {
    let mut rng = StdRng::seed_from_u64(seed);
    let positions = (0..vertices)
        .map(|_| {
            Vec3::from_array(std::array::from_fn(|_| match rng.random_range(0..4) {
                0 => rng.random_range(-1.0f32..1.0),
                1 => -0.0,
                // Any finite f32, by bit pattern.
                _ => loop {
                    let v = f32::from_bits(rng.random());
                    if v.is_finite() {
                        break v;
                    }
                },
            }))
        })
        .collect();
    let triangles = (0..triangles)
        .map(|_| std::array::from_fn(|_| rng.random_range(0..vertices as u32)))
        .collect();
    Mesh {
        positions,
        triangles,
    }
}

fn assert_bit_identical(a: &Mesh, b: &Mesh, what: &str) {
    assert_eq!(a.triangles, b.triangles, "{what}: triangles");
    assert_eq!(a.positions.len(), b.positions.len(), "{what}: vertex count");
    for (i, (p, q)) in a.positions.iter().zip(&b.positions).enumerate() {
        for k in 0..3 {
            assert_eq!(
                p[k].to_bits(),
                q[k].to_bits(),
                "{what}: vertex {i} axis {k}: {} vs {}",
                p[k],
                q[k]
            );
        }
    }
}

/// Writes `mesh` in every format and reads each file back.
fn round_trip_all_formats(mesh: &Mesh, tag: &str) {
    let dir = tempfile::tempdir().unwrap();
    for name in ["m.obj", "m.ply", "m.glb", "m.gltf", "M.OBJ"] {
        let path = dir.path().join(name);
        mesh.write(&path).unwrap();
        assert_bit_identical(&Mesh::read(&path).unwrap(), mesh, &format!("{tag} {name}"));
    }
    for format in [
        PlyFormat::Ascii,
        PlyFormat::BinaryLittleEndian,
        PlyFormat::BinaryBigEndian,
    ] {
        let path = dir.path().join("p.ply");
        ply::write_ply(&path, mesh, format).unwrap();
        assert_bit_identical(
            &ply::read_ply(&path).unwrap(),
            mesh,
            &format!("{tag} {format:?}"),
        );
    }
}

#[test]
fn random_mesh_round_trips_exactly_in_every_format() {
    for seed in 0..4 {
        round_trip_all_formats(&random_mesh(seed, 300, 500), &format!("seed {seed}"));
    }
}

#[test]
fn ply_binary_is_little_endian_by_default() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.ply");
    random_mesh(9, 4, 2).write(&path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let header = String::from_utf8_lossy(&bytes[..200]);
    assert!(
        header.contains("format binary_little_endian 1.0"),
        "{header}"
    );
    assert!(header.contains("property list uchar uint vertex_indices"));
}

#[test]
fn cactus_ply_round_trips() {
    let Some(dir) = data("cactus") else { return };
    let mesh = Mesh::read(dir.join("cactus0.ply")).unwrap();
    assert_eq!(mesh.vertex_count(), 5261);
    assert_eq!(mesh.triangles.len(), 10518);
    // First vertex line of the file: "0.513434 0.457519 0.583028".
    assert_eq!(mesh.positions[0], Vec3::new(0.513434, 0.457519, 0.583028));
    round_trip_all_formats(&mesh, "cactus0");
}

/// The `v` lines of an OBJ file, parsed with nothing but `split_whitespace`.
fn v_lines(text: &str) -> Vec<Vec3> {
    text.lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|l| {
            let c: Vec<f32> = l.split_whitespace().map(|w| w.parse().unwrap()).collect();
            Vec3::new(c[0], c[1], c[2])
        })
        .collect()
}

#[test]
fn horse_reference_obj_keeps_file_order_and_agrees_with_tobj() {
    let Some(dir) = data("horse") else { return };
    let path = dir.join("reference.obj");
    let mesh = Mesh::read(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(mesh.vertex_count(), 8431);
    assert_eq!(mesh.triangles.len(), 16843);
    assert_eq!(
        mesh.positions,
        v_lines(&text),
        "positions not in file order"
    );

    // tobj renumbers vertices by first use, so compare corner positions, triangle by triangle.
    let options = tobj::LoadOptions {
        triangulate: true,
        ..Default::default()
    };
    let (models, _) = tobj::load_obj(&path, &options).unwrap();
    let corners: Vec<Vec3> = models
        .iter()
        .flat_map(|m| {
            m.mesh.indices.iter().map(|&i| {
                let p = &m.mesh.positions[3 * i as usize..3 * i as usize + 3];
                Vec3::new(p[0], p[1], p[2])
            })
        })
        .collect();
    let ours: Vec<Vec3> = mesh
        .triangles
        .iter()
        .flat_map(|t| t.map(|i| mesh.positions[i as usize]))
        .collect();
    assert_eq!(ours, corners);
    // The reason we do not use tobj's numbering: it differs from the file's.
    let tobj_first = &models[0].mesh.positions[..3];
    assert_ne!(
        Vec3::new(tobj_first[0], tobj_first[1], tobj_first[2]),
        mesh.positions[0]
    );

    round_trip_all_formats(&mesh, "horse");
}

#[test]
fn quads_are_triangulated_in_obj_and_ply() {
    let dir = tempfile::tempdir().unwrap();
    let obj_path = dir.path().join("quad.obj");
    std::fs::write(
        &obj_path,
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1 4/1\n",
    )
    .unwrap();
    let ply_path = dir.path().join("quad.ply");
    std::fs::write(
        &ply_path,
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
         property float z\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n\
         0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n",
    )
    .unwrap();
    for path in [obj_path, ply_path] {
        let m = Mesh::read(&path).unwrap();
        assert_eq!(
            m.triangles,
            vec![[0, 1, 2], [0, 2, 3]],
            "{}",
            path.display()
        );
        // Both triangles face +Z like the quad.
        assert!(m.vertex_normals().iter().all(|n| *n == Vec3::Z));
    }
}

#[test]
fn nan_in_horse_obj_names_file_and_line() {
    let Some(dir) = data("horse") else { return };
    let text = std::fs::read_to_string(dir.join("reference.obj")).unwrap();
    // Line 812 is vertex 811 (the file starts with its v lines); make its y a NaN.
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let words: Vec<&str> = lines[811].split_whitespace().collect();
    assert_eq!(words[0], "v");
    lines[811] = format!("v {} nan {}", words[1], words[3]);
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("3.obj");
    std::fs::write(&path, lines.join("\n")).unwrap();
    let e = Mesh::read(&path).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{} line 812: vertex 811 has a non-finite y coordinate (NaN)",
            path.display()
        )
    );
    assert!(matches!(e, MeshError::NonFinite { vertex: 811, .. }));
}

#[test]
fn nan_in_ply_names_file_vertex_and_ascii_line() {
    let tmp = tempfile::tempdir().unwrap();
    let mut mesh = random_mesh(3, 10, 4);
    mesh.positions[7] = Vec3::new(0.0, 0.0, 1.0);
    let path = tmp.path().join("a.ply");
    ply::write_ply(&path, &mesh, PlyFormat::Ascii).unwrap();
    // Header: ply, format, comment, element, 3 properties, element, property, end_header.
    let text = std::fs::read_to_string(&path).unwrap();
    let header_lines = text.lines().position(|l| l == "end_header").unwrap() + 1;
    assert_eq!(header_lines, 10);
    let mut lines: Vec<&str> = text.lines().collect();
    lines[header_lines + 7] = "0 0 NaN";
    std::fs::write(&path, lines.join("\n")).unwrap();
    let e = Mesh::read(&path).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{} line 18: vertex 7 has a non-finite z coordinate (NaN)",
            path.display()
        )
    );

    // Binary: write valid, then poke a NaN into vertex 7's x.
    let path = tmp.path().join("b.ply");
    ply::write_ply(&path, &mesh, PlyFormat::BinaryLittleEndian).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    let start = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let at = start + 7 * 12;
    bytes[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    let e = Mesh::read(&path).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{}: vertex 7 has a non-finite x coordinate (NaN)",
            path.display()
        )
    );
}

#[test]
fn nan_is_refused_on_write_and_names_the_target() {
    let tmp = tempfile::tempdir().unwrap();
    let mut mesh = random_mesh(4, 5, 2);
    mesh.positions[2].y = f32::INFINITY;
    for name in ["x.obj", "x.ply", "x.glb", "x.gltf"] {
        let path = tmp.path().join(name);
        let e = mesh.write(&path).unwrap_err().to_string();
        assert_eq!(
            e,
            format!(
                "{}: vertex 2 has a non-finite y coordinate (inf)",
                path.display()
            )
        );
        assert!(!path.exists());
    }
}

#[test]
fn missing_file_and_unknown_extension_errors_name_the_path() {
    let e = Mesh::read("no/such/file.obj").unwrap_err();
    assert!(matches!(e, MeshError::Io { .. }));
    assert!(e.to_string().starts_with("no/such/file.obj: "), "{e}");
    let e = Mesh::read("mask.txt").unwrap_err();
    assert_eq!(
        e.to_string(),
        "mask.txt: unknown mesh format \"txt\" (expected one of .obj, .ply, .gltf, .glb)"
    );
}

#[test]
fn hand_glb_first_primitive() {
    let Some(dir) = data("hand") else { return };
    for side in ["left", "right"] {
        let path = dir.join(format!("webxr-generic-hand-{side}.glb"));
        let mesh = gltf::read_gltf(&path).unwrap();
        assert_eq!(mesh.vertex_count(), 1360, "{side}");
        assert_eq!(mesh.triangles.len(), 2314, "{side}");
        mesh.validate().unwrap();
        // Every vertex is used by some triangle.
        let mut used = vec![false; mesh.vertex_count()];
        for t in &mesh.triangles {
            for &i in t {
                used[i as usize] = true;
            }
        }
        assert!(used.iter().all(|&u| u), "{side}: unused vertices");
        // A hand is about 0.2 m long.
        let size = mesh.bbox_diagonal_scale();
        assert!((0.05..0.5).contains(&size), "{side}: size {size}");
        // Our writer and reader agree on it.
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("hand.glb");
        gltf::write_glb(&out, &mesh).unwrap();
        assert_bit_identical(&Mesh::read(&out).unwrap(), &mesh, side);
    }
}

#[test]
fn obj_writer_output_is_plain_text() {
    let mesh = Mesh {
        positions: vec![Vec3::new(0.1, -2.0, 3.5), Vec3::X, Vec3::Y],
        triangles: vec![[0, 1, 2]],
    };
    let mut buf = Vec::new();
    obj::write_obj_to(&mut buf, &mesh).unwrap();
    let text = String::from_utf8(buf).unwrap();
    assert!(text.contains("\nv 0.1 -2 3.5\n"), "{text}");
    assert!(text.ends_with("f 1 2 3\n"), "{text}");
}
