//! GPU context and compute kernels (each with a CPU twin).
//!
//! [`GpuContext`] owns the wgpu instance, adapter, device and queue, the limits the device was created with,
//! and the compiled pipelines of every kernel ([`Kernels`]). [`acquire`] is the one entry point the rest of
//! the crate uses: it returns `None` (and says why in one log line) when the CPU path must be taken.
//!
//! # Adapter choice
//! Primary backends only (Vulkan, Metal, DX12): with GL allowed and no Vulkan driver, wgpu would hand back
//! a GL llvmpipe adapter that cannot run compute shaders. The environment is honoured like wgpu's own
//! helpers: `WGPU_BACKEND` (comma list, intersected with the primary backends), `WGPU_ADAPTER_NAME`
//! (case-insensitive substring of the adapter name; first match in enumeration order) and
//! `WGPU_POWER_PREF` (`low`/`high`/`none`; default high performance, we only do compute).
//! `wgpu::util::initialize_adapter_from_env` exists in wgpu 30 but enumerates every backend and panics
//! (`expect`) when no adapter matches the name, so the same selection is re-implemented here without the
//! panic.
//!
//! # Limits
//! The device is requested with the WebGPU defaults (`Limits::default()`), except the two buffer-size
//! limits, which are raised to what the adapter offers (capped at [`MAX_BUFFER_BYTES`]): they only widen
//! the jobs a kernel may send at once and every kernel chunks its work to [`GpuContext::limits`].
//! No features are requested.
//!
//! # Writing a kernel
//! A kernel is a WGSL file in `shaders/` (embedded with `include_str!`), a [`KernelSpec`] constant in its
//! Rust module, a field in [`Kernels`] built in [`Kernels::new`], a `#[repr(C)]` bytemuck params struct
//! mirroring the WGSL uniform (with a compile-time size assertion), a CPU twin written like the shader, and
//! a `*_gpu` function built from the helpers below ([`GpuContext::storage_buffer`],
//! [`GpuContext::uniform_buffer`], [`GpuContext::output_buffer`], [`GpuContext::bind_group`],
//! [`GpuContext::dispatch_and_read`], all inside [`GpuContext::checked`]). See `depth_points` for the
//! pattern.
//!
//! # 1-D dispatch convention
//! A job of `n` invocations is dispatched as `ceil(n / workgroup_size)` workgroups, split over x and y when
//! that exceeds `max_compute_workgroups_per_dimension` ([`GpuContext::workgroup_grid`]). The shader
//! recovers its linear index as `gid.x + gid.y * num_workgroups.x * WORKGROUP_SIZE` and returns when the
//! index is past the job's end (the grid may hold a few more invocations than asked for).

pub mod depth_points;
pub mod fast;
pub mod fast_tables;
pub mod features;
pub mod image_gradients;
pub mod normal_window;
pub mod preprocess;
pub mod room_layout;

use std::borrow::Cow;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use wgpu::util::DeviceExt;

use crate::error::{Error, Result};

/// Cap on the buffer-size limits requested from the adapter: some drivers report several GiB, and a
/// kernel sized to that would allocate more memory than a shared machine should give one job.
pub const MAX_BUFFER_BYTES: u64 = 1 << 30;
/// How long a read-back waits for its map callback once the GPU is idle ([`GpuContext::wait_for_mapping`]):
/// the callback normally runs within the poll or milliseconds after it, on another polling thread.
const MAP_WAIT: std::time::Duration = std::time::Duration::from_secs(30);

/// The backends cog-gpu ever uses (never GL, see the module doc).
pub const PRIMARY_BACKENDS: wgpu::Backends =
    wgpu::Backends::VULKAN.union(wgpu::Backends::METAL).union(wgpu::Backends::DX12);

/// How a kernel binds one buffer or texture (binding numbers are the slice positions in
/// [`KernelSpec::bindings`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Binding {
    /// `texture_2d<u32>` read by `textureLoad` (a [`TexelRows`] copy of a buffer).
    TextureU32,
    /// `texture_2d<f32>` read by `textureLoad`, unfiltered (a [`TexelRows`] copy of a buffer).
    TextureF32,
    /// `var<uniform>`.
    Uniform,
    /// `var<uniform>` bound with a dynamic offset: one bind group serves many dispatches, each with its own
    /// record of a shared buffer (set by [`GpuContext::encode_dispatches_at`]).
    UniformDynamic,
    /// `var<storage, read>`.
    StorageRead,
    /// `var<storage, read_write>`.
    StorageReadWrite,
}

/// What is needed to build one compute pipeline: the WGSL source, its entry point, and its bind group 0.
#[derive(Clone, Copy, Debug)]
pub struct KernelSpec {
    /// Label for wgpu objects and error messages (the kernel's name).
    pub label: &'static str,
    /// WGSL source (`include_str!("../../shaders/<name>.wgsl")`).
    pub source: &'static str,
    /// Name of the `@compute` entry point.
    pub entry_point: &'static str,
    /// The buffers of `@group(0)`, binding `i` at position `i`.
    pub bindings: &'static [Binding],
}

/// The byte range `(offset, size)` of `buffer` as a binding (`size` non-zero).
pub fn buffer_range(buffer: &wgpu::Buffer, offset: u64, size: u64) -> wgpu::BindingResource<'_> {
    wgpu::BindingResource::Buffer(wgpu::BufferBinding { buffer, offset, size: wgpu::BufferSize::new(size) })
}

/// The bind group layout entry type of `binding`.
fn binding_type(binding: Binding) -> wgpu::BindingType {
    let buffer = |ty| wgpu::BindingType::Buffer {
        ty,
        has_dynamic_offset: binding == Binding::UniformDynamic,
        min_binding_size: None,
    };
    let texture = |sample_type| wgpu::BindingType::Texture {
        sample_type,
        view_dimension: wgpu::TextureViewDimension::D2,
        multisampled: false,
    };
    match binding {
        Binding::Uniform | Binding::UniformDynamic => buffer(wgpu::BufferBindingType::Uniform),
        Binding::StorageRead => buffer(wgpu::BufferBindingType::Storage { read_only: true }),
        Binding::StorageReadWrite => buffer(wgpu::BufferBindingType::Storage { read_only: false }),
        Binding::TextureU32 => texture(wgpu::TextureSampleType::Uint),
        Binding::TextureF32 => texture(wgpu::TextureSampleType::Float { filterable: false }),
    }
}

/// A buffer of `vec4` elements seen as a 2D texture, [`TexelRows::WIDTH`] texels a row: element `n` is the
/// texel `(n % WIDTH, n / WIDTH)` (WGSL twin: `TEXELS_PER_ROW` and `texel` in `shaders/fast_scores.wgsl`).
///
/// Why: lavapipe (Mesa's software Vulkan, CI's device) performs every storage-buffer load lane by lane,
/// with a branch and a bounds check per lane and per component, whatever the address — about 13 ns per
/// `vec4` on this project's 2-core machine, from cache or not, even when every lane reads the same word —
/// while a `textureLoad` is a vectorised gather: 1.4 ns from cache, 3.8–4.9 ns over 16 MB (2²⁷ scattered
/// `vec4` reads of each kind: `cargo run --release --example lavapipe_loads`, 2026-11-28). Scattered reads
/// from large read-only arrays therefore go through textures; on hardware GPUs a texture read costs about
/// what a buffer load does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TexelRows {
    /// Rows of the texture (at least 1).
    pub rows: u32,
}

