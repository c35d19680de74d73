//! The palette stream's header (issue 18): everything a client needs once to turn palette
//! frames into meshes. The base mesh is linear blend skinning of the rest mesh (FKY08 eq. 1),
//! so the header carries the rest positions, the skin and the triangles; the detail layer is
//! `S · base + h n` with `h = D xi + b` (HZY11 eq. 4), so at the detail level it also carries
//! the number of Loop levels whose steps make `S` and the detail regressor's `D` and `b`.
//!
//! # The Loop steps are rebuilt, not sent (issue 41)
//!
//! `S`'s steps and the drawn triangles follow from the base triangles alone by the rules and
//! the numbering of [`crate::mesh::subdivision`] (ARCHITECTURE.md, "Palette streams"): a
//! decoder rebuilds them ([`loop_steps`], [`PaletteDetail::rebuild`]) instead of reading ~6 MB
//! of sparse matrices and ~0.5 MB of drawn triangles for the demo hand. Every decoder (this
//! one, `web/palette.js`, the Python package's) builds each step's weights in `f64` and rounds
//! them once to `f32`, and sums a row in column order, so the decoders agree bit for bit
//! (`tests/vectors/loop-v1.json`).
//!
//! # Quantisation and its error
//!
//! - Skin weights are 16-bit, `w = q / 65535`, rounded by largest remainder so that each
//!   vertex's `q` sum to exactly 65535: every weight is within `1/65535` of the model's
//!   ([`quantise_weights`]), and the decoded weights still sum to one, so a weight error moves
//!   a skinned vertex `v` by at most `sum_k |dw_k| |T_k p - v|` (the errors sum to zero).
//! - `D` and `b` are 16-bit multiples of one step, the quantum ([`detail_quantum`]): each
//!   value is within `quantum / 2` of the model's and `h_v` within
//!   `quantum / 2 (|xi|_1 + 1)` ([`PaletteDetail::displacement_error`]). The quantum is what
//!   that bound needs: near the training poses it is no more than the bones' own
//!   quantisation may move the farthest rest vertex. (Issue 18 stored each row with its own
//!   16-bit scale, ~1000x finer than that, 3.9 MB for the demo hand; one step makes the
//!   values small integers where the detail is small, which the wire's meshopt coding packs
//!   into a few bits.)
//! - The rest positions are exact `f32`s: they are the model's.
//!
//! The wire form (protobuf `PaletteTopology`) is `crease-proto`'s; [`PaletteHeader::validate`]
//! checks one read from the wire before anything indexes with it.

use glam::Vec3;

use crate::mesh::subdivision::{LoopSubdivision, SparseMatrix, loop_steps};
use crate::runtime::displacement::DetailRegressor;
use crate::runtime::skin::SkinWeights;

/// The largest stored magnitude of a detail value.
const DETAIL_Q_MAX: f32 = 32767.0;

/// Why a palette header could not be built or does not hold together.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PaletteHeaderError {
    /// A count or a length that does not fit the others.
    #[error("palette header: {what} has {got} entries, expected {expected}")]
    Length {
        /// Which array.
        what: String,
        /// Entries found.
        got: usize,
        /// Entries the other fields need.
        expected: usize,
    },
    /// An index past the end of what it indexes.
    #[error("palette header: {what} {index} is {value}, expected < {limit}")]
    Index {
        /// Which array.
        what: String,
        /// Its position.
        index: usize,
        /// The stored index.
        value: u64,
        /// What it must stay below.
        limit: usize,
    },
    /// A value that is not finite, or otherwise unusable.
    #[error("palette header: {what}: {message}")]
    Value {
        /// Which field.
        what: String,
        /// What is wrong.
        message: String,
    },
}

fn length(what: impl Into<String>, got: usize, expected: usize) -> Result<(), PaletteHeaderError> {
    if got == expected {
        Ok(())
    } else {
        Err(PaletteHeaderError::Length {
            what: what.into(),
            got,
            expected,
        })
    }
}

