//! Edge skin: how the translation solver ([`super::translations`], FKY08 §5) predicts each mesh
//! edge from the bone rotations of a frame.
//!
//! ```text
//! e_k^s = sum_b R_b a_kb                                  (vector edge skin)
//! e_k^s = sum_b w^_kb R_b e_k^0     i.e. a_kb = w^_kb e_k^0 (FKY08 eq. 10, scalar weights)
//! ```
//!
//! FKY08 skin an edge like a vertex: a convex blend of the bones' rotations applied to the rest
//! edge `e_k^0`. That form can only rotate (and, through the blend, shrink) an edge; it cannot
//! stretch or shear it, and on the horse even the best rotation field per vertex leaves about
//! 20% of the edge vectors unexplained (BENCHMARKS.md, "eq. 11 floor"). The vector form keeps
//! the same bones but gives each (edge, bone) pair its own rest-frame vector `a_kb`, fitted by
//! least squares over the examples (`crease_train::edges`): still linear in the rotations, so
//! the solver's right-hand side is precomputed exactly as before and a frame costs the same,
//! but the edge can now stretch with the pose the way the examples do. Scalar eq. 10 weights
//! are the special case [`EdgeSkin::from_weights`].
//!
//! Storage: `k` slots per edge, edge-major, a bone index and a 3-vector per slot; unused slots
//! have a zero vector (their bone index is irrelevant but must be in range).

use glam::{Quat, Vec3};

use super::skin::{MAX_INFLUENCES, SkinError, SkinWeights};

/// Why an [`EdgeSkin`] could not be built.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum EdgeSkinError {
    /// `k` outside `1..=MAX_INFLUENCES`.
    #[error("edge influences k = {k}, must be in 1..={MAX_INFLUENCES}")]
    BadK {
        /// The rejected stride.
        k: usize,
    },
    /// `indices` and `vectors` differ in length or are not a multiple of `k` long.
    #[error(
        "edge skin arrays: {indices} indices and {vectors} vectors, expected equal lengths that \
         are a multiple of k = {k}"
    )]
    BadLength {
        /// Stride.
        k: usize,
        /// Length of the index array.
        indices: usize,
        /// Length of the vector array.
        vectors: usize,
    },
    /// A vector has a NaN or infinite coordinate.
    #[error("edge {edge}: slot {slot} vector {value} is not finite")]
    NonFinite {
        /// Edge index.
        edge: usize,
        /// Slot within the edge, `0..k`.
        slot: usize,
        /// The offending vector.
        value: Vec3,
    },
    /// A bone index is not below the bone count.
    #[error("edge {edge}: slot {slot} names bone {bone}, but there are {bone_count} bones")]
    BoneOutOfRange {
        /// Edge index.
        edge: usize,
        /// Slot within the edge.
        slot: usize,
        /// The bone index found.
        bone: u32,
        /// Number of bones.
        bone_count: usize,
    },
    /// An edge names a vertex that does not exist.
    #[error("edge {edge}: vertex {vertex} out of range, there are {vertex_count}")]
    VertexOutOfRange {
        /// Edge index.
        edge: usize,
        /// The offending vertex.
        vertex: u32,
        /// Number of vertices.
        vertex_count: usize,
    },
    /// The scalar weights have a different number of rows than there are edges.
    #[error("{rows} edge weight rows for {edges} edges")]
    RowCount {
        /// Rows of the weight table.
        rows: usize,
        /// Number of edges.
        edges: usize,
    },
    /// The scalar weights given to [`EdgeSkin::from_weights`] are invalid.
    #[error(transparent)]
    Weights(#[from] SkinError),
}

/// Per edge, `k` bones and their rest-frame edge vectors `a_kb` (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct EdgeSkin {
    k: usize,
    indices: Vec<u32>,
    vectors: Vec<Vec3>,
}

impl EdgeSkin {
    /// Validating constructor: `k` in `1..=8`, equal lengths that are a multiple of `k`, finite
    /// vectors.
    pub fn new(k: usize, indices: Vec<u32>, vectors: Vec<Vec3>) -> Result<Self, EdgeSkinError> {
        if !(1..=MAX_INFLUENCES).contains(&k) {
            return Err(EdgeSkinError::BadK { k });
        }
        if indices.len() != vectors.len() || !indices.len().is_multiple_of(k) {
            return Err(EdgeSkinError::BadLength {
                k,
                indices: indices.len(),
                vectors: vectors.len(),
            });
        }
        if let Some(i) = vectors.iter().position(|v| !v.is_finite()) {
            return Err(EdgeSkinError::NonFinite {
                edge: i / k,
                slot: i % k,
                value: vectors[i],
            });
        }
        Ok(Self {
            k,
            indices,
            vectors,
        })
    }

