//! What a scattered `vec4` read costs a compute shader on the adapter wgpu picks, by the kind of binding it
//! reads from: the measurement behind `gpu::TexelRows` (the fast kernel reads its tables, boundaries and
//! weights as textures because lavapipe runs storage-buffer loads lane by lane).
//!
//! ```sh
//! NODEVICE_SELECT=1 cargo run --release --example lavapipe_loads
//! ```
//!
//! Each kernel runs 2¹⁷ invocations of 256 dependent-free reads at hashed indices (a read the compiler
//! cannot hoist) and xors them into one word per invocation; the second of two runs is timed (the first
//! compiles the pipeline), from submission to completion. Kinds: `storage` (`var<storage, read>`, indices
//! over 16 MB), `texture` (`textureLoad` of an `rgba32uint` texture 1024 texels wide, the same 16 MB),
//! `uniform` (`var<uniform>`, 64 KB), `storage-small` and `texture-small` (indices within the first
//! 64 KB, so cache-resident like the uniform's), `storage-same` (one index per workgroup: every lane
//! reads the same word).
use std::time::Instant;
use wgpu::util::DeviceExt;

/// Reads per invocation.
const READS: u32 = 256;
/// Invocations per dispatch.
const INVOCATIONS: u32 = 64 * 2048;
/// `vec4` elements of the storage buffer and the texture (16 MB).
const ELEMENTS: u32 = 1 << 20;
/// Texels per texture row.
const WIDTH: u32 = 1024;
/// `vec4` elements of the uniform buffer (64 KB, the WebGPU default binding limit).
const UNIFORM_ELEMENTS: u32 = 4096;

/// The WGSL declaration of binding 0 and its `fetch`, per kind.
fn declaration(kind: &str) -> String {
    let storage = "@group(0) @binding(0) var<storage, read> t: array<vec4<u32>>;";
    let texture = "@group(0) @binding(0) var t: texture_2d<u32>;";
    let uniform = format!("@group(0) @binding(0) var<uniform> t: array<vec4<u32>, {UNIFORM_ELEMENTS}>;");
    let small = format!("% {UNIFORM_ELEMENTS}u");
    match kind {
        "storage" | "storage-same" => format!("{storage} fn fetch(i: u32) -> vec4<u32> {{ return t[i]; }}"),
        "storage-small" => format!("{storage} fn fetch(i: u32) -> vec4<u32> {{ return t[i {small}]; }}"),
        "texture" => {
            format!("{texture} fn fetch(i: u32) -> vec4<u32> {{ return textureLoad(t, vec2<u32>(i % {WIDTH}u, i / {WIDTH}u), 0); }}")
        }
        "texture-small" => format!(
            "{texture} fn fetch(i: u32) -> vec4<u32> {{ let j = i {small}; return textureLoad(t, vec2<u32>(j % {WIDTH}u, j / {WIDTH}u), 0); }}"
        ),
        _ => format!("{uniform} fn fetch(i: u32) -> vec4<u32> {{ return t[i {small}]; }}"),
    }
}

fn shader(kind: &str) -> String {
    // A per-lane index, or one per workgroup for `storage-same`.
    let index = if kind == "storage-same" { "hash(r * 7u + wg.x)" } else { "hash(r * 7919u + g.x)" };
    format!(
        "fn hash(x: u32) -> u32 {{ var h = x * 747796405u + 2891336453u; h = ((h >> ((h >> 28u) + 4u)) ^ h) * 277803737u; return (h >> 22u) ^ h; }}
{}
@group(0) @binding(1) var<storage, read_write> o: array<u32>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) g: vec3<u32>, @builtin(workgroup_id) wg: vec3<u32>) {{
    var acc = vec4<u32>(0u);
    for (var r = 0u; r < {READS}u; r++) {{ acc += fetch({index} % {ELEMENTS}u); }}
    o[g.x] = acc.x ^ acc.y ^ acc.z ^ acc.w;
}}",
        declaration(kind)
    )
}

fn main() {
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
        backends: cog_gpu::gpu::PRIMARY_BACKENDS,
        ..wgpu::InstanceDescriptor::new_without_display_handle()
    });
    let Ok(adapter) = pollster::block_on(instance.request_adapter(&Default::default())) else {
        eprintln!(
            "lavapipe_loads: no Vulkan, Metal or DX12 adapter (for lavapipe: apt-get install mesa-vulkan-drivers)"
        );
        std::process::exit(1);
    };
    println!("adapter: {}", adapter.get_info().name);
    let (device, queue) = pollster::block_on(adapter.request_device(&Default::default())).expect("a device");
    let words: Vec<u32> = (0..ELEMENTS * 4).map(|i| i.wrapping_mul(2_654_435_761)).collect();
    let bytes: &[u8] = bytemuck::cast_slice(&words);
    let storage = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytes,
        usage: wgpu::BufferUsages::STORAGE,
    });
    let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: &bytes[..UNIFORM_ELEMENTS as usize * 16],
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let texture = device.create_texture_with_data(
        &queue,
        &wgpu::TextureDescriptor {
            label: None,
            size: wgpu::Extent3d { width: WIDTH, height: ELEMENTS / WIDTH, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba32Uint,
            usage: wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        },
        wgpu::util::TextureDataOrder::LayerMajor,
        bytes,
    );
    let view = texture.create_view(&Default::default());
    let out = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: u64::from(INVOCATIONS) * 4,
        usage: wgpu::BufferUsages::STORAGE,
        mapped_at_creation: false,
    });
    for kind in ["storage", "texture", "uniform", "storage-small", "texture-small", "storage-same"] {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(kind),
            source: wgpu::ShaderSource::Wgsl(shader(kind).into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(kind),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let source = match kind {
            "texture" | "texture-small" => wgpu::BindingResource::TextureView(&view),
            "uniform" => uniform.as_entire_binding(),
            _ => storage.as_entire_binding(),
        };
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(kind),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: source },
                wgpu::BindGroupEntry { binding: 1, resource: out.as_entire_binding() },
            ],
        });
        let mut seconds = 0.0;
        for _ in 0..2 {
            let started = Instant::now();
            let mut encoder = device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(&pipeline);
                pass.set_bind_group(0, &bind_group, &[]);
                pass.dispatch_workgroups(INVOCATIONS / 64, 1, 1);
            }
            queue.submit([encoder.finish()]);
            device.poll(wgpu::PollType::wait_indefinitely()).expect("the dispatch completes");
            seconds = started.elapsed().as_secs_f64();
        }
        let reads = f64::from(INVOCATIONS) * f64::from(READS);
        println!("{kind:14} {seconds:.3} s  {:.1} ns per vec4 read", seconds * 1e9 / reads);
    }
}
