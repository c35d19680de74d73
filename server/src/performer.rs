//! A performer's actors placed where the capture put them (issue 38): one registration for
//! the performer, not one per hand.
//!
//! A retargeting actor registers its own markers onto its own model every frame
//! (`crease_mocap::register`: the similarity `T_a(t)` that puts the back of the hand onto the
//! model's rest back of the hand): that is what the regression needs, since it reads control
//! points in the model's frame (HZY11 §7, "expressed in the local frame of the hand"), and
//! what takes the wrist's motion out. So each hand's mesh comes out at its model's place, and
//! a performer's two hands would sit on top of each other (the demo's right hand and its
//! mirror overlap) wherever the capture had them.
//!
//! The performer's registration `T_P` puts the capture into one frame for all of its actors:
//! the registration of the performer's first retargeting actor (its *anchor*, in the room's
//! order), taken at the first frame after that actor's scale is fixed and kept from then on.
//! Each actor's mesh is then placed by
//!
//! ```text
//! P_a(t) = T_P o T_a(t)^-1        (model frame -> capture -> the performer's frame)
//! ```
//!
//! which puts every hand where the capture put it relative to the others and to where the
//! anchor was when `T_P` was fixed (the anchor starts at its model's place, at its model's
//! size). `P_a` goes to viewers in each actor's frame (`ActorFrame.placement`); the meshes and
//! palettes stay in their models' frames (the codec's quantisation box, the palette's skin),
//! so nothing else changes. *Why not register the performer's hands together every frame:*
//! the regression's inputs would then depend on where the hand is, which no example covers.
//! Actors of no performer (`""`), and actors that take control points, are not placed.

use crease_mocap::register::Similarity;
use crease_proto::ActorPlace;

/// The performers of one room: per actor its anchor, the fixed registrations, this frame's
/// placements (module docs). Lives in the room's work state (one frame at a time).
#[derive(Debug, Default)]
pub struct Performers {
    /// Per actor: its performer's anchor (an actor index), or `None` (not placed).
    anchors: Vec<Option<usize>>,
    /// Per anchor (by actor index): its performer's registration `T_P` once fixed.
    fixed: Vec<Option<Similarity>>,
    /// Per actor: its placement this frame.
    places: Vec<Option<ActorPlace>>,
}

impl Performers {
    /// The performers of actors `(performer, retargets)`, in the room's order.
    pub(crate) fn new<'a>(actors: impl IntoIterator<Item = (&'a str, bool)>) -> Performers {
        let actors: Vec<(&str, bool)> = actors.into_iter().collect();
        let anchors = actors
            .iter()
            .map(|&(performer, retargets)| {
                (retargets && !performer.is_empty())
                    .then(|| actors.iter().position(|&(p, r)| r && p == performer))
                    .flatten()
            })
            .collect();
        let n = actors.len();
        Performers {
            anchors,
            fixed: vec![None; n],
            places: vec![None; n],
        }
    }

    /// Whether any actor is placed (some performer has a retargeting actor).
    pub(crate) fn any(&self) -> bool {
        self.anchors.iter().any(Option::is_some)
    }

    /// Places every actor for this frame from `registration(k)`: actor `k`'s current
    /// capture-to-model registration and whether its scale is fixed.
    pub(crate) fn place(&mut self, registration: impl Fn(usize) -> Option<(Similarity, bool)>) {
        for k in 0..self.anchors.len() {
            self.places[k] = None;
            let Some(anchor) = self.anchors[k] else {
                continue;
            };
            // The anchor comes first among its performer's actors: fixed before they read it.
            if self.fixed[anchor].is_none()
                && let Some((t, true)) = registration(anchor)
            {
                self.fixed[anchor] = Some(t);
            }
            let (Some(performer), Some((own, _))) = (self.fixed[anchor], registration(k)) else {
                continue;
            };
            let p = compose(&performer, &own.inverse());
            self.places[k] = Some(ActorPlace {
                scale: p.scale,
                rotation: p.rotation,
                translation: p.translation,
            });
        }
    }

    /// Actor `k`'s placement this frame.
    pub(crate) fn get(&self, k: usize) -> Option<ActorPlace> {
        self.places.get(k).copied().flatten()
    }
}

