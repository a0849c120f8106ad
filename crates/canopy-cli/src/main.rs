//! `canopy`: render scenes with a choice of BVH, list the built-in scenes.

/// `println!` that never panics: a closed stdout (`canopy render … | head -1`) must not
/// abort a render or lose its image, so what cannot be printed is dropped.
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

mod bench;
mod build_args;
mod bvh;
mod check;
mod limits;
mod render;
mod safety;
mod scene_facts;
mod signals;
mod units;
mod view;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "canopy",
    version,
    about = "A path tracer and laboratory of bounding volume hierarchies"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a built-in scene (see `canopy scenes`) or a scene file to PNG or EXR.
    Render(render::RenderArgs),
    /// Build BVHs over a scene or mesh and tabulate build time, size and SAH cost.
    Bvh(bvh::BvhArgs),
    /// Benchmarks: `canopy bench paper` reproduces the report's evaluation.
    Bench(bench::BenchArgs),
    /// Validate a scene and describe what it contains, without rendering.
    Check(check::CheckArgs),
    /// View a scene in the browser while it renders: move the camera, change settings,
    /// rebuild the BVH and explore it (a local web server; prints its address).
    View(view::ViewArgs),
    /// List the built-in scenes.
    Scenes,
    /// List the GPU adapters wgpu finds (Vulkan, Metal, DX12; Mesa's lavapipe counts).
    Devices,
}

/// Exit status of a run that failed (a usage error exits with 2, from the parser).
const EXIT_ERROR: u8 = 1;
/// Exit status of a render stopped by a signal, its partial image and checkpoint saved
/// (128 + SIGINT, as shells report it).
pub const EXIT_INTERRUPTED: i32 = 130;

/// A render that stopped early on a signal; its work is saved.
#[derive(Debug)]
pub struct Interrupted(pub String);

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Interrupted {}

fn main() -> ExitCode {
    signals::install();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(args) => render::run(&args),
        Command::Bvh(args) => bvh::run(&args),
        Command::Bench(args) => bench::run(&args),
        Command::Check(args) => check::run(&args),
        Command::View(args) => view::run(&args),
        Command::Scenes => list_scenes(),
        Command::Devices => list_devices(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.is::<Interrupted>() => {
            eprintln!("{e:#}");
            ExitCode::from(EXIT_INTERRUPTED as u8)
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(EXIT_ERROR)
        }
    }
}

fn list_devices() -> anyhow::Result<()> {
    let adapters = canopy_gpu::adapters();
    if adapters.is_empty() {
        anyhow::bail!(
            "no GPU adapter found; install a Vulkan driver (on Debian: mesa-vulkan-drivers and libvulkan1 for the software one)"
        );
    }
    for adapter in adapters {
        outln!("{adapter}");
    }
    Ok(())
}

fn list_scenes() -> anyhow::Result<()> {
    for builtin in canopy_render::BUILTIN_SCENES {
        let scene = builtin.load()?;
        let counts = scene.shape_counts();
        outln!(
            "{:<12} {:>4} spheres {:>5} triangles {:>3} cuboids  {}",
            builtin.name,
            counts.spheres,
            counts.triangles,
            counts.cuboids,
            scene.description
        );
    }
    Ok(())
}
