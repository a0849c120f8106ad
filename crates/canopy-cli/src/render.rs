//! `canopy render`: load, build the acceleration structure, render with a progress bar,
//! write the image, print a summary.

use crate::build_args::{builders_help, BuildArgs};
use anyhow::{bail, Context};
use canopy_render::camera::Camera;
use canopy_render::visualize::{draw_bvh, render_heatmap, LevelRange};
use canopy_render::{output::image_format, render, write_image, Accel, AccelKind, BvhWidth, Scene};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct RenderArgs {
    /// Built-in scene name (see `canopy scenes`) or path to a scene file.
    scene: String,
    /// Output image, .png (8-bit sRGB) or .exr (linear float) [default: <scene>.png].
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Samples per pixel [default: from the scene].
    #[arg(long)]
    spp: Option<u32>,
    /// Maximum ray segments per path, the camera ray included [default: from the scene].
    #[arg(long)]
    depth: Option<u32>,
    /// Image size as WIDTHxHEIGHT [default: from the scene].
    #[arg(long, value_parser = parse_size)]
    size: Option<(u32, u32)>,
    /// Seed of the random sampling.
    #[arg(long)]
    seed: Option<u64>,
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// Acceleration structure: `none` or a BVH builder (see --help).
    #[arg(long, default_value = "binned-sah", value_parser = parse_accel, long_help = builders_help("Acceleration structure: `none` (loop over all primitives) or a BVH builder:"))]
    bvh: AccelKind,
    /// Children per BVH node: 2, or the binary tree collapsed to 4 or 8.
    #[arg(long, default_value = "2")]
    width: BvhWidth,
    #[command(flatten)]
    build: BuildArgs,
    /// Draw the BVH's boxes over the image as wireframes, coloured by tree level.
    #[arg(long)]
    show_bvh: bool,
    /// Tree levels --show-bvh draws: `a..b` (inclusive), `a..` or `a`; the root is 0.
    #[arg(long, default_value = "0..", requires = "show_bvh")]
    levels: LevelRange,
    /// Instead of rendering, write each pixel's primary-ray traversal cost (node visits
    /// plus primitive tests) as a false-colour image with a scale bar.
    #[arg(long, conflicts_with = "show_bvh")]
    heatmap: bool,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}` is not WIDTHxHEIGHT"))?;
    let dim = |d: &str| d.trim().parse::<u32>().ok().filter(|&v| v > 0);
    match (dim(w), dim(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(format!("`{s}`: width and height must be positive integers")),
    }
}

fn parse_accel(s: &str) -> Result<AccelKind, String> {
    s.parse()
        .map_err(|e: canopy_bvh::UnknownBuilder| e.to_string())
}

pub fn run(args: &RenderArgs) -> anyhow::Result<()> {
    let mut scene = canopy_render::load_scene(&args.scene)?;
    apply_overrides(&mut scene, args)?;
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| default_output(&args.scene, &scene));
    // Refuse a bad output path before spending minutes on the render.
    image_format(&output)?;

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0))
        .build()
        .context("cannot start the worker threads")?;
    let params = args.build.params()?;
    let accel = pool.install(|| Accel::build(args.bvh, args.width, &scene.primitives, &params));

    if args.show_bvh && accel.bvh().is_none() {
        bail!("--show-bvh needs a BVH; choose a builder with --bvh");
    }
    print_scene_summary(args, &scene, &accel);
    if args.heatmap {
        let map = pool.install(|| render_heatmap(&scene, &accel));
        write_image(&map.film, &output)?;
        println!(
            "heatmap     primary-ray cost: mean {:.1}, max {} (node visits + primitive tests)",
            map.mean_cost, map.max_cost
        );
        println!("image       {}", output.display());
        return Ok(());
    }

    let progress = ProgressBar::new(scene.settings.height as u64).with_style(
        ProgressStyle::with_template(
            "{spinner} rendering [{bar:40}] {percent:>3}%  {elapsed} elapsed, ETA {eta}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    let (mut film, stats) = pool.install(|| render(&scene, &accel, &|| progress.inc(1)));
    progress.finish_and_clear();
    if let (true, Some(bvh)) = (args.show_bvh, accel.bvh()) {
        let camera = Camera::new(&scene.camera, film.width, film.height);
        let drawn = draw_bvh(&mut film, &camera, bvh, args.levels);
        println!(
            "overlay     {drawn} boxes of tree levels {}",
            describe_levels(args.levels)
        );
    }
    write_image(&film, &output)?;

    println!(
        "render      {:.3} s on {} threads",
        stats.elapsed.as_secs_f64(),
        pool.current_num_threads()
    );
    println!(
        "rays        {} ({:.2} Mrays/s)",
        stats.rays,
        stats.mrays_per_second()
    );
    if stats.invalid_samples > 0 {
        println!(
            "warning     {} samples with NaN/inf radiance were dropped",
            stats.invalid_samples
        );
    }
    println!("image       {}", output.display());
    Ok(())
}

fn describe_levels(levels: LevelRange) -> String {
    match levels.last {
        usize::MAX => format!("{}..", levels.first),
        last => format!("{}..{last}", levels.first),
    }
}

fn print_scene_summary(args: &RenderArgs, scene: &Scene, accel: &Accel) {
    let s = scene.settings;
    let counts = scene.shape_counts();
    println!(
        "scene       {} ({}x{}, {} spp, depth {}, seed {})",
        args.scene, s.width, s.height, s.spp, s.max_depth, s.seed
    );
    println!(
        "primitives  {} ({} spheres, {} triangles, {} cuboids)",
        scene.primitives.len(),
        counts.spheres,
        counts.triangles,
        counts.cuboids
    );
    if scene.skipped_degenerate > 0 {
        println!(
            "warning     {} zero-area mesh triangles were left out",
            scene.skipped_degenerate
        );
    }
    match args.bvh {
        AccelKind::None => println!("bvh         none"),
        AccelKind::Bvh(_) => println!(
            "bvh         {} (width {}) built in {:.2} ms",
            args.bvh,
            args.width,
            accel.build_time.as_secs_f64() * 1e3
        ),
    }
}

fn apply_overrides(scene: &mut Scene, args: &RenderArgs) -> anyhow::Result<()> {
    let s = &mut scene.settings;
    if let Some((w, h)) = args.size {
        (s.width, s.height) = (w, h);
    }
    s.spp = args.spp.unwrap_or(s.spp);
    s.max_depth = args.depth.unwrap_or(s.max_depth);
    s.seed = args.seed.unwrap_or(s.seed);
    s.check().map_err(anyhow::Error::msg)?;
    Ok(())
}

/// `<scene name>.png` in the current directory.
fn default_output(arg: &str, scene: &Scene) -> PathBuf {
    let stem = if scene.name.is_empty() {
        Path::new(arg)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "render".into())
    } else {
        scene.name.clone()
    };
    PathBuf::from(format!("{stem}.png"))
}