/// `a o b`: `x -> a(b(x))`.
fn compose(a: &Similarity, b: &Similarity) -> Similarity {
    Similarity {
        scale: a.scale * b.scale,
        rotation: (a.rotation * b.rotation).normalize(),
        translation: a.scale * (a.rotation * b.translation) + a.translation,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crease_core::glam::{Quat, Vec3};

    fn similarity(scale: f32, axis: Vec3, angle: f32, t: Vec3) -> Similarity {
        Similarity {
            scale,
            rotation: Quat::from_axis_angle(axis.normalize(), angle),
            translation: t,
        }
    }

    #[test]
    fn composing_maps_as_applying_one_then_the_other() {
        let a = similarity(
            0.002,
            Vec3::new(1.0, 2.0, -0.5),
            0.9,
            Vec3::new(0.1, -3.0, 2.0),
        );
        let b = similarity(
            1.7,
            Vec3::new(-0.3, 0.2, 1.0),
            -2.1,
            Vec3::new(4.0, 0.5, -1.0),
        );
        for p in [Vec3::ZERO, Vec3::X, Vec3::new(-2.0, 7.0, 0.3)] {
            let want = a.apply(b.apply(p));
            let got = compose(&a, &b).apply(p);
            assert!(
                (got - want).length() < 1e-5 * want.length().max(1.0),
                "{got} vs {want}"
            );
        }
        let back = compose(&b, &b.inverse());
        assert!(
            (back.apply(Vec3::new(3.0, -1.0, 2.0)) - Vec3::new(3.0, -1.0, 2.0)).length() < 1e-5
        );
    }

    #[test]
    fn a_performers_hands_are_placed_where_the_capture_put_them() {
        // Actors: right and left of performer "ana" (retargeting), a control-point actor of
        // hers, and a retargeting actor of no performer.
        let mut performers =
            Performers::new([("ana", true), ("ana", true), ("ana", false), ("", true)]);
        assert!(performers.any());
        // The capture (millimetres): each hand's registration puts its markers onto its model.
        let right = similarity(0.001, Vec3::Y, 0.4, Vec3::new(-0.2, 0.0, -0.9));
        let left = similarity(
            0.001,
            Vec3::new(0.3, 1.0, 0.0),
            -1.1,
            Vec3::new(0.5, 0.1, -1.2),
        );
        let regs = |fixed: bool| {
            move |k: usize| match k {
                0 => Some((right, fixed)),
                1 => Some((left, fixed)),
                3 => Some((left, fixed)),
                _ => None,
            }
        };
        // Before the anchor's scale is fixed: nobody is placed.
        performers.place(regs(false));
        assert!((0..4).all(|k| performers.get(k).is_none()));
        performers.place(regs(true));
        // The anchor sits at its model's place; the left hand's model point x lands where its
        // capture point (left^-1 x) goes through the performer's registration (right).
        let anchor = performers.get(0).unwrap();
        let x = Vec3::new(0.03, 0.08, -0.01);
        assert!((anchor.apply(x) - x).length() < 1e-6);
        let placed = performers.get(1).unwrap();
        let want = right.apply(left.inverse().apply(x));
        assert!(
            (placed.apply(x) - want).length() < 1e-6,
            "{} vs {want}",
            placed.apply(x)
        );
        assert!(performers.get(2).is_none() && performers.get(3).is_none());
        // The performer's registration stays as fixed: the anchor moving in the capture moves
        // its mesh, by the inverse of its new registration.
        let moved = similarity(0.001, Vec3::Y, 0.6, Vec3::new(-0.3, 0.1, -0.9));
        performers.place(|k| (k == 0).then_some((moved, true)));
        let p = performers.get(0).unwrap();
        assert!((p.apply(x) - right.apply(moved.inverse().apply(x))).length() < 1e-6);
        assert!(performers.get(1).is_none(), "no registration, no placement");
    }
}
