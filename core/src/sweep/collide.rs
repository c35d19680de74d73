//! Self-intersection fix and collisions of the sweep hand (LYK06 "Handling self-intersections
//! and collisions"). Being written.
