//! `canopy bvh`: build BVHs over a scene or mesh with several builders and widths and
//! tabulate their shape, quality and build time.

use crate::build_args::{builders_help, BuildArgs};
use crate::limits;
use crate::units::human_bytes;
use canopy_bvh::{build_with_clipper, Aabb, BuildParams, Builder, Clipper, Tree};
use canopy_render::BvhWidth;
use clap::Args;
use serde::Serialize;
use std::time::Instant;

#[derive(Args)]
pub struct BvhArgs {
    /// Built-in scene name, scene file, or a bare OBJ/PLY mesh.
    input: String,
    /// A folder the scene may also read files from (meshes, models, maps). A scene reads
    /// only files in its own folder unless this allows more; repeat it for several.
    #[arg(long, value_name = "DIR")]
    allow_path: Vec<std::path::PathBuf>,
    /// Builders, comma-separated, or `all`.
    #[arg(long, default_value = "all", long_help = builders_help("BVH builders, comma-separated, or `all`:"))]
    bvh: String,
    /// Widths to collapse to, comma-separated (2, 4, 8).
    #[arg(long, value_delimiter = ',', default_value = "2")]
    width: Vec<BvhWidth>,
    /// Builds per measurement, 1 to 1000; the median time is reported.
    #[arg(long, default_value_t = 5, value_parser = limits::runs())]
    runs: u32,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Also compute EPO (effective parallel overlap, Aila et al. 2013), which prices the
    /// overlap of boxes that SAH ignores; needs triangles and cuboids only (no spheres).
    /// About one box query per node: seconds on large meshes.
    #[arg(long)]
    epo: bool,
    /// Optimise each tree after building by reinsertion (Bittner et al. 2013): a number of
    /// passes (`3`) or a time budget (`500ms`, `2s`); the table then shows the optimised
    /// tree, its SAH before and the time taken.
    #[arg(long, value_parser = limits::optimize_budget)]
    optimize: Option<canopy_bvh::OptimizeBudget>,
    #[command(flatten)]
    build: BuildArgs,
}

/// One builder at one width.
#[derive(Serialize)]
struct Row {
    builder: &'static str,
    width: u32,
    /// Median wall-clock build time (collapse included), milliseconds.
    build_ms: f64,
    nodes: usize,
    leaves: usize,
    /// Primitive references in leaves (more than the primitives after spatial splits).
    references: usize,
    mean_leaf_size: f32,
    max_leaf_size: usize,
    max_depth: usize,
    /// SAH cost with the root's surface area normalised to 1.
    sah_cost: f32,
    /// With `--optimize`: SAH as built, and the optimiser's milliseconds.
    #[serde(skip_serializing_if = "Option::is_none")]
    sah_before_optimize: Option<f32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    optimize_ms: Option<f64>,
    /// EPO with the scene's surface area normalised to 1 (with `--epo`).
    #[serde(skip_serializing_if = "Option::is_none")]
    epo: Option<f32>,
    memory_bytes: usize,
}

#[derive(Serialize)]
struct Report {
    input: String,
    primitives: usize,
    threads: usize,
    rows: Vec<Row>,
}

fn parse_builders(list: &str) -> anyhow::Result<Vec<Builder>> {
    if list == "all" {
        return Ok(Builder::ALL.to_vec());
    }
    list.split(',')
        .map(|name| Ok(name.trim().parse::<Builder>()?))
        .collect()
}

