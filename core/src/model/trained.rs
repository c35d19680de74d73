//! A trained model: everything the run time needs to turn control points into a mesh.
//!
//! It embeds the [`Rig`] (rest mesh, bones, weights, the training examples' bone transforms)
//! and adds the control points, the rotation regressors ([`RotationModel`]) and the edge
//! skin of the translation solver ([`EdgeSkin`]). Stored as container kind 2 with the rig's
//! sections plus:
//!
//! | tag | content |
//! |---|---|
//! | `CTRL` | JSON: control points (vertex, name), method name, default beta, default skinning |
//! | `RREG` | JSON: the [`RotationModel`] (group structure and matrices) |
//! | `EDGE` | edges, u32 x 2 per edge |
//! | `EDBI` / `EDVC` | edge skin: bone indices (u32) and rest-frame vectors (f32 x 3), stride from `CTRL` |
//!
//! | `DTLM` | JSON: the detail layer's meta ([`DetailLayer`]: subdivision levels, input, kernel, sizes) |
//! | `DTLX` / `DTLD` / `DTLB` | the detail regressor: training inputs, `D` (vertices x examples, row-major) and `b`, f32 |
//!
//! The detail sections are present only for a model with a detail layer (trained on detailed
//! examples); `S` is not stored but rebuilt from the rest topology and `levels` (it is exactly
//! determined by them).
//!
//! Files written before the vector edge skin carry `EDBW` (scalar FKY08 eq. 10 weights, f32)
//! instead of `EDVC`; they still load, as [`EdgeSkin::from_weights`].
//!
//! The default skinning (`skinning` in `CTRL`, issue 22) is written only when it is not LBS:
//! an LBS model's file is byte for byte what it was before the choice existed, and files
//! without the key (every earlier file) load as LBS. A reader older than the key ignores it
//! (serde's default for unknown fields) and skins with LBS.
//!
//! `RREG` is JSON for now: the regressors are a few hundred thousand numbers at most for the
//! models we train (serde_json writes shortest round-trip floats, so it is exact), and the
//! nested group structure stays self-describing. A binary layout is the upgrade path if load
//! time ever matters.

use std::path::Path;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use super::ModelError;
use super::file::{Container, ContainerWriter, ModelKind, Tag};
use super::rig::Rig;
use crate::mesh::subdivision::subdivided_vertex_count;
use crate::runtime::displacement::{DetailInput, DetailRegressor};
use crate::runtime::edge_skin::EdgeSkin;
use crate::runtime::kernel::Kernel;
use crate::runtime::predict::{LinearOperator, RotationModel};
use crate::runtime::skin::{SkinWeights, Skinning};

const CTRL: Tag = Tag(*b"CTRL");
const RREG: Tag = Tag(*b"RREG");
const EDGE: Tag = Tag(*b"EDGE");
const EDBI: Tag = Tag(*b"EDBI");
const EDBW: Tag = Tag(*b"EDBW");
const EDVC: Tag = Tag(*b"EDVC");
const DTLM: Tag = Tag(*b"DTLM");
const DTLX: Tag = Tag(*b"DTLX");
const DTLD: Tag = Tag(*b"DTLD");
const DTLB: Tag = Tag(*b"DTLB");

/// The detail layer of a model (HZY11 §5.2-§5.3): the base mesh Loop-subdivided `levels` times
/// (`S`, rebuilt from the rest topology), and the regressor of the displacements along the
/// subdivided normals.
#[derive(Clone, Debug, PartialEq)]
pub struct DetailLayer {
    /// Loop subdivision levels of `S` (1 or 2).
    pub levels: u32,
    /// `h(x) = D xi(x) + b`, one row per subdivided vertex.
    pub regressor: DetailRegressor,
}

#[derive(Serialize, Deserialize)]
struct DetailMeta {
    levels: u32,
    input: DetailInput,
    kernel: Kernel,
    d_in: u64,
    examples: u64,
    vertices: u64,
}

/// One control point: a mesh vertex the user moves (a marker on the surface).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ControlPoint {
    /// Vertex index in the rest mesh.
    pub vertex: u32,
    /// Display name (`c0`, `c1`, ... unless the manifest or a marker map names it).
    pub name: String,
}

/// Everything the predictor needs.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainedModel {
    /// Rest mesh, bones, weights, training examples' transforms.
    pub rig: Rig,
    /// Control points, in the order frames carry them.
    pub controls: Vec<ControlPoint>,
    /// Predictor variant it was trained with (`global`, `local`, ...).
    pub method: String,
    /// Rotation regressors.
    pub rotations: RotationModel,
    /// Mesh edges used by the translation solver.
    pub edges: Vec<[u32; 2]>,
    /// Edge skin of the translation solver, one row per edge.
    pub edge_skin: EdgeSkin,
    /// Default control-point weight of the translation solve (FKY08 eq. 11).
    pub beta: f32,
    /// The detail layer, when the model was trained on detailed examples.
    pub detail: Option<DetailLayer>,
    /// The skinning rooms on this model use unless they choose (`crease train --skinning`).
    pub skinning: Skinning,
}

