//! Deterministic randomness for the generator.
//!
//! Two kinds: a sequential generator ([`Rng`], SplitMix64) for the decisions of one frame, seeded from
//! (seed, frame index, stream) so frames do not depend on each other or on thread order; and stateless
//! hashes ([`hash_u64`], [`value_noise3`], ...) for anything evaluated per pixel in parallel, which must be a
//! pure function of its inputs. Both are written here (rather than taken from a crate) so the bytes of a
//! generated dataset can never change with a dependency's version.

use glam::Vec3;

/// The SplitMix64 finaliser: a bijective 64-bit mix with full avalanche.
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Hashes a sequence of words into one (order matters).
pub fn hash_u64(words: &[u64]) -> u64 {
    words.iter().fold(0x9e37_79b9_7f4a_7c15u64, |h, &w| mix64(h ^ mix64(w.wrapping_add(0x632b_e59b_d9b4_e019))))
}

/// Uniform in [0, 1) from the top 24 bits of a hash.
pub fn unit_from_hash(h: u64) -> f32 {
    (h >> 40) as f32 * (1.0 / 16_777_216.0)
}

/// A standard normal sample from one 64-bit hash (Box–Muller on its two 32-bit halves).
pub fn normal_from_hash(h: u64) -> f32 {
    let u1 = ((h >> 32) as u32 as f32 + 0.5) * (1.0 / 4_294_967_296.0);
    let u2 = (h as u32 as f32) * (1.0 / 4_294_967_296.0);
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

/// A sequential SplitMix64 generator.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
}

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self { state: mix64(seed ^ 0x5851_f42d_4c95_7f2d) }
    }

    /// A generator for one named stream of one frame: a pure function of the words.
    pub fn derive(words: &[u64]) -> Self {
        Self::new(hash_u64(words))
    }

    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        mix64(self.state)
    }

    /// An independent child generator (for a sub-task whose number of draws may vary).
    pub fn fork(&mut self) -> Rng {
        Rng::new(self.next_u64())
    }

    /// Uniform in [0, 1).
    pub fn f32(&mut self) -> f32 {
        unit_from_hash(self.next_u64())
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }

    /// Uniform integer in [lo, hi] (inclusive).
    pub fn int(&mut self, lo: usize, hi: usize) -> usize {
        if hi <= lo {
            return lo;
        }
        lo + (self.next_u64() % (hi - lo + 1) as u64) as usize
    }

    pub fn chance(&mut self, p: f32) -> bool {
        self.f32() < p
    }

    /// A standard normal sample.
    pub fn normal(&mut self) -> f32 {
        normal_from_hash(self.next_u64())
    }

    /// A normal sample with the given mean and spread, clamped into [lo, hi].
    pub fn normal_clamped(&mut self, mean: f32, sigma: f32, lo: f32, hi: f32) -> f32 {
        (mean + sigma * self.normal()).clamp(lo, hi)
    }

    /// +1 or -1 with equal probability.
    pub fn sign(&mut self) -> f32 {
        if self.chance(0.5) {
            1.0
        } else {
            -1.0
        }
    }

    pub fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.int(0, items.len() - 1)]
    }

    /// An index drawn with probability proportional to `weights` (all ≥ 0, not all 0).
    pub fn weighted(&mut self, weights: &[f32]) -> usize {
        let total: f32 = weights.iter().sum();
        let mut x = self.f32() * total;
        for (i, &w) in weights.iter().enumerate() {
            if x < w {
                return i;
            }
            x -= w;
        }
        weights.iter().rposition(|&w| w > 0.0).unwrap_or(0)
    }

    pub fn shuffle<T>(&mut self, items: &mut [T]) {
        for i in (1..items.len()).rev() {
            let j = self.int(0, i);
            items.swap(i, j);
        }
    }
}

/// A 32-bit integer hash of a lattice point (for value noise).
fn lattice_hash(seed: u32, x: i32, y: i32, z: i32) -> u32 {
    let mut h = seed
        ^ (x as u32).wrapping_mul(0x8da6_b343)
        ^ (y as u32).wrapping_mul(0xd816_3841)
        ^ (z as u32).wrapping_mul(0xcb1a_b31f);
    h ^= h >> 16;
    h = h.wrapping_mul(0x7feb_352d);
    h ^= h >> 15;
    h = h.wrapping_mul(0x846c_a68b);
    h ^ (h >> 16)
}

