//! `canopy bench denoise`: what denoising buys at equal time. Each scene is rendered at a
//! few sample counts with the albedo and normal, denoised by Open Image Denoise, and
//! compared with a high-sample reference (another seed): the relative MSE of the noisy and
//! the denoised image, of an undenoised render given the AOVs' and the denoiser's time as
//! extra samples, and the samples an undenoised render needs for the denoised error
//! (measured by doubling).
//! (`bench/denoise.py` adds FLIP and a glTF model.)

use super::equal_time;
use crate::limits;
use canopy_job::{denoise_film, DenoiseOptions, Oidn};
use canopy_render::{render, render_samples, Accel, Accumulator, AovSet, Film, Scene};
use clap::Args;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct DenoiseArgs {
    /// Scenes: built-in names or scene files [default: cornell paper-3].
    scenes: Vec<String>,
    /// Image size WIDTHxHEIGHT, each 1 to 65536.
    #[arg(long, default_value = "128x128", value_parser = limits::size)]
    size: (u32, u32),
    /// Sample counts to denoise, comma-separated.
    #[arg(long, default_value = "4,16,64", value_delimiter = ',', value_parser = limits::spp())]
    spp: Vec<u32>,
    /// Samples per pixel of the reference image.
    #[arg(long, default_value = "4096", value_parser = limits::spp())]
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

/// One scene at one sample count.
struct Row {
    scene: String,
    spp: u32,
    noisy: f64,
    denoised: f64,
    equal_time_spp: u32,
    equal_time: f64,
    /// Samples an undenoised render needs for the denoised error (measured).
    to_match: String,
    render_seconds: f64,
    denoise_seconds: f64,
}

pub fn run(args: &DenoiseArgs) -> anyhow::Result<()> {
    let out = args.out.as_deref();
    equal_time::check_table(out)?;
    // Before minutes of references: the denoiser must be there.
    let oidn = Oidn::load(&[])?;
    let pool = equal_time::worker_pool(args.threads)?;
    let scenes = match args.scenes.is_empty() {
        true => vec!["cornell".to_string(), "paper-3".to_string()],
        false => args.scenes.clone(),
    };
    let mut rows = Vec::new();
    for name in &scenes {
        let (scene, accel) = equal_time::load(name, args.size, &args.allow_path, out)?;
        eprintln!("{name}: reference at {} spp", args.reference_spp);
        let reference = equal_time::reference(&pool, (&scene, &accel), args.reference_spp, |_| {});
        for &spp in &args.spp {
            let row = pool.install(|| {
                let reference = (&reference, args.reference_spp);
                measure(name, &scene, spp, &accel, &oidn, reference)
            })?;
            eprintln!(
                "{name} {spp} spp: relative MSE {:.5} noisy, {:.5} denoised, {:.5} at equal time",
                row.noisy, row.denoised, row.equal_time
            );
            rows.push(row);
        }
    }
    equal_time::emit_table(&markdown(&rows, args, pool.current_num_threads()), out)
}

fn measure(
    name: &str,
    scene: &Scene,
    spp: u32,
    accel: &Accel,
    oidn: &Oidn,
    (reference, reference_spp): (&Film, u32),
) -> anyhow::Result<Row> {
    let mut s = scene.clone();
    s.settings.spp = spp;
    let start = Instant::now();
    let (w, h) = (s.settings.width, s.settings.height);
    let mut accumulator = Accumulator::new(w, h).with_aovs(AovSet::DENOISING);
    render_samples(&s, accel, &mut accumulator, spp, &|| {});
    let render_seconds = start.elapsed().as_secs_f64();
    let noisy = accumulator.film();
    let start = Instant::now();
    let options = DenoiseOptions::default();
    let denoised = denoise_film(oidn, &noisy, &accumulator.aov_images(), &options)?;
    let denoise_seconds = start.elapsed().as_secs_f64();
    // Equal time: the undenoised render's samples in the AOVs' and the denoiser's time too.
    let start = Instant::now();
    render(&s, accel, &|| {});
    let plain_seconds = start.elapsed().as_secs_f64().max(1e-9);
    let ratio = (render_seconds + denoise_seconds) / plain_seconds;
    s.settings.spp = ((spp as f64 * ratio).round() as u32).max(spp);
    let equal = render(&s, accel, &|| {}).0;
    let (noisy, denoised) = (
        relative_mse(&noisy, reference),
        relative_mse(&denoised, reference),
    );
    Ok(Row {
        scene: name.to_string(),
        spp,
        noisy,
        denoised,
        equal_time_spp: s.settings.spp,
        equal_time: relative_mse(&equal, reference),
        to_match: samples_to_match(
            scene,
            accel,
            (reference, reference_spp),
            spp,
            noisy,
            denoised,
        ),
        render_seconds,
        denoise_seconds,
    })
}

/// The samples per pixel an undenoised render needs for the error `target`: renders at
/// twice, four times ... `spp` (error `noisy` at `spp`) until one is at or below it,
/// interpolated in log-log between the two around it; "<= spp" where `spp` already does,
/// "> N" where the reference's own `reference_spp` do not (beyond them the comparison
/// measures the reference's noise).
fn samples_to_match(
    scene: &Scene,
    accel: &Accel,
    (reference, reference_spp): (&Film, u32),
    spp: u32,
    noisy: f64,
    target: f64,
) -> String {
    if noisy <= target {
        return format!("<= {spp}");
    }
    let mut s = scene.clone();
    let (mut low, mut low_error) = (spp as f64, noisy);
    let mut high = spp.saturating_mul(2);
    while high <= reference_spp {
        s.settings.spp = high;
        let error = relative_mse(&render(&s, accel, &|| {}).0, reference);
        if error <= target {
            let t = (low_error.ln() - target.ln()) / (low_error.ln() - error.ln());
            return format!(
                "{}",
                (low.ln() + t * ((high as f64).ln() - low.ln()))
                    .exp()
                    .round()
            );
        }
        (low, low_error, high) = (high as f64, error, high.saturating_mul(2));
    }
    format!("> {reference_spp}")
}

/// Mean over pixels and channels of (image - reference)² / (reference² + 0.01): an error
/// that weighs dark and bright regions alike.
fn relative_mse(film: &Film, reference: &Film) -> f64 {
    let sum: f64 = film
        .pixels
        .iter()
        .zip(&reference.pixels)
        .flat_map(|(p, q)| (0..3).map(move |c| (p[c] as f64, q[c] as f64)))
        .map(|(a, b)| (a - b).powi(2) / (b * b + 1e-2))
        .sum();
    sum / (3 * film.pixels.len()) as f64
}

fn markdown(rows: &[Row], args: &DenoiseArgs, threads: usize) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "Denoising (Open Image Denoise, guided by the albedo and normal): {}x{}, reference {} spp (another seed), {threads} threads. Relative MSE: mean of (image - reference)² / (reference² + 0.01).\n",
        args.size.0, args.size.1, args.reference_spp
    );
    let _ = writeln!(
        t,
        "| scene | spp | noisy | denoised | undenoised at equal time (spp) | samples an undenoised render needs for the denoised error | render with AOVs (s) | denoise (s) | denoise per megapixel (s) |"
    );
    let _ = writeln!(t, "|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    let megapixels = (args.size.0 as f64 * args.size.1 as f64) / 1e6;
    for r in rows {
        let _ = writeln!(
            t,
            "| {} | {} | {:.5} | {:.5} | {:.5} ({}) | {} | {:.3} | {:.3} | {:.2} |",
            r.scene,
            r.spp,
            r.noisy,
            r.denoised,
            r.equal_time,
            r.equal_time_spp,
            r.to_match,
            r.render_seconds,
            r.denoise_seconds,
            r.denoise_seconds / megapixels
        );
    }
    t
}
