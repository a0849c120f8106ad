//! Traces a file of rays against a mesh with canopy's fastest layout and batch API, for
//! `bench/embree_compare.py`: times each query over several runs and writes the hits.
//!
//! ```text
//! cargo run --release -p canopy-render --example trace_rays -- \
//!     MESH.ply RAYS.f32 closest|occluded THREADS RUNS OUT.bin [BUILDER] [WIDTH]
//! ```
//!
//! `RAYS.f32`: little-endian f32 records `ox oy oz dx dy dz t_min t_max`. `OUT.bin`: for
//! `closest`, the arrays t (f32, inf on a miss), prim (i32, -1 on a miss), u, v (f32)
//! one after the other; for `occluded`, one byte per ray. Prints one JSON line.

use canopy_bvh::{build, Aabb, BuildParams, Builder, Bvh4, Bvh8, BvhN, Hit, Ray};
use canopy_render::mesh::{parse_mesh, MeshFormat};
use glam::Vec3;
use std::time::Instant;

fn main() {
    if let Err(e) = run() {
        eprintln!("trace_rays: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 6 {
        return Err("usage: MESH RAYS closest|occluded THREADS RUNS OUT [BUILDER] [WIDTH]".into());
    }
    let (mesh_path, rays_path, query) = (&args[0], &args[1], args[2].as_str());
    let threads: usize = args[3].parse().map_err(|e| format!("threads: {e}"))?;
    let runs: usize = args[4].parse().map_err(|e| format!("runs: {e}"))?;
    let builder: Builder = args
        .get(6)
        .map_or(Ok(Builder::BinnedSah), |b| b.parse())
        .map_err(|e| e.to_string())?;
    let width = args.get(7).map_or("8", String::as_str);

    let format = MeshFormat::from_path(mesh_path).map_err(|e| e.to_string())?;
    let bytes = std::fs::read(mesh_path).map_err(|e| format!("{mesh_path}: {e}"))?;
    let mesh = parse_mesh(&bytes, format).map_err(|e| format!("{mesh_path}: {e}"))?;
    let triangles: Vec<[Vec3; 3]> = mesh
        .triangles
        .iter()
        .map(|t| t.map(|i| mesh.positions[i as usize]))
        .collect();
    let rays = read_rays(rays_path)?;

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| e.to_string())?;
    let start = Instant::now();
    let boxes: Vec<Aabb> = triangles.iter().map(|t| Aabb::from_points(*t)).collect();
    let params = BuildParams {
        max_leaf_size: std::env::var("CANOPY_LEAF")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(BuildParams::default().max_leaf_size),
        // Leaves priced in packs for the packed wide layouts, as the renderer builds them.
        leaf_block: if width == "2" {
            1
        } else {
            canopy_bvh::PACK_LANES as u32
        },
        ..BuildParams::default()
    };
    let bvh = pool.install(|| build(builder, &boxes, &params));
    let build_ms = start.elapsed().as_secs_f64() * 1e3;
    let (times, output) = match width {
        "4" => trace(
            &pack(Bvh4::from_bvh2(&bvh), &triangles),
            &rays,
            query,
            runs,
            &pool,
        )?,
        "8" => trace(
            &pack(Bvh8::from_bvh2(&bvh), &triangles),
            &rays,
            query,
            runs,
            &pool,
        )?,
        w => return Err(format!("width must be 4 or 8, not {w}")),
    };
    std::fs::write(&args[5], output).map_err(|e| format!("{}: {e}", args[5]))?;
    let mut sorted = times.clone();
    sorted.sort_by(f64::total_cmp);
    let mrays = |s: f64| rays.len() as f64 / s / 1e6;
    println!(
        "{{\"query\": \"{query}\", \"threads\": {threads}, \"rays\": {}, \"builder\": \"{builder}\", \
         \"width\": {width}, \"isa\": \"{}\", \"build_ms\": {build_ms:.2}, \"best_mrays\": {:.3}, \
         \"median_mrays\": {:.3}}}",
        rays.len(),
        canopy_bvh::Isa::best(),
        mrays(sorted[0]),
        mrays(sorted[sorted.len() / 2]),
    );
    Ok(())
}

fn pack<const N: usize>(mut bvh: BvhN<N>, triangles: &[[Vec3; 3]]) -> BvhN<N> {
    bvh.pack_triangles(|p| Some(triangles[p as usize]));
    bvh
}

fn read_rays(path: &str) -> Result<Vec<Ray>, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("{path}: {e}"))?;
    if bytes.len() % 32 != 0 {
        return Err(format!("{path}: not a whole number of 32-byte ray records"));
    }
    let f: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    Ok(f.chunks_exact(8)
        .map(|r| {
            Ray::new(
                Vec3::new(r[0], r[1], r[2]),
                Vec3::new(r[3], r[4], r[5]),
                r[6],
                r[7],
            )
        })
        .collect())
}

type Traced = (Vec<f64>, Vec<u8>);

fn trace<const N: usize>(
    bvh: &BvhN<N>,
    rays: &[Ray],
    query: &str,
    runs: usize,
    pool: &rayon::ThreadPool,
) -> Result<Traced, String>
where
    BvhN<N>: Batch,
{
    let mut times = Vec::new();
    let output = match query {
        "closest" => {
            let mut hits = vec![None; rays.len()];
            for _ in 0..runs.max(1) {
                let start = Instant::now();
                pool.install(|| bvh.closest_all(rays, &mut hits));
                times.push(start.elapsed().as_secs_f64());
            }
            let miss = Hit {
                t: f32::INFINITY,
                prim: u32::MAX,
                u: 0.0,
                v: 0.0,
            };
            let hits: Vec<Hit> = hits.iter().map(|h| h.unwrap_or(miss)).collect();
            let mut out = Vec::with_capacity(16 * hits.len());
            hits.iter().for_each(|h| out.extend(h.t.to_le_bytes()));
            hits.iter().for_each(|h| out.extend(h.prim.to_le_bytes()));
            hits.iter().for_each(|h| out.extend(h.u.to_le_bytes()));
            hits.iter().for_each(|h| out.extend(h.v.to_le_bytes()));
            out
        }
        "occluded" => {
            let mut occluded = vec![false; rays.len()];
            for _ in 0..runs.max(1) {
                let start = Instant::now();
                pool.install(|| bvh.any_all(rays, &mut occluded));
                times.push(start.elapsed().as_secs_f64());
            }
            occluded.iter().map(|&o| o as u8).collect()
        }
        q => return Err(format!("query must be closest or occluded, not {q}")),
    };
    Ok((times, output))
}

/// The batch calls of a triangle-only tree (the closure is never called).
trait Batch {
    fn closest_all(&self, rays: &[Ray], hits: &mut [Option<Hit>]);
    fn any_all(&self, rays: &[Ray], out: &mut [bool]);
}

macro_rules! batch {
    ($($t:ty),*) => {$(
        impl Batch for $t {
            fn closest_all(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
                self.intersect_batch(rays, hits, |_, _| None::<f32>);
            }
            fn any_all(&self, rays: &[Ray], out: &mut [bool]) {
                self.occluded_batch(rays, out, |_, _| false);
            }
        }
    )*};
}
batch!(Bvh4, Bvh8);