fn lattice_value(seed: u32, x: i32, y: i32, z: i32) -> f32 {
    lattice_hash(seed, x, y, z) as f32 * (2.0 / 4_294_967_296.0) - 1.0
}

fn smooth(t: f32) -> f32 {
    t * t * (3.0 - 2.0 * t)
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// Smooth value noise in [-1, 1] with unit lattice spacing.
pub fn value_noise3(seed: u32, p: Vec3) -> f32 {
    let (fx, fy, fz) = (p.x.floor(), p.y.floor(), p.z.floor());
    let (x, y, z) = (fx as i32, fy as i32, fz as i32);
    let (tx, ty, tz) = (smooth(p.x - fx), smooth(p.y - fy), smooth(p.z - fz));
    let c = |dx: i32, dy: i32, dz: i32| lattice_value(seed, x + dx, y + dy, z + dz);
    let x00 = lerp(c(0, 0, 0), c(1, 0, 0), tx);
    let x10 = lerp(c(0, 1, 0), c(1, 1, 0), tx);
    let x01 = lerp(c(0, 0, 1), c(1, 0, 1), tx);
    let x11 = lerp(c(0, 1, 1), c(1, 1, 1), tx);
    lerp(lerp(x00, x10, ty), lerp(x01, x11, ty), tz)
}

/// Smooth 2D value noise in [-1, 1] with unit lattice spacing.
pub fn value_noise2(seed: u32, x: f32, y: f32) -> f32 {
    let (fx, fy) = (x.floor(), y.floor());
    let (ix, iy) = (fx as i32, fy as i32);
    let (tx, ty) = (smooth(x - fx), smooth(y - fy));
    let c = |dx: i32, dy: i32| lattice_value(seed, ix + dx, iy + dy, 0);
    lerp(lerp(c(0, 0), c(1, 0), tx), lerp(c(0, 1), c(1, 1), tx), ty)
}

/// Two octaves of value noise (fine detail at half amplitude), in about [-1, 1].
pub fn fbm3(seed: u32, p: Vec3) -> f32 {
    (value_noise3(seed, p) + 0.5 * value_noise3(seed ^ 0x68e3_1da4, p * 2.03)) * (1.0 / 1.5)
}

/// A uniform value in [0, 1) attached to an integer cell (per-tile, per-plank tones).
pub fn cell_unit(seed: u32, x: i32, y: i32, z: i32) -> f32 {
    lattice_hash(seed, x, y, z) as f32 * (1.0 / 4_294_967_296.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generators_are_reproducible_and_uniform() {
        let mut a = Rng::derive(&[7, 3, 1]);
        let mut b = Rng::derive(&[7, 3, 1]);
        let xs: Vec<f32> = (0..10_000).map(|_| a.f32()).collect();
        assert!(xs.iter().zip((0..10_000).map(|_| b.f32())).all(|(x, y)| *x == y));
        let mean = xs.iter().sum::<f32>() / xs.len() as f32;
        assert!((mean - 0.5).abs() < 0.01, "mean {mean}");
        let mut c = Rng::derive(&[7, 3, 2]);
        assert_ne!(Rng::derive(&[7, 3, 1]).next_u64(), c.next_u64());
        let normals: Vec<f32> = (0..20_000).map(|i| normal_from_hash(hash_u64(&[i]))).collect();
        let m = normals.iter().sum::<f32>() / normals.len() as f32;
        let v = normals.iter().map(|x| (x - m) * (x - m)).sum::<f32>() / normals.len() as f32;
        assert!(m.abs() < 0.03 && (v - 1.0).abs() < 0.04, "mean {m} var {v}");
    }

    #[test]
    fn value_noise_is_continuous_and_bounded() {
        for i in 0..1000 {
            let p = Vec3::new(i as f32 * 0.137, i as f32 * 0.071, -(i as f32) * 0.05);
            let v = value_noise3(5, p);
            assert!((-1.0..=1.0).contains(&v));
            let dv = (value_noise3(5, p + Vec3::splat(1e-3)) - v).abs();
            assert!(dv < 0.02, "jump {dv} at {p}");
        }
    }
}
