//! The per-frame pass, [`HandCollider::apply`]: fold the joints, pose the primitives along the
//! sweeps, detect the contacts (digit-digit, digit-palm, object), then hand over to the
//! push-out; with its options ([`CollideOptions`]) and counts ([`CollideStats`]).

use glam::Vec3;

use super::primitives::{bound_of, overlaps, patch_height, plane_normal};
use super::{Ball, HandCollider, PALM_CURL_MIN, PALM_DEPTH, PALM_PATCH_RADIUS};
use crate::skeleton::{Digit, HandPose, PosedSkeleton};
use crate::sweeps::Sweep;

/// What [`HandCollider::apply`] does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CollideOptions {
    /// Project folded vertices onto the joint planes.
    pub fix_folds: bool,
    /// Detect (and with `resolve`, resolve) contacts between digits.
    pub digits: bool,
    /// Detect (and resolve) contacts between digits and palm.
    pub palm: bool,
    /// An external ball to detect (and resolve) contacts with.
    pub object: Option<Ball>,
    /// Push penetrating skin vertices out (otherwise contacts are only reported).
    pub resolve: bool,
    /// Fraction of a contact's depth by which each hand primitive gives way (module docs,
    /// "Symmetry"), in `[0, 1]`.
    pub share: f32,
}

impl Default for CollideOptions {
    fn default() -> Self {
        CollideOptions {
            fix_folds: true,
            digits: true,
            palm: true,
            object: None,
            resolve: true,
            share: 0.5,
        }
    }
}

/// The primitives of a [`Contact`] (indices into [`HandCollider::spheres`] and
/// [`HandCollider::palm_planes`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ContactKind {
    /// Spheres of two different digits (`a`'s digit before `b`'s in [`Digit::ALL`]).
    DigitDigit {
        /// First sphere.
        a: usize,
        /// Second sphere.
        b: usize,
    },
    /// A digit sphere and a palm plane.
    DigitPalm {
        /// The sphere.
        sphere: usize,
        /// The plane.
        plane: usize,
    },
    /// The ball and a digit sphere.
    ObjectDigit {
        /// The sphere.
        sphere: usize,
    },
    /// The ball and a palm plane.
    ObjectPalm {
        /// The plane.
        plane: usize,
    },
}

/// One contact between two primitives (LYK06's red points).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact {
    /// Which primitives.
    pub kind: ContactKind,
    /// Contact point: digit-digit, the middle of the overlap on the line of centres;
    /// digit-palm, the sphere centre projected onto the plane; object, the deepest point of
    /// the ball inside the hand primitive (on the ball's surface).
    pub point: Vec3,
    /// Overlap depth (metres, > 0).
    pub depth: f32,
    /// Unit normal: digit-digit from sphere `a` towards `b`; digit-palm the palm's outward
    /// normal; object from the ball towards the hand (the way the hand is pushed).
    pub normal: Vec3,
}

/// Counts of one [`HandCollider::apply`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CollideStats {
    /// Projections onto joint planes (a vertex between two joints can count twice).
    pub folded: usize,
    /// Contacts reported.
    pub contacts: usize,
    /// Vertices moved by the push-out.
    pub pushed: usize,
}

impl HandCollider {
    /// [`HandCollider::apply`] for joint angles: poses the skeleton (into a buffer of the
    /// collider) first. `positions` must be the sweep deformation of the same pose.
    pub fn apply_pose(
        &mut self,
        pose: &HandPose,
        positions: &mut [Vec3],
        options: &CollideOptions,
        contacts: &mut Vec<Contact>,
    ) -> CollideStats {
        let mut posed = self.posed;
        self.skeleton.pose_into(pose, &mut posed);
        self.posed = posed;
        self.apply(&posed, positions, options, contacts)
    }

