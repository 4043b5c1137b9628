//! The depth sensor model: what the ideal depth becomes in a Kinect-like camera's raw depth image.
//!
//! For every pixel, in this order (each random draw a pure function of (seed, pixel)):
//! 1. **Range**: nothing closer than `min_range`; beyond `fade_start` the return drops out in patches with
//!    probability rising linearly to 1 at `max_range`.
//! 2. **Projector shadow** (structured light: Kinect v1, Xtion, RealSense): the IR projector sits
//!    `baseline` to the right of the camera, so background just left of a foreground edge receives no
//!    pattern. A pixel is shadowed when a pixel to its right maps to a projector column left of its own
//!    (`u_p = u − fx·b/z`), found with one right-to-left scan per row.
//! 3. **Discontinuities**: pixels next to a depth jump larger than 3% of the depth (≥ 3 cm) drop out with
//!    probability `edge_dropout` (mixed-pixel filtering); time-of-flight keeps some as "flying pixels"
//!    between the two depths.
//! 4. **Dark and glossy surfaces**: low infrared reflectance, and glossiness seen head-on (screens, glass,
//!    chrome), lose the return in spatially coherent blobs (a smooth noise field thresholded by the
//!    probability), and grazing incidence (cos < 0.15) loses it per pixel.
//! 5. **Noise and quantisation**: z + N(0, σ(z)) with the axial noise of Nguyen, Izadi & Lovell (2012),
//!    `σ(z) = a + b·(z − z0)²`; structured light then quantises disparity `fx·b/z` to 1/8 pixel (the step in
//!    depth is `z²/(8·fx·b)`, 2.9 mm at 1 m and 46 mm at 4 m for a Kinect v1); finally millimetres.
//!
//! [`DepthModel::expected_spread`] is the standard deviation of the decoded depth on a flat, head-on,
//! bright wall: `sqrt(σ² + step²/12 + (1 mm)²/12)`.

use super::camera::Sensor;
use super::rng::{hash_u64, normal_from_hash, unit_from_hash, value_noise2};

/// How a sensor measures depth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Technology {
    /// Triangulation against a projected pattern, `baseline` metres from the camera; disparity quantised to
    /// `1/subpixel` of a pixel.
    StructuredLight { baseline: f32, subpixel: f32 },
    /// Time of flight (Kinect v2): millimetre output, flying pixels at edges.
    TimeOfFlight,
}

/// A depth sensor model (see the module doc for what each field does).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthModel {
    pub technology: Technology,
    pub min_range: f32,
    pub fade_start: f32,
    pub max_range: f32,
    /// σ(z) = noise_a + noise_b·(z − noise_z0)², metres.
    pub noise_a: f32,
    pub noise_b: f32,
    pub noise_z0: f32,
    pub edge_dropout: f32,
    /// Probability of an isolated random dropout.
    pub speckle_dropout: f32,
}

impl DepthModel {
    pub fn for_sensor(sensor: Sensor) -> DepthModel {
        match sensor {
            Sensor::Kv1 => DepthModel {
                technology: Technology::StructuredLight { baseline: 0.075, subpixel: 8.0 },
                min_range: 0.5,
                fade_start: 3.8,
                max_range: 5.5,
                noise_a: 0.0012,
                noise_b: 0.0019,
                noise_z0: 0.4,
                edge_dropout: 0.55,
                speckle_dropout: 0.002,
            },
            Sensor::Xtion => DepthModel {
                technology: Technology::StructuredLight { baseline: 0.075, subpixel: 8.0 },
                min_range: 0.5,
                fade_start: 3.5,
                max_range: 5.0,
                noise_a: 0.0015,
                noise_b: 0.0021,
                noise_z0: 0.4,
                edge_dropout: 0.6,
                speckle_dropout: 0.003,
            },
            Sensor::RealSense => DepthModel {
                technology: Technology::StructuredLight { baseline: 0.07, subpixel: 8.0 },
                min_range: 0.4,
                fade_start: 2.8,
                max_range: 4.5,
                noise_a: 0.002,
                noise_b: 0.004,
                noise_z0: 0.3,
                edge_dropout: 0.7,
                speckle_dropout: 0.01,
            },
            Sensor::Kv2 => DepthModel {
                technology: Technology::TimeOfFlight,
                min_range: 0.5,
                fade_start: 4.5,
                max_range: 7.5,
                noise_a: 0.0015,
                noise_b: 0.0003,
                noise_z0: 0.0,
                edge_dropout: 0.4,
                speckle_dropout: 0.001,
            },
        }
    }

    /// Axial noise σ(z) in metres.
    pub fn sigma(&self, z: f32) -> f32 {
        let d = z - self.noise_z0;
        self.noise_a + self.noise_b * d * d
    }