#[derive(Serialize, Deserialize)]
struct CtrlMeta {
    controls: Vec<ControlPoint>,
    method: String,
    beta: f32,
    edge_count: u64,
    edge_influences: u64,
    /// Absent in LBS models and in every file written before issue 22 (module docs).
    #[serde(default, skip_serializing_if = "Skinning::is_lbs")]
    skinning: Skinning,
}

impl TrainedModel {
    /// Checks that the parts agree (sizes, indices, finiteness).
    pub fn validate(&self) -> Result<(), ModelError> {
        self.rig.validate()?;
        let n = self.rig.rest.vertex_count();
        let bad = |m: String| Err(ModelError::InvalidRig(m));
        if let Some(c) = self.controls.iter().find(|c| c.vertex as usize >= n) {
            return bad(format!(
                "control point {:?} is vertex {}, the mesh has {n}",
                c.name, c.vertex
            ));
        }
        if self.rotations.control_count != self.controls.len() {
            return bad(format!(
                "regressors expect {} control points, the model lists {}",
                self.rotations.control_count,
                self.controls.len()
            ));
        }
        if self.rotations.bone_count != self.rig.bone_count {
            return bad(format!(
                "regressors predict {} bones, the rig has {}",
                self.rotations.bone_count, self.rig.bone_count
            ));
        }
        self.rotations
            .validate()
            .map_err(|e| ModelError::InvalidRig(e.to_string()))?;
        if let Some((k, e)) = self
            .edges
            .iter()
            .enumerate()
            .find(|(_, e)| e.iter().any(|&v| v as usize >= n))
        {
            return bad(format!("edge {k} is {e:?}, the mesh has {n} vertices"));
        }
        if self.edge_skin.edge_count() != self.edges.len() {
            return bad(format!(
                "{} edge skin rows for {} edges",
                self.edge_skin.edge_count(),
                self.edges.len()
            ));
        }
        self.edge_skin
            .validate_bones(self.rig.bone_count)
            .map_err(|e| ModelError::InvalidRig(e.to_string()))?;
        if !(self.beta.is_finite() && self.beta >= 0.0) {
            return bad(format!("beta is {}", self.beta));
        }
        if let Some(d) = &self.detail {
            self.validate_detail(d)?;
        }
        Ok(())
    }

    fn validate_detail(&self, d: &DetailLayer) -> Result<(), ModelError> {
        let bad = |m: String| Err(ModelError::InvalidRig(format!("detail layer: {m}")));
        if !(1..=3).contains(&d.levels) {
            return bad(format!("{} subdivision levels (expected 1 to 3)", d.levels));
        }
        d.regressor.validate().map_err(ModelError::InvalidRig)?;
        let expected = subdivided_vertex_count(&self.rig.rest, d.levels);
        if d.regressor.vertex_count() != expected {
            return bad(format!(
                "{} displacement rows, the rest mesh subdivided {} times has {expected} vertices",
                d.regressor.vertex_count(),
                d.levels
            ));
        }
        let d_in = match d.regressor.input {
            DetailInput::Controls => 3 * self.controls.len(),
            DetailInput::Rotations => 4 * self.rig.bone_count,
        };
        if d.regressor.d_in != d_in {
            return bad(format!(
                "input of dimension {} from {}, expected {d_in}",
                d.regressor.d_in,
                d.regressor.input.name()
            ));
        }
        Ok(())
    }

    /// Serialises the model (after [`TrainedModel::validate`]).
    pub fn to_bytes(&self) -> Result<Vec<u8>, ModelError> {
        self.validate()?;
        let mut w = ContainerWriter::new(ModelKind::Model);
        self.rig.write_sections(&mut w)?;
        w.add_json(
            CTRL,
            &CtrlMeta {
                controls: self.controls.clone(),
                method: self.method.clone(),
                beta: self.beta,
                edge_count: self.edges.len() as u64,
                edge_influences: self.edge_skin.k() as u64,
                skinning: self.skinning,
            },
        )?;
        w.add_json(RREG, &self.rotations)?;
        w.add_u32s(EDGE, bytemuck::cast_slice(&self.edges));
        w.add_u32s(EDBI, self.edge_skin.indices());
        w.add_f32s(EDVC, bytemuck::cast_slice(self.edge_skin.vectors()));
        if let Some(d) = &self.detail {
            let r = &d.regressor;
            w.add_json(
                DTLM,
                &DetailMeta {
                    levels: d.levels,
                    input: r.input,
                    kernel: r.kernel,
                    d_in: r.d_in as u64,
                    examples: r.example_count() as u64,
                    vertices: r.vertex_count() as u64,
                },
            )?;
            w.add_f32s(DTLX, &r.examples);
            w.add_f32s(DTLD, &r.operator.m);
            w.add_f32s(DTLB, &r.operator.b);
        }
        Ok(w.to_bytes())
    }

