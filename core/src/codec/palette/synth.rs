//! The reference decoder of palette streams: a [`PaletteHeader`] and its frames back to meshes
//! on the CPU, the computation a palette client (the browser viewer on its GPU) performs:
//!
//! ```text
//! base  = sum_k w_k (R_k rest + t_k)                       linear blend skinning, FKY08 eq. 1
//! high  = S_L ( ... S_1 (base))                            the Loop steps in turn
//! h     = D xi + b                                         HZY11 eq. 4, decoded D and b
//! out   = high + h n(high)                                 n: area-weighted unit normals
//! ```
//!
//! The normals are the textbook scatter ([`crate::runtime::detail::scatter_normals`]), the
//! definition the vertex stream's detail layer uses too. Buffers are allocated by
//! [`PaletteSynth::new`]; a frame allocates nothing.

use glam::Vec3;

use super::PaletteFrame;
use super::header::{PaletteDetail, PaletteHeader, PaletteHeaderError};
use crate::runtime::detail::{displace, scatter_normals};
use crate::runtime::skin::{BonePalette, SkinWeights, skin_lbs};

/// Why a palette frame could not be synthesised.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PaletteSynthError {
    /// The frame's bone or `xi` count does not fit the header.
    #[error("palette frame: {what} {got}, the header says {expected}")]
    Count {
        /// `bones` or `xi values`.
        what: &'static str,
        /// In the frame.
        got: usize,
        /// In the header.
        expected: usize,
    },
}

/// The detail layer's decoder state.
#[derive(Debug)]
struct DetailState {
    header: PaletteDetail,
    /// Each step's output (the last is `high`).
    levels: Vec<Vec<Vec3>>,
    h: Vec<f32>,
    normals: Vec<Vec3>,
    out: Vec<Vec3>,
}

/// Decodes a palette stream's frames into meshes (module docs).
#[derive(Debug)]
pub struct PaletteSynth {
    rest: Vec<Vec3>,
    skin: SkinWeights,
    bones: usize,
    /// The base mesh's triangles (the drawn ones at the detail level are its header's).
    triangles: Vec<[u32; 3]>,
    palette: BonePalette,
    base: Vec<Vec3>,
    detail: Option<DetailState>,
}

impl PaletteSynth {
    /// The decoder of `header`'s stream ([validated](PaletteHeader::validate) first).
    ///
    /// # Errors
    /// The header's [`PaletteHeaderError`].
    pub fn new(header: PaletteHeader) -> Result<PaletteSynth, PaletteHeaderError> {
        header.validate()?;
        let skin = header.skin_weights()?;
        let detail = match header.detail {
            Some(d) => {
                let levels = d.steps.iter().map(|m| vec![Vec3::ZERO; m.rows()]).collect();
                let n = d.vertex_count();
                Some(DetailState {
                    header: d,
                    levels,
                    h: vec![0.0; n],
                    normals: vec![Vec3::ZERO; n],
                    out: vec![Vec3::ZERO; n],
                })
            }
            None => None,
        };
        Ok(PaletteSynth {
            triangles: header.triangles,
            base: header.rest.clone(),
            rest: header.rest,
            skin,
            bones: header.bones,
            palette: BonePalette::new(),
            detail,
        })
    }

    /// The drawn mesh of the last frame (the rest mesh before the first).
    pub fn output(&self) -> &[Vec3] {
        match &self.detail {
            Some(d) => &d.out,
            None => &self.base,
        }
    }

    /// The drawn mesh's triangles: the base mesh's, or at the detail level their subdivision.
    pub fn triangles(&self) -> &[[u32; 3]] {
        self.detail
            .as_ref()
            .map_or(&self.triangles, |d| &d.header.triangles)
    }

    /// The header's rest mesh (what every frame's bones skin).
    pub fn rest(&self) -> &[Vec3] {
        &self.rest
    }

    /// The base mesh's triangles (at the detail level too, where [`PaletteSynth::triangles`]
    /// are the subdivision's).
    pub fn base_triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The skinned base mesh of the last frame.
    pub fn base(&self) -> &[Vec3] {
        &self.base
    }

    /// The decoded skin.
    pub fn skin(&self) -> &SkinWeights {
        &self.skin
    }

    /// The subdivided, undisplaced mesh `high` of the last frame (detail level; empty
    /// otherwise).
    pub fn high(&self) -> &[Vec3] {
        self.detail
            .as_ref()
            .and_then(|d| d.levels.last())
            .map_or(&[], Vec::as_slice)
    }

    /// The displacements `h` of the last frame (detail level; empty otherwise).
    pub fn displacements(&self) -> &[f32] {
        self.detail.as_ref().map_or(&[], |d| &d.h)
    }

    /// The decoded detail regressor (detail level).
    pub fn detail(&self) -> Option<&PaletteDetail> {
        self.detail.as_ref().map(|d| &d.header)
    }

    /// The drawn mesh of `frame`: the skinned base mesh, or at the detail level the detailed
    /// mesh (module docs).
    ///
    /// # Errors
    /// [`PaletteSynthError::Count`] when the frame's counts do not fit the header.
    pub fn synthesize(&mut self, frame: &PaletteFrame) -> Result<&[Vec3], PaletteSynthError> {
        let xi_len = self.detail.as_ref().map_or(0, |d| d.header.examples);
        if frame.bones.len() != self.bones {
            return Err(PaletteSynthError::Count {
                what: "bones",
                got: frame.bones.len(),
                expected: self.bones,
            });
        }
        if frame.xi.len() != xi_len {
            return Err(PaletteSynthError::Count {
                what: "xi values",
                got: frame.xi.len(),
                expected: xi_len,
            });
        }
        self.palette.update(&frame.bones);
        skin_lbs(&self.rest, &self.skin, &self.palette, &mut self.base)
            .expect("sizes and bone indices checked by validate");
        let Some(d) = &mut self.detail else {
            return Ok(&self.base);
        };
        for (k, step) in d.header.steps.iter().enumerate() {
            let (done, rest) = d.levels.split_at_mut(k);
            let input = done.last().map_or(self.base.as_slice(), Vec::as_slice);
            step.apply(input, &mut rest[0])
                .expect("step sizes checked by validate");
        }
        let high = d.levels.last().expect("at least one step");
        d.header.displacements(&frame.xi, &mut d.h);
        scatter_normals(high, &d.header.triangles, &mut d.normals).expect("one normal per vertex");
        d.out.copy_from_slice(high);
        displace(&mut d.out, &d.normals, &d.h).expect("one h per vertex");
        Ok(&d.out)
    }
}