    /// The quantisation step in depth at `z` (metres) for focal length `fx` (pixels).
    pub fn step(&self, z: f32, fx: f32) -> f32 {
        match self.technology {
            Technology::StructuredLight { baseline, subpixel } => z * z / (subpixel * fx * baseline),
            Technology::TimeOfFlight => 0.0,
        }
    }

    /// Standard deviation of the decoded depth on a flat head-on wall at `z`.
    pub fn expected_spread(&self, z: f32, fx: f32) -> f32 {
        let (s, q) = (self.sigma(z), self.step(z, fx));
        (s * s + q * q / 12.0 + 1e-6 / 12.0).sqrt()
    }

    /// Quantises a depth (metres) the way the sensor reports it.
    pub fn quantise(&self, z: f32, fx: f32) -> f32 {
        match self.technology {
            Technology::StructuredLight { baseline, subpixel } => {
                let fb = fx * baseline;
                let disparity = (fb / z * subpixel).round() / subpixel;
                if disparity <= 0.0 {
                    0.0
                } else {
                    fb / disparity
                }
            }
            Technology::TimeOfFlight => z,
        }
    }
}

/// What the sensor sees per pixel (row-major).
pub struct SensorInput<'a> {
    pub width: u32,
    pub height: u32,
    /// Focal length in pixels (the projector shadow and the quantisation scale with it).
    pub fx: f32,
    /// Ideal depth (metres, 0 = nothing).
    pub depth: &'a [f32],
    pub infrared: &'a [f32],
    pub gloss: &'a [f32],
    pub incidence: &'a [f32],
}

/// Draw keys, so the streams of different effects never coincide.
const K_RANGE: u64 = 1;
const K_EDGE: u64 = 2;
const K_FLY: u64 = 3;
const K_NOISE: u64 = 4;
const K_SPECKLE: u64 = 5;
const K_GRAZE: u64 = 6;

fn draw(seed: u64, key: u64, idx: usize) -> u64 {
    hash_u64(&[seed, key, idx as u64])
}

/// Simulates the raw depth image in millimetres (0 = missing).
pub fn simulate(model: &DepthModel, input: &SensorInput, seed: u64) -> Vec<u16> {
    let (w, h) = (input.width as usize, input.height as usize);
    let z = input.depth;
    let n = w * h;
    let mut valid: Vec<bool> = z.iter().map(|&d| d > 0.0).collect();
    let mut value: Vec<f32> = z.to_vec();
    // 1. Range: the far returns fade out in patches (a smooth field mixed with a little per-pixel
    // randomness), as the pattern's contrast does.
    let range_field = (seed >> 16) as u32 ^ 0x5eed_f00d;
    for i in 0..n {
        let d = z[i];
        if !valid[i] {
            continue;
        }
        if d < model.min_range || d >= model.max_range {
            valid[i] = false;
        } else if d > model.fade_start {
            let p = (d - model.fade_start) / (model.max_range - model.fade_start);
            let (col, row) = ((i % w) as f32, (i / w) as f32);
            let patch = 0.5 + 0.5 * value_noise2(range_field, col / 6.0, row / 6.0);
            if 0.75 * patch + 0.25 * unit_from_hash(draw(seed, K_RANGE, i)) < p {
                valid[i] = false;
            }
        }
    }
    // 2. Projector shadow.
    if let Technology::StructuredLight { baseline, .. } = model.technology {
        let fb = input.fx * baseline;
        for row in 0..h {
            let mut min_up = f32::INFINITY;
            for col in (0..w).rev() {
                let i = row * w + col;
                if z[i] <= 0.0 {
                    continue;
                }
                let up = col as f32 - fb / z[i];
                if up > min_up + 0.5 {
                    valid[i] = false;
                }
                min_up = min_up.min(up);
            }
        }
    }
    // 3. Discontinuities.
    let jump = |a: f32, b: f32| b > 0.0 && (a - b).abs() > (0.03 * a.min(b)).max(0.03);
    let tof = matches!(model.technology, Technology::TimeOfFlight);
    for row in 0..h {
        for col in 0..w {
            let i = row * w + col;
            if !valid[i] {
                continue;
            }
            let mut far_neighbour = None;
            for (dr, dc) in [(-1i32, 0i32), (1, 0), (0, -1), (0, 1)] {
                let (r, c) = (row as i32 + dr, col as i32 + dc);
                if r < 0 || c < 0 || r >= h as i32 || c >= w as i32 {
                    continue;
                }
                let j = r as usize * w + c as usize;
                if jump(z[i], z[j]) {
                    far_neighbour = Some(z[j]);
                }
            }
            if let Some(other) = far_neighbour {
                let u = unit_from_hash(draw(seed, K_EDGE, i));
                if u < model.edge_dropout {
                    valid[i] = false;
                } else if tof && u < model.edge_dropout + 0.25 {
                    let f = unit_from_hash(draw(seed, K_FLY, i));
                    value[i] = z[i] + (other - z[i]) * f;
                }
            }
        }
    }
    // 4. Dark, glossy and grazing surfaces; isolated speckle.
    let blob_a = (seed as u32) ^ 0x1234_5678;
    let blob_b = (seed >> 32) as u32 ^ 0x0bad_cafe;
    for row in 0..h {
        for col in 0..w {
            let i = row * w + col;
            if !valid[i] {
                continue;
            }
            let d = z[i];
            let dark = ((0.35 - input.infrared[i]) / 0.3).clamp(0.0, 1.0) * (0.5 + 0.25 * d).min(1.0);
            let c = input.incidence[i];
            let glossy = input.gloss[i] * (0.25 + 0.75 * c * c * c * c);
            let field_a = 0.5 + 0.5 * value_noise2(blob_a, col as f32 / 7.0, row as f32 / 7.0);
            let field_b = 0.5 + 0.5 * value_noise2(blob_b, col as f32 / 5.0, row as f32 / 5.0);
            if field_a < dark || field_b < glossy {
                valid[i] = false;
                continue;
            }
            if c < 0.15 && unit_from_hash(draw(seed, K_GRAZE, i)) < (0.15 - c) / 0.15 {
                valid[i] = false;
                continue;
            }
            if unit_from_hash(draw(seed, K_SPECKLE, i)) < model.speckle_dropout {
                valid[i] = false;
            }
        }
    }
    // 5. Noise, quantisation, millimetres.
    (0..n)
        .map(|i| {
            if !valid[i] {
                return 0;
            }
            let d = value[i];
            let noisy = d + model.sigma(d) * normal_from_hash(draw(seed, K_NOISE, i));
            let q = model.quantise(noisy.max(0.05), input.fx);
            (q * 1000.0).round().clamp(1.0, 65535.0) as u16
        })
        .collect()
}

