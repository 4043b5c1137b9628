//! Solver checkpoints: the whole state of a cutting-plane run (working set, α, w, iteration), so
//! that `resume` continues exactly where the run stopped.
//!
//! Format (all little-endian), chosen over JSON because a working set of a thousand 12k-dimensional
//! constraints would be hundreds of MB of text:
//!
//! ```text
//! magic  b"COGSSVM\0"                       8 bytes
//! version u32 = 2
//! num_examples u64, dim u64, c f64, iteration u64, data_hash u64, num_constraints u64,
//! num_oracle_state u64                       (version 2)
//! w      dim × f64
//! per constraint: example u64, loss f64, alpha f64, inactive_iterations u32, psi dim × f32
//! oracle_state   num_oracle_state × u64      (version 2)
//! checksum u64  (FNV-1a of every byte before it)
//! ```
//!
//! Version 1 (before 2026-12-07) had no oracle state; it is still read, with an empty one.
//!
//! Writes go to `<path>.tmp`, are synced, then renamed over `<path>`: a crash mid-write leaves the
//! previous checkpoint intact.

use crate::error::{write_replacing, Error, Result};
use std::path::Path;

const MAGIC: &[u8; 8] = b"COGSSVM\0";
const VERSION: u32 = 2;

/// One constraint of the working set with its dual variable.
#[derive(Clone, Debug, PartialEq)]
pub struct WorkingConstraint {
    /// The example `i` whose slack ξ_i this constraint bounds.
    pub example: usize,
    /// `Δ(y_i, ȳ)`.
    pub loss: f64,
    /// `ψ = φ(x_i, y_i) − φ(x_i, ȳ)`.
    pub psi: Vec<f32>,
    /// Its dual variable α_k from the last QP solve.
    pub alpha: f64,
    /// Consecutive QP solves in which α_k was (numerically) zero; drives pruning.
    pub inactive_iterations: u32,
}

/// The state of a cutting-plane run.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpoint {
    pub num_examples: usize,
    pub dim: usize,
    /// The regularisation constant C the α were solved with.
    pub c: f64,
    /// Completed QP solves.
    pub iteration: usize,
    /// FNV-1a hash of the ground-truth features of all examples, each followed by its
    /// [`super::SeparationOracle::example_fingerprint`]: refuses to resume on other data.
    pub data_hash: u64,
    pub w: Vec<f64>,
    pub constraints: Vec<WorkingConstraint>,
    /// The oracle's own state at the checkpoint ([`super::SeparationOracle::run_state`]), given back to it
    /// on resume so that it continues where it stood (the detector: its batch calls, full passes and
    /// candidate cache).
    pub oracle_state: Vec<u64>,
}

impl Checkpoint {
    /// Encodes the checkpoint and replaces `path` atomically (temp file, sync, rename).
    pub fn write(&self, path: &Path) -> Result<()> {
        write_replacing(path, &self.encode())
    }

    /// Reads and validates a checkpoint (magic, version, sizes, checksum, finite values).
    pub fn read(path: &Path) -> Result<Checkpoint> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        Self::decode(&bytes).map_err(|message| Error::invalid(path, format!("bad SSVM checkpoint: {message}")))
    }

    fn encode(&self) -> Vec<u8> {
        let constraint_bytes = 8 + 8 + 8 + 4 + 4 * self.dim;
        let mut out = Vec::with_capacity(
            76 + 8 * self.dim + constraint_bytes * self.constraints.len() + 8 * self.oracle_state.len(),
        );
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        for value in [self.num_examples as u64, self.dim as u64] {
            out.extend_from_slice(&value.to_le_bytes());
        }
        out.extend_from_slice(&self.c.to_le_bytes());
        for value in
            [self.iteration as u64, self.data_hash, self.constraints.len() as u64, self.oracle_state.len() as u64]
        {
            out.extend_from_slice(&value.to_le_bytes());
        }
        for value in &self.w {
            out.extend_from_slice(&value.to_le_bytes());
        }
        for constraint in &self.constraints {
            out.extend_from_slice(&(constraint.example as u64).to_le_bytes());
            out.extend_from_slice(&constraint.loss.to_le_bytes());
            out.extend_from_slice(&constraint.alpha.to_le_bytes());
            out.extend_from_slice(&constraint.inactive_iterations.to_le_bytes());
            for value in &constraint.psi {
                out.extend_from_slice(&value.to_le_bytes());
            }
        }
        for value in &self.oracle_state {
            out.extend_from_slice(&value.to_le_bytes());
        }
        let checksum = fnv1a(FNV_OFFSET, &out);
        out.extend_from_slice(&checksum.to_le_bytes());
        out
    }

    fn decode(bytes: &[u8]) -> std::result::Result<Checkpoint, String> {
        if bytes.len() < 8 + 4 + 8 || &bytes[..8] != MAGIC {
            return Err("not a cog-gpu SSVM checkpoint (magic mismatch)".into());
        }
        let (body, checksum_bytes) = bytes.split_at(bytes.len() - 8);
        let stored_checksum = u64::from_le_bytes(checksum_bytes.try_into().expect("8 bytes"));
        if fnv1a(FNV_OFFSET, body) != stored_checksum {
            return Err("checksum mismatch (truncated or corrupted file)".into());
        }
        let mut reader = Reader { bytes: body, position: 8 };
        let version = reader.u32()?;
        if !(1..=VERSION).contains(&version) {
            return Err(format!("format version {version}, this build reads versions 1 to {VERSION}"));
        }
        let num_examples = reader.usize()?;
        let dim = reader.usize()?;
        let c = reader.f64()?;
        let iteration = reader.usize()?;
        let data_hash = reader.u64()?;
        let num_constraints = reader.usize()?;
        let num_oracle_state = if version >= 2 { reader.usize()? } else { 0 };
        let constraint_bytes = 28usize.checked_add(dim.checked_mul(4).ok_or("dimension overflows")?);
        let expected = constraint_bytes
            .and_then(|per| per.checked_mul(num_constraints))
            .and_then(|all| all.checked_add(dim.checked_mul(8)?))
            .and_then(|all| all.checked_add(num_oracle_state.checked_mul(8)?))
            .and_then(|all| all.checked_add(reader.position));
        if expected != Some(body.len()) {
            return Err(format!("size does not match {num_constraints} constraints of dimension {dim}"));
        }
        if !(c.is_finite() && c > 0.0) {
            return Err(format!("C = {c}"));
        }
        let w = (0..dim).map(|_| reader.f64()).collect::<std::result::Result<Vec<_>, _>>()?;
        let mut constraints = Vec::with_capacity(num_constraints);
        for index in 0..num_constraints {
            let example = reader.usize()?;
            let loss = reader.f64()?;
            let alpha = reader.f64()?;
            let inactive_iterations = reader.u32()?;
            let psi = (0..dim).map(|_| reader.f32()).collect::<std::result::Result<Vec<_>, _>>()?;
            if example >= num_examples || !loss.is_finite() || !alpha.is_finite() || psi.iter().any(|v| !v.is_finite())
            {
                return Err(format!("constraint {index} is invalid (example {example}, loss {loss}, alpha {alpha})"));
            }
            constraints.push(WorkingConstraint { example, loss, psi, alpha, inactive_iterations });
        }
        if w.iter().any(|v| !v.is_finite()) {
            return Err("w has non-finite values".into());
        }
        let oracle_state = (0..num_oracle_state).map(|_| reader.u64()).collect::<std::result::Result<Vec<_>, _>>()?;
        Ok(Checkpoint { num_examples, dim, c, iteration, data_hash, w, constraints, oracle_state })
    }
}