impl TexelRows {
    /// Texels (`vec4` elements) per row: 8192, the WebGPU default of `max_texture_dimension_2d`.
    pub const WIDTH: u32 = 8192;
    /// Bytes of one row of 16-byte texels (a multiple of 256, as buffer-to-texture copies need).
    pub const ROW_BYTES: u64 = Self::WIDTH as u64 * 16;

    /// The rows that hold `bytes` bytes of `vec4` elements, or an error when they exceed `max_rows`.
    pub fn for_bytes(bytes: u64, max_rows: u32, what: &str) -> Result<TexelRows> {
        let rows = bytes.div_ceil(Self::ROW_BYTES).max(1);
        match u32::try_from(rows) {
            Ok(rows) if rows <= max_rows => Ok(TexelRows { rows }),
            _ => Err(Error::Gpu(format!(
                "{what}: {bytes} bytes need {rows} texture rows of {} texels, over the device's {max_rows}",
                Self::WIDTH
            ))),
        }
    }

    /// Bytes a source buffer must hold for the copy of all rows.
    pub fn bytes(self) -> u64 {
        u64::from(self.rows) * Self::ROW_BYTES
    }

    /// The texture's size.
    pub fn extent(self) -> wgpu::Extent3d {
        wgpu::Extent3d { width: Self::WIDTH, height: self.rows, depth_or_array_layers: 1 }
    }

    /// Records the copy of the first [`TexelRows::bytes`] of `buffer` into `texture`.
    pub fn encode_copy(self, encoder: &mut wgpu::CommandEncoder, buffer: &wgpu::Buffer, texture: &wgpu::Texture) {
        encoder.copy_buffer_to_texture(
            wgpu::TexelCopyBufferInfo {
                buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(Self::ROW_BYTES as u32),
                    rows_per_image: Some(self.rows),
                },
            },
            texture.as_image_copy(),
            self.extent(),
        );
    }
}

/// A compiled compute pipeline with its bind group layout and the workgroup size read from the WGSL.
#[derive(Debug)]
pub struct Kernel {
    pub label: &'static str,
    pub pipeline: wgpu::ComputePipeline,
    pub bind_group_layout: wgpu::BindGroupLayout,
    /// `@workgroup_size` of the entry point (x, y, z), taken from the shader itself so it cannot drift.
    pub workgroup_size: [u32; 3],
}

impl Kernel {
    /// Compiles `spec` on `device`. Shader or layout errors come back as [`Error::Gpu`] naming the kernel.
    pub fn new(device: &wgpu::Device, spec: &KernelSpec) -> Result<Kernel> {
        let workgroup_size = wgsl_workgroup_size(spec)?;
        let scopes = ErrorScopes::push(device);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(spec.label),
            source: wgpu::ShaderSource::Wgsl(Cow::Borrowed(spec.source)),
        });
        let entries: Vec<wgpu::BindGroupLayoutEntry> = spec
            .bindings
            .iter()
            .enumerate()
            .map(|(i, binding)| wgpu::BindGroupLayoutEntry {
                binding: i as u32,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: binding_type(*binding),
                count: None,
            })
            .collect();
        let bind_group_layout = device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(spec.label), entries: &entries });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(spec.label),
            bind_group_layouts: &[Some(&bind_group_layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(spec.label),
            layout: Some(&layout),
            module: &module,
            entry_point: Some(spec.entry_point),
            compilation_options: Default::default(),
            cache: None,
        });
        scopes.pop(&format!("building kernel '{}'", spec.label))?;
        Ok(Kernel { label: spec.label, pipeline, bind_group_layout, workgroup_size })
    }

    /// Invocations per workgroup.
    pub fn invocations_per_workgroup(&self) -> u32 {
        self.workgroup_size.iter().product()
    }
}

/// Reads the entry point's `@workgroup_size` with naga (the same front end wgpu uses).
fn wgsl_workgroup_size(spec: &KernelSpec) -> Result<[u32; 3]> {
    let module = naga::front::wgsl::parse_str(spec.source).map_err(|e| {
        // One line (it ends up in acquire's warning); tests/shaders.rs prints the full diagnostic.
        let at = e.location(spec.source).map(|l| format!(" at line {}:{}", l.line_number, l.line_position));
        Error::Gpu(format!("kernel '{}': WGSL does not parse{}: {e}", spec.label, at.unwrap_or_default()))
    })?;
    module
        .entry_points
        .iter()
        .find(|ep| ep.name == spec.entry_point && ep.stage == naga::ShaderStage::Compute)
        .map(|ep| ep.workgroup_size)
        .ok_or_else(|| Error::Gpu(format!("kernel '{}': no @compute entry point '{}'", spec.label, spec.entry_point)))
}

/// The compiled pipelines of all kernels, built once when the context is created (a shader that fails to
/// compile makes [`acquire`] fall back to the CPU instead of failing mid-run).
///
/// To add a kernel: add a `pub <name>: Kernel` field here and one line in [`Kernels::new`] building it from
/// the kernel module's `KERNEL` spec.
#[derive(Debug)]
pub struct Kernels {
    pub depth_points: Kernel,
    pub features: Kernel,
    pub fast_scores: Kernel,
    pub fast_table_scatter: Kernel,
    pub fast_table_scan: Kernel,
    pub room_layout: Kernel,
    pub normal_window: Kernel,
    pub image_gradients: Kernel,
}

impl Kernels {
    pub fn new(device: &wgpu::Device) -> Result<Kernels> {
        Ok(Kernels {
            depth_points: Kernel::new(device, &depth_points::KERNEL)?,
            features: Kernel::new(device, &features::KERNEL)?,
            fast_scores: Kernel::new(device, &fast::KERNEL)?,
            fast_table_scatter: Kernel::new(device, &fast_tables::SCATTER_KERNEL)?,
            fast_table_scan: Kernel::new(device, &fast_tables::SCAN_KERNEL)?,
            room_layout: Kernel::new(device, &room_layout::KERNEL)?,
            normal_window: Kernel::new(device, &normal_window::KERNEL)?,
            image_gradients: Kernel::new(device, &image_gradients::KERNEL)?,
        })
    }
}

