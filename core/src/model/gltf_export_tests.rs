//! Tests of `gltf_export` (a file of their own: the module is long).
use super::*;

/// Two triangles over four vertices, three frames: frame 0 is the rest pose (all-zero
/// displacements), the others move every vertex differently.
fn quad() -> (Vec<[u32; 3]>, Vec<Vec3>, Vec<Vec3>) {
    let rest = vec![
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
    ];
    let mut frames = rest.clone();
    for k in 1..3 {
        frames.extend(
            rest.iter().enumerate().map(|(v, &p)| {
                p + Vec3::new(0.1 * k as f32, -0.25 * v as f32, 0.5 * (k * v) as f32)
            }),
        );
    }
    (vec![[0, 1, 2], [0, 2, 3]], rest, frames)
}

#[test]
fn animation_reads_back_as_one_hot_morph_targets() {
    let (triangles, rest, frames) = quad();
    let bytes = animation_to_glb(&triangles, &rest, &frames, 4.0).unwrap();
    assert_eq!(
        u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize,
        bytes.len(),
        "header length"
    );
    let doc = gltf::Gltf::from_slice(&bytes).unwrap();
    let blob = doc.blob.as_deref().unwrap();
    let mesh = doc.meshes().next().unwrap();
    let prim = mesh.primitives().next().unwrap();
    let reader = prim.reader(|_| Some(blob));
    let base: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
    assert_eq!(base, rest.iter().map(|p| p.to_array()).collect::<Vec<_>>());
    let idx: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
    assert_eq!(idx, vec![0, 1, 2, 0, 2, 3]);
    assert_eq!(prim.morph_targets().count(), 3);
    for (i, ((pos, _, _), target)) in reader
        .read_morph_targets()
        .zip(prim.morph_targets())
        .enumerate()
    {
        let d: Vec<[f32; 3]> = pos.unwrap().collect();
        let want = &frames[4 * i..4 * i + 4];
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for ((b, d), w) in base.iter().zip(&d).zip(want) {
            for c in 0..3 {
                assert!(
                    (b[c] + d[c] - w[c]).abs() <= 1e-6,
                    "frame {i}: {b:?}+{d:?}!={w}"
                );
                lo[c] = lo[c].min(d[c]);
                hi[c] = hi[c].max(d[c]);
            }
        }
        let acc = target.positions().unwrap();
        // As f32: the JSON reader may round the f64 text by one f64 ulp.
        let f32s = |v: json::Value| -> Vec<f32> {
            v.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap() as f32)
                .collect()
        };
        assert_eq!(f32s(acc.min().unwrap()), lo, "frame {i} min");
        assert_eq!(f32s(acc.max().unwrap()), hi, "frame {i} max");
    }
    let anim = doc.animations().next().unwrap();
    let channel = anim.channels().next().unwrap();
    assert_eq!(channel.target().node().index(), 0);
    let sampler = channel.sampler();
    assert_eq!(
        sampler.interpolation(),
        gltf::animation::Interpolation::Linear
    );
    let r = channel.reader(|_| Some(blob));
    let times: Vec<f32> = r.read_inputs().unwrap().collect();
    assert_eq!(times, vec![0.0, 0.25, 0.5]);
    let Some(gltf::animation::util::ReadOutputs::MorphTargetWeights(w)) = r.read_outputs() else {
        panic!("weights channel")
    };
    let w: Vec<f32> = w.into_f32().collect();
    let eye: Vec<f32> = (0..9).map(|i| f32::from(i % 4 == 0)).collect();
    assert_eq!(w, eye);
}

#[test]
fn animation_rejects_malformed_input() {
    let (triangles, rest, frames) = quad();
    let err = |t: &[[u32; 3]], r: &[Vec3], f: &[Vec3], fps: f32| {
        animation_to_glb(t, r, f, fps).unwrap_err().to_string()
    };
    assert!(err(&triangles, &rest, &frames[..5], 30.0).contains("multiple"));
    assert!(err(&triangles, &rest, &[], 30.0).contains("multiple"));
    assert!(err(&[[0, 1, 4]], &rest, &frames, 30.0).contains("triangle 0"));
    assert!(err(&[], &rest, &frames, 30.0).contains("no triangles"));
    for fps in [0.0, -1.0, f32::NAN, f32::INFINITY] {
        assert!(
            err(&triangles, &rest, &frames, fps).contains("fps"),
            "{fps}"
        );
    }
    let mut bad = frames.clone();
    bad[9].y = f32::NAN;
    assert!(err(&triangles, &rest, &bad, 30.0).contains("frame 2, vertex 1"));
    bad[9] = Vec3::splat(f32::MAX);
    let mut far_rest = rest.clone();
    far_rest[1] = Vec3::splat(-f32::MAX);
    assert!(err(&triangles, &far_rest, &bad, 30.0).contains("vertex 1"));
}

#[test]
fn animation_size_limit_is_4_gib() {
    assert!(check_animation_size(5_000, 10_000, 1_000).is_ok());
    // 12 * 1e6 * 401 bytes of positions alone: 4.8 GB.
    let e = check_animation_size(1_000_000, 0, 400)
        .unwrap_err()
        .to_string();
    assert!(e.contains("4 GiB") && e.contains("400 frames"), "{e}");
    // F² weights alone overflow the limit; usize::MAX must not overflow the arithmetic.
    assert!(check_animation_size(1, 1, 40_000).is_err());
    assert!(check_animation_size(usize::MAX, usize::MAX, usize::MAX).is_err());
}
