//! `canopy render`: load, build the acceleration structure, render with a progress bar,
//! write the image, print a summary.

use crate::build_args::{builders_help, BuildArgs};
use crate::limits;
use crate::safety::{check_memory, check_output, file_stem_from_name, same_file, OutputKind};
use crate::scene_facts::SceneFacts;
use crate::signals;
use crate::Interrupted;
use anyhow::bail;
use canopy_bvh::TriangleTest;
use canopy_job::{
    CheckpointPolicy, Device, Observer, RenderJob, RenderOptions, Schedule, Structure,
};
use canopy_render::camera::Camera;
use canopy_render::visualize::{draw_bvh, render_heatmap, LevelRange};
use canopy_render::{
    write_image, write_image_with_aovs, AccelKind, Accumulator, AovSet, BvhWidth, Integrator,
    Region, Sampler, Scene,
};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Duration;

#[derive(Args)]
pub struct RenderArgs {
    /// Built-in scene name (see `canopy scenes`), scene file, or OBJ/PLY mesh.
    #[arg(required_unless_present = "resume")]
    scene: Option<String>,
    /// Output image, .png (8-bit sRGB) or .exr (linear float) [default: <scene>.png].
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Samples per pixel, 1 to 16777216 [default: from the scene].
    #[arg(long, value_parser = limits::spp())]
    spp: Option<u32>,
    /// Maximum ray segments per path, the camera ray included, 1 to 1024 [default: from
    /// the scene].
    #[arg(long, value_parser = limits::depth())]
    depth: Option<u32>,
    /// Image size as WIDTHxHEIGHT, each 1 to 65536 [default: from the scene].
    #[arg(long, value_parser = limits::size)]
    size: Option<(u32, u32)>,
    /// Seed of the random sampling.
    #[arg(long)]
    seed: Option<u64>,
    /// Estimator: `path` (light sampling with multiple importance sampling) or `bsdf`
    /// (the report's: light found only by chance) [default: from the scene, else path].
    #[arg(long)]
    integrator: Option<Integrator>,
    /// Never end paths early by Russian roulette (the path integrator's default is to,
    /// after three bounces; the image's expected value is the same).
    #[arg(long)]
    no_roulette: bool,
    /// How each sample's random numbers are drawn: `sobol` (each pixel's samples spread
    /// evenly by scrambled Sobol points over the camera's and the first bounces'
    /// dimensions: less noise) or `independent` [default: from the scene, else sobol].
    #[arg(long)]
    sampler: Option<Sampler>,
    /// Where to render: `cpu` (all cores) or `gpu` (the first adapter wgpu finds; see
    /// `canopy devices`), with either integrator, from the binary tree of the chosen
    /// builder: the same image up to rounding.
    #[arg(long, default_value = "cpu", value_parser = parse_device)]
    device: Device,
    /// The order the CPU traces paths in: `wavefront` (many at a time, stage by stage:
    /// hits, shading, one batch of shadow rays) or `depth` (one path at a time, the
    /// reference). The image is the same bit for bit.
    #[arg(long, default_value = "wavefront")]
    schedule: Schedule,
    /// Render only this rectangle of the image, as X,Y,WIDTHxHEIGHT (0,0 is the top-left
    /// pixel): an image of that size, whose pixels are exactly those of the whole
    /// image's render.
    #[arg(long, value_parser = parse_region, conflicts_with_all = ["resume", "heatmap", "show_bvh"])]
    region: Option<Region>,
    /// Worker threads, 1 to 1024 [default: all cores].
    #[arg(long, value_parser = limits::threads())]
    threads: Option<u32>,
    /// Acceleration structure: `none` or a BVH builder (see --help).
    #[arg(long, default_value = "binned-sah", value_parser = parse_accel, long_help = builders_help("Acceleration structure: `none` (loop over all primitives) or a BVH builder:"))]
    bvh: AccelKind,
    /// BVH layout, by children per node: 2 (the binary tree as built), or collapsed to 4 or
    /// 8 with SIMD box tests and triangles packed in the leaves. 8 is the fastest.
    #[arg(long, visible_alias = "bvh-layout", default_value = "8")]
    width: BvhWidth,
    #[command(flatten)]
    build: BuildArgs,
    /// Improve the BVH by reinsertion before rendering: passes (`3`) or a time (`500ms`,
    /// `2s`); see `canopy bvh --optimize`.
    #[arg(long, value_parser = limits::optimize_budget)]
    optimize: Option<canopy_bvh::OptimizeBudget>,
    /// Test triangles without the watertight test's double-precision step for rays
    /// through edges (like Embree's default mode): fewer instructions per ray; a ray
    /// within rounding of a shared edge may hit every triangle there. The CPU only.
    #[arg(long)]
    fast_triangles: bool,
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
    /// How often to save the checkpoint: seconds, or a number with s, m or h (at most
    /// 8760h, a year).
    #[arg(long, default_value = "60s", value_parser = limits::duration, requires = "checkpoint")]
    every: Duration,
    /// Continue the render saved in a checkpoint (scene and settings come from it).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["scene", "size", "spp", "depth", "seed", "integrator", "no_roulette", "sampler", "fast_triangles", "heatmap"])]
    resume: Option<PathBuf>,
    /// Also write these AOVs as layers of the (.exr) image: a comma-separated list of
    /// albedo, normal (what a denoiser takes: the first surface past mirrors and glass),
    /// depth, position and id (instance and primitive; these three of each pixel's first
    /// sample). Channels are named `albedo.R`, `normal.X`, `depth.Z`, `id.instance`, ...
    #[arg(long, value_name = "LIST", value_parser = parse_aovs, conflicts_with = "heatmap")]
    aov: Option<AovSet>,
    /// Denoise the image with Open Image Denoise 2 (installed by `scripts/oidn.sh`),
    /// guided by the albedo and normal AOVs it renders for it: the image written is the
    /// denoised one. Fails before rendering when OIDN is missing.
    #[arg(long, conflicts_with = "heatmap")]
    denoise: bool,
    /// Write the denoised image to FILE as well (.png or .exr), keeping the noisy render
    /// in the output image; implies --denoise.
    #[arg(long, value_name = "FILE", conflicts_with = "heatmap")]
    denoised_output: Option<PathBuf>,
    /// Denoise the albedo and normal before the image and use them as clean guides
    /// (OIDN's advice where they are noisy: depth of field, glass); several times slower.
    #[arg(long)]
    prefilter_guides: bool,
    /// A folder the scene may also read files from (meshes, models, maps). A scene reads
    /// only files in its own folder unless this allows more; repeat it for several.
    #[arg(long, value_name = "DIR")]
    allow_path: Vec<std::path::PathBuf>,
    /// Print the summary as one JSON object (warnings also go to stderr).
    #[arg(long)]
    json: bool,
}

