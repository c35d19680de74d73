//! The palette stream's header (issue 18): everything a client needs once to turn palette
//! frames into meshes. The base mesh is linear blend skinning of the rest mesh (FKY08 eq. 1),
//! so the header carries the rest positions and the skin; the detail layer is
//! `S · base + h n` with `h = D xi + b` (HZY11 eq. 4), so at the detail level it also carries
//! the Loop subdivision steps whose product is `S` and the detail regressor's `D` and `b`.
//!
//! # Quantisation and its error
//!
//! - Skin weights are 16-bit, `w = q / 65535`, rounded by largest remainder so that each
//!   vertex's `q` sum to exactly 65535: every weight is within `1/65535` of the model's
//!   ([`quantise_weights`]), and the decoded weights still sum to one, so a weight error moves
//!   a skinned vertex `v` by at most `sum_k |dw_k| |T_k p - v|` (the errors sum to zero).
//! - `D` and `b` are 16-bit with a scale per detailed vertex: row `v` (`D_v0 .. D_v(N-1)`,
//!   `b_v`) is stored as `q / s_v` with `s_v = max |row| / 32767`, so each value is within
//!   `s_v / 2` of the model's and `h_v` within `s_v / 2 (|xi|_1 + 1)`
//!   ([`PaletteDetail::displacement_error`]).
//! - The rest positions and the subdivision weights are exact `f32`s: they are the model's.
//!
//! The wire form (protobuf `PaletteTopology`) is `crease-proto`'s; [`PaletteHeader::validate`]
//! checks one read from the wire before anything indexes with it.

use glam::Vec3;

use crate::mesh::subdivision::{LoopSubdivision, SparseMatrix};
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

/// One Loop subdivision step, its weights as indices into a table of the distinct values.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PaletteStep {
    /// The previous level's vertex count.
    pub columns: usize,
    /// `rows + 1` offsets into `cols` and `weight_index`.
    pub row_ptr: Vec<u32>,
    /// One old vertex per entry.
    pub cols: Vec<u32>,
    /// One index into `weights` per entry.
    pub weight_index: Vec<u16>,
    /// The distinct weights.
    pub weights: Vec<f32>,
}

impl PaletteStep {
    /// Rows: the new level's vertex count.
    pub fn rows(&self) -> usize {
        self.row_ptr.len().saturating_sub(1)
    }

    /// The step of a subdivision matrix (its weights tabulated). `None` with more than 65,536
    /// distinct weights (Loop's rules give a few per vertex valence).
    pub fn from_matrix(m: &SparseMatrix) -> Option<PaletteStep> {
        let mut table: Vec<f32> = m.vals().to_vec();
        table.sort_by(f32::total_cmp);
        table.dedup_by(|a, b| a.to_bits() == b.to_bits());
        if table.len() > 1 << 16 {
            return None;
        }
        let weight_index = m
            .vals()
            .iter()
            .map(|v| {
                let i = table
                    .binary_search_by(|t| t.total_cmp(v))
                    .expect("every value is in the table");
                i as u16
            })
            .collect();
        Some(PaletteStep {
            columns: m.columns(),
            row_ptr: m.row_ptr().to_vec(),
            cols: m.cols().to_vec(),
            weight_index,
            weights: table,
        })
    }

    /// The step as a sparse matrix (after [`PaletteHeader::validate`]).
    ///
    /// # Errors
    /// The matrix's own checks (see [`SparseMatrix::from_csr`]).
    pub fn to_matrix(&self) -> Result<SparseMatrix, PaletteHeaderError> {
        let vals = self
            .weight_index
            .iter()
            .map(|&i| {
                self.weights
                    .get(usize::from(i))
                    .copied()
                    .unwrap_or(f32::NAN)
            })
            .collect();
        SparseMatrix::from_csr(self.columns, self.row_ptr.clone(), self.cols.clone(), vals).map_err(
            |e| PaletteHeaderError::Value {
                what: "subdivision step".into(),
                message: e.to_string(),
            },
        )
    }
}

/// The detail layer's part of the header: the subdivision steps and `D`, `b` quantised.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PaletteDetail {
    /// The Loop steps, first level first.
    pub steps: Vec<PaletteStep>,
    /// N: the length of every frame's `xi`.
    pub examples: usize,
    /// Per detailed vertex, `N + 1` values: its row of `D`, then `b`.
    pub rows: Vec<i16>,
    /// Per detailed vertex, the scale of its row.
    pub scales: Vec<f32>,
}

impl PaletteDetail {
    /// Detailed vertices.
    pub fn vertex_count(&self) -> usize {
        self.scales.len()
    }

    /// The decoded value of entry `q` of vertex `v`'s row: `q * s_v`.
    #[inline]
    pub fn value(&self, v: usize, q: i16) -> f32 {
        f32::from(q) * self.scales[v]
    }

