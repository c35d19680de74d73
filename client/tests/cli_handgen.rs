//! End to end: `crease handgen` writes a generated hand data set that `crease train`/`eval`
//! can read (manifests, control-point layouts), joint angles that `crease pose` turns back
//! into the same meshes, and a contact sheet that is not blank.

use crate::common;

use std::path::Path;

use crease_core::glam::Vec3;
use crease_core::mesh::{ExampleSet, Mesh};

use common::{crease, run_ok};

/// Luminance mean and variance of a PNG, and its size.
fn png_stats(path: &Path) -> (u32, u32, f64, f64) {
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(path).expect("png exists"),
    ));
    let mut reader = decoder.read_info().expect("png header");
    let mut buf = vec![0; reader.output_buffer_size().expect("size")];
    let info = reader.next_frame(&mut buf).expect("png frame");
    assert_eq!(info.color_type, png::ColorType::Rgb);
    let px = &buf[..info.buffer_size()];
    let lum: Vec<f64> = px
        .chunks(3)
        .map(|c| 0.2126 * c[0] as f64 + 0.7152 * c[1] as f64 + 0.0722 * c[2] as f64)
        .collect();
    let mean = lum.iter().sum::<f64>() / lum.len() as f64;
    let var = lum.iter().map(|l| (l - mean) * (l - mean)).sum::<f64>() / lum.len() as f64;
    (info.width, info.height, mean, var)
}