/// Checks that every corner of `triangles` is below `limit`; the error names the first
/// triangle that is not, as `what`.
fn triangles_below(
    what: &str,
    triangles: &[[u32; 3]],
    limit: usize,
) -> Result<(), PaletteHeaderError> {
    match triangles
        .iter()
        .enumerate()
        .find(|(_, t)| t.iter().any(|&i| i as usize >= limit))
    {
        Some((t, tri)) => Err(PaletteHeaderError::Index {
            what: what.into(),
            index: t,
            value: u64::from(*tri.iter().max().expect("three corners")),
            limit,
        }),
        None => Ok(()),
    }
}

/// The skin of the base mesh, quantised: `influences` (K) slots per vertex.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PaletteSkin {
    /// K, 1..=8.
    pub influences: usize,
    /// `vertices x K` bone indices (unused slots: 0).
    pub bones: Vec<u16>,
    /// `vertices x K` weights, `w = q / 65535`; each vertex's sum to 65535.
    pub weights: Vec<u16>,
}

/// The detail layer's part of the header: the Loop steps (rebuilt from the base triangles,
/// never sent) and `D`, `b` quantised with one step.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PaletteDetail {
    /// Loop levels, `1..=MAX_LEVELS`.
    pub levels: u32,
    /// The one-level matrices `S_1 .. S_L` ([`loop_steps`] of the base triangles).
    pub steps: Vec<SparseMatrix>,
    /// The drawn (subdivided) mesh's triangles.
    pub triangles: Vec<[u32; 3]>,
    /// N: the length of every frame's `xi`.
    pub examples: usize,
    /// Per detailed vertex, `N + 1` values: its row of `D`, then `b`; each `q * quantum`.
    pub rows: Vec<i16>,
    /// The step of every stored value (module docs: [`detail_quantum`]).
    pub quantum: f32,
}

impl PaletteDetail {
    /// Detailed vertices.
    pub fn vertex_count(&self) -> usize {
        self.rows.len() / self.examples.saturating_add(1)
    }

    /// The decoded value of a stored `q`: `q * quantum`.
    #[inline]
    pub fn value(&self, q: i16) -> f32 {
        f32::from(q) * self.quantum
    }

    /// `h = D xi + b` with the decoded `D` and `b`, into `out` (one per detailed vertex).
    ///
    /// # Panics
    /// If `xi` is not N values or `out` not one per detailed vertex.
    pub fn displacements(&self, xi: &[f32], out: &mut [f32]) {
        let n = self.examples;
        assert_eq!(xi.len(), n, "xi length != examples");
        assert_eq!(out.len(), self.vertex_count(), "h length != vertices");
        let s = self.quantum;
        for (o, row) in out.iter_mut().zip(self.rows.chunks_exact(n + 1)) {
            let dot: f32 = row[..n]
                .iter()
                .zip(xi)
                .map(|(&q, &x)| f32::from(q) * s * x)
                .sum();
            *o = dot + f32::from(row[n]) * s;
        }
    }

    /// A bound on `|h_v - h'_v|` between the model's regressor and the decoded one for kernel
    /// vector `xi` (module docs), before `f32` rounding; the same for every vertex.
    pub fn displacement_error(&self, xi: &[f32]) -> f32 {
        0.5 * self.quantum * (xi.iter().map(|x| x.abs()).sum::<f32>() + 1.0)
    }
}

impl PaletteDetail {
    /// The detail part of a header read from the wire: the Loop steps and the drawn triangles
    /// rebuilt from the `base_vertices` and `base_triangles` of the base mesh ([`loop_steps`]),
    /// with the stored `rows` and `quantum`.
    ///
    /// # Errors
    /// [`PaletteHeaderError::Value`] naming the subdivision's error (a triangle past the
    /// vertices, a non-manifold edge, a bad level count).
    pub fn rebuild(
        base_vertices: usize,
        base_triangles: &[[u32; 3]],
        levels: u32,
        examples: usize,
        rows: Vec<i16>,
        quantum: f32,
    ) -> Result<PaletteDetail, PaletteHeaderError> {
        let (steps, triangles) =
            loop_steps(base_vertices, base_triangles, levels).map_err(|e| {
                PaletteHeaderError::Value {
                    what: "subdivision of the base triangles".into(),
                    message: e.to_string(),
                }
            })?;
        Ok(PaletteDetail {
            levels,
            steps,
            triangles,
            examples,
            rows,
            quantum,
        })
    }
}