/// The GPU: wgpu objects, the adapter's description, the limits in force, and the compiled kernels.
pub struct GpuContext {
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    /// The chosen adapter's name, backend, device type and driver.
    pub info: wgpu::AdapterInfo,
    /// The limits the device was created with (what kernels must chunk their jobs to).
    pub limits: wgpu::Limits,
    pub kernels: Kernels,
    /// Whether the device has timestamp queries (asked for when the adapter offers them): kernels may then
    /// time their compute passes on the GPU for the debug log ([`GpuContext::pass_timer`]).
    pub timestamps: bool,
    /// Sets of buffers kept from one batch to the next (see [`BufferPool`]), [`pool_slots`] of them: a
    /// kernel holds one set's lock ([`GpuContext::pool`]) from its uploads to its read-back, so that two
    /// callers never share a buffer in flight, while a caller holding another set uploads its batch as the
    /// GPU runs the first one's.
    pub pools: Vec<Mutex<BufferPool>>,
    /// Which set a caller waits for when every set is taken (round robin).
    next_pool: AtomicUsize,
    /// The `image_gradients` kernel's constant table, uploaded on its first use and kept for the
    /// context's life ([`image_gradients::resident_table`]).
    pub(crate) gradient_table: std::sync::OnceLock<wgpu::Buffer>,
}

/// Byte offsets of the pieces packed into one buffer, each aligned for binding.
pub(crate) struct Arena {
    align: u64,
    pub(crate) len: u64,
}

impl Arena {
    pub(crate) fn new(align: u32) -> Arena {
        Arena { align: u64::from(align.max(4)), len: 0 }
    }

    /// Reserves `bytes` and returns their offset.
    pub(crate) fn place(&mut self, bytes: u64) -> u64 {
        let at = self.len.next_multiple_of(self.align);
        self.len = at + bytes;
        at
    }
}

/// Default number of [`BufferPool`] sets of a context ([`pool_slots`]).
pub const DEFAULT_POOL_SLOTS: usize = 2;

/// The number of [`BufferPool`] sets a new context keeps: `COG_GPU_POOL_SLOTS` (1–8) when set, else
/// [`DEFAULT_POOL_SLOTS`]. One set serialises batches from upload to read-back; two let one batch's
/// uploads overlap another's GPU work (chosen on an H200: see the README's "The fast path"). Each set grows
/// to the largest batch it has held, so the GPU memory kept grows with the count.
pub fn pool_slots() -> Result<usize> {
    parse_pool_slots(std::env::var("COG_GPU_POOL_SLOTS").ok().as_deref())
}

/// [`pool_slots`] of the variable's value (`None`: unset).
fn parse_pool_slots(value: Option<&str>) -> Result<usize> {
    match value {
        None => Ok(DEFAULT_POOL_SLOTS),
        Some(text) => match text.trim().parse::<usize>() {
            Ok(n) if (1..=8).contains(&n) => Ok(n),
            _ => Err(Error::Input(format!("COG_GPU_POOL_SLOTS is '{text}': expected a whole number from 1 to 8"))),
        },
    }
}

/// The size of a pooled resource that must hold `wanted` and replaces one of size `kept`: half as large
/// again as `kept` when that is more, so that slowly growing requests do not reallocate every time, but
/// never over `max` unless `wanted` itself is.
fn grown<T: Copy + Ord + std::ops::Mul<Output = T> + std::ops::Div<Output = T> + From<u8>>(
    kept: Option<T>,
    wanted: T,
    max: T,
) -> T {
    kept.map_or(wanted, |k| k * T::from(3) / T::from(2)).min(max).max(wanted)
}

/// Frames over which a pooled resource's largest request is remembered ([`BufferPool::trim`]): a resource
/// more than [`TRIM_SLACK`] times the largest request of its last `TRIM_FRAMES` frames is let go.
///
/// Chosen so that a run over a data set keeps a resource through the ordinary spread of room sizes
/// (a bathroom between two bedrooms does not reallocate the bedrooms' tables), while one large room does
/// not hold its memory for the rest of a long run.
pub const TRIM_FRAMES: usize = 8;

/// How much larger than its recent largest request a pooled resource may stay ([`TRIM_FRAMES`]): at 2,
/// the half-again growth of `grown` never triggers a trim on its own.
pub const TRIM_SLACK: u64 = 2;

/// One pooled resource with the largest request of each of its last [`TRIM_FRAMES`] frames (`peaks[0]`
/// the current frame's), in bytes for buffers and rows for textures.
struct Pooled<K, R> {
    label: &'static str,
    kind: K,
    resource: R,
    peaks: [u64; TRIM_FRAMES],
}

impl<K, R> Pooled<K, R> {
    fn new(label: &'static str, kind: K, resource: R, wanted: u64) -> Self {
        let mut peaks = [0; TRIM_FRAMES];
        peaks[0] = wanted;
        Pooled { label, kind, resource, peaks }
    }

    fn want(&mut self, wanted: u64) {
        self.peaks[0] = self.peaks[0].max(wanted);
    }

    /// Ends a frame: whether the resource, of `size`, is worth keeping (it is at most [`TRIM_SLACK`] times
    /// the largest request of the last [`TRIM_FRAMES`] frames); the frames' peaks move on by one.
    fn keep_after_frame(&mut self, size: u64) -> bool {
        let recent = self.peaks.iter().copied().max().unwrap_or(0);
        self.peaks.rotate_right(1);
        self.peaks[0] = 0;
        size <= recent.saturating_mul(TRIM_SLACK)
    }
}

/// Buffers and textures by role, reused across batches and frames instead of created (and zeroed by wgpu)
/// each time: a per-frame arena. A kernel that needs zeros clears its range itself. They grow to the
/// largest request (half as large again, `grown`) and shrink only through [`BufferPool::trim`], which
/// [`GpuContext::end_frame`] calls after each frame: a resource much larger than its recent requests, or
/// not asked for in [`TRIM_FRAMES`] frames, is dropped and made again, at the size asked, when next needed.
#[derive(Default)]
pub struct BufferPool {
    buffers: Vec<Pooled<wgpu::BufferUsages, wgpu::Buffer>>,
    /// Textures by role ([`BufferPool::texture`]).
    textures: Vec<Pooled<wgpu::TextureFormat, wgpu::Texture>>,
    /// Labels of the upload buffers (`MAP_WRITE`) unmapped by [`BufferPool::unmap_upload`] and not mapped
    /// since (wgpu 30 cannot be asked a buffer's map state).
    unmapped_uploads: Vec<&'static str>,
}