impl RenderArgs {
    /// The render's options as the flags give them: the type every front end makes, so
    /// the flags and Python's keywords set the same things, checked the same way (a
    /// field added to it fails to compile here until a flag sets it).
    fn options(&self) -> RenderOptions {
        RenderOptions {
            size: self.size.map(|(width, height)| [width, height]),
            spp: self.spp,
            max_depth: self.depth,
            seed: self.seed,
            integrator: self.integrator,
            russian_roulette: self.no_roulette.then_some(false),
            sampler: self.sampler,
            bvh: Some(self.bvh),
            width: Some(self.width),
            max_leaf_size: Some(self.build.max_leaf_size),
            fast_triangles: Some(self.fast_triangles),
            device: Some(self.device),
            schedule: Some(self.schedule),
            threads: self.threads.map(|n| n as usize),
        }
    }
}

pub(crate) fn parse_device(s: &str) -> Result<Device, String> {
    s.parse()
}

fn parse_aovs(s: &str) -> Result<AovSet, String> {
    s.parse()
}

fn parse_region(s: &str) -> Result<Region, String> {
    s.parse()
}

fn parse_accel(s: &str) -> Result<AccelKind, String> {
    s.parse()
        .map_err(|e: canopy_bvh::UnknownBuilder| e.to_string())
}