/// The FNV-1a offset basis ([`fnv1a`]'s starting state).
pub const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// FNV-1a, continued from `state` (pass [`FNV_OFFSET`] to start).
pub fn fnv1a(mut state: u64, bytes: &[u8]) -> u64 {
    for byte in bytes {
        state ^= u64::from(*byte);
        state = state.wrapping_mul(0x0000_0100_0000_01b3);
    }
    state
}

struct Reader<'a> {
    bytes: &'a [u8],
    position: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> std::result::Result<[u8; N], String> {
        let end = self.position + N;
        let slice = self.bytes.get(self.position..end).ok_or("unexpected end of file")?;
        self.position = end;
        Ok(slice.try_into().expect("slice of length N"))
    }
    fn u32(&mut self) -> std::result::Result<u32, String> {
        self.take::<4>().map(u32::from_le_bytes)
    }
    fn u64(&mut self) -> std::result::Result<u64, String> {
        self.take::<8>().map(u64::from_le_bytes)
    }
    fn usize(&mut self) -> std::result::Result<usize, String> {
        let value = self.u64()?;
        usize::try_from(value).map_err(|_| format!("count {value} does not fit in memory"))
    }
    fn f64(&mut self) -> std::result::Result<f64, String> {
        self.take::<8>().map(f64::from_le_bytes)
    }
    fn f32(&mut self) -> std::result::Result<f32, String> {
        self.take::<4>().map(f32::from_le_bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(oracle_state: Vec<u64>) -> Checkpoint {
        Checkpoint {
            num_examples: 2,
            dim: 3,
            c: 10.0,
            iteration: 4,
            data_hash: 0xfeed,
            w: vec![0.5, -1.0, 2.0],
            constraints: vec![WorkingConstraint {
                example: 1,
                loss: 0.75,
                psi: vec![1.0, 0.0, -2.0],
                alpha: 0.125,
                inactive_iterations: 3,
            }],
            oracle_state,
        }
    }

    /// Version 2 round-trips the oracle's state; a version-1 file (the layout before it: no count, no
    /// values; built here by hand from the format description) reads with an empty one.
    #[test]
    fn version_2_carries_the_oracle_state_and_version_1_still_reads() {
        let with_state = sample(vec![7, 2]);
        assert_eq!(Checkpoint::decode(&with_state.encode()).unwrap(), with_state);
        let v2 = sample(Vec::new()).encode();
        // Version 1: the version word 1, the header without num_oracle_state (the 8 bytes after
        // num_constraints, at 8 + 4 + 6·8), the same body, a new checksum.
        let header_end = 8 + 4 + 6 * 8;
        let mut v1 = Vec::new();
        v1.extend_from_slice(MAGIC);
        v1.extend_from_slice(&1u32.to_le_bytes());
        v1.extend_from_slice(&v2[12..header_end]);
        v1.extend_from_slice(&v2[header_end + 8..v2.len() - 8]);
        let checksum = fnv1a(FNV_OFFSET, &v1);
        v1.extend_from_slice(&checksum.to_le_bytes());
        assert_eq!(Checkpoint::decode(&v1).unwrap(), sample(Vec::new()));
        // A version this build does not know is refused.
        let mut v3 = with_state.encode();
        v3[8..12].copy_from_slice(&3u32.to_le_bytes());
        let n = v3.len() - 8;
        let checksum = fnv1a(FNV_OFFSET, &v3[..n]);
        v3[n..].copy_from_slice(&checksum.to_le_bytes());
        assert!(Checkpoint::decode(&v3).unwrap_err().contains("version 3"));
    }
}