impl BufferPool {
    /// The pooled buffer of `label` and `usage` with at least `size` bytes (rounded up to 4, at least 4):
    /// the kept one when it is large enough, else a new one, half as large again when that is more (`grown`).
    pub fn buffer(
        &mut self,
        device: &wgpu::Device,
        label: &'static str,
        usage: wgpu::BufferUsages,
        size: u64,
        max_size: u64,
    ) -> wgpu::Buffer {
        let size = size.max(4).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
        let slot = self.buffers.iter().position(|b| b.label == label && b.kind == usage);
        if let Some(n) = slot {
            self.buffers[n].want(size);
            if self.buffers[n].resource.size() >= size {
                return self.buffers[n].resource.clone();
            }
        }
        let grown = grown(slot.map(|n| self.buffers[n].resource.size()), size, max_size);
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: grown.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT),
            usage,
            // An upload buffer starts mapped, ready for its first batch ([`GpuContext::mapped_upload`]).
            mapped_at_creation: usage.contains(wgpu::BufferUsages::MAP_WRITE),
        });
        match slot {
            Some(n) => self.buffers[n].resource = buffer.clone(),
            None => self.buffers.push(Pooled::new(label, usage, buffer.clone(), size)),
        }
        self.unmapped_uploads.retain(|l| *l != label);
        buffer
    }

    /// The pooled texture of `label` and `format` ([`TexelRows::WIDTH`] wide, `TEXTURE_BINDING |
    /// COPY_DST`) with at least `rows` rows: the kept one when it is tall enough, else a new one of the
    /// height `grown` gives (half as tall again when that is more).
    pub fn texture(
        &mut self,
        device: &wgpu::Device,
        label: &'static str,
        format: wgpu::TextureFormat,
        rows: TexelRows,
        max_rows: u32,
    ) -> wgpu::Texture {
        let slot = self.textures.iter().position(|t| t.label == label && t.kind == format);
        if let Some(n) = slot {
            self.textures[n].want(u64::from(rows.rows));
            if self.textures[n].resource.height() >= rows.rows {
                return self.textures[n].resource.clone();
            }
        }
        let grown = grown(slot.map(|n| self.textures[n].resource.height()), rows.rows, max_rows);
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: TexelRows { rows: grown }.extent(),
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        match slot {
            Some(n) => self.textures[n].resource = texture.clone(),
            None => self.textures.push(Pooled::new(label, format, texture.clone(), u64::from(rows.rows))),
        }
        texture
    }

    /// Ends a frame for this pool set: drops every resource more than [`TRIM_SLACK`] times the largest
    /// request of its last [`TRIM_FRAMES`] frames (also one not asked for in that many frames); the next
    /// request makes it again at the size asked. Safe between batches: a batch holds the set's lock from
    /// its uploads to its read-back, and a clone still held elsewhere keeps its resource alive.
    pub fn trim(&mut self) {
        self.buffers.retain_mut(|b| {
            let size = b.resource.size();
            b.keep_after_frame(size)
        });
        self.textures.retain_mut(|t| {
            let rows = u64::from(t.resource.height());
            t.keep_after_frame(rows)
        });
        let buffers = &self.buffers;
        self.unmapped_uploads.retain(|label| buffers.iter().any(|b| b.label == *label));
    }

    /// Bytes the set holds: its buffers' sizes and its textures' texels.
    pub fn bytes(&self) -> u64 {
        let buffers: u64 = self.buffers.iter().map(|b| b.resource.size()).sum();
        let textures: u64 = self
            .textures
            .iter()
            .map(|t| {
                let size = t.resource.size();
                let texel = t.kind.block_copy_size(None).unwrap_or(0);
                u64::from(size.width) * u64::from(size.height) * u64::from(texel)
            })
            .sum();
        buffers + textures
    }

    /// Unmaps the upload buffer `buffer` of `label` (from [`GpuContext::mapped_upload`]) before the
    /// submission that copies from it; the next `mapped_upload` maps it again.
    pub fn unmap_upload(&mut self, label: &'static str, buffer: &wgpu::Buffer) {
        buffer.unmap();
        if !self.unmapped_uploads.contains(&label) {
            self.unmapped_uploads.push(label);
        }
    }
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuContext").field("adapter", &self.adapter_summary()).finish_non_exhaustive()
    }
}

/// Logs the force-CPU message once per process, not once per caller.
static FORCE_CPU_LOGGED: AtomicBool = AtomicBool::new(false);

/// The GPU context, or `None` when the CPU path must be used.
///
/// With `force_cpu` it returns `None` (logging that once, at info level). Otherwise it creates the context;
/// when that fails (no adapter, no device, a kernel that does not compile) it logs one warning line naming
/// the reason and returns `None`. It never panics.
pub fn acquire(force_cpu: bool) -> Option<GpuContext> {
    if force_cpu {
        if !FORCE_CPU_LOGGED.swap(true, Ordering::Relaxed) {
            log::info!("GPU disabled (--cpu): using the CPU path");
        }
        return None;
    }
    match GpuContext::new() {
        Ok(ctx) => {
            log::info!("GPU: {}", ctx.adapter_summary());
            Some(ctx)
        }
        Err(e) => {
            let reason = match e {
                Error::Gpu(message) => message,
                other => other.to_string(),
            };
            // wgpu's validation messages span lines; the warning must stay one line.
            let reason = reason.split('\n').map(str::trim).filter(|l| !l.is_empty()).collect::<Vec<_>>().join(" | ");
            log::warn!(
                "no GPU adapter (Vulkan/Metal/DX12) usable ({reason}): using the CPU path; \
                 on Linux install mesa-vulkan-drivers for lavapipe"
            );
            None
        }
    }
}

/// The backends to try: `WGPU_BACKEND` when set, restricted to the primary backends.
fn backends_from_env() -> Result<wgpu::Backends> {
    match std::env::var("WGPU_BACKEND") {
        Ok(list) => {
            let chosen = wgpu::Backends::from_comma_list(&list) & PRIMARY_BACKENDS;
            if chosen.is_empty() {
                Err(Error::Gpu(format!("WGPU_BACKEND='{list}' names none of vulkan, metal, dx12")))
            } else {
                Ok(chosen)
            }
        }
        Err(_) => Ok(PRIMARY_BACKENDS),
    }
}

/// The first adapter (enumeration order) whose name contains `wanted`, case-insensitively, as
/// `wgpu::util::initialize_adapter_from_env` does, but an error instead of a panic when none matches.
async fn adapter_by_name(instance: &wgpu::Instance, backends: wgpu::Backends, wanted: &str) -> Result<wgpu::Adapter> {
    let wanted_lower = wanted.to_lowercase();
    let adapters = instance.enumerate_adapters(backends).await;
    let names: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
    adapters
        .into_iter()
        .find(|a| a.get_info().name.to_lowercase().contains(&wanted_lower))
        .ok_or_else(|| Error::Gpu(format!("WGPU_ADAPTER_NAME='{wanted}' matches none of the adapters {names:?}")))
}

/// The limits to request: WebGPU defaults, buffer sizes raised to the adapter's (see the module doc).
fn required_limits(adapter: &wgpu::Limits) -> wgpu::Limits {
    let defaults = wgpu::Limits::default();
    let raise = |default: u64, offered: u64| offered.min(MAX_BUFFER_BYTES).max(default);
    wgpu::Limits {
        max_storage_buffer_binding_size: raise(
            defaults.max_storage_buffer_binding_size,
            adapter.max_storage_buffer_binding_size,
        ),
        max_buffer_size: raise(defaults.max_buffer_size, adapter.max_buffer_size),
        ..defaults
    }
}

impl GpuContext {
    /// Creates the context (see the module doc for the adapter choice). Blocks until the device is ready.
    pub fn new() -> Result<GpuContext> {
        pollster::block_on(Self::new_async())
    }