/// What the render command reports: printed as text lines, or as one JSON object with
/// `--json`. Warnings also go to stderr as they happen.
#[derive(Default, Serialize)]
struct Summary {
    #[serde(flatten)]
    facts: SceneFacts,
    /// `none`, or the builder's name.
    bvh: String,
    bvh_width: u32,
    /// The triangle test: `watertight`, or `fast` (`--fast-triangles`, or the checkpoint
    /// resumed was rendered so).
    triangles: &'static str,
    build_ms: f64,
    /// `cpu`, or the GPU adapter rendered on.
    device: String,
    /// The rectangle rendered (X,Y,WIDTHxHEIGHT), when not the whole image.
    region: Option<String>,
    threads: usize,
    /// Samples per pixel in the image (fewer than `spp` when interrupted).
    samples: u32,
    render_seconds: f64,
    rays: u64,
    /// The shadow rays among `rays`.
    shadow_rays: u64,
    mrays_per_second: f64,
    image: String,
    /// The AOV layers written into the image, comma-separated.
    aovs: Option<String>,
    /// The denoised image, when written apart from the image.
    denoised_image: Option<String>,
    denoise_seconds: Option<f64>,
    /// Where the render's state was saved, when it was interrupted.
    checkpoint: Option<String>,
    interrupted: bool,
    heatmap_mean_cost: Option<f64>,
    heatmap_max_cost: Option<u32>,
    warnings: Vec<String>,
}

impl Summary {
    fn warn(&mut self, message: String) {
        eprintln!("warning: {message}");
        self.warnings.push(message);
    }
}

/// Prints a summary line unless the summary is to be printed as JSON.
macro_rules! say {
    ($json:expr, $($arg:tt)*) => {
        if !$json {
            outln!($($arg)*);
        }
    };
}

/// The scene to render and where its samples start from.
struct Job {
    /// How a checkpoint names the scene: a built-in name or an absolute path.
    source: String,
    scene: Scene,
    /// The samples of the checkpoint this render continues, if any.
    accumulator: Option<Accumulator>,
    /// The checkpoint this render continues, if any, and the render that wrote it.
    resumed_from: Option<PathBuf>,
    resume_owner: Option<u64>,
    /// The triangle test of the render continued (it goes on in the same mode).
    resumed_triangle_test: Option<TriangleTest>,
}

fn load_job(args: &RenderArgs) -> anyhow::Result<Job> {
    if let Some(path) = &args.resume {
        let resumed = canopy_job::Resumed::load(path, &args.allow_path)?;
        return Ok(Job {
            source: resumed.source,
            scene: resumed.scene,
            accumulator: Some(resumed.accumulator),
            resumed_from: Some(resumed.path),
            resume_owner: Some(resumed.owner),
            resumed_triangle_test: Some(resumed.triangle_test),
        });
    }
    let arg = args
        .scene
        .as_deref()
        .expect("clap requires a scene without --resume");
    let mut scene = canopy_render::load_scene_allowing(arg, &args.allow_path)?;
    args.options()
        .apply_to_settings(&mut scene.settings)
        .map_err(anyhow::Error::msg)?;
    Ok(Job {
        source: canopy_render::scene_source(arg)?,
        scene,
        accumulator: None,
        resumed_from: None,
        resume_owner: None,
        resumed_triangle_test: None,
    })
}

/// Where the image and the checkpoint go, checked before any work: neither may be an
/// input of the scene or each other, a checkpoint slot must be free or hold a canopy
/// checkpoint, and both directories must be writable.
struct Destinations {
    image: PathBuf,
    /// The denoised image, when written apart.
    denoised: Option<PathBuf>,
    /// Saved periodically when asked (`--checkpoint`, or the resumed file).
    periodic: Option<PathBuf>,
    /// Where an interrupted render saves its state.
    on_interrupt: PathBuf,
}

