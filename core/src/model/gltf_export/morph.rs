//! The baked vertex animation of `super`: a mesh's frames as morph targets (the layout is in
//! the parent module's docs), sized against the GLB limit before anything is computed, then
//! streamed to the file.

use std::collections::BTreeMap;
use std::io::{self, Write};
use std::path::Path;

use glam::Vec3;
use json::validation::{Checked, USize64};

use super::{F32, INDEX, ModelError, U32, VERTEX, accessor_at, flat_f32, json, min_max};

/// Largest GLB the format can describe: the header stores the file length as a u32.
pub const GLB_MAX_BYTES: u64 = u32::MAX as u64;

/// GLB header (12 bytes) plus the JSON and BIN chunk headers (8 each).
pub(super) const GLB_FIXED_BYTES: u64 = 28;

/// Bytes of the binary chunk of a baked animation (layout in the module docs); `None` when that
/// does not even fit a u64.
pub(super) fn animation_bin_bytes(vertices: usize, triangles: usize, frames: usize) -> Option<u64> {
    let (n, t, f) = (vertices as u64, triangles as u64, frames as u64);
    let mesh = n.checked_mul(12)?;
    let weights = f.checked_mul(f)?.checked_mul(4)?;
    mesh.checked_mul(f.checked_add(1)?)?
        .checked_add(t.checked_mul(12)?)?
        .checked_add(f.checked_mul(4)?)?
        .checked_add(weights)
}

/// Fails with [`ModelError::Export`] when `frames` frames of a mesh with `vertices` vertices and
/// `triangles` triangles cannot fit one GLB (see the module docs); call it before computing the
/// frames. Passing does not guarantee the JSON also fits, which [`animation_to_glb`] checks.
pub fn check_animation_size(
    vertices: usize,
    triangles: usize,
    frames: usize,
) -> Result<(), ModelError> {
    match animation_bin_bytes(vertices, triangles, frames) {
        Some(bytes) if bytes <= GLB_MAX_BYTES - GLB_FIXED_BYTES => Ok(()),
        bytes => Err(ModelError::Export(format!(
            "{frames} frames of a {vertices}-vertex mesh need {} of morph-target data (12 bytes \
             per vertex per frame plus 4 × frames² of weights); a GLB holds at most 4 GiB (its \
             header stores the length as a u32): split the frames over several files",
            bytes.map_or_else(|| "more than 2^64 bytes".into(), |b| format!("{b} bytes"))
        ))),
    }
}

/// Writes `F = frames.len() / rest.len()` frames of one mesh to `path` as a GLB whose animation
/// plays them through morph targets (layout in the module docs), atomically, streaming the
/// binary chunk from `frames`.
///
/// `triangles` index `rest`; `frames` holds frame 0's positions, then frame 1's, ...; keyframe
/// `i` is at `i / fps` seconds.
pub fn export_animation_glb(
    path: impl AsRef<Path>,
    triangles: &[[u32; 3]],
    rest: &[Vec3],
    frames: &[Vec3],
    fps: f32,
) -> Result<(), ModelError> {
    let path = path.as_ref();
    let glb = AnimationGlb::new(triangles, rest, frames, fps)?;
    crate::atomic::write_atomic_with(path, |out| glb.write(out)).map_err(|error| ModelError::Io {
        path: path.to_path_buf(),
        error,
    })
}

/// The GLB bytes [`export_animation_glb`] writes.
pub fn animation_to_glb(
    triangles: &[[u32; 3]],
    rest: &[Vec3],
    frames: &[Vec3],
    fps: f32,
) -> Result<Vec<u8>, ModelError> {
    let glb = AnimationGlb::new(triangles, rest, frames, fps)?;
    // The total was checked against GLB_MAX_BYTES, so it fits in memory's address range.
    let mut bytes = Vec::with_capacity(glb.total_bytes() as usize);
    glb.write(&mut bytes)
        .map_err(|e| ModelError::Export(e.to_string()))?;
    Ok(bytes)
}

/// A baked vertex animation ready to write: the JSON chunk is built, the binary chunk is
/// produced from the borrowed positions while writing.
pub(super) struct AnimationGlb<'a> {
    /// JSON chunk, padded with spaces to a multiple of 4.
    json: Vec<u8>,
    /// Binary chunk length (a multiple of 4: every value is 4 bytes).
    bin_bytes: u64,
    triangles: &'a [[u32; 3]],
    rest: &'a [Vec3],
    frames: &'a [Vec3],
    /// Keyframe times in seconds, strictly increasing.
    times: Vec<f32>,
}