    /// FKY08 eq. 10's scalar edge weights as vectors: `a_kb = w^_kb (v_k0^0 - v_k1^0)`.
    pub fn from_weights(
        rest: &[Vec3],
        edges: &[[u32; 2]],
        weights: &SkinWeights,
    ) -> Result<Self, EdgeSkinError> {
        if weights.vertex_count() != edges.len() {
            return Err(EdgeSkinError::RowCount {
                rows: weights.vertex_count(),
                edges: edges.len(),
            });
        }
        let k = weights.k();
        let mut vectors = Vec::with_capacity(edges.len() * k);
        for (edge, (&[a, b], (_, w))) in edges.iter().zip(weights.iter()).enumerate() {
            for v in [a, b] {
                if v as usize >= rest.len() {
                    return Err(EdgeSkinError::VertexOutOfRange {
                        edge,
                        vertex: v,
                        vertex_count: rest.len(),
                    });
                }
            }
            let e0 = rest[a as usize] - rest[b as usize];
            vectors.extend(w.iter().map(|&x| e0 * x));
        }
        Self::new(k, weights.indices().to_vec(), vectors)
    }

    /// Slots per edge.
    pub fn k(&self) -> usize {
        self.k
    }

    /// Number of edges.
    pub fn edge_count(&self) -> usize {
        self.indices.len() / self.k
    }

    /// The bones and vectors of edge `e` (each `k` long). Panics if `e` is out of range.
    pub fn edge(&self, e: usize) -> (&[u32], &[Vec3]) {
        let r = e * self.k..(e + 1) * self.k;
        (&self.indices[r.clone()], &self.vectors[r])
    }

    /// All bone indices, edge-major.
    pub fn indices(&self) -> &[u32] {
        &self.indices
    }

    /// All vectors, edge-major.
    pub fn vectors(&self) -> &[Vec3] {
        &self.vectors
    }

    /// The skinned edge `e_k^s = sum_b R_b a_kb` for per-bone `rotations`. Panics if `e` or a
    /// bone index is out of range.
    pub fn predict(&self, e: usize, rotations: &[Quat]) -> Vec3 {
        let (idx, vec) = self.edge(e);
        idx.iter()
            .zip(vec)
            .filter(|(_, a)| **a != Vec3::ZERO)
            .map(|(&b, &a)| rotations[b as usize] * a)
            .sum()
    }

    /// Checks that every slot names a bone below `bone_count`.
    pub fn validate_bones(&self, bone_count: usize) -> Result<(), EdgeSkinError> {
        match self.indices.iter().position(|&b| b as usize >= bone_count) {
            None => Ok(()),
            Some(i) => Err(EdgeSkinError::BoneOutOfRange {
                edge: i / self.k,
                slot: i % self.k,
                bone: self.indices[i],
                bone_count,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_weights_reproduces_eq10_blend() {
        let rest = [
            Vec3::ZERO,
            Vec3::new(1.0, 2.0, 0.5),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        let edges = [[0u32, 1], [1, 2]];
        let w = SkinWeights::new(2, vec![0, 1, 1, 0], vec![0.75, 0.25, 1.0, 0.0]).unwrap();
        let s = EdgeSkin::from_weights(&rest, &edges, &w).unwrap();
        let rot = [
            Quat::from_rotation_z(0.3),
            Quat::from_rotation_x(-1.1) * Quat::from_rotation_y(0.4),
        ];
        for (e, &[a, b]) in edges.iter().enumerate() {
            let e0 = rest[a as usize] - rest[b as usize];
            let (idx, ws) = w.vertex(e);
            let want: Vec3 = idx
                .iter()
                .zip(ws)
                .map(|(&bone, &x)| (rot[bone as usize] * e0) * x)
                .sum();
            assert!((s.predict(e, &rot) - want).length() < 1e-6, "edge {e}");
        }
    }

    #[test]
    fn rejects_bad_input() {
        assert_eq!(
            EdgeSkin::new(0, vec![], vec![]),
            Err(EdgeSkinError::BadK { k: 0 })
        );
        assert!(matches!(
            EdgeSkin::new(2, vec![0, 1, 2], vec![Vec3::ZERO; 3]),
            Err(EdgeSkinError::BadLength { .. })
        ));
        assert!(matches!(
            EdgeSkin::new(1, vec![0, 0], vec![Vec3::X, Vec3::NAN]),
            Err(EdgeSkinError::NonFinite {
                edge: 1,
                slot: 0,
                ..
            })
        ));
        let s = EdgeSkin::new(2, vec![0, 3], vec![Vec3::X, Vec3::Y]).unwrap();
        assert!(matches!(
            s.validate_bones(3),
            Err(EdgeSkinError::BoneOutOfRange {
                edge: 0,
                slot: 1,
                bone: 3,
                ..
            })
        ));
        assert!(s.validate_bones(4).is_ok());
    }
}
