//! [`Rig`]: a rest mesh, proxy bones with skin weights, and the bone transforms that pose the
//! rest mesh as each training example (FKY08 §4: "proxy bones").
//!
//! # Sections (container kind 1, see [`crate::model::file`])
//!
//! | tag    | content                                                                         |
//! |--------|---------------------------------------------------------------------------------|
//! | `META` | JSON: `vertex_count`, `triangle_count`, `bone_count`, `influences` (k), `example_names`, `fit_rms` |
//! | `VPOS` | rest positions, f32 x 3 per vertex                                              |
//! | `TRIS` | triangles, u32 x 3 per triangle                                                 |
//! | `SKBI` | skin bone indices, u32 x k per vertex (vertex-major)                            |
//! | `SKBW` | skin weights, f32 x k per vertex (vertex-major)                                 |
//! | `XFRM` | example bone transforms, f32 x 7 per bone per example, example-major: rotation quaternion `x y z w`, then translation `x y z` |
//!
//! Every size is checked against `META` on load, and the loaded rig is [`Rig::validate`]d.

use std::path::Path;

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

use super::ModelError;
use super::file::{Container, ContainerWriter, FormatError, ModelKind, Tag};
use crate::mesh::Mesh;
use crate::runtime::skin::{BonePalette, RigidTransform, SkinWeights, skin_lbs};

/// How far `|q|` of a stored rotation may be from 1. A quaternion normalised in f32 is within
/// ~1e-7; 1e-4 catches unnormalised ones (a regression output, a scaled matrix) without tripping
/// on values that went through a text format with 6 significant digits.
pub const QUAT_UNIT_TOLERANCE: f32 = 1e-4;

const META: Tag = Tag(*b"META");
const VPOS: Tag = Tag(*b"VPOS");
const TRIS: Tag = Tag(*b"TRIS");
const SKBI: Tag = Tag(*b"SKBI");
const SKBW: Tag = Tag(*b"SKBW");
const XFRM: Tag = Tag(*b"XFRM");

/// f32 values per stored bone transform: quaternion (4) + translation (3).
const FLOATS_PER_TRANSFORM: usize = 7;

/// A skinning rig: the rest mesh, `bone_count` proxy bones, per-vertex skin weights, and for
/// each example pose the bone transforms that map the rest pose onto it.
#[derive(Clone, Debug, PartialEq)]
pub struct Rig {
    /// The rest (reference) pose.
    pub rest: Mesh,
    /// Number of proxy bones.
    pub bone_count: usize,
    /// Skin weights, one set per rest vertex.
    pub skin: SkinWeights,
    /// One entry per example pose.
    pub examples: Vec<RigExample>,
    /// RMS vertex error of the fit over the examples (LBS of the rest mesh vs the example
    /// meshes) with the largest bounding-box side scaled to 1 (the HZY11 Table 2 protocol);
    /// `None` when unknown.
    pub fit_rms: Option<f32>,
}

/// The bone transforms of one example pose.
#[derive(Clone, Debug, PartialEq)]
pub struct RigExample {
    /// The example's name (usually its file stem).
    pub name: String,
    /// `bone_count` transforms mapping rest-pose positions to this example.
    pub transforms: Vec<RigidTransform>,
}

/// The `META` section.
#[derive(Debug, Serialize, Deserialize)]
struct RigMeta {
    vertex_count: u64,
    triangle_count: u64,
    bone_count: u64,
    influences: u64,
    example_names: Vec<String>,
    fit_rms: Option<f32>,
}

