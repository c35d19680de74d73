//! A trained model mirrored across a plane through the origin (issue 38): the left hand from
//! the right-hand model, without a second training.
//!
//! The reflection is `M = I - 2 n n^T` for the plane's unit normal `n`. Every part of the model
//! is carried through `M` so that the mirrored model's prediction for mirrored control points is
//! the mirror of the original's prediction (to float rounding):
//!
//! - **rest mesh**: positions `M p`; each triangle `[a, b, c]` becomes `[a, c, b]`, so the
//!   winding, and with it every face normal, stays outward (`M` alone would turn it inward);
//! - **bone transforms** `x -> R x + t` become `x -> (M R M) x + M t`. `M R M` is a rotation
//!   (two reflections); for the quaternion `(v, w)` of `R` it is `(-M v, w)`: a rotation by the
//!   same angle about the mirrored axis, turned the other way;
//! - **rotation regressors** (FKY08 eq. 7, HZY11 eqs. 2-3): every kernel reads its control
//!   vectors only through `|x - y|^2` and `x . y` ([`crate::runtime::kernel::Kernel`]), both kept
//!   by the orthogonal `M` when the training inputs are mirrored too, so the kernel vector `xi`
//!   and the heat weights are the same for mirrored controls. The output rows `(x, y, z, w)` of
//!   each bone are a quaternion, so its `x y z` rows are mapped by the linear `-M` (and `w` kept),
//!   and a pose-local model's base rotations like any other rotation. The quaternion map is an
//!   orthogonal map of R^4, so blending's sign alignment and normalisation commute with it;
//! - **edge skin** (FKY08 eq. 10): the rest-frame vectors `a_kb` become `M a_kb`;
//! - **detail layer** (HZY11 §5.2): displacements run along the subdivided normals, which the
//!   mirrored winding keeps outward, so `h` is unchanged; its rows follow the subdivided vertex
//!   order, which depends on the winding (edges numbered by first appearance), so they are
//!   permuted onto the mirrored subdivision's order. The regressor's training inputs are control
//!   vectors (mirrored as points) or rotations (mirrored as quaternions);
//! - **control points** keep their vertices; their names swap sides ([`mirror_name`]).
//!
//! A plane through the origin keeps the kernels' dot products; a plane elsewhere would not (the
//! polynomial and Gaussian-linear kernels read `x . y`), so only planes through the origin are
//! offered. Where the mirrored hand appears in a room is set by its control points anyway.

use std::collections::HashMap;

use glam::{Quat, Vec3};

use super::ModelError;
use super::rig::{Rig, RigExample};
use super::trained::{ControlPoint, DetailLayer, TrainedModel};
use crate::mesh::Mesh;
use crate::mesh::subdivision::{LoopSubdivision, SparseMatrix};
use crate::runtime::displacement::{DetailInput, DetailRegressor};
use crate::runtime::edge_skin::EdgeSkin;
use crate::runtime::predict::{
    ControlGroup, GroupRegression, LinearOperator, PoseModel, RotationModel,
};
use crate::runtime::skin::RigidTransform;

/// A plane through the origin, by its unit normal: the reflection a model is mirrored by.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MirrorPlane {
    normal: Vec3,
}

/// Why a mirror plane was refused.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MirrorPlaneError {
    /// The text is neither an axis nor three numbers.
    #[error(
        "mirror plane {0:?}: expected an axis the plane is normal to (x, y or z) or a normal \
         \"nx,ny,nz\""
    )]
    Syntax(String),
    /// The normal is zero or not finite.
    #[error("mirror plane normal {0} is zero or not finite")]
    Normal(Vec3),
}

impl MirrorPlane {
    /// The plane `x = 0` (normal along x): a right hand modelled with the thumb toward `+x`
    /// becomes a left hand.
    pub const X: MirrorPlane = MirrorPlane { normal: Vec3::X };

