//! `canopy bench paper`: the report's evaluation (its section 4) reproduced on this
//! machine — every reference scene rendered with the report's methods and canopy's other
//! builders at every width, repeated, timed and tabulated.

mod denoise;
mod equal_time;
mod gpu;
mod lights;
mod plots;
mod report_figures;
mod table3;
mod tables;

use crate::build_args::BuildArgs;
use crate::limits;
use anyhow::Context;
use canopy_bvh::{Builder, TriangleTest};
use canopy_render::{
    render, render_counted, Accel, AccelKind, BuiltinScene, BvhWidth, Integrator, Scene,
};
use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct BenchArgs {
    #[command(subcommand)]
    what: BenchCommand,
}

#[derive(Subcommand)]
enum BenchCommand {
    /// Reproduce the report's Tables 1 and 2 (and more) on this machine.
    Paper(PaperArgs),
    /// Equal-time error of light sampling against the report's integrator, with the
    /// shadow rays' share of the time.
    Lights(lights::LightsArgs),
    /// The same renders on the CPU and on the GPU: seconds, Mrays/s, speed-up.
    Gpu(gpu::GpuArgs),
    /// Error of renders denoised by Open Image Denoise against undenoised ones at equal
    /// time, and the denoiser's time.
    Denoise(denoise::DenoiseArgs),
}

#[derive(Args)]
struct PaperArgs {
    /// Tiny images, 2 spp, 2 runs: a smoke test of the whole pipeline in seconds.
    #[arg(long)]
    quick: bool,
    /// Renders per measurement, 1 to 1000 [default: 6, as in the report; 2 with --quick].
    #[arg(long, value_parser = limits::runs())]
    runs: Option<u32>,
    /// Folder for results.md, results.csv, results.json, the plots and table3.png.
    #[arg(short, long, default_value = "bench-paper")]
    out: PathBuf,
    /// Remake the tables, plots and pictures of an earlier run from its results.json,
    /// without measuring again.
    #[arg(long, value_name = "RESULTS_JSON")]
    from: Option<PathBuf>,
    /// Which reference scenes, comma-separated numbers 1 to 6 [default: all].
    #[arg(long, value_delimiter = ',', value_parser = clap::value_parser!(u32).range(1..=6))]
    scenes: Vec<u32>,
    /// `report` for the report's six methods only, `all` to add canopy's builders.
    #[arg(long, default_value = "all", value_parser = ["report", "all"])]
    methods: String,
    /// Only the method of this label (repeatable; `--list-methods` prints the labels):
    /// one cell of the tables, as `canopy_rt.distributed.bench_paper` runs them.
    #[arg(long = "method", value_name = "LABEL")]
    only: Vec<String>,
    /// Print the labels of the methods `--methods` selects, one a line, and stop.
    #[arg(long)]
    list_methods: bool,
    /// Write only results.json: no tables, plots or pictures (`--from` makes them later,
    /// from this run's file or from cells run elsewhere and merged).
    #[arg(long)]
    json_only: bool,
    /// Image size WIDTHxHEIGHT, each 1 to 65536 [default: 480x480, as in the report;
    /// 32x32 with --quick].
    #[arg(long, value_parser = limits::size)]
    size: Option<(u32, u32)>,
    /// Samples per pixel, 1 to 16777216 [default: 128; 2 with --quick].
    #[arg(long, value_parser = limits::spp())]
    spp: Option<u32>,
    /// Worker threads, 1 to 1024 [default: all cores].
    #[arg(long, value_parser = limits::threads())]
    threads: Option<u32>,
    /// Estimator: `bsdf` is the report's (no light sampling), so the times compare with
    /// its tables; `path` adds light sampling.
    #[arg(long, default_value = "bsdf")]
    integrator: Integrator,
    /// Test triangles as `canopy render --fast-triangles` does (without the watertight
    /// test's double-precision step for rays through edges), in every method's render.
    #[arg(long)]
    fast_triangles: bool,
    #[command(flatten)]
    build: BuildArgs,
}

/// One way to accelerate a render, as the tables name it.
struct Method {
    label: String,
    kind: AccelKind,
    width: BvhWidth,
    /// Row of the report's Table 1, for the methods the report measured.
    report_row: Option<usize>,
}