    async fn new_async() -> Result<GpuContext> {
        let backends = backends_from_env()?;
        let descriptor =
            wgpu::InstanceDescriptor { backends, ..wgpu::InstanceDescriptor::new_without_display_handle().with_env() };
        let instance = wgpu::Instance::new(descriptor);
        let adapter = match std::env::var("WGPU_ADAPTER_NAME") {
            Ok(wanted) => adapter_by_name(&instance, backends, &wanted).await?,
            Err(_) => instance
                .request_adapter(&wgpu::RequestAdapterOptions {
                    power_preference: wgpu::PowerPreference::from_env()
                        .unwrap_or(wgpu::PowerPreference::HighPerformance),
                    ..Default::default()
                })
                .await
                .map_err(|e| Error::Gpu(format!("no adapter on {backends:?}: {e}")))?,
        };
        let info = adapter.get_info();
        let limits = required_limits(&adapter.limits());
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        log::debug!("adapter {}: timestamp queries {}", info.name, if timestamps { "available" } else { "absent" });
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("cog-gpu"),
                required_features: if timestamps { wgpu::Features::TIMESTAMP_QUERY } else { wgpu::Features::empty() },
                required_limits: limits.clone(),
                experimental_features: wgpu::ExperimentalFeatures::disabled(),
                memory_hints: wgpu::MemoryHints::Performance,
                trace: wgpu::Trace::Off,
            })
            .await
            .map_err(|e| Error::Gpu(format!("adapter '{}' ({:?}) gave no device: {e}", info.name, info.backend)))?;
        // wgpu's default handler panics; errors outside a `checked` scope are logged instead, and the
        // scoped calls still report theirs as `Error::Gpu`.
        device.on_uncaptured_error(Arc::new(|e: wgpu::Error| log::error!("GPU error outside a checked scope: {e}")));
        device.set_device_lost_callback(|reason, message| log::error!("GPU device lost ({reason:?}): {message}"));
        let kernels = Kernels::new(&device)?;
        let pools = (0..pool_slots()?).map(|_| Mutex::default()).collect();
        Ok(GpuContext {
            instance,
            adapter,
            device,
            queue,
            info,
            limits,
            kernels,
            timestamps,
            pools,
            next_pool: AtomicUsize::new(0),
            gradient_table: std::sync::OnceLock::new(),
        })
    }

    /// One line for logs: adapter name, backend, device type and driver.
    pub fn adapter_summary(&self) -> String {
        let i = &self.info;
        let driver = [i.driver.as_str(), i.driver_info.as_str()]
            .into_iter()
            .filter(|s| !s.is_empty())
            .collect::<Vec<_>>()
            .join(" ");
        format!(
            "{} ({:?}, {:?}, driver: {})",
            i.name,
            i.backend,
            i.device_type,
            if driver.is_empty() { "?" } else { &driver }
        )
    }

    /// Runs `f` with wgpu's validation, out-of-memory and internal errors captured: any error raised by
    /// the GPU calls inside `f` (on this thread) becomes `Err(Error::Gpu)` mentioning `what`.
    pub fn checked<R>(&self, what: &str, f: impl FnOnce() -> Result<R>) -> Result<R> {
        let scopes = ErrorScopes::push(&self.device);
        let result = f();
        let scoped = scopes.pop(what);
        let value = result?;
        scoped?;
        Ok(value)
    }

    /// A storage buffer (read or read-write in the shader) holding `data`; also a copy source and target.
    /// An empty slice gives a 4-byte buffer, since zero-sized bindings are invalid.
    pub fn storage_buffer<T: bytemuck::Pod>(&self, label: &str, data: &[T]) -> wgpu::Buffer {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let contents: &[u8] = if bytes.is_empty() { &[0; 4] } else { bytes };
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        })
    }

    /// A zero-filled storage buffer of `size_bytes` (rounded up to 4, at least 4) for a kernel to write.
    pub fn output_buffer(&self, label: &str, size_bytes: u64) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size_bytes.max(4).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// A uniform buffer holding `value` (a `#[repr(C)]` params struct laid out like its WGSL twin).
    pub fn uniform_buffer<T: bytemuck::Pod>(&self, label: &str, value: &T) -> wgpu::Buffer {
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::bytes_of(value),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        })
    }

    /// Bind group 0 of `kernel`, binding `i` = the whole of `buffers[i]`.
    pub fn bind_group(&self, kernel: &Kernel, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
        let resources: Vec<wgpu::BindingResource> = buffers.iter().map(|b| b.as_entire_binding()).collect();
        self.bind_group_resources(kernel, &resources)
    }

    /// Bind group 0 of `kernel`, binding `i` = the byte range `(offset, size)` of `ranges[i].0` (offsets
    /// must be multiples of the device's storage / uniform offset alignment, sizes non-zero).
    pub fn bind_group_ranges(&self, kernel: &Kernel, ranges: &[(&wgpu::Buffer, u64, u64)]) -> wgpu::BindGroup {
        let resources: Vec<wgpu::BindingResource> =
            ranges.iter().map(|&(buffer, offset, size)| buffer_range(buffer, offset, size)).collect();
        self.bind_group_resources(kernel, &resources)
    }

    /// Bind group 0 of `kernel`, binding `i` = `resources[i]` (buffer ranges and texture views).
    pub fn bind_group_resources(&self, kernel: &Kernel, resources: &[wgpu::BindingResource]) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = resources
            .iter()
            .enumerate()
            .map(|(i, resource)| wgpu::BindGroupEntry { binding: i as u32, resource: resource.clone() })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(kernel.label),
            layout: &kernel.bind_group_layout,
            entries: &entries,
        })
    }

    /// Records several 1-D dispatches of `kernel` (`(bind group, invocations)` each, in order) in one
    /// compute pass: no submission and no wait between them.
    pub fn encode_dispatches(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        kernel: &Kernel,
        jobs: &[(wgpu::BindGroup, u32)],
    ) -> Result<()> {
        let layered: Vec<(&wgpu::BindGroup, u32, u32)> = jobs.iter().map(|(b, n)| (b, *n, 1)).collect();
        self.encode_layered_dispatches(encoder, kernel, &layered, None)
    }

    /// A timer of up to `passes` compute passes on the GPU, when the device has timestamp queries and the
    /// debug log is on (it costs a query set and a read-back); `None` otherwise.
    pub fn pass_timer(&self, passes: u32) -> Option<PassTimer> {
        (self.timestamps && log::log_enabled!(log::Level::Debug)).then(|| PassTimer::new(self, passes))
    }

    /// Records one compute pass of `kernel` (a 1-D kernel, whose binding 0 is a
    /// [`Binding::UniformDynamic`]) with one dispatch per job `(dynamic offset, invocations)`, all
    /// through `bind_group`; the pass is timed as pass `index` of `timer` when there is one.
    pub fn encode_dispatches_at(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        kernel: &Kernel,
        bind_group: &wgpu::BindGroup,
        jobs: &[(u32, u32)],
        timer: Option<(&PassTimer, u32)>,
    ) -> Result<()> {
        let grids =
            jobs.iter().map(|&(_, invocations)| self.grid_1d(kernel, invocations)).collect::<Result<Vec<_>>>()?;
        let mut pass = begin_pass(encoder, kernel, timer);
        for (&(offset, _), [x, y, z]) in jobs.iter().zip(grids) {
            if x == 0 {
                continue;
            }
            pass.set_bind_group(0, bind_group, &[offset]);
            pass.dispatch_workgroups(x, y, z);
        }
        Ok(())
    }

    /// Records one compute pass of `kernel` (a 1-D kernel) with one dispatch per job `(bind group,
    /// invocations, layers)`: the 1-D grid of the invocations (see the module doc), repeated `layers` times
    /// along workgroup z (at most `max_compute_workgroups_per_dimension`), so that one dispatch does the same
    /// job for many items (the shader reads its item from `global_invocation_id.z`). The pass is timed as pass
    /// `index` of `timer` when there is one.
    pub fn encode_layered_dispatches(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        kernel: &Kernel,
        jobs: &[(&wgpu::BindGroup, u32, u32)],
        timer: Option<(&PassTimer, u32)>,
    ) -> Result<()> {
        let max_layers = self.limits.max_compute_workgroups_per_dimension;
        let grids = jobs
            .iter()
            .map(|&(_, invocations, layers)| {
                if layers > max_layers {
                    return Err(Error::Gpu(format!(
                        "kernel '{}': {layers} layers exceed the {max_layers} workgroups per dimension",
                        kernel.label
                    )));
                }
                let [x, y, _] = self.grid_1d(kernel, invocations)?;
                Ok([x, y, layers])
            })
            .collect::<Result<Vec<_>>>()?;
        let mut pass = begin_pass(encoder, kernel, timer);
        for ((bind_group, _, _), [x, y, z]) in jobs.iter().zip(grids) {
            if x == 0 || z == 0 {
                continue;
            }
            pass.set_bind_group(0, *bind_group, &[]);
            pass.dispatch_workgroups(x, y, z);
        }
        Ok(())
    }

    /// The workgroup grid of a 1-D dispatch of `invocations` invocations of `kernel` (a 1-D kernel: workgroup
    /// y = z = 1; an error otherwise).
    fn grid_1d(&self, kernel: &Kernel, invocations: u32) -> Result<[u32; 3]> {
        if kernel.workgroup_size[1] != 1 || kernel.workgroup_size[2] != 1 {
            return Err(Error::Gpu(format!(
                "kernel '{}' has workgroup size {:?}; a 1-D dispatch needs y = z = 1",
                kernel.label, kernel.workgroup_size
            )));
        }
        self.workgroup_grid(invocations.div_ceil(kernel.workgroup_size[0]))
    }

    /// Workgroup counts (x, y, 1) covering at least `workgroups` workgroups with x and y within
    /// `max_compute_workgroups_per_dimension`; see the module doc for the index the shader computes.
    pub fn workgroup_grid(&self, workgroups: u32) -> Result<[u32; 3]> {
        workgroup_grid(workgroups, self.limits.max_compute_workgroups_per_dimension)
    }

    /// Records a 1-D dispatch of `invocations` invocations of `kernel` (a 1-D kernel: workgroup y = z = 1).
    pub fn encode_dispatch(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        kernel: &Kernel,
        bind_group: &wgpu::BindGroup,
        invocations: u32,
    ) -> Result<()> {
        self.encode_layered_dispatches(encoder, kernel, &[(bind_group, invocations, 1)], None)
    }

    /// Dispatches `kernel` over `invocations` invocations, then reads the first `count` elements of
    /// `output` back, all in one submission.
    pub fn dispatch_and_read<T: bytemuck::Pod>(
        &self,
        kernel: &Kernel,
        bind_group: &wgpu::BindGroup,
        invocations: u32,
        output: &wgpu::Buffer,
        count: usize,
    ) -> Result<Vec<T>> {
        let mut encoder =
            self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(kernel.label) });
        self.encode_dispatch(&mut encoder, kernel, bind_group, invocations)?;
        self.read_buffer_after(encoder, output, count)
    }

    /// Reads the first `count` elements of type `T` from `buffer` (which needs `COPY_SRC`).
    pub fn read_buffer<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer, count: usize) -> Result<Vec<T>> {
        let encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("read back") });
        self.read_buffer_after(encoder, buffer, count)
    }

    /// Appends a copy of `buffer`'s first `count` elements to `encoder`, submits it, waits, and returns them.
    pub fn read_buffer_after<T: bytemuck::Pod>(
        &self,
        encoder: wgpu::CommandEncoder,
        buffer: &wgpu::Buffer,
        count: usize,
    ) -> Result<Vec<T>> {
        let bytes = (count * std::mem::size_of::<T>()) as u64;
        if bytes > buffer.size() {
            return Err(Error::Gpu(format!(
                "reading {count} elements ({bytes} bytes) from a {}-byte buffer",
                buffer.size()
            )));
        }
        if bytes == 0 {
            return Ok(Vec::new());
        }
        let copy_bytes = bytes.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT).min(buffer.size());
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("read back staging"),
            size: copy_bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.read_buffer_through(encoder, buffer, count, &staging)
    }

    /// Waits until the map callback behind `mapped` has run. Another thread polling the same device (the
    /// engines' fast-path calls run concurrently, and so do tests sharing one context) may collect this
    /// mapping's callback and run it after this thread's `poll` has already returned with the GPU idle,
    /// so one poll is not enough: poll, then wait briefly for the callback, and again, up to
    /// [`MAP_WAIT`].
    ///
    /// `submission` is the submission the mapping waits for: the poll blocks until it is done, not until
    /// the latest one (another caller's batch may be running on another pool set). `None`: the buffer is in
    /// no unfinished submission, so a non-blocking poll maps it.
    fn wait_for_mapping(
        &self,
        mapped: &std::sync::mpsc::Receiver<std::result::Result<(), wgpu::BufferAsyncError>>,
        submission: Option<&wgpu::SubmissionIndex>,
    ) -> Result<std::result::Result<(), wgpu::BufferAsyncError>> {
        let started = std::time::Instant::now();
        loop {
            let until = match submission {
                Some(index) => wgpu::PollType::Wait { submission_index: Some(index.clone()), timeout: None },
                None => wgpu::PollType::Poll,
            };
            self.device.poll(until).map_err(|e| Error::Gpu(format!("waiting for the GPU: {e}")))?;
            match mapped.recv_timeout(std::time::Duration::from_millis(10)) {
                Ok(status) => return Ok(status),
                Err(std::sync::mpsc::RecvTimeoutError::Timeout) if started.elapsed() < MAP_WAIT => continue,
                Err(_) => {
                    return Err(Error::Gpu(format!(
                        "a buffer to map was not mapped {} s after the GPU went idle",
                        MAP_WAIT.as_secs()
                    )))
                }
            }
        }
    }

    /// One of the context's [`BufferPool`] sets, locked: the first free one, else (all taken) the next in
    /// turn, waiting for it.
    pub fn pool(&self) -> std::sync::MutexGuard<'_, BufferPool> {
        for pool in &self.pools {
            match pool.try_lock() {
                Ok(guard) => return guard,
                Err(std::sync::TryLockError::Poisoned(p)) => return p.into_inner(),
                Err(std::sync::TryLockError::WouldBlock) => {}
            }
        }
        let turn = self.next_pool.fetch_add(1, Ordering::Relaxed) % self.pools.len();
        self.pools[turn].lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Ends a frame: trims every pool set ([`BufferPool::trim`]), waiting for a set that a batch holds.
    /// Called once per frame by [`crate::detect`] on the GPU path, so that a long run's GPU memory follows
    /// its recent frames rather than its largest one.
    pub fn end_frame(&self) {
        for pool in &self.pools {
            pool.lock().unwrap_or_else(|p| p.into_inner()).trim();
        }
    }

    /// GPU memory the pool sets hold now ([`BufferPool::bytes`], summed over the sets).
    pub fn pooled_bytes(&self) -> u64 {
        self.pools.iter().map(|pool| pool.lock().unwrap_or_else(|p| p.into_inner()).bytes()).sum()
    }

    /// `pool`'s upload buffer (`MAP_WRITE | COPY_SRC`, label `label`) of at least `bytes`, mapped for
    /// writing: the batch writes its inputs into it, unmaps it and copies them into its storage buffers in
    /// its own submission. Unlike `queue.write_buffer`, which makes a fresh staging buffer per call (new
    /// host memory, page faults), its pages are reused batch after batch. It is re-mapped here: its last
    /// submission has completed (the pool set's holder waited for its read-back), so one poll maps it.
    pub fn mapped_upload(&self, pool: &mut BufferPool, label: &'static str, bytes: u64) -> Result<wgpu::Buffer> {
        let usage = wgpu::BufferUsages::MAP_WRITE | wgpu::BufferUsages::COPY_SRC;
        let upload = pool.buffer(&self.device, label, usage, bytes, self.limits.max_buffer_size);
        if pool.unmapped_uploads.contains(&label) {
            pool.unmapped_uploads.retain(|l| *l != label);
            let (sink, mapped) = std::sync::mpsc::channel();
            upload.map_async(wgpu::MapMode::Write, .., move |r| {
                let _ = sink.send(r);
            });
            if let Err(e) = self.wait_for_mapping(&mapped, None)? {
                return Err(Error::Gpu(format!("mapping the upload buffer: {e}")));
            }
        }
        Ok(upload)
    }

    /// [`GpuContext::read_buffer_after`] through the given `MAP_READ | COPY_DST` staging buffer (a pooled one,
    /// at least as large as what is read; it is unmapped again before this returns).
    pub fn read_buffer_through<T: bytemuck::Pod>(
        &self,
        mut encoder: wgpu::CommandEncoder,
        buffer: &wgpu::Buffer,
        count: usize,
        staging: &wgpu::Buffer,
    ) -> Result<Vec<T>> {
        let bytes = (count * std::mem::size_of::<T>()) as u64;
        if bytes > buffer.size() || bytes > staging.size() {
            return Err(Error::Gpu(format!(
                "reading {count} elements ({bytes} bytes) from a {}-byte buffer through a {}-byte staging buffer",
                buffer.size(),
                staging.size()
            )));
        }
        if bytes == 0 {
            return Ok(Vec::new());
        }
        let copy_bytes = bytes.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT).min(buffer.size()).min(staging.size());
        encoder.copy_buffer_to_buffer(buffer, 0, staging, 0, Some(copy_bytes));
        let submission = self.queue.submit([encoder.finish()]);
        let (sink, mapped) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, ..copy_bytes, move |r| {
            // The receiver is gone only after this call gave up; nothing is left to tell.
            let _ = sink.send(r);
        });
        match self.wait_for_mapping(&mapped, Some(&submission))? {
            Ok(()) => {}
            Err(e) => return Err(Error::Gpu(format!("mapping the read-back buffer: {e}"))),
        }
        let values = {
            let view = staging
                .get_mapped_range(..copy_bytes)
                .map_err(|e| Error::Gpu(format!("reading the mapped buffer: {e}")))?;
            // Collecting (not casting in place) copes with any alignment of the mapping.
            let mut values: Vec<T> = bytemuck::pod_collect_to_vec(&view[..bytes as usize]);
            values.truncate(count);
            values
        };
        staging.unmap();
        Ok(values)
    }
}

