//! Every WGSL file under `shaders/` parses and validates with naga (the front end wgpu uses), and stays
//! within the WebGPU default compute limits: workgroup storage ≤ 16384 bytes per entry point and
//! ≤ 256 invocations per workgroup. New shaders are covered by dropping them into the directory.

use std::path::{Path, PathBuf};

use naga::valid::{Capabilities, ValidationFlags, Validator};

/// WebGPU default `maxComputeWorkgroupStorageSize`.
const MAX_WORKGROUP_STORAGE_BYTES: u32 = 16384;
/// WebGPU default `maxComputeInvocationsPerWorkgroup`.
const MAX_INVOCATIONS_PER_WORKGROUP: u32 = 256;
/// WebGPU default `maxComputeWorkgroupSizeX/Y/Z`.
const MAX_WORKGROUP_SIZE: [u32; 3] = [256, 256, 64];

fn shader_files() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|entry| entry.expect("directory entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "wgsl"))
        .collect();
    files.sort();
    files
}

/// Parses and validates with no optional capabilities: what a device with no requested features accepts.
fn validate(source: &str) -> Result<(naga::Module, naga::valid::ModuleInfo), String> {
    let module = naga::front::wgsl::parse_str(source).map_err(|e| e.emit_to_string(source))?;
    let info = Validator::new(ValidationFlags::all(), Capabilities::empty())
        .validate(&module)
        .map_err(|e| e.emit_to_string(source))?;
    Ok((module, info))
}

/// Bytes of `var<workgroup>` storage each entry point uses, counted as WebGPU does: each variable's size
/// rounded up to 16 bytes.
fn workgroup_storage_per_entry_point(module: &naga::Module, info: &naga::valid::ModuleInfo) -> Vec<(String, u32)> {
    let mut layouter = naga::proc::Layouter::default();
    layouter.update(module.to_ctx()).expect("type layouts");
    module
        .entry_points
        .iter()
        .enumerate()
        .map(|(i, ep)| {
            let uses = info.get_entry_point(i);
            let bytes = module
                .global_variables
                .iter()
                .filter(|(handle, var)| var.space == naga::AddressSpace::WorkGroup && !uses[*handle].is_empty())
                .map(|(_, var)| layouter[var.ty].size.next_multiple_of(16))
                .sum();
            (ep.name.clone(), bytes)
        })
        .collect()
}

#[test]
fn shaders_directory_is_not_empty() {
    let files = shader_files();
    assert!(
        files.iter().any(|f| f.ends_with("depth_points.wgsl")),
        "shaders/ must hold depth_points.wgsl, found {files:?}"
    );
}

#[test]
fn every_shader_validates_and_fits_the_default_limits() {
    let mut failures = Vec::new();
    for path in shader_files() {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let source = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let (module, info) = match validate(&source) {
            Ok(v) => v,
            Err(e) => {
                failures.push(format!("{name}: invalid WGSL:\n{e}"));
                continue;
            }
        };
        let compute: Vec<_> = module.entry_points.iter().filter(|ep| ep.stage == naga::ShaderStage::Compute).collect();
        if compute.is_empty() {
            failures.push(format!("{name}: no @compute entry point"));
        }
        for ep in compute {
            let size = ep.workgroup_size;
            let invocations: u32 = size.iter().product();
            if invocations > MAX_INVOCATIONS_PER_WORKGROUP || size.iter().zip(MAX_WORKGROUP_SIZE).any(|(s, m)| *s > m) {
                failures.push(format!("{name}: entry point '{}' has workgroup size {size:?}", ep.name));
            }
        }
        for (entry, bytes) in workgroup_storage_per_entry_point(&module, &info) {
            eprintln!("{name}: {entry}: {bytes} bytes of workgroup storage");
            if bytes > MAX_WORKGROUP_STORAGE_BYTES {
                failures.push(format!("{name}: entry point '{entry}' uses {bytes} > {MAX_WORKGROUP_STORAGE_BYTES} bytes of workgroup storage"));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn validator_rejects_broken_shaders() {
    // A type error the parser accepts but the validator must catch would be ideal; WGSL's front end
    // already type-checks, so check both stages catch something.
    let type_error = "@compute @workgroup_size(1) fn main() { let a: u32 = 1.5; }";
    assert!(validate(type_error).is_err(), "a float assigned to a u32 must be rejected");
    // Writing through a read-only storage buffer is caught by the front end or the validator.
    let read_only_write = "@group(0) @binding(0) var<storage, read> data: array<u32>;\n\
                           @compute @workgroup_size(1) fn main() { data[0] = 1u; }";
    assert!(validate(read_only_write).is_err(), "a store to var<storage, read> must be rejected");
    let fine = "@group(0) @binding(0) var<storage, read_write> data: array<u32>;\n\
                @compute @workgroup_size(1) fn main() { data[0] = 1u; }";
    assert!(validate(fine).is_ok(), "the same shader with read_write must validate");
}

#[test]
fn workgroup_storage_is_counted_per_entry_point() {
    // 3000 f32 (12000 bytes) used by `a`, 100 vec4 (1600 bytes) used by `b`, one u32 (4 → 16 bytes) by both.
    let source = "var<workgroup> big: array<f32, 3000>;\n\
                  var<workgroup> small: array<vec4<f32>, 100>;\n\
                  var<workgroup> flag: u32;\n\
                  @compute @workgroup_size(64) fn a() { big[0] = f32(flag); }\n\
                  @compute @workgroup_size(64) fn b() { small[0] = vec4<f32>(f32(flag)); }";
    let (module, info) = validate(source).expect("valid");
    let sizes = workgroup_storage_per_entry_point(&module, &info);
    assert_eq!(sizes, vec![("a".to_string(), 12000 + 16), ("b".to_string(), 1600 + 16)]);
    // And one that is too large must show up as such.
    let (module, info) =
        validate("var<workgroup> huge: array<f32, 4097>;\n@compute @workgroup_size(64) fn main() { huge[0] = 1.0; }")
            .expect("valid");
    let sizes = workgroup_storage_per_entry_point(&module, &info);
    assert!(sizes[0].1 > MAX_WORKGROUP_STORAGE_BYTES, "{sizes:?}");
}