    /// The plane through the origin normal to `normal` (normalised here).
    ///
    /// # Errors
    /// [`MirrorPlaneError::Normal`] for a zero or non-finite normal.
    pub fn new(normal: Vec3) -> Result<MirrorPlane, MirrorPlaneError> {
        match normal.try_normalize() {
            Some(n) if n.is_finite() => Ok(MirrorPlane { normal: n }),
            _ => Err(MirrorPlaneError::Normal(normal)),
        }
    }

    /// Parses `x`, `y`, `z` (the plane normal to that axis: `x` is the plane `x = 0`) or a normal
    /// `nx,ny,nz`.
    ///
    /// # Errors
    /// [`MirrorPlaneError`] naming the text.
    pub fn parse(text: &str) -> Result<MirrorPlane, MirrorPlaneError> {
        match text.trim().to_ascii_lowercase().as_str() {
            "x" => return Ok(MirrorPlane::X),
            "y" => return Ok(MirrorPlane { normal: Vec3::Y }),
            "z" => return Ok(MirrorPlane { normal: Vec3::Z }),
            _ => {}
        }
        let parts: Vec<f32> = text
            .split(',')
            .map(|s| s.trim().parse::<f32>())
            .collect::<Result<_, _>>()
            .map_err(|_| MirrorPlaneError::Syntax(text.to_string()))?;
        match parts[..] {
            [x, y, z] => MirrorPlane::new(Vec3::new(x, y, z)),
            _ => Err(MirrorPlaneError::Syntax(text.to_string())),
        }
    }

    /// The unit normal.
    pub fn normal(&self) -> Vec3 {
        self.normal
    }

    /// `M p`: a point (or a vector: the plane passes through the origin).
    pub fn point(&self, p: Vec3) -> Vec3 {
        p - 2.0 * self.normal.dot(p) * self.normal
    }

    /// `M R M` as a quaternion: `(-M v, w)` for `R = (v, w)`.
    pub fn rotation(&self, q: Quat) -> Quat {
        let v = -self.point(Vec3::new(q.x, q.y, q.z));
        Quat::from_xyzw(v.x, v.y, v.z, q.w)
    }

    /// The bone transform `x -> R x + t` seen in the mirror: `x -> (M R M) x + M t`.
    pub fn transform(&self, t: RigidTransform) -> RigidTransform {
        RigidTransform {
            rotation: self.rotation(t.rotation),
            translation: self.point(t.translation),
        }
    }

    /// Mirrors `values` read as consecutive points `x y z`.
    fn points_in_place(&self, values: &mut [f32]) {
        for c in values.chunks_exact_mut(3) {
            let p = self.point(Vec3::new(c[0], c[1], c[2]));
            c.copy_from_slice(&p.to_array());
        }
    }

    /// [`MirrorPlane::rotation`] of the four values `x y z w`, which need not be a unit
    /// quaternion: the map is linear (`-M` on `x y z`, `w` kept).
    fn rotation4(&self, [x, y, z, w]: [f32; 4]) -> [f32; 4] {
        self.rotation(Quat::from_xyzw(x, y, z, w)).to_array()
    }

    /// Mirrors `values` read as consecutive quaternions `x y z w`.
    fn rotations_in_place(&self, values: &mut [f32]) {
        for c in values.chunks_exact_mut(4) {
            let q = self.rotation4([c[0], c[1], c[2], c[3]]);
            c.copy_from_slice(&q);
        }
    }

