//! cog-gpu: 3D object detection in indoor RGB-D images with Clouds of Oriented Gradients
//! (Ren & Sudderth, TPAMI), with the heavy feature work in WGSL compute shaders.
//!
//! Data flows one way through the modules:
//! `frame` (SUN RGB-D frames, point clouds) → `geometry` (cuboids, IoU, projection) → `features`
//! (definitions, CPU reference and fast path) → `gpu` (context and kernels with their CPU twins) →
//! `backend` (which of the two scores) → later stages (detection, learning, the room layout
//! `room_layout`, cascade and its cross-category `exclusion`, evaluation).
//! `synth` writes frames in the same layout the `frame` module reads.

pub mod backend;
pub mod calibration;
pub mod cascade;
pub mod category;
pub mod detect;
pub mod diagnose;
pub mod draw;
pub mod error;
pub mod eval;
pub mod exclusion;
pub mod features;
pub mod frame;
pub mod geometry;
pub mod gpu;
pub mod learn;
pub mod limits;
pub mod model;
pub mod nms;
pub mod ply;
pub mod room_layout;
pub mod synth;

pub use error::{Error, Result};
