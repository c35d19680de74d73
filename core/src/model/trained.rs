//! A trained model: everything the run time needs to turn control points into a mesh.
//!
//! It embeds the [`Rig`] (rest mesh, bones, weights, the training examples' bone transforms)
//! and adds the control points, the rotation regressors ([`RotationModel`]) and the edge
//! skin of the translation solver ([`EdgeSkin`]). Stored as container kind 2 with the rig's
//! sections plus:
//!
//! | tag | content |
//! |---|---|
//! | `CTRL` | JSON: control points (vertex, name), method name, default beta |
//! | `RREG` | JSON: the [`RotationModel`] (group structure and matrices) |
//! | `EDGE` | edges, u32 x 2 per edge |
//! | `EDBI` / `EDVC` | edge skin: bone indices (u32) and rest-frame vectors (f32 x 3), stride from `CTRL` |
//!
//! Files written before the vector edge skin carry `EDBW` (scalar FKY08 eq. 10 weights, f32)
//! instead of `EDVC`; they still load, as [`EdgeSkin::from_weights`].
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
use crate::runtime::edge_skin::EdgeSkin;
use crate::runtime::predict::RotationModel;
use crate::runtime::skin::SkinWeights;

const CTRL: Tag = Tag(*b"CTRL");
const RREG: Tag = Tag(*b"RREG");
const EDGE: Tag = Tag(*b"EDGE");
const EDBI: Tag = Tag(*b"EDBI");
const EDBW: Tag = Tag(*b"EDBW");
const EDVC: Tag = Tag(*b"EDVC");

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
}

#[derive(Serialize, Deserialize)]
struct CtrlMeta {
    controls: Vec<ControlPoint>,
    method: String,
    beta: f32,
    edge_count: u64,
    edge_influences: u64,
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
            },
        )?;
        w.add_json(RREG, &self.rotations)?;
        w.add_u32s(EDGE, bytemuck::cast_slice(&self.edges));
        w.add_u32s(EDBI, self.edge_skin.indices());
        w.add_f32s(EDVC, bytemuck::cast_slice(self.edge_skin.vectors()));
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
        let model = TrainedModel {
            rig,
            controls: meta.controls,
            method: meta.method,
            rotations,
            edges,
            edge_skin,
            beta: meta.beta,
        };
        model.validate()?;
        Ok(model)
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
