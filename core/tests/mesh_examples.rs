//! Example sets: folders and TOML manifests, ordering, validation errors, the real data sets.

use std::path::{Path, PathBuf};

use crease_core::glam::Vec3;
use crease_core::mesh::{ExampleSet, Mesh, MeshError, PlyFormat, ply};

use crate::common;
use common::shared_data as data;

/// A small strip of two triangles, moved by `t`.
fn strip(t: f32) -> Mesh {
    Mesh {
        positions: vec![
            Vec3::new(0.0, 0.0, t),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, t),
            Vec3::new(0.0, 1.0, 0.0),
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
    }
}

/// Writes `strip(i)` to each relative name under `dir`, making folders as needed.
fn populate(dir: &Path, names: &[&str]) {
    for (i, name) in names.iter().enumerate() {
        let path = dir.join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        strip(i as f32).write(&path).unwrap();
    }
}

fn names(set: &ExampleSet) -> Vec<&str> {
    set.examples.iter().map(|e| e.name.as_str()).collect()
}

#[test]
fn folder_order_is_natural_with_reference_first() {
    let tmp = tempfile::tempdir().unwrap();
    populate(
        tmp.path(),
        &[
            "poses/10.obj",
            "poses/2.obj",
            "poses/1.ply",
            "gallop/0002.glb",
            "gallop/0001.obj",
            "reference.obj",
            "zzz/deeper/reference.obj",
        ],
    );
    std::fs::write(tmp.path().join("notes.txt"), "not a mesh").unwrap();
    std::fs::write(tmp.path().join(".hidden.obj"), "garbage").unwrap();
    let mut seen = Vec::new();
    let set = ExampleSet::load_with_progress(tmp.path(), |p| {
        seen.push((p.index, p.total, p.name.to_owned()))
    })
    .unwrap();
    assert_eq!(
        names(&set),
        vec![
            "reference.obj",
            "gallop/0001.obj",
            "gallop/0002.glb",
            "poses/1.ply",
            "poses/2.obj",
            "poses/10.obj",
            "zzz/deeper/reference.obj",
        ]
    );
    assert_eq!(set.rest_name, "reference.obj");
    assert_eq!(set.rest, strip(5.0));
    assert_eq!(set.examples[0].mesh, set.rest);
    assert_eq!(set.examples[5].mesh, strip(0.0));
    assert_eq!(set.root, tmp.path());
    assert_eq!(set.control_points, None);
    assert_eq!(seen.len(), 7);
    assert_eq!(seen[1], (1, 7, "gallop/0001.obj".to_owned()));
}

#[test]
fn folder_without_reference_uses_first_in_natural_order() {
    let tmp = tempfile::tempdir().unwrap();
    populate(tmp.path(), &["pose10.ply", "pose2.ply", "pose1.ply"]);
    let set = ExampleSet::load(tmp.path()).unwrap();
    assert_eq!(names(&set), vec!["pose1.ply", "pose2.ply", "pose10.ply"]);
    assert_eq!(set.rest_name, "pose1.ply");
}

#[test]
fn topology_mismatch_names_file_and_first_differing_triangle() {
    let tmp = tempfile::tempdir().unwrap();
    populate(tmp.path(), &["reference.obj", "gallop/0001.obj"]);
    let mut bad = strip(7.0);
    bad.triangles[1] = [0, 2, 1];
    let bad_path = tmp.path().join("gallop/0007.obj");
    bad.write(&bad_path).unwrap();
    let e = ExampleSet::load(tmp.path()).unwrap_err();
    assert!(matches!(e, MeshError::TopologyMismatch { triangle: 1, .. }));
    assert_eq!(
        e.to_string(),
        format!(
            "{}: triangle 1 is [0, 2, 1], reference.obj has [0, 2, 3]",
            bad_path.display()
        )
    );
}