fn plan_destinations(args: &RenderArgs, job: &Job) -> anyhow::Result<Destinations> {
    let image = match &args.output {
        Some(path) => path.clone(),
        None => default_output(args.scene.as_deref().unwrap_or("render"), &job.scene),
    };
    let inputs = &job.scene.inputs;
    check_output(&image, "image", OutputKind::Image, inputs)?;
    if args.aov.is_some_and(|set| !set.is_empty())
        && canopy_render::output::image_format(&image)? != image::ImageFormat::OpenExr
    {
        return Err(canopy_render::OutputError::LayersNeedExr { path: image }.into());
    }
    if args.heatmap {
        return Ok(Destinations {
            on_interrupt: default_checkpoint(&image),
            image,
            denoised: None,
            periodic: None,
        });
    }
    let denoised = args.denoised_output.clone();
    if let Some(path) = &denoised {
        check_output(path, "denoised image", OutputKind::Image, inputs)?;
        if same_file(path, &image) {
            bail!(
                "{}: the image and the denoised image cannot be the same file",
                path.display()
            );
        }
    }
    let periodic = args.checkpoint.clone().or_else(|| job.resumed_from.clone());
    let on_interrupt = periodic
        .clone()
        .unwrap_or_else(|| default_checkpoint(&image));
    if same_file(&on_interrupt, &image) {
        bail!(
            "{}: the image and the checkpoint cannot be the same file",
            image.display()
        );
    }
    check_output(&on_interrupt, "checkpoint", OutputKind::Checkpoint, inputs)?;
    if denoised
        .as_ref()
        .is_some_and(|d| same_file(&on_interrupt, d))
    {
        bail!(
            "{}: the denoised image and the checkpoint cannot be the same file",
            on_interrupt.display()
        );
    }
    Ok(Destinations {
        image,
        denoised,
        periodic,
        on_interrupt,
    })
}