impl Rig {
    /// Checks that the parts agree: finite rest positions, triangle indices in range, one skin
    /// entry per vertex, bone indices below `bone_count`, `bone_count` finite unit-rotation
    /// transforms per example. The error names the first offending item.
    pub fn validate(&self) -> Result<(), ModelError> {
        let n = self.rest.vertex_count();
        if let Some(v) = self.rest.positions.iter().position(|p| !p.is_finite()) {
            return Err(invalid(format!(
                "rest vertex {v} is {}",
                self.rest.positions[v]
            )));
        }
        for (t, tri) in self.rest.triangles.iter().enumerate() {
            if let Some(&i) = tri.iter().find(|&&i| i as usize >= n) {
                return Err(invalid(format!(
                    "triangle {t} names vertex {i}, the mesh has {n}"
                )));
            }
        }
        if self.skin.vertex_count() != n {
            return Err(invalid(format!(
                "skin weights cover {} vertices, the rest mesh has {n}",
                self.skin.vertex_count()
            )));
        }
        self.skin.validate_bones(self.bone_count)?;
        for (e, ex) in self.examples.iter().enumerate() {
            if ex.transforms.len() != self.bone_count {
                return Err(invalid(format!(
                    "example {e} ({:?}) has {} transforms, expected {} (one per bone)",
                    ex.name,
                    ex.transforms.len(),
                    self.bone_count
                )));
            }
            for (b, t) in ex.transforms.iter().enumerate() {
                if !t.is_finite() {
                    return Err(invalid(format!(
                        "example {e} ({:?}), bone {b}: transform is not finite: {t:?}",
                        ex.name
                    )));
                }
                let len = t.rotation.length();
                if (len - 1.0).abs() > QUAT_UNIT_TOLERANCE {
                    return Err(invalid(format!(
                        "example {e} ({:?}), bone {b}: rotation is not a unit quaternion \
                         (|q| = {len})",
                        ex.name
                    )));
                }
            }
        }
        if self.fit_rms.is_some_and(|r| !r.is_finite() || r < 0.0) {
            return Err(invalid(format!("fit_rms is {:?}", self.fit_rms)));
        }
        Ok(())
    }

    /// Serialises the rig (after [`Rig::validate`]) into a container.
    pub fn to_bytes(&self) -> Result<Vec<u8>, ModelError> {
        let mut w = ContainerWriter::new(ModelKind::Rig);
        self.write_sections(&mut w)?;
        Ok(w.to_bytes())
    }

    /// Adds the rig's sections (META, VPOS, TRIS, SKBI, SKBW, XFRM) to a container, after
    /// [`Rig::validate`]; other model kinds embed a rig this way.
    pub fn write_sections(&self, w: &mut ContainerWriter) -> Result<(), ModelError> {
        self.validate()?;
        let meta = RigMeta {
            vertex_count: self.rest.vertex_count() as u64,
            triangle_count: self.rest.triangles.len() as u64,
            bone_count: self.bone_count as u64,
            influences: self.skin.k() as u64,
            example_names: self.examples.iter().map(|e| e.name.clone()).collect(),
            fit_rms: self.fit_rms,
        };
        w.add_json(META, &meta)?;
        w.add_f32s(VPOS, bytemuck::cast_slice(&self.rest.positions));
        w.add_u32s(TRIS, bytemuck::cast_slice(&self.rest.triangles));
        w.add_u32s(SKBI, self.skin.indices());
        w.add_f32s(SKBW, self.skin.weights());
        let xf: Vec<f32> = self
            .examples
            .iter()
            .flat_map(|e| &e.transforms)
            .flat_map(|t| {
                let (q, p) = (t.rotation, t.translation);
                [q.x, q.y, q.z, q.w, p.x, p.y, p.z]
            })
            .collect();
        w.add_f32s(XFRM, &xf);
        Ok(())
    }

    /// Parses and validates a rig from container bytes. Never panics on malformed input.
    pub fn from_bytes(bytes: &[u8]) -> Result<Rig, ModelError> {
        let c = Container::parse(bytes)?;
        c.expect_kind(ModelKind::Rig)?;
        Rig::read_sections(&c)
    }