#[test]
fn vertex_count_mismatch_names_both_counts() {
    let tmp = tempfile::tempdir().unwrap();
    populate(tmp.path(), &["reference.obj"]);
    let mut bad = strip(1.0);
    bad.positions.push(Vec3::ONE);
    let bad_path = tmp.path().join("x.ply");
    bad.write(&bad_path).unwrap();
    let e = ExampleSet::load(tmp.path()).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!("{}: 5 vertices, reference.obj has 4", bad_path.display())
    );
}

#[test]
fn nan_in_an_example_names_its_file_and_line() {
    let tmp = tempfile::tempdir().unwrap();
    populate(tmp.path(), &["reference.obj"]);
    let path = tmp.path().join("poses/3.obj");
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(
        &path,
        "# c\nv 0 0 0\nv 1 0 0\nv 1 inf 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n",
    )
    .unwrap();
    let e = ExampleSet::load(tmp.path()).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{} line 4: vertex 2 has a non-finite y coordinate (inf)",
            path.display()
        )
    );
}

#[test]
fn empty_folder_is_an_error() {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("mask.txt"), "1 2 3").unwrap();
    let e = ExampleSet::load(tmp.path()).unwrap_err();
    assert!(e.to_string().contains("no mesh files"), "{e}");
}

#[test]
fn manifest_globs_in_natural_order_skipping_the_rest() {
    let tmp = tempfile::tempdir().unwrap();
    populate(
        tmp.path(),
        &[
            "reference.obj",
            "gallop/0002.obj",
            "gallop/0001.obj",
            "poses/10.obj",
            "poses/2.obj",
            "poses/1.obj",
            "unused/9.obj",
        ],
    );
    std::fs::write(tmp.path().join("poses/readme.txt"), "x").unwrap();
    let manifest = tmp.path().join("set.toml");
    std::fs::write(
        &manifest,
        r#"# the horse, in short
rest = "reference.obj"
examples = ["poses/*", "gallop/*.obj", "*.obj", "poses/2.obj"]
control_points = [3, 0, 2]
control_point_names = ["tip", "root", "mid"]
"#,
    )
    .unwrap();
    let set = ExampleSet::load(&manifest).unwrap();
    assert_eq!(
        set.control_point_names,
        Some(vec!["tip".to_owned(), "root".to_owned(), "mid".to_owned()])
    );
    assert_eq!(
        names(&set),
        vec![
            "reference.obj",
            "poses/1.obj",
            "poses/2.obj",
            "poses/10.obj",
            "gallop/0001.obj",
            "gallop/0002.obj",
        ]
    );
    assert_eq!(set.control_points, Some(vec![3, 0, 2]));
    assert_eq!(set.root, tmp.path());
}

fn manifest_error(body: &str, files: &[&str]) -> (PathBuf, String, tempfile::TempDir) {
    let tmp = tempfile::tempdir().unwrap();
    populate(tmp.path(), files);
    let manifest = tmp.path().join("set.toml");
    std::fs::write(&manifest, body).unwrap();
    let e = ExampleSet::load(&manifest).unwrap_err().to_string();
    (manifest, e, tmp)
}

#[test]
fn manifest_rejects_unknown_keys_with_line() {
    let (m, e, _t) = manifest_error(
        "rest = \"reference.obj\"\nexamples = []\ncontrol_point = [1]\n",
        &["reference.obj"],
    );
    assert!(
        e.starts_with(&format!(
            "{} line 3: unknown field `control_point`",
            m.display()
        )),
        "{e}"
    );
}

#[test]
fn manifest_control_point_names_must_match_the_points() {
    let (m, e, _t) = manifest_error(
        "rest = \"reference.obj\"\ncontrol_points = [0, 1]\ncontrol_point_names = [\"a\"]\n",
        &["reference.obj"],
    );
    assert!(
        e.starts_with(&format!("{} line 3", m.display()))
            && e.contains("1 names for 2 control points"),
        "{e}"
    );
}