/// The step `D` and `b` are stored with (module docs): the bones' own quantisation error at
/// the rest vertex farthest from the origin (`2 ROTATION_ERROR |p|`, the rotation part of
/// [`super::vertex_error_bound`]) spread over `(|xi|_1 + 1) / 2` for the largest `|xi|_1` of
/// the regressor's training inputs, so that near the examples `D`'s rounding moves a detailed
/// vertex no more than the bones' rounding already may; raised to `max |value| / 32767` where
/// that is coarser, so that every value fits 16 bits. 1 when everything is zero.
pub fn detail_quantum(rest: &[Vec3], regressor: &DetailRegressor) -> f32 {
    let op = &regressor.operator;
    let max =
        op.m.iter()
            .chain(&op.b)
            .filter(|x| x.is_finite())
            .fold(0.0f32, |m, x| m.max(x.abs()));
    let radius = rest
        .iter()
        .filter(|p| p.is_finite())
        .fold(0.0f32, |m, p| m.max(p.length()));
    let n = regressor.example_count();
    let d = regressor.d_in;
    let mut xi = vec![0.0f32; n];
    let mut xi_norm = 0.0f32;
    if d > 0 && regressor.examples.len() == n * d {
        for x in regressor.examples.chunks_exact(d) {
            regressor.kernel_vector(x, &mut xi);
            let norm: f32 = xi.iter().map(|v| v.abs()).sum();
            if norm.is_finite() {
                xi_norm = xi_norm.max(norm);
            }
        }
    }
    let target = 2.0 * (2.0 * super::ROTATION_ERROR * radius) / (xi_norm + 1.0);
    let floor = max / DETAIL_Q_MAX;
    let q = target.max(floor);
    if q.is_finite() && q > 0.0 { q } else { 1.0 }
}

/// A palette stream's header, decoded (module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PaletteHeader {
    /// Bones of every frame.
    pub bones: usize,
    /// The rest mesh's positions.
    pub rest: Vec<Vec3>,
    /// Its skin.
    pub skin: PaletteSkin,
    /// The base mesh's triangles (the drawn ones at the detail level are
    /// [`PaletteDetail::triangles`], their subdivision: [`PaletteHeader::drawn_triangles`]).
    pub triangles: Vec<[u32; 3]>,
    /// The detail layer, at the detail level.
    pub detail: Option<PaletteDetail>,
}

/// Quantises one vertex's weights (summing to 1) to `u16`s summing to exactly 65535, each within
/// `1/65535` of its weight: the floors, then one more unit to the largest remainders.
pub fn quantise_weights(weights: &[f32], out: &mut [u16]) {
    const ONE: f64 = 65535.0;
    let total: f64 = weights.iter().map(|&w| f64::from(w.max(0.0))).sum();
    let scale = if total > 0.0 { ONE / total } else { 0.0 };
    let mut rem = [(0.0f64, 0usize); 8];
    let mut sum = 0u32;
    for (k, (&w, o)) in weights.iter().zip(out.iter_mut()).enumerate() {
        let x = f64::from(w.max(0.0)) * scale;
        let f = x.floor();
        *o = f as u16;
        sum += f as u32;
        rem[k] = (x - f, k);
    }
    let k = weights.len().min(8);
    rem[..k].sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let missing = (ONE as u32).saturating_sub(sum) as usize;
    if total > 0.0 {
        for &(_, slot) in rem[..k].iter().cycle().take(missing) {
            out[slot] += 1;
        }
    } else if let Some(first) = out.first_mut() {
        // No weight at all (an invalid skin): the whole vertex on its first slot's bone.
        *first = ONE as u16;
    }
}