impl<'a> AnimationGlb<'a> {
    fn new(
        triangles: &'a [[u32; 3]],
        rest: &'a [Vec3],
        frames: &'a [Vec3],
        fps: f32,
    ) -> Result<Self, ModelError> {
        let export = |m: String| Err(ModelError::Export(m));
        let n = rest.len();
        if n == 0 || triangles.is_empty() {
            return export("the rest mesh has no triangles".into());
        }
        if frames.is_empty() || !frames.len().is_multiple_of(n) {
            return export(format!(
                "{} frame positions are not a positive multiple of the {n} rest vertices",
                frames.len()
            ));
        }
        let f = frames.len() / n;
        if let Some(t) = triangles
            .iter()
            .position(|t| t.iter().any(|&i| i as usize >= n))
        {
            return export(format!(
                "triangle {t} {:?} indexes beyond the {n} vertices",
                triangles[t]
            ));
        }
        if !(fps.is_finite() && fps > 0.0) {
            return export(format!("fps must be a positive number, got {fps}"));
        }
        check_animation_size(n, triangles.len(), f)?;
        let times: Vec<f32> = (0..f).map(|i| i as f32 / fps).collect();
        if !times.windows(2).all(|w| w[0] < w[1]) || !times[f - 1].is_finite() {
            return export(format!(
                "{f} keyframes at {fps} fps do not give strictly increasing finite f32 times"
            ));
        }
        if let Some(v) = rest.iter().position(|p| !p.is_finite()) {
            return export(format!("rest vertex {v} is not finite: {}", rest[v]));
        }

        let mut root = json::Root::default();
        let mut offset = 0u64;
        let mut reserve = |bytes: u64| {
            let at = offset;
            offset += bytes;
            at
        };
        let (lo, hi) = min_max(rest.iter().copied());
        let vec3 = json::accessor::Type::Vec3;
        let scalar = json::accessor::Type::Scalar;
        let mesh_bytes = 12 * n as u64;
        let position = accessor_at(
            &mut root,
            reserve(mesh_bytes),
            mesh_bytes,
            n,
            F32,
            vec3,
            Some(VERTEX),
            Some((lo.to_array().to_vec(), hi.to_array().to_vec())),
        );
        let index_bytes = 12 * triangles.len() as u64;
        let indices = accessor_at(
            &mut root,
            reserve(index_bytes),
            index_bytes,
            3 * triangles.len(),
            U32,
            scalar,
            Some(INDEX),
            None,
        );
        let input = accessor_at(
            &mut root,
            reserve(4 * f as u64),
            4 * f as u64,
            f,
            F32,
            scalar,
            None,
            Some((vec![times[0]], vec![times[f - 1]])),
        );
        let weight_bytes = 4 * (f as u64) * (f as u64);
        let output = accessor_at(
            &mut root,
            reserve(weight_bytes),
            weight_bytes,
            f * f,
            F32,
            scalar,
            None,
            None,
        );
        let mut targets = Vec::with_capacity(f);
        for (i, frame) in frames.chunks_exact(n).enumerate() {
            // The same f32 subtraction as in `write`, so min/max bound the written values.
            let displacements = frame.iter().zip(rest).map(|(&p, &r)| p - r);
            if let Some(v) = displacements.clone().position(|d| !d.is_finite()) {
                return export(format!(
                    "frame {i}, vertex {v}: position {} is not finite or too far from the rest \
                     position {}",
                    frame[v], rest[v]
                ));
            }
            let (lo, hi) = min_max(displacements);
            let positions = accessor_at(
                &mut root,
                reserve(mesh_bytes),
                mesh_bytes,
                n,
                F32,
                vec3,
                Some(VERTEX),
                Some((lo.to_array().to_vec(), hi.to_array().to_vec())),
            );
            targets.push(json::mesh::MorphTarget {
                positions: Some(positions),
                normals: None,
                tangents: None,
            });
        }
        let bin_bytes = offset;
        debug_assert_eq!(Some(bin_bytes), animation_bin_bytes(n, triangles.len(), f));

        let mut attributes = BTreeMap::new();
        attributes.insert(Checked::Valid(json::mesh::Semantic::Positions), position);
        let mesh = root.push(json::Mesh {
            extensions: None,
            extras: Default::default(),
            name: Some("rest".into()),
            primitives: vec![json::mesh::Primitive {
                attributes,
                extensions: None,
                extras: Default::default(),
                indices: Some(indices),
                material: None,
                mode: Checked::Valid(json::mesh::Mode::Triangles),
                targets: Some(targets),
            }],
            weights: Some(vec![0.0; f]),
        });
        let node = root.push(json::Node {
            name: Some("animation".into()),
            mesh: Some(mesh),
            ..Default::default()
        });
        let scene = root.push(json::Scene {
            extensions: None,
            extras: Default::default(),
            name: Some("animation".into()),
            nodes: vec![node],
        });
        root.scene = Some(scene);
        root.push(json::Animation {
            extensions: None,
            extras: Default::default(),
            channels: vec![json::animation::Channel {
                sampler: json::Index::new(0),
                target: json::animation::Target {
                    extensions: None,
                    extras: Default::default(),
                    node,
                    path: Checked::Valid(json::animation::Property::MorphTargetWeights),
                },
                extensions: None,
                extras: Default::default(),
            }],
            name: Some("frames".into()),
            samplers: vec![json::animation::Sampler {
                extensions: None,
                extras: Default::default(),
                input,
                interpolation: Checked::Valid(json::animation::Interpolation::Linear),
                output,
            }],
        });
        root.asset = json::Asset {
            generator: Some(format!("crease {}", env!("CARGO_PKG_VERSION"))),
            version: "2.0".into(),
            ..Default::default()
        };
        root.push(json::Buffer {
            byte_length: USize64::from(bin_bytes),
            name: None,
            uri: None,
            extensions: None,
            extras: Default::default(),
        });
        let mut json = root
            .to_vec()
            .map_err(|e| ModelError::Export(e.to_string()))?;
        json.resize(json.len().next_multiple_of(4), b' ');
        let glb = AnimationGlb {
            json,
            bin_bytes,
            triangles,
            rest,
            frames,
            times,
        };
        if glb.total_bytes() > GLB_MAX_BYTES {
            return export(format!(
                "the GLB would take {} bytes; at most 4 GiB fit (its header stores the length as \
                 a u32): split the frames over several files",
                glb.total_bytes()
            ));
        }
        Ok(glb)
    }

