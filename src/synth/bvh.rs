//! A bounding volume hierarchy over primitives: median splits on the longest centroid axis, leaves of up
//! to four primitives, front-to-back traversal.

use glam::Vec3;

use super::shape::{Hit, Prim};

#[derive(Clone, Copy, Debug)]
struct Node {
    min: Vec3,
    max: Vec3,
    /// Inner node: index of the left child; leaf: index of the first primitive.
    first: u32,
    /// Leaf: number of primitives; inner: 0.
    count: u32,
    /// Inner node: index of the right child.
    right: u32,
    axis: u8,
}

/// The hierarchy; primitives are reordered into leaf order.
pub struct Bvh {
    nodes: Vec<Node>,
    pub prims: Vec<Prim>,
}

const LEAF_SIZE: usize = 4;

impl Bvh {
    pub fn build(mut prims: Vec<Prim>) -> Bvh {
        let mut nodes = Vec::with_capacity(2 * prims.len() / LEAF_SIZE + 1);
        let bounds: Vec<(Vec3, Vec3)> = prims.iter().map(|p| p.bounds()).collect();
        let mut order: Vec<usize> = (0..prims.len()).collect();
        if !prims.is_empty() {
            build_node(&mut nodes, &bounds, &mut order, 0, prims.len());
        }
        let reordered: Vec<Prim> = order.iter().map(|&i| prims[i]).collect();
        prims.clear();
        Bvh { nodes, prims: reordered }
    }

    /// The nearest hit before `t_max`: (hit, primitive index).
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<(Hit, usize)> {
        if self.nodes.is_empty() {
            return None;
        }
        let inv = dir.recip();
        let neg = [dir.x < 0.0, dir.y < 0.0, dir.z < 0.0];
        let mut best: Option<(Hit, usize)> = None;
        let mut limit = t_max;
        let mut stack = [0u32; 64];
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            let node = &self.nodes[stack[sp] as usize];
            if !slab(node.min, node.max, origin, inv, limit) {
                continue;
            }
            if node.count > 0 {
                let first = node.first as usize;
                for i in first..first + node.count as usize {
                    if let Some(h) = self.prims[i].intersect(origin, dir, limit) {
                        limit = h.t;
                        best = Some((h, i));
                    }
                }
            } else {
                // Visit the near child first: push it last.
                let (near, far) =
                    if neg[node.axis as usize] { (node.right, node.first) } else { (node.first, node.right) };
                if sp + 2 <= stack.len() {
                    stack[sp] = far;
                    stack[sp + 1] = near;
                    sp += 2;
                }
            }
        }
        best
    }

    /// Whether anything blocks the segment (origin, origin + dir·t_max).
    pub fn occluded(&self, origin: Vec3, dir: Vec3, t_max: f32, ignore_instance: Option<u32>) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let inv = dir.recip();
        let mut stack = [0u32; 64];
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            let node = &self.nodes[stack[sp] as usize];
            if !slab(node.min, node.max, origin, inv, t_max) {
                continue;
            }
            if node.count > 0 {
                let first = node.first as usize;
                for p in &self.prims[first..first + node.count as usize] {
                    if Some(p.instance) == ignore_instance {
                        continue;
                    }
                    if p.intersect(origin, dir, t_max).is_some() {
                        return true;
                    }
                }
            } else if sp + 2 <= stack.len() {
                stack[sp] = node.first;
                stack[sp + 1] = node.right;
                sp += 2;
            }
        }
        false
    }
}

#[inline]
fn slab(min: Vec3, max: Vec3, origin: Vec3, inv: Vec3, t_max: f32) -> bool {
    let t0 = (min - origin) * inv;
    let t1 = (max - origin) * inv;
    let t_enter = t0.min(t1).max_element().max(0.0);
    let t_exit = t0.max(t1).min_element().min(t_max);
    t_enter <= t_exit
}

fn build_node(nodes: &mut Vec<Node>, bounds: &[(Vec3, Vec3)], order: &mut [usize], start: usize, end: usize) -> u32 {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    let (mut clo, mut chi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for &i in &order[start..end] {
        lo = lo.min(bounds[i].0);
        hi = hi.max(bounds[i].1);
        let c = 0.5 * (bounds[i].0 + bounds[i].1);
        clo = clo.min(c);
        chi = chi.max(c);
    }
    let index = nodes.len() as u32;
    nodes.push(Node { min: lo, max: hi, first: start as u32, count: (end - start) as u32, right: 0, axis: 0 });
    if end - start <= LEAF_SIZE {
        return index;
    }
    let extent = chi - clo;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let mid = (start + end) / 2;
    let key = |i: usize| 0.5 * (bounds[i].0[axis] + bounds[i].1[axis]);
    // A total order (centroid, then index) keeps the build deterministic.
    order[start..end].select_nth_unstable_by(mid - start, |&a, &b| key(a).total_cmp(&key(b)).then(a.cmp(&b)));
    let left = build_node(nodes, bounds, order, start, mid);
    let right = build_node(nodes, bounds, order, mid, end);
    nodes[index as usize] = Node { min: lo, max: hi, first: left, count: 0, right, axis: axis as u8 };
    index
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::rng::Rng;
    use crate::synth::shape::Shape;
    use glam::Mat3;

    #[test]
    fn bvh_agrees_with_brute_force() {
        let mut rng = Rng::new(3);
        let prims: Vec<Prim> = (0..300)
            .map(|i| {
                let shape = match i % 3 {
                    0 => Shape::Box,
                    1 => Shape::Ellipsoid,
                    _ => Shape::Frustum { bottom: 1.0, top: 0.5 },
                };
                let c = Vec3::new(rng.range(-5.0, 5.0), rng.range(-5.0, 5.0), rng.range(-5.0, 5.0));
                let half = Vec3::new(rng.range(0.05, 0.5), rng.range(0.05, 0.5), rng.range(0.05, 0.5));
                Prim::new(shape, c, Mat3::from_rotation_z(rng.range(0.0, 3.0)), half, 0, i, 0)
            })
            .collect();
        let bvh = Bvh::build(prims.clone());
        for _ in 0..2000 {
            let o = Vec3::new(rng.range(-6.0, 6.0), rng.range(-6.0, 6.0), rng.range(-6.0, 6.0));
            let d = Vec3::new(rng.normal(), rng.normal(), rng.normal());
            let brute = prims
                .iter()
                .filter_map(|p| p.intersect(o, d, 1e9).map(|h| (h.t, p.instance)))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            let fast = bvh.intersect(o, d, 1e9).map(|(h, i)| (h.t, bvh.prims[i].instance));
            match (brute, fast) {
                (None, None) => {}
                (Some(a), Some(b)) => assert!((a.0 - b.0).abs() < 1e-5 && a.1 == b.1, "{a:?} vs {b:?}"),
                other => panic!("mismatch {other:?}"),
            }
            assert_eq!(bvh.occluded(o, d, 1e9, None), brute.is_some());
        }
    }
}
