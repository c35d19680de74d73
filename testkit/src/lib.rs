//! crease-testkit: what the workspace's tests share, so each fixture is written once. A
//! dev-dependency only (`publish = false`): no normal build depends on it.
//!
//! Layout:
//! - [`mesh`]: the fixture meshes (a tube, a grid, a tetrahedron, and the tube's bend),
//!   re-exported from `crease_core::mesh::test_meshes`, where they are defined.
//! - [`model`] (feature `model`): the tiny trained model of the server, demo and CLI tests: a
//!   bending tube trained in-process, and its poses.
//! - [`server`] (feature `server`): a crease server in this process on free loopback ports,
//!   returned as a [`server::Served`] guard that stops it when dropped.
//! - [`python`]: the venv with python-osc that the VMC tests send with.
//!
//! Who can use it (ARCHITECTURE.md: a dev-dependency may not depend on the crate under test):
//! the kit depends on `crease-core`, `crease-train` and `crease-server` (and, through the
//! server, `crease-proto` and `crease-mocap`), so only the crates it does not reach take it as a
//! dev-dependency (`crease-hand`, `crease-demo`, `crease-cli`; the last two do). For the
//! others, the meshes are defined in core (its unit tests need them inside the crate: a kit
//! built on core would hand them a second, foreign `Mesh`), behind core's `test-meshes`
//! feature, which core's and train's tests turn on themselves; and crease-server's tests
//! compile [`model`] and [`server`] into their `tests/common` with `#[path]`, which is why
//! those two files name only other crates, never `crate::`.
//!
//! The features are on by default (for the docs); the workspace's entry turns them off, and a
//! user names what it needs: `features = ["model", "server"]`.

pub mod mesh;
#[cfg(feature = "model")]
pub mod model;
pub mod python;
#[cfg(feature = "server")]
pub mod server;