    /// An operator whose output is quaternions, 4 rows `x y z w` each, mapped so that its
    /// output is the mirrored rotations: being linear, [`MirrorPlane::rotation`] goes through
    /// `m xi + b` column by column.
    fn rotation_rows(&self, op: &LinearOperator) -> LinearOperator {
        let cols = op.cols;
        let mut m = op.m.clone();
        let mut b = op.b.clone();
        for q in 0..op.rows / 4 {
            let r = 4 * q;
            let v = self.rotation4([b[r], b[r + 1], b[r + 2], b[r + 3]]);
            b[r..r + 4].copy_from_slice(&v);
            for c in 0..cols {
                let at = |k: usize| (r + k) * cols + c;
                let v = self.rotation4([m[at(0)], m[at(1)], m[at(2)], m[at(3)]]);
                for (k, x) in v.into_iter().enumerate() {
                    m[at(k)] = x;
                }
            }
        }
        LinearOperator {
            rows: op.rows,
            cols,
            m,
            b,
        }
    }
}

/// `x`, `y` or `z` for the axis planes, else the normal `nx,ny,nz`: what
/// [`MirrorPlane::parse`] reads back (a room's `Actor.mirror`, a mirrored model's name).
impl std::fmt::Display for MirrorPlane {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.normal.to_array() {
            [1.0, 0.0, 0.0] => f.write_str("x"),
            [0.0, 1.0, 0.0] => f.write_str("y"),
            [0.0, 0.0, 1.0] => f.write_str("z"),
            [x, y, z] => write!(f, "{x},{y},{z}"),
        }
    }
}

impl std::str::FromStr for MirrorPlane {
    type Err = MirrorPlaneError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        MirrorPlane::parse(s)
    }
}

/// A name with its side swapped: the words `right`/`left` and the one-letter side marks
/// `r`/`l`, in the case they are written in. Words are split at the separators `_ . - : /` and
/// space, and where a lower-case letter is followed by an upper-case one: `RightHand` ->
/// `LeftHand`, `thumb.R` -> `thumb.L`, `l_index_tip` -> `r_index_tip`, `handR` -> `handL`.
/// Anything else is kept: `index_tip`, `Ring1` and `c0` stay as they are.
pub fn mirror_name(name: &str) -> String {
    let is_sep = |c: char| matches!(c, '_' | '.' | '-' | ' ' | ':' | '/');
    let mut out = String::with_capacity(name.len() + 1);
    let mut word = String::new();
    let mut prev: Option<char> = None;
    for c in name.chars() {
        let boundary = is_sep(c) || (c.is_uppercase() && prev.is_some_and(char::is_lowercase));
        if boundary {
            out.push_str(&swap_side(&word));
            word.clear();
        }
        if is_sep(c) {
            out.push(c);
        } else {
            word.push(c);
        }
        prev = Some(c);
    }
    out.push_str(&swap_side(&word));
    out
}

/// `word` with its side swapped when it is one (`right`, `left`, `r`, `l`, any case), in the
/// same case: all capitals, capitalised, or lower case.
fn swap_side(word: &str) -> String {
    let other = match word.to_ascii_lowercase().as_str() {
        "right" => "left",
        "left" => "right",
        "r" => "l",
        "l" => "r",
        _ => return word.to_string(),
    };
    if word.chars().all(char::is_uppercase) {
        other.to_ascii_uppercase()
    } else if word.starts_with(char::is_uppercase) {
        let mut o = other.to_string();
        o[..1].make_ascii_uppercase();
        o
    } else {
        other.to_string()
    }
}

