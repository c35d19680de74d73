//! The whole sweep hand as one per-frame deformer: the rest skin bound to the sweeps
//! ([`super::sweeps`]), the palm-control surface ([`super::palm`]), the creases
//! ([`super::creases`], detailed resolution) and the self-intersection fix and collisions
//! ([`super::collide`]), applied in that order (LYK06 §2-§5); the creases come last so the
//! fold fix does not flatten them.

use glam::Vec3;

use super::collide::{CollideOptions, CollideStats, Contact, HandCollider};
use super::creases::{Creases, skin_texture, standard_creases};
use super::palm::PalmSurface;
use super::skeleton::{HandPose, HandSkeleton};
use super::surface::{HandSurface, Resolution, SurfaceError};
use super::sweeps::{SweepHand, SweepSamples};
use crease_core::mesh::Mesh;

/// Seed of the detailed hand's static skin texture.
const TEXTURE_SEED: u32 = 1;

/// Which layers [`HandRig::deform`] applies (all on by default; layers the rig was built
/// without are skipped whatever these say).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Layers {
    /// The palm-control surface (bulge, no crushing).
    pub palm: bool,
    /// The creases.
    pub creases: bool,
    /// The self-intersection fix and collisions ([`CollideOptions`]: folds at the joints,
    /// digit-digit, digit-palm, an optional ball; push-out on), or none.
    pub collide: Option<CollideOptions>,
}

impl Default for Layers {
    fn default() -> Self {
        Layers {
            palm: true,
            creases: true,
            collide: Some(CollideOptions::default()),
        }
    }
}

impl Layers {
    /// Only the sweeps (LYK06 §2), no palm surface, creases or collisions.
    pub const SWEEPS_ONLY: Layers = Layers {
        palm: false,
        creases: false,
        collide: None,
    };
}

/// Per-frame working memory of [`HandRig::deform`] (reuse it: no allocation per frame).
#[derive(Clone, Debug, Default)]
pub struct RigScratch {
    samples: SweepSamples,
    /// The rig's collider with its per-frame buffers (cloned on first use).
    collider: Option<HandCollider>,
    contacts: Vec<Contact>,
    stats: CollideStats,
}

impl RigScratch {
    /// Fresh scratch.
    pub fn new() -> Self {
        RigScratch::default()
    }

    /// The sweep samples of the last deformed pose.
    pub fn samples(&self) -> &SweepSamples {
        &self.samples
    }

    /// The contacts found in the last deformed pose (empty without collisions).
    pub fn contacts(&self) -> &[Contact] {
        &self.contacts
    }

    /// What the collision layer did in the last deformed pose.
    pub fn collide_stats(&self) -> CollideStats {
        self.stats
    }
}

/// The bound sweep hand (module docs).
#[derive(Clone, Debug)]
pub struct HandRig {
    rest: Mesh,
    hand: SweepHand,
    palm: Option<PalmSurface>,
    creases: Option<Creases>,
    collider: Option<HandCollider>,
}

impl HandRig {
    /// The adult right hand at `resolution`, built and bound: the base resolution without
    /// creases, the detailed one with the static skin texture and the creases.
    pub fn build(resolution: Resolution) -> Result<HandRig, SurfaceError> {
        let skeleton = HandSkeleton::adult_right();
        let mut rest = HandSurface::build(resolution)?.mesh;
        let detailed = resolution == Resolution::Detailed;
        if detailed {
            let normals = rest.vertex_normals();
            skin_texture(&mut rest, &normals, TEXTURE_SEED);
        }
        Ok(HandRig::bind(&skeleton, rest, detailed))
    }

    /// Binds a rest mesh (in the flat pose of `skeleton`) to all layers; creases only when
    /// `creases` is set (they need a fine mesh: ~0.5 mm edges).
    pub fn bind(skeleton: &HandSkeleton, rest: Mesh, creases: bool) -> HandRig {
        let normals = rest.vertex_normals();
        let hand = SweepHand::bind(skeleton, &rest);
        let palm = PalmSurface::bind(skeleton, &rest, &normals);
        let creases =
            creases.then(|| Creases::bind(skeleton, &hand, &rest, &normals, standard_creases()));
        let collider = HandCollider::build(&hand, &rest).ok();
        HandRig {
            rest,
            hand,
            palm,
            creases,
            collider,
        }
    }

    /// The rest mesh (flat pose).
    pub fn rest(&self) -> &Mesh {
        &self.rest
    }

    /// The skeleton.
    pub fn skeleton(&self) -> &HandSkeleton {
        self.hand.skeleton()
    }

    /// The sweep binding.
    pub fn sweeps(&self) -> &SweepHand {
        &self.hand
    }

    /// The palm-control surface, if the mesh has a palm.
    pub fn palm(&self) -> Option<&PalmSurface> {
        self.palm.as_ref()
    }

    /// The collider (self-intersection and collision primitives), if it could be built.
    pub fn collider(&self) -> Option<&HandCollider> {
        self.collider.as_ref()
    }

    /// The creases, if bound.
    pub fn creases(&self) -> Option<&Creases> {
        self.creases.as_ref()
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.rest.positions.len()
    }

    /// Deforms the hand to `pose` into `out` with the chosen layers, in the order sweeps,
    /// palm surface, folds and collisions, creases. Allocation-free after the first call with
    /// a given `scratch`.
    ///
    /// # Panics
    /// If `out.len()` differs from [`HandRig::vertex_count`].
    pub fn deform(
        &self,
        pose: &HandPose,
        layers: Layers,
        scratch: &mut RigScratch,
        out: &mut [Vec3],
    ) {
        self.hand.sample(pose, &mut scratch.samples);
        self.hand.skin_into(&scratch.samples, out);
        if let (true, Some(palm)) = (layers.palm, &self.palm) {
            palm.apply(pose, out);
        }
        scratch.contacts.clear();
        scratch.stats = CollideStats::default();
        if let (Some(options), Some(template)) = (&layers.collide, &self.collider) {
            let collider = scratch.collider.get_or_insert_with(|| template.clone());
            scratch.stats =
                collider.apply(scratch.samples.posed(), out, options, &mut scratch.contacts);
        }
        if let (true, Some(creases)) = (layers.creases, &self.creases) {
            creases.apply(pose, &self.hand, &scratch.samples, out);
        }
    }

    /// [`HandRig::deform`] into a new mesh with the rest topology.
    pub fn posed_mesh(&self, pose: &HandPose, layers: Layers) -> Mesh {
        let mut out = vec![Vec3::ZERO; self.vertex_count()];
        self.deform(pose, layers, &mut RigScratch::new(), &mut out);
        Mesh {
            positions: out,
            triangles: self.rest.triangles.clone(),
        }
    }
}