    /// Length of the whole GLB.
    fn total_bytes(&self) -> u64 {
        GLB_FIXED_BYTES + self.json.len() as u64 + self.bin_bytes
    }

    /// Writes the GLB: header, JSON chunk, BIN chunk in the layout of the module docs. Every
    /// length fits a u32: [`Self::new`] checked the total against [`GLB_MAX_BYTES`].
    fn write(&self, out: &mut dyn Write) -> io::Result<()> {
        out.write_all(b"glTF")?;
        out.write_all(&2u32.to_le_bytes())?;
        out.write_all(&(self.total_bytes() as u32).to_le_bytes())?;
        out.write_all(&(self.json.len() as u32).to_le_bytes())?;
        out.write_all(b"JSON")?;
        out.write_all(&self.json)?;
        out.write_all(&(self.bin_bytes as u32).to_le_bytes())?;
        out.write_all(b"BIN\0")?;
        let n = self.rest.len();
        let f = self.times.len();
        let mut buf = Vec::with_capacity(12 * n.max(f));
        let mut put_vec3s = |out: &mut dyn Write, values: &mut dyn Iterator<Item = Vec3>| {
            buf.clear();
            buf.extend(values.flat_map(|v| v.to_array()).flat_map(f32::to_le_bytes));
            out.write_all(&buf)
        };
        put_vec3s(out, &mut self.rest.iter().copied())?;
        let indices: Vec<u8> = self
            .triangles
            .iter()
            .flatten()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        out.write_all(&indices)?;
        out.write_all(&flat_f32(self.times.iter().copied()))?;
        let mut row = vec![0u8; 4 * f];
        for k in 0..f {
            // One-hot keyframe k: only target k is shown.
            row.fill(0);
            row[4 * k..4 * k + 4].copy_from_slice(&1.0f32.to_le_bytes());
            out.write_all(&row)?;
        }
        for frame in self.frames.chunks_exact(n) {
            put_vec3s(out, &mut frame.iter().zip(self.rest).map(|(&p, &r)| p - r))?;
        }
        Ok(())
    }
}