fn methods(all: bool) -> Vec<Method> {
    let method = |label: &str, kind, width, report_row| Method {
        label: label.to_string(),
        kind,
        width,
        report_row,
    };
    let agglomerative = AccelKind::Bvh(Builder::Agglomerative);
    let mut list = vec![
        method("No BVH", AccelKind::None, BvhWidth::Two, Some(0)),
        method(
            "Top Down x sorted",
            AccelKind::Bvh(Builder::SortAxis(0)),
            BvhWidth::Two,
            Some(1),
        ),
        method(
            "Top Down Morton",
            AccelKind::Bvh(Builder::MortonMedian),
            BvhWidth::Two,
            Some(2),
        ),
        method("Agglom. 2 children", agglomerative, BvhWidth::Two, Some(3)),
        method("Agglom. 4 children", agglomerative, BvhWidth::Four, Some(4)),
        method(
            "Agglom. 8 children",
            agglomerative,
            BvhWidth::Eight,
            Some(5),
        ),
    ];
    if all {
        for builder in [
            Builder::Lbvh,
            Builder::BinnedSah,
            Builder::SweepSah,
            Builder::Ploc,
        ] {
            for width in BvhWidth::ALL {
                list.push(method(
                    &format!("{builder} x{width}"),
                    AccelKind::Bvh(builder),
                    width,
                    None,
                ));
            }
        }
    }
    list
}

/// The settings of a run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RunConfig {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub runs: u32,
    pub threads: usize,
    /// The triangle test every render used: `watertight` or `fast` (runs written before
    /// the option existed were watertight).
    #[serde(default = "watertight")]
    pub triangles: String,
}

fn watertight() -> String {
    TriangleTest::Watertight.name().to_string()
}

/// Everything a run measured: what `results.json` holds.
#[derive(Debug, Serialize, Deserialize)]
pub struct RunRecord {
    pub settings: String,
    pub command: String,
    pub config: RunConfig,
    pub measurements: Vec<Measurement>,
}

/// One scene rendered with one method.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Measurement {
    pub scene: String,
    pub method: String,
    pub builder: String,
    pub width: u32,
    /// Render time of every run, seconds.
    pub seconds: Vec<f64>,
    pub mean_s: f64,
    /// Sample standard deviation of the runs (0 for one run).
    pub std_s: f64,
    /// Mean time without a BVH over this mean (when no BVH was measured too).
    pub speedup: Option<f64>,
    pub report_mean_s: Option<f64>,
    pub report_speedup: Option<f64>,
    pub build_ms: f64,
    pub sah_cost: f32,
    /// Ray segments per render.
    pub rays: u64,
    pub mrays_per_s: f64,
    pub nodes_per_ray: f64,
    pub prims_per_ray: f64,
}

fn mean_and_std(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = if xs.len() > 1 {
        xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    (mean, var.sqrt())
}

pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    match &args.what {
        BenchCommand::Paper(args) => paper(args),
        BenchCommand::Lights(args) => lights::run(args),
        BenchCommand::Gpu(args) => gpu::run(args),
        BenchCommand::Denoise(args) => denoise::run(args),
    }
}