    /// One frame: poses the primitives along the sweeps of `posed`, projects folded vertices
    /// onto the joint planes, detects contacts (written to `contacts`, cleared first) and, with
    /// [`CollideOptions::resolve`], pushes penetrating vertices out. `positions` is the skin
    /// deformed by [`SweepHand::deform_into`] for the same pose; it is modified in place.
    /// Allocates nothing once `contacts` has grown to the frame's count.
    ///
    /// # Panics
    /// If `positions.len()` differs from [`HandCollider::vertex_count`].
    ///
    /// [`SweepHand::deform_into`]: crate::sweeps::SweepHand::deform_into
    pub fn apply(
        &mut self,
        posed: &PosedSkeleton,
        positions: &mut [Vec3],
        options: &CollideOptions,
        contacts: &mut Vec<Contact>,
    ) -> CollideStats {
        assert_eq!(positions.len(), self.classes.len(), "positions length");
        contacts.clear();
        let sweeps = Digit::ALL.map(|d| Sweep::of_digit(posed, d));
        let mut stats = CollideStats::default();

        // LYK06 "Folding at joints": project folded vertices onto the joint planes.
        for p in &mut self.fold_planes {
            let f = sweeps[p.digit.index()].frame_at_arc(p.arc);
            p.point = f.position;
            p.normal = f.rotation * Vec3::Y;
        }
        if options.fix_folds {
            for e in &self.fold_entries {
                let p = &self.fold_planes[e.plane as usize];
                let v = &mut positions[e.vertex as usize];
                let h = p.normal.dot(*v - p.point);
                if h * e.side < 0.0 {
                    *v -= h * p.normal;
                    stats.folded += 1;
                }
            }
        }

        // Posed primitives.
        for s in &mut self.spheres {
            s.center = sweeps[s.digit.index()].frame_at_arc(s.arc).position;
        }
        for (p, ring) in self.palm_planes.iter_mut().zip(&self.plane_neighbours) {
            p.point = positions[p.vertex as usize];
            p.normal = plane_normal(positions, ring);
        }
        self.sphere_depth.fill(0.0);
        self.plane_depth.fill(0.0);
        let bounds = Digit::ALL.map(|d| {
            let (a, b) = self.sphere_range[d.index()];
            bound_of(self.spheres[a..b].iter().map(|s| (s.center, s.radius)))
        });
        let palm_bound = bound_of(
            self.palm_planes
                .iter()
                .map(|p| (p.point, PALM_PATCH_RADIUS + PALM_DEPTH)),
        );
        // LYK06: joint angles first. A finger curled less than PALM_CURL_MIN cannot reach
        // the palm; the thumb reaches it by opposition at any curl, so only its bound culls it.
        let palm_active = Digit::ALL.map(|d| {
            let chain = posed.chain(d);
            let metacarpal = chain[1].axis();
            let distal = chain[d.chain_len() - 2].axis();
            d == Digit::Thumb || metacarpal.dot(distal) <= PALM_CURL_MIN.cos()
        });

        // Digit-digit: sphere pairs of different digits whose digit bounds overlap.
        if options.digits {
            for da in 0..5 {
                for db in da + 1..5 {
                    if !overlaps(bounds[da], bounds[db]) {
                        continue;
                    }
                    let (a0, a1) = self.sphere_range[da];
                    let (b0, b1) = self.sphere_range[db];
                    for i in a0..a1 {
                        let (ca, ra) = (self.spheres[i].center, self.spheres[i].radius);
                        for j in b0..b1 {
                            let (cb, rb) = (self.spheres[j].center, self.spheres[j].radius);
                            let dist = (cb - ca).length();
                            let depth = ra + rb - dist;
                            if depth <= 0.0 {
                                continue;
                            }
                            let normal = if dist > 0.0 {
                                (cb - ca) / dist
                            } else {
                                Vec3::X
                            };
                            contacts.push(Contact {
                                kind: ContactKind::DigitDigit { a: i, b: j },
                                point: ca + normal * (ra - 0.5 * depth),
                                depth,
                                normal,
                            });
                            self.sphere_depth[i] = self.sphere_depth[i].max(depth);
                            self.sphere_depth[j] = self.sphere_depth[j].max(depth);
                        }
                    }
                }
            }
        }

        // Digit-palm: palm-reaching spheres against the palm patches.
        if options.palm {
            for d in Digit::ALL {
                if !palm_active[d.index()] || !overlaps(bounds[d.index()], palm_bound) {
                    continue;
                }
                let (a, b) = self.sphere_range[d.index()];
                for i in a..b {
                    let s = self.spheres[i];
                    if !s.palm_reach {
                        continue;
                    }
                    for (k, p) in self.palm_planes.iter().enumerate() {
                        let Some(h) = patch_height(p.point, p.normal, s.center) else {
                            continue;
                        };
                        let depth = s.radius - h;
                        if depth <= 0.0 || h < -PALM_DEPTH {
                            continue;
                        }
                        contacts.push(Contact {
                            kind: ContactKind::DigitPalm {
                                sphere: i,
                                plane: k,
                            },
                            point: s.center - h * p.normal,
                            depth,
                            normal: p.normal,
                        });
                        self.sphere_depth[i] = self.sphere_depth[i].max(depth);
                        self.plane_depth[k] = self.plane_depth[k].max(depth);
                    }
                }
            }
        }

        // LYK06 "Collision detection with other objects": the ball against every primitive.
        if let Some(ball) = options.object {
            for (i, s) in self.spheres.iter().enumerate() {
                let dist = (s.center - ball.center).length();
                let depth = ball.radius + s.radius - dist;
                if depth > 0.0 {
                    let normal = if dist > 0.0 {
                        (s.center - ball.center) / dist
                    } else {
                        Vec3::Z
                    };
                    contacts.push(Contact {
                        kind: ContactKind::ObjectDigit { sphere: i },
                        point: ball.center + normal * ball.radius,
                        depth,
                        normal,
                    });
                }
            }
            for (k, p) in self.palm_planes.iter().enumerate() {
                let Some(h) = patch_height(p.point, p.normal, ball.center) else {
                    continue;
                };
                let depth = ball.radius - h;
                if depth > 0.0 && h > -PALM_DEPTH - ball.radius {
                    contacts.push(Contact {
                        kind: ContactKind::ObjectPalm { plane: k },
                        point: ball.center - ball.radius * p.normal,
                        depth,
                        normal: -p.normal,
                    });
                }
            }
        }
        stats.contacts = contacts.len();

        if options.resolve && (options.digits || options.palm || options.object.is_some()) {
            stats.pushed = self.push_out(positions, options, palm_active, &bounds, palm_bound);
        }
        stats
    }
}