    /// Parses and validates a model. Never panics on malformed input.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, ModelError> {
        let c = Container::parse(bytes)?;
        c.expect_kind(ModelKind::Model)?;
        let rig = Rig::read_sections(&c)?;
        let meta: CtrlMeta = c.json(CTRL)?;
        let rotations: RotationModel = c.json(RREG)?;
        let too_big = |what: &str| ModelError::InvalidRig(format!("{what} does not fit in memory"));
        let ne = usize::try_from(meta.edge_count).map_err(|_| too_big("edge_count"))?;
        let k = usize::try_from(meta.edge_influences).map_err(|_| too_big("edge_influences"))?;
        let ek = ne
            .checked_mul(k)
            .ok_or_else(|| too_big("edges x influences"))?;
        let e2 = ne.checked_mul(2).ok_or_else(|| too_big("2 x edges"))?;
        let edges = c.u32s(EDGE, e2, &format!("2 x {ne} edges"))?;
        let edges: Vec<[u32; 2]> = edges.chunks_exact(2).map(|e| [e[0], e[1]]).collect();
        let what = format!("{k} influences x {ne} edges");
        let indices = c.u32s(EDBI, ek, &what)?;
        let invalid = |e: crate::runtime::edge_skin::EdgeSkinError| {
            ModelError::InvalidRig(format!("edge skin: {e}"))
        };
        let edge_skin = if c.section(EDVC).is_some() {
            let e3 = ek.checked_mul(3).ok_or_else(|| too_big("3 x edge slots"))?;
            let v = c.f32s(EDVC, e3, &format!("3 x {what}"))?;
            let v = v
                .chunks_exact(3)
                .map(|p| Vec3::new(p[0], p[1], p[2]))
                .collect();
            EdgeSkin::new(k, indices, v).map_err(invalid)?
        } else {
            let weights = SkinWeights::new(k, indices, c.f32s(EDBW, ek, &what)?)?;
            EdgeSkin::from_weights(&rig.rest.positions, &edges, &weights).map_err(invalid)?
        };
        let detail = match c.section(DTLM) {
            None => None,
            Some(_) => Some(read_detail(&c)?),
        };
        let model = TrainedModel {
            rig,
            controls: meta.controls,
            method: meta.method,
            rotations,
            edges,
            edge_skin,
            beta: meta.beta,
            detail,
            skinning: meta.skinning,
        };
        model.validate()?;
        Ok(model)
    }

    /// Vertices of the detailed output, when the model has a detail layer.
    pub fn detail_vertex_count(&self) -> Option<usize> {
        self.detail.as_ref().map(|d| d.regressor.vertex_count())
    }

    /// Writes the model atomically.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), ModelError> {
        super::save_bytes(path.as_ref(), &self.to_bytes()?)
    }

    /// Reads and validates a model file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, ModelError> {
        Self::from_bytes(&super::read_bytes(path.as_ref())?)
    }
}

fn read_detail(c: &Container<'_>) -> Result<DetailLayer, ModelError> {
    let meta: DetailMeta = c.json(DTLM)?;
    let too_big =
        |what: &str| ModelError::InvalidRig(format!("detail layer: {what} does not fit in memory"));
    let size = |v: u64, what: &str| usize::try_from(v).map_err(|_| too_big(what));
    let (d_in, n, rows) = (
        size(meta.d_in, "d_in")?,
        size(meta.examples, "examples")?,
        size(meta.vertices, "vertices")?,
    );
    let nx = n
        .checked_mul(d_in)
        .ok_or_else(|| too_big("examples x d_in"))?;
    let nd = rows
        .checked_mul(n)
        .ok_or_else(|| too_big("vertices x examples"))?;
    let examples = c.f32s(DTLX, nx, &format!("{n} examples x {d_in} inputs"))?;
    let m = c.f32s(DTLD, nd, &format!("{rows} vertices x {n} examples"))?;
    let b = c.f32s(DTLB, rows, &format!("{rows} vertices"))?;
    Ok(DetailLayer {
        levels: meta.levels,
        regressor: DetailRegressor {
            input: meta.input,
            kernel: meta.kernel,
            d_in,
            examples,
            operator: LinearOperator {
                rows,
                cols: n,
                m,
                b,
            },
        },
    })
}