/// Begins a compute pass of `kernel` with its pipeline set, timed as pass `index` of `timer` when there is one.
fn begin_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    kernel: &Kernel,
    timer: Option<(&PassTimer, u32)>,
) -> wgpu::ComputePass<'e> {
    let timestamp_writes = timer.map(|(timer, index)| wgpu::ComputePassTimestampWrites {
        query_set: &timer.queries,
        beginning_of_pass_write_index: Some(2 * index),
        end_of_pass_write_index: Some(2 * index + 1),
    });
    let mut pass =
        encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(kernel.label), timestamp_writes });
    pass.set_pipeline(&kernel.pipeline);
    pass
}

/// GPU timestamps at the beginning and end of a few compute passes (a diagnostic for the debug log).
pub struct PassTimer {
    queries: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    passes: u32,
}

impl PassTimer {
    fn new(ctx: &GpuContext, passes: u32) -> PassTimer {
        let queries = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("pass timer"),
            ty: wgpu::QueryType::Timestamp,
            count: 2 * passes,
        });
        let resolved = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pass timer resolved"),
            size: 16 * u64::from(passes),
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        PassTimer { queries, resolved, passes }
    }

    /// Records the resolution of the timestamps into `encoder` (after the timed passes).
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.queries, 0..2 * self.passes, &self.resolved, 0);
    }

    /// Seconds each pass took on the GPU (after the encoder that [`PassTimer::resolve`]d was submitted; a
    /// pass that did not run reads 0).
    pub fn seconds(&self, ctx: &GpuContext) -> Result<Vec<f64>> {
        let encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pass timer") });
        let ticks: Vec<u64> = ctx.read_buffer_after(encoder, &self.resolved, 2 * self.passes as usize)?;
        let period = f64::from(ctx.queue.get_timestamp_period()) * 1e-9;
        Ok(ticks.chunks(2).map(|t| t[1].saturating_sub(t[0]) as f64 * period).collect())
    }
}