pub fn run(args: &RenderArgs) -> anyhow::Result<()> {
    let job = load_job(args)?;
    let dest = plan_destinations(args, &job)?;
    let scene = &job.scene;
    let settings = scene.settings;
    let region = job
        .accumulator
        .as_ref()
        .map_or(args.region, |a| Some(a.region))
        .unwrap_or(Region::full(settings.width, settings.height));
    region
        .check_within(settings.width, settings.height)
        .map_err(|e| anyhow::anyhow!("--region: {e}"))?;
    let denoise = args.denoise || args.denoised_output.is_some() || args.prefilter_guides;
    let written_aovs = args.aov.unwrap_or_default();
    let aovs = match &job.accumulator {
        // A resumed render goes on with the layers it has.
        Some(resumed) if !resumed.aovs.set.includes(written_aovs) => bail!(
            "--aov: the render to resume holds the AOVs [{}], not all of [{written_aovs}]",
            resumed.aovs.set
        ),
        Some(resumed) => resumed.aovs.set,
        None if denoise => written_aovs.union(AovSet::DENOISING),
        None => written_aovs,
    };
    // Before any work: a denoise that cannot happen is said now, not after the render.
    let oidn = denoise.then(|| canopy_job::Oidn::load(&[])).transpose()?;
    let aov_bytes = match aovs.is_empty() {
        true => 0,
        false => canopy_job::AOV_BYTES_PER_PIXEL,
    };
    check_memory(
        region.pixels() as u64 * (limits::BYTES_PER_PIXEL + aov_bytes),
        &format!("a {}x{} image", region.width, region.height),
    )?;
    if let AccelKind::Bvh(builder) = args.bvh {
        let mesh_triangles: usize = scene.meshes.iter().map(|m| m.mesh.indices().len()).sum();
        args.build
            .check_memory(builder, scene.primitives.len() + mesh_triangles)?;
    }
    if args.device == Device::Gpu && args.heatmap {
        bail!("--heatmap counts CPU traversal work; drop --device gpu");
    }
    // Told in the flags' words before the options' own check says it in theirs.
    if args.device == Device::Gpu && args.fast_triangles {
        bail!("--fast-triangles chooses the CPU's triangle test (the GPU's is watertight); drop --device gpu");
    }
    if args.device == Device::Gpu && job.resumed_triangle_test == Some(TriangleTest::Fast) {
        bail!("the render to resume tests triangles in the fast mode, which the GPU does not have (its test is watertight); resume it without --device gpu");
    }
    if args.device == Device::Gpu && args.bvh == AccelKind::None {
        bail!("--device gpu traces through a BVH; choose a builder with --bvh");
    }
    let mut render_job = RenderJob {
        scene,
        source: job.source.clone(),
        structure: Structure {
            params: args.build.params(),
            optimize: args.optimize,
            ..Structure::default()
        },
        region,
        aovs,
        checkpoint: CheckpointPolicy {
            periodic: dest.periodic.clone(),
            every: args.every,
            on_interrupt: Some(dest.on_interrupt.clone()),
        },
        resume: job.accumulator.clone(),
        resume_owner: job.resume_owner,
        ..RenderJob::new(scene, "")
    };
    args.options()
        .apply_to_job(&mut render_job)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    if let Some(test) = job.resumed_triangle_test {
        render_job.structure.triangle_test = test;
    }
    let prepared = render_job.prepare()?;
    let accel = prepared.accel();
    if args.show_bvh && accel.tree().is_none() {
        bail!("--show-bvh needs a BVH; choose a builder with --bvh");
    }

    let mut summary = Summary {
        facts: SceneFacts::of(&job.source, scene),
        bvh: args.bvh.to_string(),
        bvh_width: prepared.width().children(),
        triangles: prepared.triangle_test().name(),
        build_ms: prepared.build_time().as_secs_f64() * 1e3,
        device: prepared.device_name(),
        threads: prepared.threads(),
        region: (!region.is_full(settings.width, settings.height)).then(|| region.to_string()),
        ..Summary::default()
    };
    if !args.heatmap {
        // From here (before the summary says the render starts) a first signal stops the
        // render after its pass and keeps the work.
        signals::render_started();
    }
    print_scene_summary(&summary, args.json);
    for warning in scene.warnings() {
        summary.warn(warning);
    }
    summary.image = dest.image.display().to_string();
    if args.heatmap {
        let map = prepared.install(|| render_heatmap(scene, accel));
        write_image(&map.film, &dest.image)?;
        summary.heatmap_mean_cost = Some(map.mean_cost);
        summary.heatmap_max_cost = Some(map.max_cost);
        say!(
            args.json,
            "heatmap     primary-ray cost: mean {:.1}, max {} (node visits + primitive tests)",
            map.mean_cost,
            map.max_cost
        );
        return finish(&summary, args.json);
    }

    let mut observer = Terminal::new(settings.spp, region.height, &mut summary);
    if let Some(resumed) = &job.accumulator {
        observer
            .progress
            .set_position(resumed.samples as u64 * region.height as u64);
    }
    let run = prepared.run(&mut observer);
    observer.progress.finish_and_clear();
    let run = run?;
    if run.accumulator.samples == 0 {
        // Stopped before its first pass ended: nothing to keep, nothing written.
        return Err(
            Interrupted("interrupted before the first sample; nothing was written".into()).into(),
        );
    }
    let aov_images = run.accumulator.aov_images();
    let noisy = run.accumulator.film();
    let denoised = match &oidn {
        Some(oidn) => {
            let start = std::time::Instant::now();
            let options = canopy_job::DenoiseOptions {
                threads: Some(prepared.threads()),
                prefilter: args.prefilter_guides,
            };
            let denoised =
                canopy_job::denoise_film(oidn, &noisy, &aov_images, &options).map_err(|e| {
                    let saved = keep_samples(&prepared, &run, &dest);
                    samples_kept(e.into(), "denoised", saved)
                })?;
            summary.denoise_seconds = Some(start.elapsed().as_secs_f64());
            Some(denoised)
        }
        None => None,
    };
    // The denoised image goes to its own file when one is named, else it is the image.
    let (mut film, apart) = match (&dest.denoised, denoised) {
        (Some(path), Some(denoised)) => (noisy, Some((path, denoised))),
        (_, denoised) => (denoised.unwrap_or(noisy), None),
    };
    if let (true, Some(tree)) = (args.show_bvh, accel.tree()) {
        let camera = Camera::new(&scene.camera, settings.width, settings.height);
        let drawn = draw_bvh(&mut film, &camera, tree, args.levels);
        say!(
            args.json,
            "overlay     {drawn} boxes of tree levels {}",
            describe_levels(args.levels)
        );
    }
    let layers = aov_images.only(written_aovs);
    let mut written = write_image_with_aovs(&film, &layers, &dest.image);
    if let (Ok(()), Some((path, denoised))) = (&written, &apart) {
        written = write_image(denoised, path);
        summary.denoised_image = Some(path.display().to_string());
    }
    if let Err(e) = written {
        let saved = keep_samples(&prepared, &run, &dest);
        return Err(samples_kept(anyhow::Error::from(e), "written", saved));
    }
    if !layers.set.is_empty() {
        summary.aovs = Some(layers.set.to_string());
    }
    let stats = run.stats;
    summary.samples = run.accumulator.samples;
    summary.render_seconds = stats.elapsed.as_secs_f64();
    summary.rays = stats.rays;
    summary.shadow_rays = stats.shadow_rays;
    summary.mrays_per_second = stats.mrays_per_second();
    match args.device {
        Device::Gpu => say!(
            args.json,
            "render      {:.3} s on {}",
            summary.render_seconds,
            summary.device
        ),
        Device::Cpu => say!(
            args.json,
            "render      {:.3} s on {} threads",
            summary.render_seconds,
            summary.threads
        ),
    }
    say!(
        args.json,
        "rays        {} ({:.2} Mrays/s), {} of them shadow rays",
        stats.rays,
        summary.mrays_per_second,
        stats.shadow_rays
    );
    if let Some(seconds) = summary.denoise_seconds {
        say!(args.json, "denoise     {seconds:.3} s (Open Image Denoise)");
    }
    if let Some(path) = &summary.denoised_image {
        say!(args.json, "denoised    {path}");
    }
    if run.accumulator.invalid_samples > 0 {
        summary.warn(format!(
            "{} samples with NaN/inf radiance were dropped",
            run.accumulator.invalid_samples
        ));
    }
    if !run.complete {
        summary.interrupted = true;
        summary.checkpoint = run.saved.as_ref().map(|p| p.display().to_string());
        say!(
            args.json,
            "partial     {} of {} samples per pixel: the image is noisier than asked",
            run.accumulator.samples,
            settings.spp
        );
        finish(&summary, args.json)?;
        let Some(saved) = &run.saved else {
            // The warning said why; the image holds every sample there is.
            bail!(
                "interrupted; the checkpoint could not be saved, so the render cannot be resumed (the image {} holds its {} samples per pixel)",
                dest.image.display(),
                run.accumulator.samples
            );
        };
        return Err(Interrupted(format!(
            "interrupted; the render so far is saved: continue with `canopy render --resume {} -o {}`",
            saved.display(),
            dest.image.display()
        ))
        .into());
    }
    finish(&summary, args.json)
}

