//! A compact AABB tree over a fixed set of primitives (triangles or edges),
//! built once from their boxes and refitted whenever they move.
//!
//! Why not a crate: obvhs (already a dependency, for ray tracing) builds
//! wide BVHs for rays and has no box-overlap query or cheap refit of a fixed
//! topology; parry3d and bvh pull another glam/nalgebra. What the cloth
//! needs is a box query on a tree whose topology never changes (the body and
//! cloth meshes keep their triangles), refitted in O(n) each frame: about
//! 150 lines.
//!
//! Layout: nodes in depth-first order, a node's left child directly follows
//! it, so a reverse sweep over the nodes refits children before parents.
//! Leaves hold up to [`LEAF_SIZE`] primitives. Queries visit primitives in
//! a fixed order (tree order), so results are deterministic.

use glam::Vec3;

/// Axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb { min: Vec3::splat(f32::MAX), max: Vec3::splat(f32::MIN) };

    pub fn from_points(points: &[Vec3]) -> Aabb {
        points.iter().fold(Aabb::EMPTY, |b, &p| b.grow(p))
    }
    pub fn around(p: Vec3, r: f32) -> Aabb {
        Aabb { min: p - Vec3::splat(r), max: p + Vec3::splat(r) }
    }
    #[inline]
    pub fn grow(self, p: Vec3) -> Aabb {
        Aabb { min: self.min.min(p), max: self.max.max(p) }
    }
    #[inline]
    pub fn union(self, o: Aabb) -> Aabb {
        Aabb { min: self.min.min(o.min), max: self.max.max(o.max) }
    }
    /// Distance from `p` to the nearest face of the box (negative outside it): every point
    /// within this distance of `p` lies in the box.
    #[inline]
    pub fn margin(&self, p: Vec3) -> f32 {
        (p - self.min).min(self.max - p).min_element()
    }
    /// Squared distance from `p` to the box (0 inside): no point in the box is nearer.
    #[inline]
    pub fn distance_squared(&self, p: Vec3) -> f32 {
        let outside = (self.min - p).max(p - self.max).max(Vec3::ZERO);
        outside.length_squared()
    }
    #[inline]
    pub fn inflate(self, r: f32) -> Aabb {
        Aabb { min: self.min - Vec3::splat(r), max: self.max + Vec3::splat(r) }
    }
    #[inline]
    pub fn overlaps(&self, o: &Aabb) -> bool {
        self.min.cmple(o.max).all() && o.min.cmple(self.max).all()
    }
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }
    /// Half the diagonal: the radius of a sphere around [`Aabb::center`] holding the box.
    pub fn half_diagonal(&self) -> f32 {
        0.5 * self.min.distance(self.max)
    }
}

pub const LEAF_SIZE: usize = 4;

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: first primitive slot in `prims`; inner: index of the right child.
    index: u32,
    /// Leaf: number of primitives; inner: 0.
    count: u32,
}

/// Bounding-volume hierarchy with a fixed topology.
#[derive(Clone, Debug, Default)]
pub struct AabbTree {
    nodes: Vec<Node>,
    prims: Vec<u32>,
}

impl AabbTree {
    /// Builds a tree over `boxes` by median splits along the longest axis
    /// of the centroids (ties by primitive id, so the tree is deterministic).
    pub fn build(boxes: &[Aabb]) -> AabbTree {
        let mut tree = AabbTree { nodes: Vec::with_capacity(2 * boxes.len() / LEAF_SIZE + 1), prims: Vec::new() };
        if boxes.is_empty() {
            return tree;
        }
        let mut ids: Vec<u32> = (0..boxes.len() as u32).collect();
        let centers: Vec<Vec3> = boxes.iter().map(Aabb::center).collect();
        tree.split_at(&mut ids, &centers, 0);
        tree.prims = ids;
        tree.refit(boxes);
        tree
    }

    /// Appends the subtree over `ids`, which start at slot `first` of the final `prims`.
    fn split_at(&mut self, ids: &mut [u32], centers: &[Vec3], first: usize) {
        let me = self.nodes.len();
        self.nodes.push(Node { bounds: Aabb::EMPTY, index: first as u32, count: ids.len() as u32 });
        if ids.len() <= LEAF_SIZE {
            return;
        }
        let b = ids.iter().fold(Aabb::EMPTY, |b, &i| b.grow(centers[i as usize]));
        let axis = (b.max - b.min).max_position();
        let mid = ids.len() / 2;
        ids.select_nth_unstable_by(mid, |&a, &c| {
            centers[a as usize][axis].total_cmp(&centers[c as usize][axis]).then(a.cmp(&c))
        });
        let (left, right) = ids.split_at_mut(mid);
        self.split_at(left, centers, first);
        let r = self.nodes.len() as u32;
        self.split_at(right, centers, first + mid);
        self.nodes[me].index = r;
        self.nodes[me].count = 0;
    }

    /// Recomputes every node's box from the primitives' new `boxes` (same
    /// primitives as at build time).
    pub fn refit(&mut self, boxes: &[Aabb]) {
        for k in (0..self.nodes.len()).rev() {
            let n = self.nodes[k];
            self.nodes[k].bounds = if n.count > 0 {
                let s = n.index as usize;
                self.prims[s..s + n.count as usize].iter().fold(Aabb::EMPTY, |b, &p| b.union(boxes[p as usize]))
            } else {
                self.nodes[k + 1].bounds.union(self.nodes[n.index as usize].bounds)
            };
        }
    }

    /// Bounds of everything.
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, |n| n.bounds)
    }

    /// Calls `f` with every primitive whose leaf box overlaps `query` (leaf
    /// granularity: test the primitive's own box or geometry in `f`).
    #[inline]
    pub fn query(&self, query: &Aabb, mut f: impl FnMut(u32)) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let k = stack[top];
            let n = &self.nodes[k as usize];
            if !n.bounds.overlaps(query) {
                continue;
            }
            if n.count > 0 {
                let s = n.index as usize;
                for &p in &self.prims[s..s + n.count as usize] {
                    f(p);
                }
            } else {
                // Left first: push right, then left.
                stack[top] = n.index;
                stack[top + 1] = k + 1;
                top += 2;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn query_finds_exactly_the_overlapping_boxes() {
        let boxes: Vec<Aabb> = (0..1000)
            .map(|i| {
                let f = i as f32;
                let c = Vec3::new((f * 0.37).sin(), (f * 0.91).cos(), (f * 0.13).sin()) * 2.0;
                Aabb::around(c, 0.01 + 0.05 * (f * 0.7).sin().abs())
            })
            .collect();
        let mut tree = AabbTree::build(&boxes);
        for round in 0..2 {
            let moved: Vec<Aabb> = boxes
                .iter()
                .map(|b| Aabb { min: b.min + Vec3::X * round as f32, max: b.max + Vec3::X * round as f32 })
                .collect();
            tree.refit(&moved);
            for q in 0..50 {
                let f = q as f32;
                let query = Aabb::around(Vec3::new(f.sin() * 2.0 + round as f32, f.cos(), 0.3 * f.sin()), 0.3);
                let mut got = Vec::new();
                tree.query(&query, |p| {
                    if moved[p as usize].overlaps(&query) {
                        got.push(p)
                    }
                });
                got.sort_unstable();
                let want: Vec<u32> = (0..moved.len() as u32).filter(|&p| moved[p as usize].overlaps(&query)).collect();
                assert_eq!(got, want);
            }
        }
    }
}