impl TrainedModel {
    /// The model mirrored across `plane` (module docs): its prediction for mirrored control
    /// points is the mirror of this model's.
    ///
    /// # Errors
    /// [`ModelError::InvalidRig`] when the model does not validate, or its detail layer's
    /// subdivision cannot be rebuilt.
    pub fn mirrored(&self, plane: &MirrorPlane) -> Result<TrainedModel, ModelError> {
        self.validate()?;
        let rig = mirror_rig(&self.rig, plane);
        let detail = match &self.detail {
            None => None,
            Some(layer) => Some(mirror_detail(layer, &self.rig.rest, &rig.rest, plane)?),
        };
        let model = TrainedModel {
            controls: (self.controls.iter())
                .map(|c| ControlPoint {
                    vertex: c.vertex,
                    name: mirror_name(&c.name),
                })
                .collect(),
            method: self.method.clone(),
            rotations: mirror_rotations(&self.rotations, plane),
            edges: self.edges.clone(),
            edge_skin: EdgeSkin::new(
                self.edge_skin.k(),
                self.edge_skin.indices().to_vec(),
                self.edge_skin
                    .vectors()
                    .iter()
                    .map(|&a| plane.point(a))
                    .collect(),
            )
            .map_err(|e| ModelError::InvalidRig(e.to_string()))?,
            beta: self.beta,
            detail,
            skinning: self.skinning,
            rig,
        };
        // Valid by construction from a valid model: `train/tests/mirror.rs` saves and loads one,
        // which validates it.
        debug_assert!(model.validate().is_ok(), "{:?}", model.validate());
        Ok(model)
    }
}

fn mirror_rig(rig: &Rig, plane: &MirrorPlane) -> Rig {
    Rig {
        rest: mirror_mesh(&rig.rest, plane),
        bone_count: rig.bone_count,
        skin: rig.skin.clone(),
        examples: (rig.examples.iter())
            .map(|ex| RigExample {
                name: ex.name.clone(),
                transforms: ex.transforms.iter().map(|&t| plane.transform(t)).collect(),
            })
            .collect(),
        fit_rms: rig.fit_rms,
    }
}

/// Positions mirrored, each triangle's winding reversed (`[a, b, c]` -> `[a, c, b]`).
pub fn mirror_mesh(mesh: &Mesh, plane: &MirrorPlane) -> Mesh {
    Mesh {
        positions: mesh.positions.iter().map(|&p| plane.point(p)).collect(),
        triangles: mesh.triangles.iter().map(|&[a, b, c]| [a, c, b]).collect(),
    }
}

fn mirror_rotations(model: &RotationModel, plane: &MirrorPlane) -> RotationModel {
    let groups = (model.groups.iter())
        .map(|g| {
            let mut inputs = g.inputs.clone();
            plane.points_in_place(&mut inputs);
            let regression = match &g.regression {
                GroupRegression::Global(op) => GroupRegression::Global(plane.rotation_rows(op)),
                GroupRegression::PoseLocal(poses) => GroupRegression::PoseLocal(
                    (poses.iter())
                        .map(|p| PoseModel {
                            neighbours: p.neighbours.clone(),
                            operator: plane.rotation_rows(&p.operator),
                            base: p.base.iter().map(|&q| plane.rotation(q)).collect(),
                        })
                        .collect(),
                ),
            };
            ControlGroup {
                controls: g.controls.clone(),
                bones: g.bones.clone(),
                kernel: g.kernel,
                heat_sigma: g.heat_sigma,
                inputs,
                regression,
            }
        })
        .collect();
    RotationModel {
        control_count: model.control_count,
        bone_count: model.bone_count,
        example_count: model.example_count,
        blend_poses: model.blend_poses,
        groups,
    }
}

fn mirror_detail(
    layer: &DetailLayer,
    rest: &Mesh,
    mirrored_rest: &Mesh,
    plane: &MirrorPlane,
) -> Result<DetailLayer, ModelError> {
    let invalid = |e: String| ModelError::InvalidRig(format!("mirroring the detail layer: {e}"));
    let original = LoopSubdivision::new(rest, layer.levels).map_err(|e| invalid(e.to_string()))?;
    let mirrored =
        LoopSubdivision::new(mirrored_rest, layer.levels).map_err(|e| invalid(e.to_string()))?;
    let order = subdivision_order(original.steps(), mirrored.steps()).map_err(invalid)?;
    let r = &layer.regressor;
    let op = &r.operator;
    let mut m = Vec::with_capacity(op.m.len());
    let mut b = Vec::with_capacity(op.b.len());
    for &i in &order {
        let i = i as usize;
        m.extend_from_slice(&op.m[i * op.cols..(i + 1) * op.cols]);
        b.push(op.b[i]);
    }
    let mut examples = r.examples.clone();
    match r.input {
        DetailInput::Controls => plane.points_in_place(&mut examples),
        DetailInput::Rotations => plane.rotations_in_place(&mut examples),
    }
    Ok(DetailLayer {
        levels: layer.levels,
        regressor: DetailRegressor {
            input: r.input,
            kernel: r.kernel,
            d_in: r.d_in,
            examples,
            operator: LinearOperator {
                rows: op.rows,
                cols: op.cols,
                m,
                b,
            },
        },
    })
}

