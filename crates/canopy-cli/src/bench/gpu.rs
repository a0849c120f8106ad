//! `canopy bench gpu`: the same renders on the CPU and on the GPU in one run — seconds,
//! Mrays/s and the GPU's speed-up — with the report's estimator (`bsdf`, so that times
//! compare with its tables) unless asked otherwise. The GPU renders one sample per pixel
//! per dispatch, as `canopy render --device gpu` does.

use crate::limits;
use anyhow::Context;
use canopy_bvh::BuildParams;
use canopy_render::{
    load_scene_allowing, render, Accel, AccelKind, Accumulator, BvhWidth, Integrator, Scene,
};
use clap::Args;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct GpuArgs {
    /// Scenes: built-in names, scene files, meshes or glTF models [default: paper-1,
    /// paper-5, bench/scenes/dragon-lit.toml (the 202k dragon), and the textured
    /// CesiumMilkTruck and AlphaBlendModeTest from scenes/gltf, where they load].
    scenes: Vec<String>,
    /// Image size WIDTHxHEIGHT, each 1 to 65536.
    #[arg(long, default_value = "480x480", value_parser = limits::size)]
    size: (u32, u32),
    /// Samples per pixel.
    #[arg(long, default_value = "128", value_parser = limits::spp())]
    spp: u32,
    /// Most ray segments per path (the report's 4 bounces).
    #[arg(long, default_value = "4", value_parser = limits::depth())]
    depth: u32,
    /// Estimator: `bsdf` (the report's) or `path` (light sampling).
    #[arg(long, default_value = "bsdf")]
    integrator: Integrator,
    /// CPU worker threads, 1 to 1024 [default: all cores].
    #[arg(long, value_parser = limits::threads())]
    threads: Option<u32>,
    /// A folder the scenes may also read files from (see `canopy render --allow-path`).
    #[arg(long, value_name = "DIR")]
    allow_path: Vec<PathBuf>,
}

struct Row {
    scene: String,
    device: String,
    seconds: f64,
    rays: u64,
}

pub fn run(args: &GpuArgs) -> anyhow::Result<()> {
    let gpu = canopy_gpu::Gpu::new()?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0) as usize)
        .build()
        .context("cannot start the worker threads")?;
    let scenes = if args.scenes.is_empty() {
        default_scenes(&args.allow_path)
    } else {
        args.scenes.clone()
    };
    let params = BuildParams::default();
    let mut rows = Vec::new();
    for name in &scenes {
        // Mesh instances stay instances on both devices (two-level traversal).
        let mut scene = load_scene_allowing(name, &args.allow_path)?;
        (scene.settings.width, scene.settings.height) = args.size;
        scene.settings.spp = args.spp;
        scene.settings.max_depth = args.depth;
        scene.settings.integrator = args.integrator;
        let cpu = pool.install(|| {
            let accel =
                Accel::for_scene(&scene, AccelKind::default(), BvhWidth::Eight, &params, None);
            let start = Instant::now();
            let (_, stats) = render(&scene, &accel, &|| {});
            (start.elapsed().as_secs_f64(), stats.rays)
        });
        rows.push(Row {
            scene: name.clone(),
            device: format!("CPU, {} threads", pool.current_num_threads()),
            seconds: cpu.0,
            rays: cpu.1,
        });
        let (seconds, rays) = render_on_gpu(&gpu, &scene, &params)?;
        rows.push(Row {
            scene: name.clone(),
            device: gpu.describe(),
            seconds,
            rays,
        });
    }
    print_table(args, &rows, &gpu);
    Ok(())
}

/// The built-in reference scenes, and the dragon when its scene loads (it needs the
/// shared meshes next to the repository, and `--allow-path` naming their folder).
fn default_scenes(allowed: &[PathBuf]) -> Vec<String> {
    let mut scenes = vec!["paper-1".to_string(), "paper-5".to_string()];
    // The 202k dragon, a textured model, and one with a normal map and see-through
    // surfaces, where they load (run from the repository).
    for file in [
        "bench/scenes/dragon-lit.toml",
        "scenes/gltf/CesiumMilkTruck.glb",
        "scenes/gltf/AlphaBlendModeTest.glb",
    ] {
        match load_scene_allowing(file, allowed) {
            Ok(_) => scenes.push(file.to_string()),
            Err(e) => eprintln!("skipping {file}: {e}"),
        }
    }
    scenes
}

/// Seconds and rays of the whole render on the GPU, upload and tree excluded.
fn render_on_gpu(
    gpu: &canopy_gpu::Gpu,
    scene: &Scene,
    params: &BuildParams,
) -> anyhow::Result<(f64, u64)> {
    let accel = Accel::for_scene(scene, AccelKind::default(), BvhWidth::Two, params, None);
    let renderer = canopy_gpu::Renderer::for_accel(gpu, scene, &accel)?;
    let mut accumulator = Accumulator::new(scene.settings.width, scene.settings.height);
    let start = Instant::now();
    while accumulator.samples < scene.settings.spp {
        renderer.render_samples(&mut accumulator, 1)?;
    }
    Ok((start.elapsed().as_secs_f64(), accumulator.rays))
}

fn print_table(args: &GpuArgs, rows: &[Row], gpu: &canopy_gpu::Gpu) {
    outln!(
        "{}x{}, {} spp, depth {}, {} integrator",
        args.size.0,
        args.size.1,
        args.spp,
        args.depth,
        args.integrator
    );
    outln!(
        "{:<34} {:<50} {:>9} {:>9} {:>8}",
        "scene",
        "device",
        "seconds",
        "Mrays/s",
        "speed-up"
    );
    for pair in rows.chunks(2) {
        let cpu_seconds = pair[0].seconds;
        for row in pair {
            outln!(
                "{:<34} {:<50} {:>9.3} {:>9.2} {:>7.2}x",
                row.scene,
                row.device,
                row.seconds,
                row.rays as f64 / row.seconds.max(1e-9) / 1e6,
                cpu_seconds / row.seconds.max(1e-9)
            );
        }
    }
    if gpu.is_software() {
        outln!(
            "note: {} runs on the CPU (a software driver): its figures show correctness, not GPU speed",
            gpu.describe()
        );
    }
}