#[test]
fn manifest_detailed_set_is_paired_by_file_name() {
    let tmp = tempfile::tempdir().unwrap();
    populate(tmp.path(), &["base/a.obj", "base/b.obj", "base/c.obj"]);
    populate(
        tmp.path(),
        &[
            "hi/a.obj",
            "hi/b.obj",
            "hi/c.obj",
            "other/a.obj",
            "other/x.obj",
            "other/c.obj",
        ],
    );
    let write = |name: &str, body: &str| {
        let p = tmp.path().join(name);
        std::fs::write(&p, body).unwrap();
        p
    };
    write(
        "hi.toml",
        "rest = \"hi/a.obj\"\nexamples = [\"hi/*.obj\"]\n",
    );
    write(
        "other.toml",
        "rest = \"other/a.obj\"\nexamples = [\"other/*.obj\"]\n",
    );
    write(
        "two.toml",
        "rest = \"hi/a.obj\"\nexamples = [\"hi/b.obj\"]\n",
    );
    let base = |detailed: &str| {
        let m = write(
            "set.toml",
            &format!(
                "rest = \"base/a.obj\"\nexamples = [\"base/*.obj\"]\ndetailed = \"{detailed}\"\n"
            ),
        );
        ExampleSet::load(m).unwrap()
    };
    let set = base("hi.toml");
    assert_eq!(set.detailed, Some(tmp.path().join("hi.toml")));
    let d = set.load_detailed().unwrap().expect("a detailed set");
    assert_eq!(names(&d), ["hi/a.obj", "hi/b.obj", "hi/c.obj"]);
    // In natural order pose 1 is c.obj in the detailed set (a, c, x), b.obj in the base set:
    // refused by name.
    let e = base("other.toml").load_detailed().unwrap_err().to_string();
    assert!(
        e.contains("\"other/c.obj\"") && e.contains("\"base/b.obj\""),
        "{e}"
    );
    let e = base("two.toml").load_detailed().unwrap_err().to_string();
    assert!(e.contains("2 detailed examples for 3 base examples"), "{e}");
    // Without the key there is nothing to load.
    let plain = write(
        "plain.toml",
        "rest = \"base/a.obj\"\nexamples = [\"base/*.obj\"]\n",
    );
    assert!(
        ExampleSet::load(plain)
            .unwrap()
            .load_detailed()
            .unwrap()
            .is_none()
    );
}

#[test]
fn manifest_errors_are_clear() {
    let files = &["reference.obj", "a/1.obj"];
    let (m, e, _t) = manifest_error("examples = [\"a/*.obj\"]\n", files);
    assert!(e.starts_with(&m.display().to_string()), "{e}");
    assert!(e.contains("missing field `rest`"), "{e}");

    let (m, e, _t) = manifest_error(
        "rest = \"reference.obj\"\nexamples = [\"b/*.obj\"]\n",
        files,
    );
    assert_eq!(
        e,
        format!(
            "{}: examples[0] = \"b/*.obj\" matched no mesh files",
            m.display()
        )
    );

    let (m, e, _t) = manifest_error(
        "rest = \"reference.obj\"\ncontrol_points = [\n  1,\n  4,\n]\n",
        files,
    );
    assert_eq!(
        e,
        format!(
            "{} line 4: control_points[1] = 4 is out of range (reference.obj has 4 vertices)",
            m.display()
        )
    );

    let (m, e, _t) = manifest_error("rest = \"reference.obj\"\ncontrol_points = [-1]\n", files);
    assert!(e.starts_with(&format!("{} line 2: ", m.display())), "{e}");

    let (_m, e, t) = manifest_error("rest = \"missing.obj\"\n", files);
    assert!(
        e.starts_with(&t.path().join("missing.obj").display().to_string()),
        "{e}"
    );
}