/// The filled depth written to `depth_bfx/`: the raw measurement where there is one, the ideal depth in
/// the holes (a perfect in-painting), clamped at 8 m like the toolbox.
pub fn filled(raw_mm: &[u16], ideal: &[f32]) -> Vec<u16> {
    raw_mm
        .iter()
        .zip(ideal)
        .map(|(&r, &z)| if r > 0 { r.min(8000) } else { (z * 1000.0).round().clamp(0.0, 8000.0) as u16 })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disparity_quantisation_step_matches_the_formula() {
        let m = DepthModel::for_sensor(Sensor::Kv1);
        let fx = 520.0;
        // Around 3 m the representable depths are spaced z²/(8·fx·b) ≈ 28.8 mm apart.
        let mut levels: Vec<i64> =
            (0..2000).map(|k| (m.quantise(2.9 + k as f32 * 1e-4, fx) * 1e5).round() as i64).collect();
        levels.dedup();
        let gaps: Vec<f32> = levels.windows(2).map(|w| (w[1] - w[0]) as f32 * 1e-5).collect();
        let mean_gap = gaps.iter().sum::<f32>() / gaps.len() as f32;
        let expected = 2.95f32 * 2.95 / (8.0 * fx * 0.075);
        assert!((mean_gap - expected).abs() / expected < 0.05, "{mean_gap} vs {expected}");
    }

    #[test]
    fn projector_shadow_falls_left_of_a_foreground_edge() {
        // A row: background at 3 m, a foreground block at 1 m in columns 50..80.
        let (w, h) = (120u32, 1u32);
        let depth: Vec<f32> = (0..w).map(|c| if (50..80).contains(&c) { 1.0 } else { 3.0 }).collect();
        let ones = vec![1.0f32; w as usize];
        let zeros = vec![0.0f32; w as usize];
        let mut model = DepthModel::for_sensor(Sensor::Kv1);
        model.edge_dropout = 0.0;
        model.speckle_dropout = 0.0;
        let input = SensorInput {
            width: w,
            height: h,
            fx: 520.0,
            depth: &depth,
            infrared: &ones,
            gloss: &zeros,
            incidence: &ones,
        };
        let out = simulate(&model, &input, 9);
        // Shadow width fx·b·(1/z_fg − 1/z_bg) = 39·(1 − 1/3) = 26 px left of column 50, none on the right.
        let missing: Vec<usize> = (0..w as usize).filter(|&c| out[c] == 0).collect();
        assert!(missing.iter().all(|&c| (23..50).contains(&c)), "{missing:?}");
        assert!(missing.len() >= 24 && missing.len() <= 27, "{}", missing.len());
    }
}