impl PaletteHeader {
    /// The base-level header of a rest mesh (`rest`, `triangles`) skinned by `skin` over
    /// `bones` bones.
    ///
    /// # Errors
    /// [`PaletteHeaderError`] when the skin does not fit the mesh or a bone index does not fit
    /// 16 bits.
    pub fn base(
        rest: &[Vec3],
        triangles: &[[u32; 3]],
        skin: &SkinWeights,
        bones: usize,
    ) -> Result<PaletteHeader, PaletteHeaderError> {
        length("skin", skin.vertex_count(), rest.len())?;
        let k = skin.k();
        let mut out = PaletteSkin {
            influences: k,
            bones: Vec::with_capacity(rest.len() * k),
            weights: vec![0; rest.len() * k],
        };
        for v in 0..rest.len() {
            let (ids, ws) = skin.vertex(v);
            for (slot, (&b, &w)) in ids.iter().zip(ws).enumerate() {
                // Unused slots point at bone 0 (the format's convention).
                let b = if w > 0.0 { b } else { 0 };
                if b as usize >= bones || b > u32::from(u16::MAX) {
                    return Err(PaletteHeaderError::Index {
                        what: "skin bone".into(),
                        index: v * k + slot,
                        value: u64::from(b),
                        limit: bones.min(1 << 16),
                    });
                }
                out.bones.push(b as u16);
            }
            quantise_weights(ws, &mut out.weights[v * k..(v + 1) * k]);
        }
        Ok(PaletteHeader {
            bones,
            rest: rest.to_vec(),
            skin: out,
            triangles: triangles.to_vec(),
            detail: None,
        })
    }

    /// This header at the detail level: `subdivision`'s steps and triangles, `regressor`'s
    /// `D` and `b` quantised with [`detail_quantum`] (module docs).
    ///
    /// # Errors
    /// [`PaletteHeaderError`] when the regressor or the subdivision does not fit the mesh.
    pub fn with_detail(
        mut self,
        subdivision: &LoopSubdivision,
        regressor: &DetailRegressor,
    ) -> Result<PaletteHeader, PaletteHeaderError> {
        length(
            "subdivision base vertices",
            subdivision.base_vertex_count(),
            self.rest.len(),
        )?;
        let nv = subdivision.vertex_count();
        length("detail regressor rows", regressor.vertex_count(), nv)?;
        let n = regressor.example_count();
        let op = &regressor.operator;
        let quantum = detail_quantum(&self.rest, regressor);
        let q = |x: f32| {
            if x.is_finite() {
                (x / quantum).round().clamp(-DETAIL_Q_MAX, DETAIL_Q_MAX) as i16
            } else {
                0
            }
        };
        let mut rows = Vec::with_capacity(nv * (n + 1));
        for v in 0..nv {
            rows.extend(op.m[v * n..(v + 1) * n].iter().map(|&x| q(x)));
            rows.push(q(op.b[v]));
        }
        self.detail = Some(PaletteDetail {
            levels: subdivision.levels(),
            steps: subdivision.steps().to_vec(),
            triangles: subdivision.triangles().to_vec(),
            examples: n,
            rows,
            quantum,
        });
        Ok(self)
    }

    /// The drawn mesh's triangles: the base mesh's, or at the detail level their subdivision.
    pub fn drawn_triangles(&self) -> &[[u32; 3]] {
        self.detail
            .as_ref()
            .map_or(&self.triangles, |d| &d.triangles)
    }

    /// Vertices of the drawn mesh.
    pub fn vertex_count(&self) -> usize {
        self.detail
            .as_ref()
            .map_or(self.rest.len(), PaletteDetail::vertex_count)
    }

    /// The length of every frame's `xi`: N at the detail level, else 0.
    pub fn xi_len(&self) -> usize {
        self.detail.as_ref().map_or(0, |d| d.examples)
    }

    /// The decoded skin (weights `q / 65535`).
    ///
    /// # Errors
    /// [`PaletteHeaderError`] when it does not hold together (call [`PaletteHeader::validate`]
    /// first for the precise field).
    pub fn skin_weights(&self) -> Result<SkinWeights, PaletteHeaderError> {
        let s = &self.skin;
        SkinWeights::new(
            s.influences,
            s.bones.iter().map(|&b| u32::from(b)).collect(),
            s.weights.iter().map(|&q| f32::from(q) / 65535.0).collect(),
        )
        .map_err(|e| PaletteHeaderError::Value {
            what: "skin".into(),
            message: e.to_string(),
        })
    }

