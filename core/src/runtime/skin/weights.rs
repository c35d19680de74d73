//! [`SkinWeights`]: per-vertex bone influences with a fixed stride, validated once at
//! construction (shape, finite non-negative weights summing to 1, heaviest first) so that the
//! skinning calls check sizes once per call and never per vertex.

use super::{MAX_INFLUENCES, SkinError, WEIGHT_SUM_TOLERANCE};

/// Per-vertex bone influences with a fixed stride `k` (1..=8): vertex `v` owns entries
/// `v*k .. (v+1)*k` of `indices` and `weights`, heaviest first. Unused slots have weight 0.
///
/// Invariants, checked by [`SkinWeights::new`] and kept because the fields are private: `k` in
/// `1..=8`, equal array lengths that are a multiple of `k`, weights finite, `>= 0`, summing to 1
/// per vertex within [`WEIGHT_SUM_TOLERANCE`], each vertex's slots in non-increasing weight
/// order.
#[derive(Clone, Debug, PartialEq)]
pub struct SkinWeights {
    k: usize,
    indices: Vec<u32>,
    weights: Vec<f32>,
    /// Largest bone index in `indices` (cached so skinning calls check it in O(1)).
    max_bone: Option<u32>,
}

impl SkinWeights {
    /// Validating constructor; the error names the first offending vertex (and slot, as given).
    ///
    /// Each vertex's slots are then reordered by weight, heaviest first (stable on ties), so
    /// zero-weight padding ends up last and slot 0 is the dual-quaternion pivot.
    pub fn new(k: usize, mut indices: Vec<u32>, mut weights: Vec<f32>) -> Result<Self, SkinError> {
        if !(1..=MAX_INFLUENCES).contains(&k) {
            return Err(SkinError::BadK { k });
        }
        if indices.len() != weights.len() || !indices.len().is_multiple_of(k) {
            return Err(SkinError::BadLength {
                k,
                indices: indices.len(),
                weights: weights.len(),
            });
        }
        for (vertex, ws) in weights.chunks_exact(k).enumerate() {
            let mut sum = 0.0f32;
            for (slot, &value) in ws.iter().enumerate() {
                if !value.is_finite() {
                    return Err(SkinError::NonFiniteWeight {
                        vertex,
                        slot,
                        value,
                    });
                }
                if value < 0.0 {
                    return Err(SkinError::NegativeWeight {
                        vertex,
                        slot,
                        value,
                    });
                }
                sum += value;
            }
            if (sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE {
                return Err(SkinError::WeightSum { vertex, sum });
            }
        }
        for (ii, ww) in indices.chunks_exact_mut(k).zip(weights.chunks_exact_mut(k)) {
            // Insertion sort: k <= 8, and usually already in order.
            for j in 1..k {
                let mut i = j;
                while i > 0 && ww[i] > ww[i - 1] {
                    ww.swap(i, i - 1);
                    ii.swap(i, i - 1);
                    i -= 1;
                }
            }
        }
        let max_bone = indices.iter().copied().max();
        Ok(Self {
            k,
            indices,
            weights,
            max_bone,
        })
    }

    /// Influences per vertex.
    pub fn k(&self) -> usize {
        self.k
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.indices.len() / self.k
    }

    /// The bone indices and weights of vertex `v` (each `k` long). Panics if `v` is out of range.
    pub fn vertex(&self, v: usize) -> (&[u32], &[f32]) {
        let r = v * self.k..(v + 1) * self.k;
        (&self.indices[r.clone()], &self.weights[r])
    }

    /// All bone indices, vertex-major.
    pub fn indices(&self) -> &[u32] {
        &self.indices
    }

    /// All weights, vertex-major.
    pub fn weights(&self) -> &[f32] {
        &self.weights
    }

    /// Iterates over vertices as `(indices, weights)` pairs.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = (&[u32], &[f32])> + '_ {
        self.indices
            .chunks_exact(self.k)
            .zip(self.weights.chunks_exact(self.k))
    }

    /// Largest bone index referenced by any slot (including zero-weight slots); `None` when
    /// there are no vertices.
    pub fn max_bone_index(&self) -> Option<u32> {
        self.max_bone
    }

    /// Checks that every slot (zero-weight ones too: a GPU shader reads them) names a bone below
    /// `bone_count`; the error names the first offending vertex and slot (as stored, heaviest
    /// first).
    pub fn validate_bones(&self, bone_count: usize) -> Result<(), SkinError> {
        if self.max_bone.is_none_or(|m| (m as usize) < bone_count) {
            return Ok(());
        }
        for (i, &bone) in self.indices.iter().enumerate() {
            if bone as usize >= bone_count {
                return Err(SkinError::BoneOutOfRange {
                    vertex: i / self.k,
                    slot: i % self.k,
                    bone,
                    bone_count,
                });
            }
        }
        Ok(())
    }

    /// Checks that `rest` and `out` match the vertex count and the bones fit in the palette.
    pub(super) fn check_call(
        &self,
        rest: usize,
        out: usize,
        bones: usize,
    ) -> Result<(), SkinError> {
        let expected = self.vertex_count();
        if rest != expected {
            return Err(SkinError::VertexCount {
                what: "rest positions",
                expected,
                got: rest,
            });
        }
        if out != expected {
            return Err(SkinError::VertexCount {
                what: "output",
                expected,
                got: out,
            });
        }
        self.validate_bones(bones)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn new_rejects_bad_shapes() {
        assert_eq!(
            SkinWeights::new(0, vec![], vec![]),
            Err(SkinError::BadK { k: 0 })
        );
        assert_eq!(
            SkinWeights::new(9, vec![], vec![]),
            Err(SkinError::BadK { k: 9 })
        );
        assert!(matches!(
            SkinWeights::new(2, vec![0, 1, 2], vec![0.5, 0.5, 1.0]),
            Err(SkinError::BadLength { .. })
        ));
        assert!(matches!(
            SkinWeights::new(2, vec![0, 1], vec![0.5, 0.25, 0.25, 0.0]),
            Err(SkinError::BadLength { .. })
        ));
    }

    #[test]
    fn zero_weight_slots_and_empty_are_fine() {
        let s = SkinWeights::new(4, vec![3, 0, 0, 0], vec![1.0, 0.0, 0.0, 0.0]).unwrap();
        assert_eq!(s.vertex_count(), 1);
        assert_eq!(s.max_bone_index(), Some(3));
        assert!(s.validate_bones(4).is_ok());
        let e = SkinWeights::new(4, vec![], vec![]).unwrap();
        assert_eq!(e.vertex_count(), 0);
        assert_eq!(e.max_bone_index(), None);
        assert!(e.validate_bones(0).is_ok());
    }
}