#[test]
fn horse_folder_has_59_frames_rest_first() {
    let Some(dir) = data("horse") else { return };
    let start = std::time::Instant::now();
    let set = ExampleSet::load(&dir).unwrap();
    eprintln!("horse: 59 OBJ files loaded in {:?}", start.elapsed());
    // reference + gallop/0001..0048 + poses/1..10.
    assert_eq!(set.examples.len(), 59);
    assert_eq!(set.rest_name, "reference.obj");
    let names = names(&set);
    assert_eq!(names[0], "reference.obj");
    let gallop: Vec<String> = (1..=48).map(|i| format!("gallop/{i:04}.obj")).collect();
    let poses: Vec<String> = (1..=10).map(|i| format!("poses/{i}.obj")).collect();
    let want: Vec<&str> = std::iter::once("reference.obj")
        .chain(gallop.iter().map(String::as_str))
        .chain(poses.iter().map(String::as_str))
        .collect();
    assert_eq!(names, want);
    assert!(set.examples.iter().all(|e| e.mesh.vertex_count() == 8431));
    // The gallop is a 24-frame loop (data README): frame k and k + 24 match within 1e-4.
    let (a, b) = (&set.examples[1].mesh, &set.examples[25].mesh);
    let max = a
        .positions
        .iter()
        .zip(&b.positions)
        .map(|(p, q)| (*p - *q).abs().max_element())
        .fold(0.0f32, f32::max);
    assert!(max <= 1e-4, "gallop 1 vs 25: {max}");
}

#[test]
fn cactus_folder_rest_is_cactus0_and_mask_is_ignored() {
    let Some(dir) = data("cactus") else { return };
    let set = ExampleSet::load(&dir).unwrap();
    let want: Vec<String> = (0..19).map(|i| format!("cactus{i}.ply")).collect();
    assert_eq!(names(&set), want);
    assert_eq!(set.rest_name, "cactus0.ply");
    assert_eq!(set.rest.vertex_count(), 5261);
}

#[test]
fn cactus_manifest_with_control_points() {
    let Some(dir) = data("cactus") else { return };
    let tmp = tempfile::tempdir().unwrap();
    // A manifest outside the data folder, pointing into it.
    let rel = pathdiff(&dir, tmp.path());
    let manifest = tmp.path().join("cactus.toml");
    std::fs::write(
        &manifest,
        format!(
            "rest = \"{rel}/cactus0.ply\"\nexamples = [\"{rel}/cactus1*.ply\"]\n\
             control_points = [0, 5260]\n"
        ),
    )
    .unwrap();
    let set = ExampleSet::load(&manifest).unwrap();
    let want: Vec<String> = std::iter::once(0)
        .chain(1..2)
        .chain(10..19)
        .map(|i| format!("{rel}/cactus{i}.ply"))
        .collect();
    assert_eq!(names(&set), want);
    assert_eq!(set.control_points, Some(vec![0, 5260]));

    // Binary copy of one frame in a folder set reads identically to the ASCII original.
    let copy = tmp.path().join("bin");
    std::fs::create_dir(&copy).unwrap();
    ply::write_ply(
        copy.join("reference.ply"),
        &set.rest,
        PlyFormat::BinaryLittleEndian,
    )
    .unwrap();
    let one = ExampleSet::load(&copy).unwrap();
    assert_eq!(one.rest, set.rest);
}

/// `target` relative to `base`, via a common absolute prefix (both exist).
fn pathdiff(target: &Path, base: &Path) -> String {
    let t = std::fs::canonicalize(target).unwrap();
    let b = std::fs::canonicalize(base).unwrap();
    let tc: Vec<_> = t.components().collect();
    let bc: Vec<_> = b.components().collect();
    let common = tc.iter().zip(&bc).take_while(|(x, y)| x == y).count();
    let mut parts: Vec<String> = vec!["..".to_owned(); bc.len() - common];
    parts.extend(
        tc[common..]
            .iter()
            .map(|c| c.as_os_str().to_string_lossy().into_owned()),
    );
    parts.join("/")
}