    /// Checks that every count, length and index fits (a header read from the wire), so that
    /// a decoder can index with it without further checks.
    ///
    /// # Errors
    /// The first [`PaletteHeaderError`] found, naming the field.
    pub fn validate(&self) -> Result<(), PaletteHeaderError> {
        let nb = self.rest.len();
        if let Some(i) = self.rest.iter().position(|p| !p.is_finite()) {
            return Err(PaletteHeaderError::Value {
                what: format!("rest position {i}"),
                message: "not finite".into(),
            });
        }
        let s = &self.skin;
        if !(1..=8).contains(&s.influences) {
            return Err(PaletteHeaderError::Value {
                what: "influences".into(),
                message: format!("{}, expected 1..=8", s.influences),
            });
        }
        length("skin bones", s.bones.len(), nb * s.influences)?;
        length("skin weights", s.weights.len(), nb * s.influences)?;
        if let Some(i) = s.bones.iter().position(|&b| usize::from(b) >= self.bones) {
            return Err(PaletteHeaderError::Index {
                what: "skin bone".into(),
                index: i,
                value: u64::from(s.bones[i]),
                limit: self.bones,
            });
        }
        for (v, w) in s.weights.chunks_exact(s.influences).enumerate() {
            let sum: u32 = w.iter().map(|&q| u32::from(q)).sum();
            if sum != 65535 {
                return Err(PaletteHeaderError::Value {
                    what: format!("skin weights of vertex {v}"),
                    message: format!("sum to {sum}, expected 65535"),
                });
            }
        }
        triangles_below("triangle", &self.triangles, nb)?;
        if let Some(d) = &self.detail {
            length("subdivision steps", d.steps.len(), d.levels as usize)?;
            let mut columns = nb;
            for (l, step) in d.steps.iter().enumerate() {
                length(format!("subdivision[{l}] columns"), step.columns(), columns)?;
                columns = step.rows();
            }
            if d.steps.is_empty() {
                return Err(PaletteHeaderError::Value {
                    what: "subdivision".into(),
                    message: "no steps at the detail level".into(),
                });
            }
            length("detail rows", d.rows.len(), columns * (d.examples + 1))?;
            if !(d.quantum.is_finite() && d.quantum > 0.0) {
                return Err(PaletteHeaderError::Value {
                    what: "detail quantum".into(),
                    message: format!("{}, expected a finite value > 0", d.quantum),
                });
            }
            triangles_below("drawn triangle", &d.triangles, columns)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn quantised_weights_sum_to_one_and_stay_within_one_unit() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        for k in 1..=8usize {
            for _ in 0..500 {
                let raw: Vec<f64> = (0..k).map(|_| rng.random_range(0.0..1.0)).collect();
                let total: f64 = raw.iter().sum();
                let w: Vec<f32> = raw.iter().map(|x| (x / total) as f32).collect();
                let mut q = vec![0u16; k];
                quantise_weights(&w, &mut q);
                assert_eq!(q.iter().map(|&x| u32::from(x)).sum::<u32>(), 65535, "{w:?}");
                for (&x, &wk) in q.iter().zip(&w) {
                    let err = (f64::from(x) / 65535.0 - f64::from(wk)).abs();
                    // 1 unit, plus the input's own deviation from a sum of exactly 1.
                    assert!(err <= 1.0 / 65535.0 + 1e-6, "{wk} -> {x}: {err}");
                }
            }
        }
        // Exact weights stay exact.
        let mut q = [0u16; 2];
        quantise_weights(&[1.0, 0.0], &mut q);
        assert_eq!(q, [65535, 0]);
    }

    /// A small detail regressor: `rows` vertices, two examples of one input, a Gaussian.
    fn regressor(m: Vec<f32>, b: Vec<f32>) -> DetailRegressor {
        use crate::runtime::displacement::DetailInput;
        use crate::runtime::kernel::Kernel;
        use crate::runtime::predict::LinearOperator;
        DetailRegressor {
            input: DetailInput::Rotations,
            kernel: Kernel::Gaussian { sigma: 1.0 },
            d_in: 1,
            examples: vec![0.0, 1.0],
            operator: LinearOperator {
                rows: b.len(),
                cols: 2,
                m,
                b,
            },
        }
    }

    /// The quantum by its rule, computed here from its parts: the Gaussian's kernel vectors at
    /// the two inputs are `[1, e^-1/2]` and `[e^-1/2, 1]`, so `|xi|_1 = 1 + e^-1/2`; the
    /// farthest rest vertex is at 2.
    #[test]
    fn the_quantum_follows_the_bones_error_and_the_largest_value() {
        let rest = [Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, -2.0, 0.0)];
        let small = regressor(vec![1e-6, -2e-6, 3e-7, 0.0], vec![5e-7, 0.0]);
        let xi_norm = 1.0 + (-0.5f64).exp();
        let bones = 2.0 * f64::from(super::super::ROTATION_ERROR) * 2.0;
        let want = 2.0 * bones / (xi_norm + 1.0);
        let got = f64::from(detail_quantum(&rest, &small));
        assert!((got - want).abs() <= 1e-6 * want, "{got} vs {want}");
        // Values too large for 16 bits at that step raise it to max / 32767.
        let large = regressor(vec![3.0, -7.0, 0.5, 0.0], vec![1.0, 0.0]);
        assert_eq!(detail_quantum(&rest, &large), 7.0 / 32767.0);
        // Nothing at all: 1 (every value is 0 at any step).
        let zero = regressor(vec![0.0; 4], vec![0.0; 2]);
        assert_eq!(detail_quantum(&[Vec3::ZERO], &zero), 1.0);
    }

