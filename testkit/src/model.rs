//! The tiny trained model the server, demo and CLI tests stream: a tube of [`RINGS`] rings of
//! [`AROUND`] vertices, z from 0 to 7 ([`tube`]), bent at z = 3.5 ([`bent`]), trained
//! in-process into 4 bones (2 influences a vertex) and 3 control points ([`model`]); with a fixed
//! detail layer on request ([`model_with_detail`]).
//!
//! This file names only `crease_core` and `crease_train`, never `crate::`: crease-server's tests,
//! which cannot take the kit as a dev-dependency (it depends on the server), compile it into
//! their `tests/common` with `#[path]`.

use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;
use crease_core::mesh::test_meshes;
use crease_core::model::TrainedModel;
use crease_train::bones::FitOptions;
use crease_train::pipeline::{self, ControlSpec, TrainInput, TrainOptions};

/// Rings of the model's tube (one a unit of height).
pub const RINGS: usize = 8;
/// Vertices around each ring.
pub const AROUND: usize = 6;

/// The model's rest mesh: the shared tube with [`RINGS`] rings of [`AROUND`] vertices, ring `r`
/// at z = `r` (0 to 7), unit radius.
pub fn tube() -> Mesh {
    test_meshes::tube(RINGS, AROUND, (RINGS - 1) as f32)
}

/// `rest` with its upper half (z > 3.5) turned by `angle` about the x axis through z = 3.5.
pub fn bent(rest: &Mesh, angle: f32) -> Vec<Vec3> {
    test_meshes::bend(rest, 3.5, angle)
}

/// [`bent`] as a mesh (`rest`'s triangles): for tests that write poses to files.
pub fn bent_mesh(rest: &Mesh, angle: f32) -> Mesh {
    Mesh {
        positions: bent(rest, angle),
        triangles: rest.triangles.clone(),
    }
}

/// The tube curled: the ring at height `z` turned about the x axis through the origin by
/// `angle * z / (RINGS - 1)`, a bend whose rotation grows along the tube. Its fitted bones
/// blend over the rings (where [`bent`]'s are rigid segments), so LBS and DQS differ on it.
pub fn curled(rest: &Mesh, angle: f32) -> Vec<Vec3> {
    rest.positions
        .iter()
        .map(|&p| Quat::from_rotation_x(angle * p.z / (RINGS - 1) as f32) * p)
        .collect()
}

/// The tube model trained on [`bent`] (see [`model_of`]).
pub fn model() -> TrainedModel {
    model_of(bent)
}

/// The tube model trained on `deform` at 0 to 1.25 rad (six examples, 0.25 rad apart): 4 bones,
/// 2 influences a vertex, control points at vertices 0, 45 and 42.
///
/// # Panics
/// If training fails (it does not on the tube).
pub fn model_of(deform: fn(&Mesh, f32) -> Vec<Vec3>) -> TrainedModel {
    let rest = tube();
    let frames: Vec<Vec<Vec3>> = (0..6).map(|k| deform(&rest, 0.25 * k as f32)).collect();
    let refs: Vec<&[Vec3]> = frames.iter().map(Vec::as_slice).collect();
    let names: Vec<String> = (0..frames.len()).map(|k| format!("f{k}")).collect();
    let options = TrainOptions {
        fit: FitOptions {
            bones: 4,
            max_influences: 2,
            ..FitOptions::default()
        },
        controls: ControlSpec::Vertices(vec![0, 45, 42]),
        ..TrainOptions::default()
    };
    pipeline::train(
        TrainInput {
            rest: &rest,
            frames: &refs,
            names: &names,
        },
        &options,
        &mut |_| {},
    )
    .expect("the tube model trains")
    .0
}

/// The tube model with a fixed detail layer (one Loop level, a displacement per detail vertex
/// that does not depend on the controls): detail frames are checkable in-process.
pub fn model_with_detail() -> TrainedModel {
    use crease_core::mesh::subdivision::subdivided_vertex_count;
    use crease_core::model::DetailLayer;
    use crease_core::runtime::displacement::{DetailInput, DetailRegressor};
    let mut model = model();
    let n = subdivided_vertex_count(&model.rig.rest, 1);
    let h: Vec<f32> = (0..n)
        .map(|i| 0.02 * ((i * 7919) % 13) as f32 / 13.0)
        .collect();
    model.detail = Some(DetailLayer {
        levels: 1,
        regressor: DetailRegressor::fixed(DetailInput::Controls, 3 * model.controls.len(), h),
    });
    model
}
