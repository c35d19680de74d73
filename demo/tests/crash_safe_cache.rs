//! The demo cache is crash-safe (issue 21): a process saving it (`hand_model::save_cache`, what
//! `crease-server` calls after training the demo model) killed with SIGKILL at random moments,
//! many times, always leaves one whole model, the previous or the new, never a corrupt or
//! missing file.
//!
//! The demo model itself takes minutes to train, so the writer here is this test binary
//! re-run as a child (`CREASE_CACHE_WRITER` set) that saves two models, A and B, alternately
//! through `save_cache` until it is killed: every kill lands in or between saves. `CREASE_KILLS`
//! sets the number of kills (default 100).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_core::model::TrainedModel;
use crease_demo::hand_model::{CACHE_FILE, save_cache};
use crease_testkit::mesh::{bend, tube};
use crease_train::bones::FitOptions;
use crease_train::pipeline::{self, ControlSpec, TrainInput, TrainOptions};

/// A tube of `rings` rings of 24 vertices along z (ring `r` at z = `r`), bent by `angle`
/// beyond its middle.
fn bent_tube(rings: usize, angle: f32) -> Mesh {
    let mut mesh = tube(rings, 24, (rings - 1) as f32);
    mesh.positions = bend(&mesh, rings as f32 / 2.0, angle);
    mesh
}

fn train(bones: usize) -> TrainedModel {
    const RINGS: usize = 120;
    let rest = bent_tube(RINGS, 0.0);
    let frames: Vec<Vec<Vec3>> = (0..6)
        .map(|k| bent_tube(RINGS, 0.2 * k as f32).positions)
        .collect();
    let refs: Vec<&[Vec3]> = frames.iter().map(Vec::as_slice).collect();
    let names: Vec<String> = (0..frames.len()).map(|k| format!("f{k}")).collect();
    let options = TrainOptions {
        fit: FitOptions {
            bones,
            max_influences: 4,
            ..FitOptions::default()
        },
        controls: ControlSpec::Vertices(vec![0, 1500, 2870]),
        ..TrainOptions::default()
    };
    let input = TrainInput {
        rest: &rest,
        frames: &refs,
        names: &names,
    };
    pipeline::train(input, &options, &mut |_| {}).unwrap().0
}

/// The child: saves A and B alternately into `dir/cache` until killed.
#[test]
#[ignore = "the writer child of killed_cache_writers_leave_one_whole_model"]
fn cache_writer_loop() {
    let Some(dir) = std::env::var_os("CREASE_CACHE_WRITER").map(PathBuf::from) else {
        return;
    };
    let a = TrainedModel::load(dir.join("a.crease")).unwrap();
    let b = TrainedModel::load(dir.join("b.crease")).unwrap();
    let cache = dir.join("cache");
    for k in 0u64.. {
        save_cache(&cache, if k.is_multiple_of(2) { &b } else { &a }).unwrap();
        if k == 0 {
            println!("ready");
        }
    }
}

fn temps(dir: &Path) -> usize {
    let prefix = format!(".{CACHE_FILE}.tmp-");
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
        .count()
}

#[test]
fn killed_cache_writers_leave_one_whole_model() {
    let kills: usize = std::env::var("CREASE_KILLS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(100);
    let dir = tempfile::tempdir().unwrap();
    let a = train(3);
    let b = train(6);
    a.save(dir.path().join("a.crease")).unwrap();
    b.save(dir.path().join("b.crease")).unwrap();
    let old = std::fs::read(dir.path().join("a.crease")).unwrap();
    let new = std::fs::read(dir.path().join("b.crease")).unwrap();
    assert_ne!(old, new);
    let cache_dir = dir.path().join("cache");
    let cache = save_cache(&cache_dir, &a).unwrap();
    assert_eq!(
        std::fs::read(&cache).unwrap(),
        old,
        "save_cache writes the model's bytes"
    );

    // Kill times after the child's first save: uniform over about two saves.
    let start = std::time::Instant::now();
    for _ in 0..5 {
        save_cache(&cache_dir, &b).unwrap();
    }
    let save = start.elapsed() / 5;
    // The child runs this binary's writer test by its full name: its module path inside the
    // test binary (tests/all.rs), without the binary's own crate name.
    let (_, module) = module_path!().split_once("::").unwrap();
    let writer_test = format!("{module}::cache_writer_loop");
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let (mut saw_old, mut saw_new, mut mid_write) = (0, 0, 0);
    for k in 0..kills {
        std::fs::write(&cache, &old).unwrap();
        let mut child = Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                &writer_test,
                "--ignored",
                "--nocapture",
                "--test-threads=1",
            ])
            .env("CREASE_CACHE_WRITER", dir.path())
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        let mut out = BufReader::new(child.stdout.take().unwrap());
        while !line.contains("ready") {
            line.clear();
            assert!(
                out.read_line(&mut line).unwrap() > 0,
                "the writer child ended early"
            );
        }
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let fraction = (state >> 11) as f64 / (1u64 << 53) as f64;
        std::thread::sleep(save.mul_f64(2.0 * fraction));
        child.kill().unwrap();
        child.wait().unwrap();
        if temps(&cache_dir) > 0 {
            mid_write += 1;
        }
        let bytes =
            std::fs::read(&cache).unwrap_or_else(|e| panic!("kill {k}: the cache is missing: {e}"));
        if bytes == old {
            saw_old += 1;
        } else if bytes == new {
            saw_new += 1;
        } else {
            panic!(
                "kill {k}: the cache is neither model ({} bytes)",
                bytes.len()
            );
        }
        // The file reads as a model (the reader checks every section's CRC).
        TrainedModel::from_bytes(&bytes).unwrap();
    }
    save_cache(&cache_dir, &a).unwrap();
    assert_eq!(
        temps(&cache_dir),
        0,
        "a save removes killed writers' temporary files"
    );
    println!(
        "demo cache: {kills} kills of a writer saving a {}/{}-byte model every {:.1} ms: A {saw_old}, B {saw_new}, corrupt or missing 0; {mid_write} killed while the temporary file existed",
        old.len(),
        new.len(),
        save.as_secs_f64() * 1e3
    );
}
