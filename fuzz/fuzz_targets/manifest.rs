//! Example-set manifests (`.toml`, `core::mesh::ExampleSet::load`): the input is written as a
//! manifest in a temporary folder that holds three small meshes (`rest.obj`, `a.obj`, `b.obj`)
//! and loaded as `crease train` would.
#![no_main]
use crease_core::mesh::ExampleSet;
use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;
use std::sync::OnceLock;

fn folder() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("crease-fuzz-manifest-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temporary folder");
        let tet = |dx: f32| {
            format!(
                "v 0 0 0\nv {} 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
                1.0 + dx
            )
        };
        for (name, dx) in [("rest.obj", 0.0), ("a.obj", 0.5), ("b.obj", -0.25)] {
            std::fs::write(dir.join(name), tet(dx)).expect("mesh");
        }
        dir
    })
}

fuzz_target!(|data: &[u8]| {
    let path = folder().join("manifest.toml");
    std::fs::write(&path, data).expect("write the manifest");
    if let Ok(set) = ExampleSet::load(&path) {
        assert!(!set.examples.is_empty());
    }
});