#[test]
fn handgen_writes_a_trainable_data_set_and_pose_reproduces_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("hands");
    let stdout = run_ok(
        crease()
            .args([
                "handgen", "--train", "12", "--test", "3", "--seed", "5", "--out",
            ])
            .arg(&out),
    );
    assert!(stdout.contains("base: "), "{stdout}");
    assert!(stdout.contains("detailed: "), "{stdout}");

    // Base manifests: 12 training meshes (rest first), the three layouts.
    for (layout, n) in [("palm", 17), ("back", 15), ("glove13", 13)] {
        let set = ExampleSet::load(out.join(format!("train-{layout}.toml"))).expect("manifest");
        assert_eq!(set.examples.len(), 12, "{layout}");
        assert!(set.rest_name.ends_with("00-flat.ply"), "{}", set.rest_name);
        let cps = set.control_points.as_ref().expect("control points");
        assert_eq!(cps.len(), n, "{layout}");
        let mut unique = cps.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), n, "{layout}: repeated control points {cps:?}");
        let names = set.control_point_names.as_ref().expect("names");
        assert_eq!(names.len(), n, "{layout}");
        if layout == "glove13" {
            assert_eq!(names[..3], ["hand_top", "hand_left", "hand_right"]);
            assert!(names.contains(&"thumb_tip".to_owned()));
        }
    }
    let test = ExampleSet::load(out.join("test.toml")).expect("test manifest");
    assert_eq!(test.examples.len(), 3);
    let train = ExampleSet::load(out.join("train-back.toml")).expect("train");
    assert_eq!(test.rest.triangles, train.rest.triangles, "shared topology");
    assert!((6_000..=10_000).contains(&train.rest.vertex_count()));

    // Detailed manifests, named by the base ones (`detailed = ...`): same poses, >= 150K
    // vertices, shared topology.
    let detailed = train
        .load_detailed()
        .expect("detailed")
        .expect("train-back.toml names its detailed set");
    assert_eq!(detailed.examples.len(), 12);
    assert!(detailed.rest.vertex_count() >= 150_000);
    let dtest = test
        .load_detailed()
        .expect("detailed test")
        .expect("test.toml names its detailed set");
    assert_eq!(dtest.examples.len(), test.examples.len());
    assert_eq!(dtest.rest.triangles, detailed.rest.triangles);

    // glove13 geometry against the recording's layout: hand_left/hand_right ~3 cm apart near
    // the wrist (hand_left on the thumb side, -X), hand_top ~5 cm distal, all on the back.
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("handgen.json")).unwrap())
            .expect("summary json");
    let glove = &summary["layouts"]["glove13"]["base"];
    let at = |name: &str| -> Vec3 {
        let lm = glove
            .as_array()
            .unwrap()
            .iter()
            .find(|l| l["name"] == name)
            .unwrap_or_else(|| panic!("no landmark {name}"));
        train.rest.positions[lm["vertex"].as_u64().unwrap() as usize]
    };
    let (top, left, right) = (at("hand_top"), at("hand_left"), at("hand_right"));
    assert!(
        left.x < right.x,
        "hand_left {left} should be radial of hand_right {right}"
    );
    assert!(
        (0.02..0.045).contains(&left.distance(right)),
        "{left} {right}"
    );
    assert!((0.035..0.07).contains(&top.distance(left)), "{top} {left}");
    assert!(top.z > 0.0 && left.z > 0.0 && right.z > 0.0, "on the back");
    assert!(at("index_tip").y > at("index_middle").y + 0.03);

    // Joint angles round trip: `crease pose --angles` reproduces a test mesh exactly.
    let angles = out.join("poses/test/001-sampled.json");
    let posed = dir.path().join("posed.ply");
    run_ok(
        crease()
            .args(["pose", "--angles"])
            .arg(&angles)
            .arg("--out")
            .arg(&posed),
    );
    let a = Mesh::read(&posed).expect("posed mesh");
    let b = Mesh::read(out.join("base/test/001-sampled.ply")).expect("test mesh");
    let worst = a
        .positions
        .iter()
        .zip(&b.positions)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0f32, f32::max);
    assert!(
        worst < 1e-6,
        "pose --angles differs from handgen by {worst} m"
    );

    // The posed skeleton's joint centres beside the angles: all 25 WebXR joints, each inside
    // the test mesh near its skin (within a finger's thickness of a vertex).
    let joints: std::collections::BTreeMap<String, [f32; 3]> = serde_json::from_str(
        &std::fs::read_to_string(out.join("poses/test/001-sampled.joints.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(joints.len(), 25, "{:?}", joints.keys());
    for (name, p) in &joints {
        let p = crease_core::glam::Vec3::from(*p);
        let nearest = b
            .positions
            .iter()
            .map(|v| v.distance(p))
            .fold(f32::MAX, f32::min);
        assert!(
            nearest < 0.015,
            "joint {name} at {p} is {nearest} m from the mesh"
        );
    }

    // A named pose differs from the flat hand.
    let fist = dir.path().join("fist.obj");
    run_ok(
        crease()
            .args(["pose", "--pose", "fist", "--out"])
            .arg(&fist),
    );
    let fist = Mesh::read(&fist).expect("fist");
    let moved = fist
        .positions
        .iter()
        .zip(&train.rest.positions)
        .filter(|(p, q)| p.distance(**q) > 0.01)
        .count();
    assert!(moved > 1000, "only {moved} vertices moved in the fist");

    // Contact sheet: 15 poses x 2 views, not blank.
    let (w, h, mean, var) = png_stats(&out.join("contact-sheet.png"));
    eprintln!("contact sheet {w}x{h}: luminance mean {mean:.1}, variance {var:.1}");
    assert!(w >= 1000 && h >= 300, "{w}x{h}");
    assert!(var > 100.0, "contact sheet looks blank (variance {var})");
}

#[test]
fn handgen_and_pose_reject_bad_input() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = crease()
        .args(["handgen", "--train", "0", "--base-only", "--out"])
        .arg(dir.path().join("x"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--train"));

    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, r#"{"index_pip_flexion": 0.5, "elbow": 1.0}"#).unwrap();
    let out = crease()
        .args(["pose", "--angles"])
        .arg(&bad)
        .arg("--out")
        .arg(dir.path().join("y.obj"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.json") && err.contains("elbow"), "{err}");
}

/// Vertices of `mesh` deeper than `tolerance` inside the ball (`centre`, `radius`), and the
/// deepest one's depth.
fn inside_ball(mesh: &Mesh, centre: Vec3, radius: f32, tolerance: f32) -> (usize, f32) {
    let depths: Vec<f32> = mesh
        .positions
        .iter()
        .map(|p| radius - p.distance(centre))
        .filter(|&d| d > tolerance)
        .collect();
    (depths.len(), depths.iter().copied().fold(0.0, f32::max))
}

/// `--collide-sphere` (issue 22; LYK06 "Collision detection with other objects"): the grasp
/// closes around a ball in the palm; without the flag the skin passes through it, with it no
/// vertex is left inside (beyond 0.1 mm), in `crease pose` and in `crease handgen`'s meshes.
#[test]
fn a_collide_sphere_pushes_the_hand_out_of_it() {
    const BALL: &str = "0,0.07,-0.045,0.03";
    let (centre, radius, tolerance) = (Vec3::new(0.0, 0.07, -0.045), 0.03, 1e-4);
    let dir = tempfile::tempdir().expect("temp dir");
    let pose = |name: &str, ball: Option<&str>| {
        let path = dir.path().join(name);
        let mut cmd = crease();
        cmd.args(["pose", "--pose", "grasp", "--out"]).arg(&path);
        if let Some(b) = ball {
            cmd.args(["--collide-sphere", b]);
        }
        run_ok(&mut cmd);
        Mesh::read(&path).expect("posed mesh")
    };
    let free = pose("free.ply", None);
    let (inside, deepest) = inside_ball(&free, centre, radius, tolerance);
    eprintln!("grasp without the ball: {inside} vertices inside, deepest {deepest} m");
    assert!(
        inside > 50 && deepest > 0.003,
        "the test ball should cut the grasping hand: {inside} vertices, deepest {deepest} m"
    );
    let held = pose("held.ply", Some(BALL));
    let (inside, deepest) = inside_ball(&held, centre, radius, tolerance);
    assert_eq!(
        inside, 0,
        "{inside} vertices left inside the ball, deepest {deepest} m"
    );
    // The rest of the hand stays where it was: only skin near the ball moved.
    let moved = free
        .positions
        .iter()
        .zip(&held.positions)
        .filter(|(a, b)| a.distance(**b) > 1e-6)
        .count();
    assert!(
        moved > 0 && moved < free.positions.len() / 2,
        "{moved} of {} vertices moved",
        free.positions.len()
    );

    // handgen: every mesh pushed out, the ball in the summary and the manifests' header.
    let out = dir.path().join("hands");
    run_ok(
        crease()
            .args([
                "handgen",
                "--train",
                "8",
                "--test",
                "2",
                "--base-only",
                "--collide-sphere",
                BALL,
                "--out",
            ])
            .arg(&out),
    );
    let set = ExampleSet::load(out.join("train-back.toml")).expect("manifest");
    let test = ExampleSet::load(out.join("test.toml")).expect("test manifest");
    assert_eq!(set.examples.len() + test.examples.len(), 10);
    for e in set.examples.iter().chain(&test.examples) {
        let (inside, deepest) = inside_ball(&e.mesh, centre, radius, tolerance);
        assert_eq!(
            inside, 0,
            "{}: {inside} vertices inside, deepest {deepest} m",
            e.name
        );
    }
    // The grasp (a named training pose) equals `crease pose --collide-sphere`.
    let grasp = set
        .examples
        .iter()
        .find(|e| e.name.contains("grasp"))
        .expect("the grasp is a training pose");
    let worst = grasp
        .mesh
        .positions
        .iter()
        .zip(&held.positions)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0f32, f32::max);
    assert!(
        worst < 1e-6,
        "handgen's grasp differs from pose's by {worst} m"
    );
    let manifest = std::fs::read_to_string(out.join("train-back.toml")).unwrap();
    assert!(
        manifest.contains("--collide-sphere 0,0.07,-0.045,0.03"),
        "{manifest}"
    );
    let summary = std::fs::read_to_string(out.join("handgen.json")).unwrap();
    assert!(summary.contains("\"ball\""), "{summary}");

    // Bad balls are refused naming what is wrong.
    for (bad, says) in [
        ("0,0.07,-0.045", "expected X,Y,Z,R"),
        ("0,0.07,-0.045,-0.01", "radius R must be > 0"),
        ("0,nan,0,0.01", "finite"),
    ] {
        let out = crease()
            .args(["pose", "--pose", "grasp", "--collide-sphere", bad, "--out"])
            .arg(dir.path().join("bad.ply"))
            .output()
            .unwrap();
        assert!(!out.status.success(), "{bad}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{bad}: {err}");
    }
}

/// `crease eval --hands extrapolation` (issue 20) generates in memory what `crease handgen
/// --train 10` writes: the same named training poses, sampled test poses and control points,
/// so its table equals the one of `crease eval` on the written manifests.
#[test]
fn eval_hands_protocol_matches_the_written_data_set() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("hands");
    run_ok(
        crease()
            .args([
                "handgen",
                "--train",
                "10",
                "--test",
                "4",
                "--seed",
                "3",
                "--base-only",
                "--out",
            ])
            .arg(&out),
    );
    let (train, test) =
        crease_hand::dataset::example_sets(10, 4, 3, crease_hand::dataset::Layout::Glove13)
            .expect("in-memory sets");
    let written = ExampleSet::load(out.join("train-glove13.toml")).expect("train manifest");
    let written_test = ExampleSet::load(out.join("test.toml")).expect("test manifest");
    for (mem, file) in [(&train, &written), (&test, &written_test)] {
        assert_eq!(mem.examples.len(), file.examples.len());
        for (a, b) in mem.examples.iter().zip(&file.examples) {
            assert!(b.name.ends_with(&a.name), "{} vs {}", a.name, b.name);
            assert_eq!(a.mesh.triangles, b.mesh.triangles);
            assert_eq!(a.mesh.positions, b.mesh.positions, "{}", a.name);
        }
    }
    assert_eq!(train.control_points, written.control_points);
    let names: Vec<&str> = train.examples.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(names[0], "train/00-flat.ply");
    assert!(names.iter().all(|n| !n.contains("sampled")), "{names:?}");

    let table = |args: &[&str]| -> serde_json::Value {
        let mut cmd = crease();
        cmd.args([
            "eval",
            "--bones",
            "12",
            "--max-influences",
            "3",
            "--methods",
            "global",
        ])
        .args(["--refine", "2,0.01", "--json"])
        .args(args);
        let json: serde_json::Value = serde_json::from_str(&run_ok(&mut cmd)).expect("json");
        let mut rows = json["test"].as_object().expect("a test table").clone();
        for row in rows.values_mut() {
            row.as_object_mut().unwrap().remove("us_per_frame");
        }
        serde_json::Value::Object(rows)
    };
    let from_files = table(&[
        "--examples",
        out.join("train-glove13.toml").to_str().unwrap(),
        "--test",
        out.join("test.toml").to_str().unwrap(),
    ]);
    let generated = table(&[
        "--hands",
        "extrapolation",
        "--hand-layout",
        "glove13",
        "--hand-test",
        "4",
        "--hand-seed",
        "3",
    ]);
    for row in [
        "global",
        "global+refine",
        "nearest",
        "nearest+refine",
        "refine-from-rest",
    ] {
        assert!(generated.get(row).is_some(), "no {row} row: {generated}");
    }
    assert_eq!(generated, from_files);
}
