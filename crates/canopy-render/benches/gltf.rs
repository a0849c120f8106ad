//! glTF benchmarks: load time of CesiumMilkTruck and of a fleet of 4096 trucks (each a
//! copy of the truck's node tree sharing its meshes and textures: 20,480 instances), and
//! the share of render time texture lookups take (the truck rendered with its textures
//! and with its factors alone, in the same run).
//!
//! `cargo bench -p canopy-render --bench gltf`

use canopy_render::gltf_scene::parse_gltf;
use canopy_render::scene_file::DirAssets;
use canopy_render::texture::MaterialMaps;
use canopy_render::{integrator, Accel};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use serde_json::Value;
use std::path::PathBuf;
use std::time::Duration;

fn truck_path() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../scenes/gltf/CesiumMilkTruck.glb"
    ))
}

/// The JSON and binary chunks of a GLB file.
fn chunks(glb: &[u8]) -> (Value, Vec<u8>) {
    let chunk = |at: usize| {
        let len = u32::from_le_bytes(glb[at..at + 4].try_into().unwrap()) as usize;
        (glb[at + 8..at + 8 + len].to_vec(), at + 8 + len)
    };
    let (json, next) = chunk(12);
    let (bin, _) = chunk(next);
    (serde_json::from_slice(&json).unwrap(), bin)
}

fn glb(json: &Value, bin: &[u8]) -> Vec<u8> {
    let pad = |mut v: Vec<u8>, with: u8| {
        while !v.len().is_multiple_of(4) {
            v.push(with);
        }
        v
    };
    let json = pad(serde_json::to_vec(json).unwrap(), b' ');
    let bin = pad(bin.to_vec(), 0);
    let mut out = b"glTF".to_vec();
    out.extend(2u32.to_le_bytes());
    out.extend(((12 + 8 + json.len() + 8 + bin.len()) as u32).to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    out
}

/// The truck's scene `copies` times on a grid: every node copied per truck (a node has
/// one parent), meshes, materials and images shared.
fn fleet(truck: &[u8], copies: usize) -> Vec<u8> {
    let (mut json, bin) = chunks(truck);
    let nodes = json["nodes"].as_array().unwrap().clone();
    let scene = json["scene"].as_u64().unwrap_or(0) as usize;
    let roots: Vec<u64> = json["scenes"][scene]["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_u64().unwrap())
        .collect();
    let side = (copies as f64).sqrt().ceil() as usize;
    let mut all = Vec::new();
    let mut parents = Vec::new();
    for copy in 0..copies {
        let base = (all.len() + copies) as u64;
        for node in &nodes {
            let mut node = node.clone();
            if let Some(children) = node.get_mut("children") {
                for c in children.as_array_mut().unwrap() {
                    *c = (c.as_u64().unwrap() + base).into();
                }
            }
            all.push(node);
        }
        let (x, z) = ((copy % side) as f64 * 6.0, (copy / side) as f64 * 4.0);
        parents.push(serde_json::json!({
            "translation": [x, 0.0, z],
            "children": roots.iter().map(|r| r + base).collect::<Vec<_>>(),
        }));
    }
    parents.extend(all);
    json["nodes"] = parents.into();
    json["scenes"][scene]["nodes"] = (0..copies as u64).collect::<Vec<_>>().into();
    glb(&json, &bin)
}

fn load(c: &mut Criterion) {
    let truck = std::fs::read(truck_path()).unwrap();
    let (assets, _) = DirAssets::beside(&truck_path());
    let many = fleet(&truck, 4096);
    let instances = parse_gltf(&many, &assets, "fleet").unwrap().instances.len();
    let mut group = c.benchmark_group("gltf/load");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500));
    group.bench_function("CesiumMilkTruck", |b| {
        b.iter(|| parse_gltf(&truck, &assets, "truck").unwrap())
    });
    group.throughput(Throughput::Elements(instances as u64));
    group.bench_function(format!("fleet-{instances}-instances"), |b| {
        b.iter(|| parse_gltf(&many, &assets, "fleet").unwrap())
    });
    group.finish();
}

fn textures(c: &mut Criterion) {
    let truck = std::fs::read(truck_path()).unwrap();
    let (assets, _) = DirAssets::beside(&truck_path());
    let mut textured = parse_gltf(&truck, &assets, "truck").unwrap();
    (
        textured.settings.width,
        textured.settings.height,
        textured.settings.spp,
    ) = (160, 160, 4);
    let mut plain = textured.clone();
    plain.material_maps = vec![MaterialMaps::default(); plain.material_maps.len()];
    let accel = Accel::default_for(&textured);
    assert!(textured.is_textured() && !plain.is_textured());
    let (a, b) = (
        integrator::render(&textured, &accel, &|| {}).0,
        integrator::render(&plain, &accel, &|| {}).0,
    );
    assert_ne!(a.pixels, b.pixels, "the textures show");
    let mut group = c.benchmark_group("gltf/render-truck-160px-4spp");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500));
    group.bench_function("textured", |b| {
        b.iter(|| integrator::render(&textured, &accel, &|| {}))
    });
    group.bench_function("factors-only", |b| {
        b.iter(|| integrator::render(&plain, &accel, &|| {}))
    });
    group.finish();
}

criterion_group!(benches, load, textures);
criterion_main!(benches);