    /// Reads and validates the rig sections of a container (any kind that embeds a rig).
    pub fn read_sections(c: &Container<'_>) -> Result<Rig, ModelError> {
        let meta: RigMeta = c.json(META)?;
        let bad_meta = |detail: String| FormatError::Metadata { tag: META, detail };
        let to_usize = |v: u64, what: &str| {
            usize::try_from(v).map_err(|_| bad_meta(format!("{what} = {v} does not fit in memory")))
        };
        let n = to_usize(meta.vertex_count, "vertex_count")?;
        let t = to_usize(meta.triangle_count, "triangle_count")?;
        let bones = to_usize(meta.bone_count, "bone_count")?;
        let k = to_usize(meta.influences, "influences")?;
        let e = meta.example_names.len();
        // Products of counts: an overflow means the metadata cannot match any section.
        let count = |a: usize, b: usize, what: &str| {
            a.checked_mul(b)
                .ok_or_else(|| bad_meta(format!("{what} overflows")))
        };

        let pos = c.f32s(
            VPOS,
            count(3, n, "3 x vertex_count")?,
            &format!("3 x {n} vertices"),
        )?;
        let tris = c.u32s(
            TRIS,
            count(3, t, "3 x triangle_count")?,
            &format!("3 x {t} triangles"),
        )?;
        let kn = count(k, n, "influences x vertex_count")?;
        let what_kn = format!("{k} influences x {n} vertices");
        let indices = c.u32s(SKBI, kn, &what_kn)?;
        let weights = c.f32s(SKBW, kn, &what_kn)?;
        let xf_len = count(
            count(FLOATS_PER_TRANSFORM, bones, "bones")?,
            e,
            "bones x examples",
        )?;
        let xf = c.f32s(
            XFRM,
            xf_len,
            &format!("{FLOATS_PER_TRANSFORM} x {bones} bones x {e} examples"),
        )?;

        let rest = Mesh {
            positions: pos.chunks_exact(3).map(Vec3::from_slice).collect(),
            triangles: tris.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        };
        let skin = SkinWeights::new(k, indices, weights)?;
        let per_example = FLOATS_PER_TRANSFORM * bones;
        let examples = meta
            .example_names
            .into_iter()
            .enumerate()
            .map(|(i, name)| RigExample {
                name,
                transforms: xf[i * per_example..(i + 1) * per_example]
                    .chunks_exact(FLOATS_PER_TRANSFORM)
                    .map(|f| RigidTransform {
                        rotation: Quat::from_xyzw(f[0], f[1], f[2], f[3]),
                        translation: Vec3::new(f[4], f[5], f[6]),
                    })
                    .collect(),
            })
            .collect();
        let rig = Rig {
            rest,
            bone_count: bones,
            skin,
            examples,
            fit_rms: meta.fit_rms,
        };
        rig.validate()?;
        Ok(rig)
    }

    /// Writes the rig to `path` atomically (see [`super::file::write_atomic`]). The rig is validated and
    /// serialised in memory first, so an invalid rig leaves an existing file untouched.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), ModelError> {
        super::save_bytes(path.as_ref(), &self.to_bytes()?)
    }

    /// Reads and validates a rig file.
    pub fn load(path: impl AsRef<Path>) -> Result<Rig, ModelError> {
        Rig::from_bytes(&super::read_bytes(path.as_ref())?)
    }

    /// Skins the rest mesh into `out` with example `example`'s transforms (LBS). A convenience
    /// for tools and tests: it builds a [`BonePalette`] per call; per-frame code keeps one.
    pub fn skin_example(&self, example: usize, out: &mut [Vec3]) -> Result<(), ModelError> {
        let ex = self
            .examples
            .get(example)
            .ok_or(ModelError::NoSuchExample {
                index: example,
                count: self.examples.len(),
            })?;
        let palette = BonePalette::from_transforms(&ex.transforms);
        skin_lbs(&self.rest.positions, &self.skin, &palette, out)?;
        Ok(())
    }
}

/// A [`ModelError::InvalidRig`].
fn invalid(msg: String) -> ModelError {
    ModelError::InvalidRig(msg)
}