/// Splits `workgroups` over x and y: x ≤ `max_per_dimension`, y = ⌈workgroups / x⌉ ≤ `max_per_dimension`,
/// x·y ≥ workgroups with fewer than y spare workgroups.
pub fn workgroup_grid(workgroups: u32, max_per_dimension: u32) -> Result<[u32; 3]> {
    if workgroups <= max_per_dimension {
        return Ok([workgroups, 1, 1]);
    }
    let y = workgroups.div_ceil(max_per_dimension);
    if y > max_per_dimension {
        return Err(Error::Gpu(format!(
            "{workgroups} workgroups exceed {max_per_dimension}² (the per-dimension limit squared); chunk the job"
        )));
    }
    Ok([workgroups.div_ceil(y), y, 1])
}

/// The three error scopes (validation, out of memory, internal) pushed together and popped in reverse.
struct ErrorScopes {
    guards: Vec<wgpu::ErrorScopeGuard>,
}

impl ErrorScopes {
    fn push(device: &wgpu::Device) -> ErrorScopes {
        let guards = [wgpu::ErrorFilter::Validation, wgpu::ErrorFilter::OutOfMemory, wgpu::ErrorFilter::Internal]
            .into_iter()
            .map(|filter| device.push_error_scope(filter))
            .collect();
        ErrorScopes { guards }
    }