/// Keeps the samples of `run`, whose images could not be made or written, where a resume
/// finds them: its own checkpoint if it saved one, else beside the image, here, or in
/// the temporary folder (a full disk takes the place beside the image with it). Returns
/// where, if anywhere.
fn keep_samples(
    prepared: &canopy_job::Prepared,
    run: &canopy_job::Outcome,
    dest: &Destinations,
) -> Option<PathBuf> {
    if let Some(path) = &run.saved {
        return Some(path.clone());
    }
    let name = default_checkpoint(&dest.image);
    let name = name.file_name().unwrap_or_default().to_string_lossy();
    std::iter::once(dest.on_interrupt.clone())
        .chain(canopy_render::output_policy::fallback_places(
            &dest.image,
            &name,
        ))
        .find(|place| prepared.save_checkpoint(&run.accumulator, place).is_ok())
}

/// `error` (the image could not be `what`: written, denoised), telling where the samples
/// were kept ([`keep_samples`]).
fn samples_kept(error: anyhow::Error, what: &str, saved: Option<PathBuf>) -> anyhow::Error {
    match saved {
        Some(path) => error.context(format!(
            "the image could not be {what}, but the render is saved in {}: write it with `canopy render --resume {} -o OTHER.png`",
            path.display(),
            path.display()
        )),
        None => error.context(format!("the image could not be {what}, and neither could a checkpoint of its samples be written (beside it, here, or in the temporary folder)")),
    }
}

