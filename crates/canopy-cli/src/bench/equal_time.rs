//! What the equal-time benchmarks (`bench lights`, `bench denoise`) share: a worker pool,
//! each scene loaded at the table's size with its structure and a high-sample reference,
//! and the table written where asked.

use anyhow::Context;
use canopy_render::{load_scene_allowing, render, Accel, Film, Scene};
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// The benchmark's worker threads (`None` or 0: all cores).
pub fn worker_pool(threads: Option<u32>) -> anyhow::Result<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0) as usize)
        .build()
        .context("cannot start the worker threads")
}

/// Refuses a table path that cannot be written, before minutes of rendering.
pub fn check_table(out: Option<&Path>) -> anyhow::Result<()> {
    if let Some(out) = out {
        crate::safety::check_output(out, "table", crate::safety::OutputKind::Data, &[])?;
    }
    Ok(())
}

/// Scene `name` (reading only its own folder and `allowed`) at `size`, with its default
/// 8-wide structure; the table `out` must not be one of its files.
pub fn load(
    name: &str,
    size: (u32, u32),
    allowed: &[PathBuf],
    out: Option<&Path>,
) -> anyhow::Result<(Scene, Accel)> {
    let mut scene = load_scene_allowing(name, allowed)?;
    if let Some(out) = out {
        crate::safety::refuse_inputs(out, &scene.inputs, "table")?;
    }
    (scene.settings.width, scene.settings.height) = size;
    let accel = Accel::default_for(&scene);
    Ok((scene, accel))
}

/// The reference image: `scene` (as `adjust` leaves it) at `spp` samples, drawn from
/// another seed than the renders it is compared with.
pub fn reference(
    pool: &rayon::ThreadPool,
    (scene, accel): (&Scene, &Accel),
    spp: u32,
    adjust: impl Fn(&mut Scene) + Send + Sync,
) -> Film {
    pool.install(|| {
        let mut s = scene.clone();
        adjust(&mut s);
        s.settings.spp = spp;
        s.settings.seed = 1_000_003;
        render(&s, accel, &|| {}).0
    })
}

/// Prints the table, and writes it atomically to `out` too where given.
pub fn emit_table(table: &str, out: Option<&Path>) -> anyhow::Result<()> {
    outln!("{table}");
    if let Some(out) = out {
        canopy_render::output::write_atomically(out, |w| w.write_all(table.as_bytes()))
            .with_context(|| format!("cannot write {}", out.display()))?;
    }
    Ok(())
}