    /// Every stored value is within half a quantum of the model's, and `h` within the bound,
    /// checked against `h` computed in `f64` from the model's own `D` and `b`.
    #[test]
    fn stored_values_stay_within_half_a_quantum() {
        use crate::mesh::Mesh;
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let mesh = Mesh {
            positions: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(0.1, 0.0, 0.0),
                Vec3::new(0.0, 0.1, 0.0),
                Vec3::new(0.0, 0.0, 0.1),
            ],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        };
        let sub = LoopSubdivision::new(&mesh, 2).unwrap();
        let nv = sub.vertex_count();
        let m: Vec<f32> = (0..nv * 2).map(|_| rng.random_range(-1e-4..1e-4)).collect();
        let b: Vec<f32> = (0..nv).map(|_| rng.random_range(-1e-4..1e-4)).collect();
        let reg = regressor(m.clone(), b.clone());
        let skin = SkinWeights::new(1, vec![0; 4], vec![1.0; 4]).unwrap();
        let header = PaletteHeader::base(&mesh.positions, &mesh.triangles, &skin, 1)
            .unwrap()
            .with_detail(&sub, &reg)
            .unwrap();
        header.validate().unwrap();
        let d = header.detail.as_ref().unwrap();
        assert_eq!(d.quantum, detail_quantum(&mesh.positions, &reg));
        assert_eq!(header.drawn_triangles(), sub.triangles());
        for v in 0..nv {
            let row = &d.rows[v * 3..v * 3 + 3];
            for (j, want) in [m[v * 2], m[v * 2 + 1], b[v]].into_iter().enumerate() {
                let err = (d.value(row[j]) - want).abs();
                assert!(err <= 0.5 * d.quantum * (1.0 + 1e-5), "v {v} j {j}: {err}");
            }
        }
        let xi = [0.7f32, -1.3];
        let mut h = vec![0.0; nv];
        d.displacements(&xi, &mut h);
        let bound = d.displacement_error(&xi);
        for v in 0..nv {
            let exact =
                f64::from(m[v * 2]) * 0.7 + f64::from(m[v * 2 + 1]) * -1.3 + f64::from(b[v]);
            let err = (f64::from(h[v]) - exact).abs();
            assert!(
                err <= f64::from(bound) * 1.001 + 1e-9,
                "v {v}: {err} > {bound}"
            );
        }
        // The rebuild from the base triangles is the same detail part.
        let again =
            PaletteDetail::rebuild(4, &mesh.triangles, 2, 2, d.rows.clone(), d.quantum).unwrap();
        assert_eq!(&again, d);
    }
}