pub fn run(args: &BvhArgs) -> anyhow::Result<()> {
    let builders = parse_builders(&args.bvh)?;
    let params = args.build.params();
    let mut scene = canopy_render::load_scene_allowing(&args.input, &args.allow_path)?;
    if !scene.instances.is_empty() {
        // One tree over every placed triangle: the instances baked into world space.
        let flat = scene.primitives.len() as u64 + scene.instanced_triangles();
        crate::safety::check_memory(
            flat * std::mem::size_of::<canopy_render::scene::Primitive>() as u64,
            &format!("baking {flat} instanced triangles into one tree"),
        )?;
        scene = scene.with_instances_baked();
    }
    if args.epo && scene.shape_counts().spheres > 0 {
        anyhow::bail!(
            "--epo: {} has spheres, whose area inside a box canopy does not compute; EPO needs triangles and cuboids only",
            args.input
        );
    }
    let boxes = scene.primitive_bounds();
    let mut rows = Vec::new();
    for &builder in &builders {
        args.build.check_memory(builder, boxes.len())?;
        for &width in &args.width {
            let clipper = canopy_render::clipper(&scene.primitives);
            let (mut row, tree) = measure(
                builder,
                width,
                (&boxes, &clipper),
                &params,
                args.runs,
                args.optimize,
            );
            if args.epo {
                let area = |prim: u32, region: &Aabb| {
                    scene.primitives[prim as usize]
                        .shape
                        .area_in_box(region)
                        .unwrap_or(0.0)
                };
                row.epo = Some(canopy_bvh::epo(tree.view(), &params.sah, area));
            }
            rows.push(row);
        }
    }
    let report = Report {
        input: args.input.clone(),
        primitives: boxes.len(),
        threads: rayon::current_num_threads(),
        rows,
    };
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_table(&report);
    }
    Ok(())
}

fn measure(
    builder: Builder,
    width: BvhWidth,
    (boxes, clipper): (&[Aabb], &dyn Clipper),
    params: &BuildParams,
    runs: u32,
    optimize: Option<canopy_bvh::OptimizeBudget>,
) -> (Row, Tree) {
    // Timed: the build and the collapse to the requested width.
    let mut optimized = None;
    let mut build_once = || {
        let bvh = build_with_clipper(builder, boxes, params, clipper);
        let bvh = match optimize {
            Some(budget) => {
                let start = Instant::now();
                let (bvh, report) = canopy_bvh::optimize(&bvh, &params.sah, budget);
                optimized = Some((report, start.elapsed().as_secs_f64() * 1e3));
                bvh
            }
            None => bvh,
        };
        Tree::new(bvh, width)
    };
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..runs {
        let start = Instant::now();
        let built = build_once();
        times.push(start.elapsed().as_secs_f64() * 1e3);
        last = Some(built);
    }
    times.sort_by(f64::total_cmp);
    let tree = last.expect("at least one run");
    let stats = tree.stats(&params.sah);
    let row = Row {
        builder: builder.name(),
        width: width.children(),
        build_ms: times[times.len() / 2],
        nodes: stats.nodes,
        leaves: stats.leaves,
        references: stats.references,
        mean_leaf_size: stats.mean_leaf_size(),
        max_leaf_size: stats.max_leaf_size,
        max_depth: stats.max_depth,
        sah_cost: stats.sah_cost,
        sah_before_optimize: optimized.map(|(r, _)| r.sah_before),
        optimize_ms: optimized.map(|(_, ms)| ms),
        epo: None,
        memory_bytes: stats.memory_bytes,
    };
    (row, tree)
}

fn print_table(report: &Report) {
    outln!(
        "{}: {} primitives, {} threads",
        report.input,
        report.primitives,
        report.threads
    );
    outln!(
        "{:<14} {:>5} {:>10} {:>8} {:>8} {:>8} {:>6} {:>5} {:>6} {:>9} {:>9} {:>10}",
        "builder",
        "width",
        "build ms",
        "nodes",
        "leaves",
        "refs",
        "leaf",
        "max",
        "depth",
        "SAH",
        "EPO",
        "memory"
    );
    for r in &report.rows {
        if let (Some(before), Some(ms)) = (r.sah_before_optimize, r.optimize_ms) {
            outln!(
                "{:<14} {:>5} optimised in {ms:.1} ms: SAH {before:.2} -> {:.2}",
                r.builder,
                r.width,
                r.sah_cost
            );
        }
        let epo = r.epo.map_or("-".to_string(), |e| format!("{e:.2}"));
        outln!(
            "{:<14} {:>5} {:>10.2} {:>8} {:>8} {:>8} {:>6.2} {:>5} {:>6} {:>9.2} {:>9} {:>10}",
            r.builder,
            r.width,
            r.build_ms,
            r.nodes,
            r.leaves,
            r.references,
            r.mean_leaf_size,
            r.max_leaf_size,
            r.max_depth,
            r.sah_cost,
            epo,
            human_bytes(r.memory_bytes as u64)
        );
    }
}