/// Prints the image line, or the whole summary as JSON.
fn finish(summary: &Summary, json: bool) -> anyhow::Result<()> {
    if json {
        outln!("{}", serde_json::to_string_pretty(summary)?);
    } else {
        outln!("image       {}", summary.image);
    }
    Ok(())
}

/// The render as the terminal shows it: a progress bar by rows, warnings above it, and
/// Ctrl-C, SIGTERM and SIGHUP to stop it after the pass in flight (which is then saved);
/// a second signal ends the process at once.
struct Terminal<'a> {
    progress: ProgressBar,
    summary: &'a mut Summary,
}

impl<'a> Terminal<'a> {
    fn new(spp: u32, rows: u32, summary: &'a mut Summary) -> Self {
        let progress = ProgressBar::new(spp as u64 * rows as u64).with_style(
            ProgressStyle::with_template(
                "{spinner} rendering [{bar:40}] {percent:>3}%  {elapsed} elapsed, ETA {eta}",
            )
            .expect("valid template")
            .progress_chars("=> "),
        );
        Self { progress, summary }
    }
}

impl Observer for Terminal<'_> {
    fn rows_done(&self, rows: u64) {
        self.progress.inc(rows);
    }

    fn keep_going(&mut self) -> bool {
        !signals::stop_requested()
    }

    fn warning(&mut self, message: String) {
        let summary = &mut *self.summary;
        self.progress.suspend(|| summary.warn(message));
    }
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

fn print_scene_summary(s: &Summary, json: bool) {
    say!(
        json,
        "scene       {} ({})",
        s.facts.scene,
        s.facts.settings_text()
    );
    say!(json, "primitives  {}", s.facts.primitives_text());
    if s.bvh == "none" {
        say!(json, "bvh         none");
    } else {
        say!(
            json,
            "bvh         {} (width {}) built in {:.2} ms",
            s.bvh,
            s.bvh_width,
            s.build_ms
        );
    }
}

/// `<scene name>.png` in the current directory, the name made into a plain file name
/// (a scene from a stranger cannot direct the image elsewhere).
fn default_output(arg: &str, scene: &Scene) -> PathBuf {
    let name = if scene.name.is_empty() {
        Path::new(arg)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    } else {
        scene.name.clone()
    };
    PathBuf::from(format!("{}.png", file_stem_from_name(&name)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{FromArgMatches, Parser};

    #[derive(Parser)]
    struct Render {
        #[command(flatten)]
        args: RenderArgs,
    }

    /// Every render option has a flag: a command line giving them all gives every one.
    #[test]
    fn every_render_option_has_a_flag() {
        let line = [
            "render",
            "paper-1",
            "--size",
            "8x6",
            "--spp",
            "2",
            "--depth",
            "3",
            "--seed",
            "4",
            "--integrator",
            "bsdf",
            "--no-roulette",
            "--sampler",
            "independent",
            "--bvh",
            "sweep-sah",
            "--width",
            "4",
            "--max-leaf-size",
            "2",
            "--fast-triangles",
            "--device",
            "cpu",
            "--schedule",
            "depth",
            "--threads",
            "1",
        ];
        let matches = <Render as clap::CommandFactory>::command().get_matches_from(line);
        let options = Render::from_arg_matches(&matches).unwrap().args.options();
        assert_eq!(options.given(), RenderOptions::names());
        assert_eq!(options.size, Some([8, 6]));
        assert_eq!(options.russian_roulette, Some(false));
        assert_eq!(options.max_leaf_size, Some(2));
    }
}
