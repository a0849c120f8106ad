//! `canopy bench lights`: what light sampling buys. Each scene is rendered by both
//! integrators in the same time budget and compared with a high-sample reference (path
//! integrator, another seed): RMSE of the displayed image and the ratio, plus the share
//! of render time the shadow rays take.

use super::equal_time;
use crate::limits;
use canopy_render::{render, render_counted, Accel, Film, Integrator, Scene};
use clap::Args;
use glam::Vec3;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct LightsArgs {
    /// Scenes: built-in names or scene files [default: cornell].
    scenes: Vec<String>,
    /// Image size WIDTHxHEIGHT, each 1 to 65536.
    #[arg(long, default_value = "128x128", value_parser = limits::size)]
    size: (u32, u32),
    /// Render time each integrator gets, in seconds.
    #[arg(long, default_value = "4", value_parser = limits::duration)]
    seconds: std::time::Duration,
    /// Samples per pixel of the reference image.
    #[arg(long, default_value = "2048", value_parser = limits::spp())]
    reference_spp: u32,
    /// Worker threads, 1 to 1024 [default: all cores].
    #[arg(long, value_parser = limits::threads())]
    threads: Option<u32>,
    /// Write the table (Markdown) here too.
    #[arg(short, long)]
    out: Option<PathBuf>,
    /// A folder the scenes may also read files from (see `canopy render --allow-path`).
    #[arg(long, value_name = "DIR")]
    allow_path: Vec<PathBuf>,
}

/// One integrator on one scene at the time budget.
struct Row {
    scene: String,
    integrator: Integrator,
    spp: u32,
    seconds: f64,
    rmse: f64,
    /// `rmse` scaled to the time budget as if error fell exactly as 1/√time.
    rmse_at_budget: f64,
    rmse_unclamped: f64,
    shadow_share: f64,
    shadow_rays_share: f64,
}

pub fn run(args: &LightsArgs) -> anyhow::Result<()> {
    let out = args.out.as_deref();
    equal_time::check_table(out)?;
    let pool = equal_time::worker_pool(args.threads)?;
    let scenes = if args.scenes.is_empty() {
        vec!["cornell".to_string()]
    } else {
        args.scenes.clone()
    };
    let mut rows = Vec::new();
    for name in &scenes {
        let (scene, accel) = equal_time::load(name, args.size, &args.allow_path, out)?;
        let name = if scene.name.is_empty() {
            name.clone()
        } else {
            scene.name.clone()
        };
        let name = &name;
        eprintln!("{name}: reference at {} spp", args.reference_spp);
        let reference = equal_time::reference(&pool, (&scene, &accel), args.reference_spp, |s| {
            s.settings.integrator = Integrator::Path
        });
        for integrator in [Integrator::Bsdf, Integrator::Path] {
            let row = pool
                .install(|| measure(name, &scene, integrator, &accel, &reference, args.seconds));
            eprintln!(
                "{name} {integrator}: {} spp in {:.2} s, RMSE {:.4}",
                row.spp, row.seconds, row.rmse
            );
            rows.push(row);
        }
    }
    equal_time::emit_table(&markdown(&rows, args, pool.current_num_threads()), out)
}

fn measure(
    name: &str,
    scene: &Scene,
    integrator: Integrator,
    accel: &Accel,
    reference: &Film,
    budget: std::time::Duration,
) -> Row {
    let mut s = scene.clone();
    s.settings.integrator = integrator;
    s.settings.seed = 7;
    // The shadow-ray share, from a counted render of a few samples.
    s.settings.spp = 4;
    let (_, probe) = render_counted(&s, accel, &|| {});
    // Calibrate on renders of a tenth of the budget or more (short ones run slow).
    let per_sample = loop {
        let start = Instant::now();
        render(&s, accel, &|| {});
        let took = start.elapsed().as_secs_f64();
        if took >= 0.1 * budget.as_secs_f64() || s.settings.spp >= 1 << 20 {
            break took / s.settings.spp as f64;
        }
        s.settings.spp *= 2;
    };
    s.settings.spp = ((budget.as_secs_f64() / per_sample) as u32).max(1);
    let start = Instant::now();
    let (film, _) = render(&s, accel, &|| {});
    let seconds = start.elapsed().as_secs_f64();
    // Error falls as 1/√time: scale it to exactly the budget, for a fair ratio.
    let to_budget = (seconds / budget.as_secs_f64()).sqrt();
    Row {
        scene: name.to_string(),
        integrator,
        spp: s.settings.spp,
        seconds,
        rmse: rmse(&film, reference, true),
        rmse_at_budget: rmse(&film, reference, true) * to_budget,
        rmse_unclamped: rmse(&film, reference, false),
        shadow_share: probe.shadow_time.as_secs_f64() / probe.thread_time.as_secs_f64().max(1e-12),
        shadow_rays_share: probe.shadow_rays as f64 / probe.rays.max(1) as f64,
    }
}

/// Root-mean-square error per channel; `displayed` clamps radiance to 1 first, as an
/// 8-bit image shows it (unclamped, the directly seen light's edge pixels dominate).
fn rmse(film: &Film, reference: &Film, displayed: bool) -> f64 {
    let clamp = |p: Vec3| if displayed { p.min(Vec3::ONE) } else { p };
    let sum: f64 = film
        .pixels
        .iter()
        .zip(&reference.pixels)
        .map(|(p, q)| (clamp(*p) - clamp(*q)).length_squared() as f64)
        .sum();
    (sum / (3 * film.pixels.len()) as f64).sqrt()
}

fn markdown(rows: &[Row], args: &LightsArgs, threads: usize) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "Equal-time error: {}x{}, {:.1} s per integrator, reference {} spp (path integrator, another seed), {threads} threads. RMSE per channel of the displayed image (radiance clamped to 1) unless said.\n",
        args.size.0,
        args.size.1,
        args.seconds.as_secs_f64(),
        args.reference_spp
    );
    let _ = writeln!(
        t,
        "| scene | integrator | spp | seconds | RMSE (displayed) | RMSE at exactly the budget | RMSE (radiance) | error ratio bsdf/path at equal time | shadow rays (share of rays) | shadow-ray time (share) |"
    );
    let _ = writeln!(t, "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for row in rows {
        let bsdf = rows
            .iter()
            .find(|r| r.scene == row.scene && r.integrator == Integrator::Bsdf);
        let ratio = match (row.integrator, bsdf) {
            (Integrator::Path, Some(b)) => format!("{:.1}x", b.rmse_at_budget / row.rmse_at_budget),
            _ => String::new(),
        };
        let _ = writeln!(
            t,
            "| {} | {} | {} | {:.2} | {:.4} | {:.4} | {:.4} | {ratio} | {:.0}% | {:.0}% |",
            row.scene,
            row.integrator,
            row.spp,
            row.seconds,
            row.rmse,
            row.rmse_at_budget,
            row.rmse_unclamped,
            100.0 * row.shadow_rays_share,
            100.0 * row.shadow_share
        );
    }
    t
}