/// For each vertex of the mirrored mesh's subdivision, the same vertex's index in the original's.
/// Level by level: a coarse vertex keeps its index; a new (odd) vertex is the one on the same
/// coarse edge, read from its row of the level's matrix (the two largest weights: 3/8 on an
/// interior edge's ends, 1/2 on a boundary edge's).
fn subdivision_order(
    original: &[SparseMatrix],
    mirrored: &[SparseMatrix],
) -> Result<Vec<u32>, String> {
    let Some(first) = original.first() else {
        return Err("no subdivision levels".into());
    };
    let mut order: Vec<u32> = (0..first.columns() as u32).collect();
    for (level, (so, sm)) in original.iter().zip(mirrored).enumerate() {
        if so.rows() != sm.rows() || so.columns() != order.len() {
            return Err(format!(
                "level {level}: {} and {} vertices",
                so.rows(),
                sm.rows()
            ));
        }
        let coarse = order.len();
        let mut by_edge = HashMap::with_capacity(so.rows() - coarse);
        for r in coarse..so.rows() {
            by_edge.insert(edge_of(so, r)?, r as u32);
        }
        let mut next = order.clone();
        for r in coarse..sm.rows() {
            let [a, b] = edge_of(sm, r)?;
            let (a, b) = (order[a as usize], order[b as usize]);
            let key = [a.min(b), a.max(b)];
            let Some(&v) = by_edge.get(&key) else {
                return Err(format!("level {level}: no vertex on edge {key:?}"));
            };
            next.push(v);
        }
        order = next;
    }
    Ok(order)
}

