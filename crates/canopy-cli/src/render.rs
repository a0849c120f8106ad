//! `canopy render`: load, build the acceleration structure, render with a progress bar,
//! write the image, print a summary.

use crate::build_args::{builders_help, BuildArgs};
use anyhow::{bail, Context};
use canopy_render::camera::Camera;
use canopy_render::checkpoint::Checkpoint;
use canopy_render::visualize::{draw_bvh, render_heatmap, LevelRange};
use canopy_render::{
    output::image_format, render_samples, write_image, Accel, AccelKind, Accumulator, BvhWidth,
    RenderStats, Scene,
};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

#[derive(Args)]
pub struct RenderArgs {
    /// Built-in scene name (see `canopy scenes`), scene file, or OBJ/PLY mesh.
    #[arg(required_unless_present = "resume")]
    scene: Option<String>,
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
    /// BVH layout, by children per node: 2 (the binary tree as built), or collapsed to 4 or
    /// 8 with SIMD box tests and triangles packed in the leaves. 8 is the fastest.
    #[arg(long, visible_alias = "bvh-layout", default_value = "8")]
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
    /// Save the render's progress to FILE periodically (atomically), to resume it later.
    #[arg(long, value_name = "FILE")]
    checkpoint: Option<PathBuf>,
    /// How often to save the checkpoint: seconds, or a number with s, m or h.
    #[arg(long, default_value = "60s", value_parser = parse_duration, requires = "checkpoint")]
    every: Duration,
    /// Continue the render saved in a checkpoint (scene and settings come from it).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["scene", "size", "spp", "depth", "seed", "heatmap"])]
    resume: Option<PathBuf>,
}

fn parse_duration(s: &str) -> Result<Duration, String> {
    let (number, unit) = match s.char_indices().find(|(_, c)| c.is_ascii_alphabetic()) {
        Some((i, _)) => s.split_at(i),
        None => (s, "s"),
    };
    let scale = match unit {
        "s" => 1.0,
        "m" => 60.0,
        "h" => 3600.0,
        _ => return Err(format!("`{s}`: use seconds, or a number with s, m or h")),
    };
    match number.trim().parse::<f64>() {
        Ok(n) if n >= 0.0 && n.is_finite() => Ok(Duration::from_secs_f64(n * scale)),
        _ => Err(format!("`{s}` is not a duration")),
    }
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
    let (scene_arg, scene, accumulator) = match &args.resume {
        Some(path) => {
            let checkpoint = Checkpoint::load(path)?;
            let mut scene = canopy_render::load_scene(&checkpoint.scene)?;
            scene.settings = checkpoint.settings;
            checkpoint.matches(&scene, path)?;
            (checkpoint.scene, scene, checkpoint.accumulator)
        }
        None => {
            let arg = args
                .scene
                .clone()
                .expect("clap requires a scene without --resume");
            let mut scene = canopy_render::load_scene(&arg)?;
            apply_overrides(&mut scene, args)?;
            let accumulator = Accumulator::new(scene.settings.width, scene.settings.height);
            (arg, scene, accumulator)
        }
    };
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| default_output(&scene_arg, &scene));
    // Refuse a bad output path before spending minutes on the render.
    image_format(&output)?;

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0))
        .build()
        .context("cannot start the worker threads")?;
    let params = args.build.params()?;
    let accel = pool.install(|| Accel::build(args.bvh, args.width, &scene.primitives, &params));

    if args.show_bvh && accel.tree().is_none() {
        bail!("--show-bvh needs a BVH; choose a builder with --bvh");
    }
    print_scene_summary(args, &scene_arg, &scene, &accel);
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

    let checkpoint_path = args.checkpoint.clone().or_else(|| args.resume.clone());
    let run = pool.install(|| {
        progressive(
            &scene,
            &scene_arg,
            &accel,
            accumulator,
            checkpoint_path.as_deref(),
            args.every,
        )
    })?;
    let mut film = run.accumulator.film();
    if let (true, Some(tree)) = (args.show_bvh, accel.tree()) {
        let camera = Camera::new(&scene.camera, film.width, film.height);
        let drawn = draw_bvh(&mut film, &camera, tree, args.levels);
        println!(
            "overlay     {drawn} boxes of tree levels {}",
            describe_levels(args.levels)
        );
    }
    write_image(&film, &output)?;

    let stats = run.stats;
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
    if run.accumulator.invalid_samples > 0 {
        println!(
            "warning     {} samples with NaN/inf radiance were dropped",
            run.accumulator.invalid_samples
        );
    }
    println!("image       {}", output.display());
    let (done, spp) = (run.accumulator.samples, scene.settings.spp);
    if done < spp {
        let saved = checkpoint_path.unwrap_or_else(|| default_checkpoint(&output));
        Checkpoint::new(&scene_arg, &scene, run.accumulator).save(&saved)?;
        println!("partial     {done} of {spp} samples per pixel: the image is noisier than asked");
        bail!(
            "interrupted; the render so far is saved: continue with `canopy render --resume {} -o {}`",
            saved.display(),
            output.display()
        );
    }
    if let Some(path) = checkpoint_path {
        // The render is complete: its checkpoint has nothing left to give.
        let _ = std::fs::remove_file(path);
    }
    Ok(())
}