    /// Pops all scopes; the first captured error becomes `Error::Gpu` prefixed with `what`.
    fn pop(mut self, what: &str) -> Result<()> {
        let mut first_error = None;
        while let Some(guard) = self.guards.pop() {
            if let Some(e) = pollster::block_on(guard.pop()) {
                first_error.get_or_insert(e);
            }
        }
        match first_error {
            Some(e) => Err(Error::Gpu(format!("{what}: {e}"))),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texel_rows_hold_the_bytes_in_whole_rows_of_256_byte_multiples() {
        // 8192 texels of 16 bytes: 131 072 bytes a row, a multiple of the copy alignment.
        assert_eq!(TexelRows::ROW_BYTES, 131_072);
        assert_eq!(TexelRows::ROW_BYTES % u64::from(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT), 0);
        let rows = |bytes| TexelRows::for_bytes(bytes, 8192, "test").map(|r| r.rows);
        assert_eq!(rows(0).unwrap(), 1, "an empty buffer still gets a texture of one row");
        assert_eq!(rows(16).unwrap(), 1);
        assert_eq!(rows(131_072).unwrap(), 1);
        assert_eq!(rows(131_073).unwrap(), 2);
        assert_eq!(TexelRows::for_bytes(131_073, 8192, "test").unwrap().bytes(), 262_144);
        // 8192 rows are 1 GiB; one byte more needs a row the device does not have.
        assert_eq!(rows(1 << 30).unwrap(), 8192);
        let err = TexelRows::for_bytes((1 << 30) + 1, 8192, "the tables").unwrap_err().to_string();
        assert!(err.contains("the tables") && err.contains("8193 texture rows"), "{err}");
    }

    #[test]
    fn pooled_resources_grow_by_half_within_the_maximum() {
        assert_eq!(grown(None, 120u64, 1000), 120, "a first request gets what it asks");
        assert_eq!(grown(Some(100u64), 120, 1000), 150, "half as large again as the kept one");
        assert_eq!(grown(Some(100u64), 400, 1000), 400, "or the request when that is more");
        assert_eq!(grown(Some(100u32), 120, 130), 130, "capped at the maximum");
        assert_eq!(grown(Some(100u32), 140, 130), 140, "unless the request itself is over it");
    }

    #[test]
    fn a_pooled_resource_is_kept_while_a_recent_frame_asked_for_at_least_half_of_it() {
        // Asked for its own size every frame: never let go.
        let mut steady = Pooled::new("steady", (), (), 1000);
        for frame in 0..100 {
            assert!(steady.keep_after_frame(1000), "frame {frame}");
            steady.want(1000);
        }
        // One large frame (1000), then small ones (100): kept while the large request is among the last
        // TRIM_FRAMES frames (ends 1..=8), let go at the ninth frame's end (1000 > 2·100).
        let mut large = Pooled::new("large", (), (), 1000);
        for end in 1..=TRIM_FRAMES {
            assert!(large.keep_after_frame(1000), "end {end}");
            large.want(100);
        }
        assert!(!large.keep_after_frame(1000), "nine frames after the large one");
        // Half as large again as the requests (the growth of `grown`) is within the slack.
        let mut grown_once = Pooled::new("grown", (), (), 100);
        for end in 0..3 * TRIM_FRAMES {
            assert!(grown_once.keep_after_frame(150), "end {end}");
            grown_once.want(100);
        }
        assert!(Pooled::new("edge", (), (), 100).keep_after_frame(200), "exactly TRIM_SLACK times is kept");
        assert!(!Pooled::new("edge", (), (), 100).keep_after_frame(201), "more is not");
        // Asked for once, then never: let go at the end of the ninth frame.
        let mut unused = Pooled::new("unused", (), (), 64);
        for end in 1..=TRIM_FRAMES {
            assert!(unused.keep_after_frame(64), "end {end}");
        }
        assert!(!unused.keep_after_frame(64));
    }

    #[test]
    fn pool_slots_default_to_two_and_take_one_to_eight() {
        assert_eq!(parse_pool_slots(None).unwrap(), DEFAULT_POOL_SLOTS);
        assert_eq!(DEFAULT_POOL_SLOTS, 2);
        assert_eq!(parse_pool_slots(Some("1")).unwrap(), 1);
        assert_eq!(parse_pool_slots(Some(" 8 ")).unwrap(), 8);
        for bad in ["0", "9", "two", "", "-1", "2.5"] {
            let message = parse_pool_slots(Some(bad)).unwrap_err().to_string();
            assert!(message.contains("COG_GPU_POOL_SLOTS") && message.contains(&format!("'{bad}'")), "{message}");
        }
    }

    #[test]
    fn grid_stays_in_one_row_below_the_limit() {
        assert_eq!(workgroup_grid(0, 65535).unwrap(), [0, 1, 1]);
        assert_eq!(workgroup_grid(4800, 65535).unwrap(), [4800, 1, 1]);
        assert_eq!(workgroup_grid(65535, 65535).unwrap(), [65535, 1, 1]);
    }

    #[test]
    fn grid_splits_over_y_and_covers_the_job() {
        // 10 workgroups with at most 4 per dimension: y = 3 rows of x = 4 (12 ≥ 10, 2 spare < y).
        assert_eq!(workgroup_grid(10, 4).unwrap(), [4, 3, 1]);
        for (n, max) in [(65536u32, 65535u32), (1_000_000, 65535), (16, 4), (15, 4), (5, 4)] {
            let [x, y, z] = workgroup_grid(n, max).unwrap();
            assert!(x <= max && y <= max && z == 1, "{n}/{max}: {x}×{y}");
            assert!(x as u64 * y as u64 >= n as u64, "{n}/{max}: {x}×{y} does not cover");
            assert!((x as u64 * y as u64) - (n as u64) < y as u64, "{n}/{max}: {x}×{y} wastes a whole column");
        }
        assert!(workgroup_grid(4 * 4 + 1, 4).is_err(), "17 > 4² must not be silently truncated");
    }

    #[test]
    fn limits_are_webgpu_defaults_with_buffer_sizes_from_the_adapter() {
        let adapter = wgpu::Limits {
            max_storage_buffer_binding_size: 4 << 30,
            max_buffer_size: 512 << 20,
            max_compute_workgroup_storage_size: 32768,
            ..wgpu::Limits::default()
        };
        let limits = required_limits(&adapter);
        assert_eq!(limits.max_storage_buffer_binding_size, MAX_BUFFER_BYTES);
        assert_eq!(limits.max_buffer_size, 512 << 20);
        assert_eq!(limits.max_compute_workgroup_storage_size, 16384, "not raised: kernels stay in the defaults");
        assert_eq!(limits.max_compute_workgroups_per_dimension, 65535);
    }
}