/// The coarse edge `[a, b]` (`a < b`) an odd vertex's row sits on.
fn edge_of(step: &SparseMatrix, row: usize) -> Result<[u32; 2], String> {
    let (cols, vals) = step.row(row);
    let mut best: [(f32, u32); 2] = [(f32::NEG_INFINITY, 0); 2];
    for (&c, &v) in cols.iter().zip(vals) {
        if v > best[0].0 {
            best = [(v, c), best[0]];
        } else if v > best[1].0 {
            best[1] = (v, c);
        }
    }
    if cols.len() < 2 || best[1].0 <= 0.25 {
        return Err(format!("row {row} is not an edge vertex's"));
    }
    let (a, b) = (best[0].1, best[1].1);
    Ok([a.min(b), a.max(b)])
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Mat3;

    /// The reflection as a matrix, built independently of [`MirrorPlane::point`].
    fn reflection(n: Vec3) -> Mat3 {
        let n = n.normalize();
        Mat3::IDENTITY - Mat3::from_cols(n * n.x, n * n.y, n * n.z) * 2.0
    }

    #[test]
    fn a_mirrored_rotation_is_the_reflection_on_both_sides() {
        for n in [
            Vec3::X,
            Vec3::new(0.3, -1.0, 0.5),
            Vec3::new(-2.0, 0.1, 1.0),
        ] {
            let plane = MirrorPlane::new(n).unwrap();
            let m = reflection(n);
            assert!(
                (m * Vec3::new(0.2, 0.7, -1.1) - plane.point(Vec3::new(0.2, 0.7, -1.1))).length()
                    < 1e-6
            );
            for (axis, angle) in [(Vec3::Y, 0.7), (Vec3::new(1.0, 2.0, -0.5), -2.1)] {
                let q = Quat::from_axis_angle(axis.normalize(), angle);
                let want = m * Mat3::from_quat(q) * m;
                let got = Mat3::from_quat(plane.rotation(q));
                assert!(
                    (got - want).to_cols_array().iter().all(|d| d.abs() < 1e-5),
                    "n {n}, q {q}: {got} vs M R M {want}"
                );
            }
        }
    }

    #[test]
    fn rotation_rows_map_an_operators_output_like_its_quaternions() {
        let plane = MirrorPlane::new(Vec3::new(0.4, 1.0, -0.3)).unwrap();
        let op = LinearOperator {
            rows: 8,
            cols: 2,
            m: (0..16).map(|i| (i as f32 * 0.37).sin()).collect(),
            b: (0..8).map(|i| (i as f32 * 0.91).cos()).collect(),
        };
        let xi = [0.6, -1.3];
        let (mut y, mut z) = ([0.0; 8], [0.0; 8]);
        op.apply(&xi, &mut y);
        plane.rotation_rows(&op).apply(&xi, &mut z);
        for k in 0..2 {
            let q = Quat::from_slice(&y[4 * k..4 * k + 4]);
            let want = plane.rotation(q);
            let got = Quat::from_slice(&z[4 * k..4 * k + 4]);
            assert!((got - want).length() < 1e-5, "bone {k}: {got} vs {want}");
        }
    }

    #[test]
    fn planes_parse_from_axes_and_normals() {
        assert_eq!(MirrorPlane::parse("x").unwrap(), MirrorPlane::X);
        assert_eq!(MirrorPlane::parse(" Z ").unwrap().normal(), Vec3::Z);
        let n = MirrorPlane::parse("0, 3, 4").unwrap().normal();
        assert!((n - Vec3::new(0.0, 0.6, 0.8)).length() < 1e-6);
        assert!(matches!(
            MirrorPlane::parse("w"),
            Err(MirrorPlaneError::Syntax(_))
        ));
        assert!(matches!(
            MirrorPlane::parse("1,2"),
            Err(MirrorPlaneError::Syntax(_))
        ));
        assert!(matches!(
            MirrorPlane::parse("0,0,0"),
            Err(MirrorPlaneError::Normal(_))
        ));
        assert!(matches!(
            MirrorPlane::parse("nan,0,1"),
            Err(MirrorPlaneError::Normal(_))
        ));
    }

    #[test]
    fn planes_print_as_they_parse() {
        for text in [
            "x",
            "y",
            "z",
            "0.6,0.8,0",
            "-0.26726124,0.5345225,0.80178374",
        ] {
            let plane = MirrorPlane::parse(text).unwrap();
            let back = MirrorPlane::parse(&plane.to_string()).unwrap();
            assert!(
                (back.normal() - plane.normal()).length() < 1e-6,
                "{text}: {back:?}"
            );
        }
        assert_eq!(MirrorPlane::parse("0,2,0").unwrap().to_string(), "y");
        assert_eq!(MirrorPlane::parse("-1,0,0").unwrap().to_string(), "-1,0,0");
    }

    #[test]
    fn names_swap_sides_and_keep_everything_else() {
        for (name, want) in [
            ("RightHand", "LeftHand"),
            ("LeftIndexProximal", "RightIndexProximal"),
            ("thumb.R", "thumb.L"),
            ("l_index_tip", "r_index_tip"),
            ("R_wrist", "L_wrist"),
            ("handR", "handL"),
            ("RIGHT_PINKY", "LEFT_PINKY"),
            ("right-wrist", "left-wrist"),
            ("index_tip", "index_tip"),
            ("Ring1", "Ring1"),
            ("c0", "c0"),
            ("bright", "bright"),
            ("", ""),
        ] {
            assert_eq!(mirror_name(name), want, "{name:?}");
        }
    }
}