/// What a (possibly interrupted) progressive render produced.
struct Progressive {
    accumulator: Accumulator,
    /// Rays and time of this session (not of earlier, resumed ones).
    stats: RenderStats,
}

/// Renders one sample per pixel at a time until the scene's spp are done or Ctrl-C is
/// pressed, saving a checkpoint every `every` when asked. Passes add samples in order, so
/// the image is the same as an uninterrupted render's.
fn progressive(
    scene: &Scene,
    scene_arg: &str,
    accel: &Accel,
    mut accumulator: Accumulator,
    checkpoint: Option<&Path>,
    every: Duration,
) -> anyhow::Result<Progressive> {
    let interrupted = Arc::new(AtomicBool::new(false));
    let flag = interrupted.clone();
    // Without a handler (another one is installed) Ctrl-C just ends the process as usual.
    let _ = ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst));
    let (spp, rows) = (scene.settings.spp as u64, scene.settings.height as u64);
    let progress = ProgressBar::new(spp * rows).with_style(
        ProgressStyle::with_template(
            "{spinner} rendering [{bar:40}] {percent:>3}%  {elapsed} elapsed, ETA {eta}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    progress.set_position(accumulator.samples as u64 * rows);
    let mut stats = RenderStats::default();
    let mut last_save = Instant::now();
    while accumulator.samples < scene.settings.spp && !interrupted.load(Ordering::SeqCst) {
        let pass = render_samples(scene, accel, &mut accumulator, 1, &|| progress.inc(1));
        stats.rays += pass.rays;
        stats.elapsed += pass.elapsed;
        if let Some(path) = checkpoint {
            if last_save.elapsed() >= every && accumulator.samples < scene.settings.spp {
                Checkpoint::new(scene_arg, scene, accumulator.clone()).save(path)?;
                last_save = Instant::now();
            }
        }
    }
    progress.finish_and_clear();
    Ok(Progressive { accumulator, stats })
}

/// `<output>.checkpoint`, beside the image.
fn default_checkpoint(output: &Path) -> PathBuf {
    let mut name = output.file_name().unwrap_or_default().to_os_string();
    name.push(".checkpoint");
    output.with_file_name(name)
}

fn describe_levels(levels: LevelRange) -> String {
    match levels.last {
        usize::MAX => format!("{}..", levels.first),
        last => format!("{}..{last}", levels.first),
    }
}

fn print_scene_summary(args: &RenderArgs, scene_arg: &str, scene: &Scene, accel: &Accel) {
    let s = scene.settings;
    let counts = scene.shape_counts();
    println!(
        "scene       {} ({}x{}, {} spp, depth {}, seed {})",
        scene_arg, s.width, s.height, s.spp, s.max_depth, s.seed
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