fn paper(args: &PaperArgs) -> anyhow::Result<()> {
    let params = args.build.params();
    if let Some(from) = &args.from {
        let bytes = canopy_render::files::read_regular_file(from, 256 << 20)
            .with_context(|| format!("cannot read {}", from.display()))?;
        let text = String::from_utf8(bytes)
            .with_context(|| format!("{}: not a text (UTF-8) file", from.display()))?;
        let record: RunRecord = serde_json::from_str(&text).with_context(|| {
            format!(
                "{}: not a results.json of `canopy bench paper`",
                from.display()
            )
        })?;
        // The run's input is never among what it writes.
        for name in OUTPUT_FILES {
            crate::safety::refuse_inputs(
                &args.out.join(name),
                std::slice::from_ref(from),
                "benchmark output",
            )?;
        }
        std::fs::create_dir_all(&args.out)
            .with_context(|| format!("cannot create {}", args.out.display()))?;
        write_outputs(&record, &args.out, &params)?;
        outln!(
            "remade the outputs of {} measurements in {}",
            record.measurements.len(),
            args.out.display()
        );
        return Ok(());
    }
    let mut methods = methods(args.methods == "all");
    if args.list_methods {
        for method in &methods {
            outln!("{}", method.label);
        }
        return Ok(());
    }
    if !args.only.is_empty() {
        if let Some(unknown) = args
            .only
            .iter()
            .find(|label| !methods.iter().any(|m| &m.label == *label))
        {
            let known: Vec<&str> = methods.iter().map(|m| m.label.as_str()).collect();
            anyhow::bail!(
                "no method `{unknown}` (with --methods {}: {})",
                args.methods,
                known.join(", ")
            );
        }
        methods.retain(|m| args.only.contains(&m.label));
    }
    let runs = args.runs.unwrap_or(if args.quick { 2 } else { 6 });
    let scene_numbers: Vec<usize> = if args.scenes.is_empty() {
        (1..=6).collect()
    } else {
        args.scenes.iter().map(|&n| n as usize).collect()
    };
    let (width, height) = match args.size {
        Some(size) => size,
        None if args.quick => (32, 32),
        None => (480, 480),
    };
    crate::safety::check_memory(
        width as u64 * height as u64 * crate::limits::BYTES_PER_PIXEL,
        &format!("a {width}x{height} image"),
    )?;
    let spp = args.spp.unwrap_or(if args.quick { 2 } else { 128 });
    let triangles = if args.fast_triangles {
        TriangleTest::Fast
    } else {
        TriangleTest::Watertight
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0) as usize)
        .build()
        .context("cannot start the worker threads")?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    // Every file the run writes can be written: found now, not after the benchmark.
    for name in OUTPUT_FILES.iter().chain(&["results.json"]) {
        crate::safety::check_output(
            &args.out.join(name),
            "benchmark output",
            crate::safety::OutputKind::Data,
            &[],
        )?;
    }

    let total = (scene_numbers.len() * methods.len()) as u64 * runs as u64;
    let progress = ProgressBar::new(total).with_style(
        ProgressStyle::with_template("{spinner} [{bar:30}] {pos}/{len} renders  {msg}  ETA {eta}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    let mut measurements = Vec::new();
    for &n in &scene_numbers {
        let name = format!("paper-{n}");
        let mut scene = BuiltinScene::find(&name)
            .expect("paper scenes are built in")
            .load()?;
        scene.settings.width = width;
        scene.settings.height = height;
        scene.settings.spp = spp;
        scene.settings.integrator = args.integrator;
        let mut none_mean = None;
        for method in &methods {
            let m = pool.install(|| {
                let accel = accel_for(&scene, method, &params, triangles);
                measure(&scene, n, method, &accel, &params, runs, &progress)
            });
            if method.kind == AccelKind::None {
                none_mean = Some(m.mean_s);
            }
            let mut m = m;
            m.speedup = none_mean.map(|none| none / m.mean_s);
            measurements.push(m);
        }
    }
    progress.finish_and_clear();

    let settings = format!(
        "{width}x{height}, {spp} spp, depth {}, {} integrator, {} triangle test, {runs} runs per measurement, {} threads ({} cores), canopy {}.",
        BuiltinScene::find("paper-1").expect("built in").load()?.settings.max_depth,
        args.integrator,
        triangles.name(),
        pool.current_num_threads(),
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        env!("CARGO_PKG_VERSION")
    );
    let record = RunRecord {
        settings,
        command: std::env::args().collect::<Vec<_>>().join(" "),
        config: RunConfig {
            width,
            height,
            spp,
            runs,
            threads: pool.current_num_threads(),
            triangles: triangles.name().to_string(),
        },
        measurements,
    };
    keep_results(&args.out, &serde_json::to_string_pretty(&record)?)?;
    if !args.json_only {
        pool.install(|| write_outputs(&record, &args.out, &params))?;
    }
    outln!(
        "wrote {} measurements to {}",
        record.measurements.len(),
        args.out.display()
    );
    Ok(())
}

/// What [`write_outputs`] writes into the output directory (a run also writes
/// `results.json`, which `--from` reads).
const OUTPUT_FILES: [&str; 6] = [
    "results.md",
    "results.csv",
    "render_time.png",
    "speedup.png",
    "build_vs_sah.png",
    "table3.png",
];

/// Tables, plots and the Table 3 pictures of a run: [`OUTPUT_FILES`].
fn write_outputs(
    record: &RunRecord,
    out: &Path,
    params: &canopy_bvh::BuildParams,
) -> anyhow::Result<()> {
    let m = &record.measurements;
    write_atomic(
        &out.join("results.md"),
        &tables::markdown(m, &record.settings, &record.command),
    )?;
    write_atomic(&out.join("results.csv"), &tables::csv(m))?;
    plots::write_plots(out, m)?;
    // Pictures at most 240 pixels wide and 16 spp: they show trees, not light.
    let size = record.config.width.min(record.config.height).min(240);
    table3::write_table3(
        &out.join("table3.png"),
        &methods(false),
        size,
        record.config.spp.min(16),
        params,
    )
}

/// The structure `method` renders `scene` with, its triangles tested by `triangles`.
fn accel_for(
    scene: &Scene,
    method: &Method,
    params: &canopy_bvh::BuildParams,
    triangles: TriangleTest,
) -> Accel {
    Accel::for_scene(scene, method.kind, method.width, params, None).with_triangle_test(triangles)
}

fn measure(
    scene: &Scene,
    number: usize,
    method: &Method,
    accel: &Accel,
    params: &canopy_bvh::BuildParams,
    runs: u32,
    progress: &ProgressBar,
) -> Measurement {
    let sah_cost = accel
        .tree()
        .map_or(0.0, |tree| tree.stats(&params.sah).sah_cost);
    let mut seconds = Vec::new();
    let mut rays = 0;
    for run in 1..=runs {
        progress.set_message(format!(
            "{} · {} · run {run}/{runs}",
            scene.name, method.label
        ));
        let (_, stats) = render(scene, accel, &|| {});
        seconds.push(stats.elapsed.as_secs_f64());
        rays = stats.rays;
        progress.inc(1);
    }
    // Traversal work per ray, from a separate 1-spp render (counting slows rendering).
    let mut one_spp = scene.clone();
    one_spp.settings.spp = 1;
    let (_, counted) = render_counted(&one_spp, accel, &|| {});
    let per_ray = |x: u64| x as f64 / counted.rays.max(1) as f64;
    let (mean_s, std_s) = mean_and_std(&seconds);
    Measurement {
        scene: scene.name.clone(),
        method: method.label.clone(),
        builder: method.kind.to_string(),
        width: method.width.children(),
        seconds,
        mean_s,
        std_s,
        speedup: None,
        report_mean_s: method
            .report_row
            .map(|row| report_figures::report_seconds(row, number)),
        report_speedup: method
            .report_row
            .map(|row| report_figures::report_speedup(row, number)),
        build_ms: accel.build_time.as_secs_f64() * 1e3,
        sah_cost,
        rays,
        mrays_per_s: rays as f64 / mean_s.max(1e-9) / 1e6,
        nodes_per_ray: per_ray(counted.traversal.nodes_visited),
        prims_per_ray: per_ray(counted.traversal.primitives_tested),
    }
}

/// Writes the run's `results.json` into `out`; when that fails (a full disk, a folder
/// gone), the measurements are kept in the working directory or the temporary folder,
/// and the error says where and how to make the tables from them.
fn keep_results(out: &Path, json: &str) -> anyhow::Result<()> {
    let target = out.join("results.json");
    let Err(error) = write_atomic(&target, json) else {
        return Ok(());
    };
    let kept = canopy_render::output_policy::fallback_places(&target, "canopy-results.json")
        .into_iter()
        .find(|place| write_atomic(place, json).is_ok());
    Err(match kept {
        Some(place) => error.context(format!(
            "the measurements are kept in {}: make the tables with `canopy bench paper --from {} --out DIR`",
            place.display(),
            place.display()
        )),
        None => error.context("the measurements could not be kept anywhere"),
    })
}

/// Writes a text file through a temporary sibling, so a failure leaves no partial file.
fn write_atomic(path: &Path, text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    canopy_render::output::write_atomically(path, |w| w.write_all(text.as_bytes()))
        .with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_standard_deviation() {
        let (mean, std) = mean_and_std(&[2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0]);
        assert_eq!(mean, 5.0);
        assert!((std - 2.138).abs() < 1e-3);
        assert_eq!(mean_and_std(&[3.0]), (3.0, 0.0));
    }

    #[test]
    fn results_json_gives_back_the_same_numbers() {
        // A remake from results.json must print the tables the run printed: a mean read
        // back one ulp off can round the other way at the table's fourth digit. This value
        // is one serde_json parses one ulp off without its `float_roundtrip` feature.
        let mean = 0.0020796181086732758_f64;
        let text = serde_json::to_string(&mean).unwrap();
        assert_eq!(serde_json::from_str::<f64>(&text).unwrap(), mean);
    }

    #[test]
    fn report_methods_come_first_and_all_adds_twelve() {
        assert_eq!(methods(false).len(), 6);
        assert_eq!(methods(true).len(), 18);
        assert_eq!(methods(true)[0].kind, AccelKind::None);
    }

    #[test]
    fn every_method_renders_with_the_chosen_triangle_test() {
        let scene = BuiltinScene::find("paper-3").unwrap().load().unwrap();
        let params = canopy_bvh::BuildParams::default();
        for method in methods(true) {
            for test in [TriangleTest::Fast, TriangleTest::Watertight] {
                let accel = accel_for(&scene, &method, &params, test);
                assert_eq!(accel.triangle_test(), test, "{}", method.label);
            }
        }
    }
}
