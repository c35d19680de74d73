//! The push-out (module docs, "Resolution"): skin vertices pushed out of the primitives of
//! other parts of the hand and of the ball, bucket by bucket behind a bounding-sphere cull.

use glam::Vec3;

use super::primitives::{overlaps, penetration, shape_near};
use super::{
    Bucket, CULL_MARGIN, CollideOptions, HandCollider, MAX_PUSHES, Obstacle, Owner, PUSH_SLACK,
    Shape,
};

impl HandCollider {
    /// The push-out pass (module docs, "Resolution"); returns the number of vertices moved.
    pub(super) fn push_out(
        &mut self,
        positions: &mut [Vec3],
        options: &CollideOptions,
        palm_active: [bool; 5],
        digit_bounds: &[(Vec3, f32); 5],
        palm_bound: (Vec3, f32),
    ) -> usize {
        let share = options.share.clamp(0.0, 1.0);
        self.obstacles.clear();
        for (s, depth) in self.spheres.iter().zip(&self.sphere_depth) {
            let d = s.digit.index();
            self.obstacles.push(Obstacle {
                shape: Shape::Sphere(s.center, (s.radius - share * depth).max(0.0)),
                owner: Owner::Digit {
                    digit: d as u8,
                    sphere: 0,
                },
                palm_reach: s.palm_reach && palm_active[d],
            });
        }
        if options.palm {
            for (p, depth) in self.palm_planes.iter().zip(&self.plane_depth) {
                self.obstacles.push(Obstacle {
                    shape: Shape::Plane(p.point, p.normal, share * depth),
                    owner: Owner::Palm,
                    palm_reach: false,
                });
            }
        }
        if let Some(ball) = options.object {
            self.obstacles.push(Obstacle {
                shape: Shape::Sphere(ball.center, ball.radius),
                owner: Owner::Object,
                palm_reach: false,
            });
        }
        // Bucket bounds: anchor and farthest member.
        for (b, bound) in self.buckets.iter().zip(&mut self.bucket_bound) {
            let anchor = match b.owner {
                Owner::Digit { sphere, .. } => self.spheres[sphere as usize].center,
                _ => positions[b.anchor_vertex as usize],
            };
            let r2 = self.members[b.start as usize..b.end as usize]
                .iter()
                .map(|&i| (positions[i as usize] - anchor).length_squared())
                .fold(0.0f32, f32::max);
            *bound = (anchor, r2.sqrt());
        }
        let mut pushed = 0;
        // Obstacles: the spheres, then (with `options.palm`) the planes, then the ball.
        let planes_in = if options.palm {
            self.palm_planes.len()
        } else {
            0
        };
        let palm_planes = self.spheres.len()..self.spheres.len() + planes_in;
        for (b, &(anchor, radius)) in self.buckets.iter().zip(&self.bucket_bound) {
            // Cull with a margin, so that the usual pushes (a few millimetres) stay inside it.
            let bound = (anchor, radius + CULL_MARGIN);
            self.candidates.clear();
            // Spheres digit by digit, behind the digit's bound.
            for (d, &(a, e)) in self.sphere_range.iter().enumerate() {
                let wanted = match b.owner {
                    Owner::Digit { digit, .. } => options.digits && digit as usize != d,
                    _ => options.palm && palm_active[d],
                };
                if !wanted || !overlaps(digit_bounds[d], bound) {
                    continue;
                }
                for k in a..e {
                    let o = &self.obstacles[k];
                    if relevant(b, o, options, palm_active) && shape_near(o.shape, bound) {
                        self.candidates.push(k as u32);
                    }
                }
            }
            let planes = options.palm && overlaps(palm_bound, bound);
            let rest = if planes {
                palm_planes.start..self.obstacles.len()
            } else {
                palm_planes.end..self.obstacles.len()
            };
            for k in rest {
                let o = &self.obstacles[k];
                if relevant(b, o, options, palm_active) && shape_near(o.shape, bound) {
                    self.candidates.push(k as u32);
                }
            }
            if self.candidates.is_empty() {
                continue;
            }
            self.round.clear();
            self.flat.clear();
            for &k in &self.candidates {
                match self.obstacles[k as usize].shape {
                    Shape::Sphere(c, r) => self.round.push((c, r * r)),
                    plane => self.flat.push(plane),
                }
            }
            for &i in &self.members[b.start as usize..b.end as usize] {
                let v = &mut positions[i as usize];
                // Fast rejection: most vertices of a bucket touch none of its candidates.
                if self
                    .round
                    .iter()
                    .all(|&(c, r2)| (*v - c).length_squared() >= r2)
                    && self.flat.iter().all(|&p| penetration(p, *v).is_none())
                {
                    continue;
                }
                let obstacles = &self.obstacles;
                let mut moved =
                    push_vertex(v, self.candidates.iter().map(|&k| obstacles[k as usize]));
                if moved && (*v - anchor).length_squared() > bound.1 * bound.1 {
                    // Pushed beyond the cull's bound: the primitives culled for the bucket
                    // may now hold it.
                    moved |= push_vertex(
                        v,
                        obstacles
                            .iter()
                            .copied()
                            .filter(|o| relevant(b, o, options, palm_active)),
                    );
                }
                pushed += usize::from(moved);
            }
        }
        pushed
    }
}

/// Whether the vertices of bucket `b` are pushed out of obstacle `o` (module docs,
/// "Resolution").
fn relevant(b: &Bucket, o: &Obstacle, options: &CollideOptions, palm_active: [bool; 5]) -> bool {
    match (b.owner, o.owner) {
        (_, Owner::Object) => true,
        (Owner::Digit { digit: a, .. }, Owner::Digit { digit: d, .. }) => options.digits && a != d,
        (Owner::Digit { digit, .. }, Owner::Palm) => b.palm_reach && palm_active[digit as usize],
        (Owner::Palm, Owner::Digit { .. }) => options.palm && o.palm_reach,
        _ => false,
    }
}

/// Pushes `v` out of the deepest of `obstacles`, again and again up to [`MAX_PUSHES`] times,
/// then out of the ball if it is still inside; whether it moved.
fn push_vertex(v: &mut Vec3, obstacles: impl Iterator<Item = Obstacle> + Clone) -> bool {
    let mut moved = false;
    for _ in 0..MAX_PUSHES {
        let mut deepest = (0.0f32, Vec3::ZERO);
        for o in obstacles.clone() {
            match penetration(o.shape, *v) {
                Some((pen, dir)) if pen > deepest.0 => deepest = (pen, dir),
                _ => {}
            }
        }
        if deepest.0 <= 0.0 {
            break;
        }
        *v += (deepest.0 + PUSH_SLACK) * deepest.1;
        moved = true;
    }
    // The ball is rigid (module docs): where the hand's own primitives push a vertex back into
    // it (a fist closing on a ball in the palm: the skin between a finger's spheres and the
    // ball bounces for all MAX_PUSHES), the last push is out of the ball. The hand primitive
    // then keeps the overlap, as a finger pressing on a held ball does.
    for o in obstacles.filter(|o| o.owner == Owner::Object) {
        if let Some((pen, dir)) = penetration(o.shape, *v)
            && pen > 0.0
        {
            *v += (pen + PUSH_SLACK) * dir;
            moved = true;
        }
    }
    moved
}