    /// `h = D xi + b` with the decoded `D` and `b`, into `out` (one per detailed vertex).
    ///
    /// # Panics
    /// If `xi` is not N values or `out` not one per detailed vertex.
    pub fn displacements(&self, xi: &[f32], out: &mut [f32]) {
        let n = self.examples;
        assert_eq!(xi.len(), n, "xi length != examples");
        assert_eq!(out.len(), self.vertex_count(), "h length != vertices");
        for (v, (o, row)) in out
            .iter_mut()
            .zip(self.rows.chunks_exact(n + 1))
            .enumerate()
        {
            let s = self.scales[v];
            let dot: f32 = row[..n]
                .iter()
                .zip(xi)
                .map(|(&q, &x)| f32::from(q) * s * x)
                .sum();
            *o = dot + f32::from(row[n]) * s;
        }
    }

    /// A bound on `|h_v - h'_v|` between the model's regressor and the decoded one for kernel
    /// vector `xi` (module docs), before `f32` rounding.
    pub fn displacement_error(&self, v: usize, xi: &[f32]) -> f32 {
        0.5 * self.scales[v] * (xi.iter().map(|x| x.abs()).sum::<f32>() + 1.0)
    }
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
    /// The triangles of the drawn mesh (base, or detailed with [`PaletteHeader::detail`]).
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
    /// `D` and `b` quantised (module docs).
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
        let mut rows = Vec::with_capacity(nv * (n + 1));
        let mut scales = Vec::with_capacity(nv);
        for v in 0..nv {
            let d = &op.m[v * n..(v + 1) * n];
            let b = op.b[v];
            let max = d.iter().chain([&b]).fold(0.0f32, |m, x| m.max(x.abs()));
            let s = if max.is_finite() && max > 0.0 {
                max / DETAIL_Q_MAX
            } else {
                0.0
            };
            let q = |x: f32| {
                if s > 0.0 {
                    (x / s).round().clamp(-DETAIL_Q_MAX, DETAIL_Q_MAX) as i16
                } else {
                    0
                }
            };
            rows.extend(d.iter().map(|&x| q(x)));
            rows.push(q(b));
            scales.push(s);
        }
        let steps = subdivision
            .steps()
            .iter()
            .map(|m| {
                PaletteStep::from_matrix(m).ok_or_else(|| PaletteHeaderError::Value {
                    what: "subdivision step".into(),
                    message: "more than 65536 distinct weights".into(),
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        self.triangles = subdivision.triangles().to_vec();
        self.detail = Some(PaletteDetail {
            steps,
            examples: n,
            rows,
            scales,
        });
        Ok(self)
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
        let mut columns = nb;
        if let Some(d) = &self.detail {
            if d.steps.is_empty() {
                return Err(PaletteHeaderError::Value {
                    what: "subdivision".into(),
                    message: "no steps at the detail level".into(),
                });
            }
            for (l, step) in d.steps.iter().enumerate() {
                length(format!("subdivision[{l}] columns"), step.columns, columns)?;
                step.to_matrix().map_err(|e| PaletteHeaderError::Value {
                    what: format!("subdivision[{l}]"),
                    message: e.to_string(),
                })?;
                if let Some(e) = step
                    .weight_index
                    .iter()
                    .position(|&i| usize::from(i) >= step.weights.len())
                {
                    return Err(PaletteHeaderError::Index {
                        what: format!("subdivision[{l}] weight_index"),
                        index: e,
                        value: u64::from(step.weight_index[e]),
                        limit: step.weights.len(),
                    });
                }
                columns = step.rows();
            }
            length("detail scales", d.scales.len(), columns)?;
            length("detail rows", d.rows.len(), columns * (d.examples + 1))?;
            if let Some(v) = d.scales.iter().position(|s| !s.is_finite()) {
                return Err(PaletteHeaderError::Value {
                    what: format!("detail scale {v}"),
                    message: "not finite".into(),
                });
            }
        }
        if let Some((t, &tri)) = self
            .triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&i| i as usize >= columns))
        {
            return Err(PaletteHeaderError::Index {
                what: "triangle".into(),
                index: t,
                value: u64::from(*tri.iter().max().expect("three corners")),
                limit: columns,
            });
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

    #[test]
    fn a_step_tabulates_its_weights_and_rebuilds_the_same_matrix() {
        let m = SparseMatrix::from_csr(
            3,
            vec![0, 2, 3, 6],
            vec![0, 2, 1, 0, 1, 2],
            vec![0.375, 0.625, 1.0, 0.375, 0.25, 0.375],
        )
        .unwrap();
        let step = PaletteStep::from_matrix(&m).unwrap();
        assert_eq!(step.weights, vec![0.25, 0.375, 0.625, 1.0]);
        assert_eq!(step.weight_index, vec![1, 2, 3, 1, 0, 1]);
        assert_eq!(step.to_matrix().unwrap(), m);
    }
}
