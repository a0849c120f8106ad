//! The render thread: builds the tree when asked, and renders the view through canopy-job
//! while some page is open — a quick preview at a quarter of the size first, then the
//! full image pass by pass, each pass published as a frame — until the target samples
//! are in or the view changes. A change that leaves the samples valid (exposure, a
//! higher target, the boxes' levels, another tree of the same triangle test: every such
//! tree gives the same hits) continues from them.

use crate::frame::{encode, resident_bytes, Overlay};
use crate::protocol::{FrameInfo, ServerMessage, TreeReport};
use crate::session::{Control, Frame, Session, Shown};
use crate::settings::{Mode, TreeSettings, ViewSettings};
use canopy_gpu::{Gpu, Renderer as GpuRenderer};
use canopy_job::{Device, Observer, RenderJob, Structure};
use canopy_render::film::srgb_to_linear;
use canopy_render::visualize::render_heatmap;
use canopy_render::{Accel, AccelKind, Accumulator, Film, Scene};
use glam::Vec3;
use std::sync::{Arc, RwLockReadGuard};
use std::time::Instant;

/// Preview images are this many times smaller on each side.
const PREVIEW_DIVISOR: u32 = 4;

/// Samples of a view, to continue from.
struct Kept {
    view: ViewSettings,
    accumulator: Accumulator,
}

/// The GPU a viewer renders on, and the scene uploaded to it with the tree built last.
struct GpuStage<'g> {
    gpu: &'g Gpu,
    uploaded: Option<GpuRenderer<'g>>,
}

impl<'g> GpuStage<'g> {
    /// The upload of `scene` (at its full size) and `accel`: the one kept, unless its
    /// integrator is another.
    fn renderer(&mut self, scene: &Scene, accel: &Accel) -> Result<&GpuRenderer<'g>, String> {
        let integrator = scene.settings.integrator;
        if self
            .uploaded
            .as_ref()
            .is_some_and(|r| r.integrator() != integrator)
        {
            self.uploaded = None;
        }
        if self.uploaded.is_none() {
            let renderer = GpuRenderer::for_accel(self.gpu, scene, accel)
                .map_err(|e| format!("cannot render the view on the GPU: {e}"))?;
            self.uploaded = Some(renderer);
        }
        Ok(self.uploaded.as_ref().expect("uploaded above"))
    }
}

/// Runs until the session shuts down, rendering on `gpu` where given. A job that cannot
/// run is told to the pages (as an error notice) and not tried again until something
/// changes.
pub(crate) fn run(session: &Session, gpu: Option<&Gpu>) {
    let mut stage = gpu.map(|gpu| GpuStage {
        gpu,
        uploaded: None,
    });
    let mut built_generation = None;
    let mut built_test = None;
    let mut finished_generation = None;
    let mut kept: Option<Kept> = None;
    loop {
        let Some(control) = session.wait_for_work(|c| {
            built_generation != Some(c.tree_generation)
                || finished_generation != Some(c.view_generation)
        }) else {
            return;
        };
        if built_generation != Some(control.tree_generation) {
            if let Some(scene) = session.take_pending_scene() {
                *session.scene.write().unwrap_or_else(|e| e.into_inner()) = scene;
                // The old scene's samples.
                kept = None;
            }
            if built_test.is_some_and(|test| test != control.tree.triangle_test) {
                // Another triangle test may hit rays through edges elsewhere: samples
                // of the two would mix two images.
                kept = None;
            }
            let report = build(session, &control.tree);
            session.publish_tree(report);
            if let Some(stage) = &mut stage {
                // Uploaded with the old tree (and scene).
                stage.uploaded = None;
            }
            built_generation = Some(control.tree_generation);
            built_test = Some(control.tree.triangle_test);
            // The image does not depend on the tree (of one triangle test), but its
            // frames name the tree's speed: render the view again so the page shows the
            // new one's.
            finished_generation = None;
        }
        let accel = session
            .accel
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
            .expect("built above");
        apply_view(session, &control.view, None);
        let complete = match control.view.mode {
            Mode::Heatmap => {
                heatmap(session, &control, &accel);
                true
            }
            Mode::Render | Mode::Boxes | Mode::Albedo | Mode::Normal => {
                let resume = kept
                    .take()
                    .filter(|k| k.view.keeps_samples(&control.view))
                    .map(|k| k.accumulator)
                    .filter(|a| a.samples <= control.view.spp);
                let (accumulator, complete) =
                    render(session, &control, &accel, stage.as_mut(), resume);
                kept = accumulator.map(|accumulator| Kept {
                    view: control.view.clone(),
                    accumulator,
                });
                complete
            }
        };
        if complete {
            finished_generation = Some(control.view_generation);
        }
    }
}

/// Builds the tree, stores it in the session and reports it.
fn build(session: &Session, tree: &TreeSettings) -> TreeReport {
    let scene = read(session);
    let accel = Accel::for_scene(
        &scene,
        AccelKind::Bvh(tree.builder),
        tree.width,
        &tree.params(),
        None,
    )
    .with_triangle_test(tree.triangle_test);
    let report = tree_report(&scene, &accel, tree);
    *session.accel.lock().unwrap_or_else(|e| e.into_inner()) = Some(Arc::new(accel));
    report
}

fn tree_report(scene: &Scene, accel: &Accel, settings: &TreeSettings) -> TreeReport {
    let costs = settings.params().sah;
    let trees: Vec<_> = accel
        .world()
        .blases()
        .iter()
        .filter_map(|b| b.tree())
        .collect();
    // The tree of the scene's own primitives, or of its first mesh where it has none.
    let main = match scene.primitives.is_empty() {
        true => trees.get(1).or(trees.first()),
        false => trees.first(),
    };
    let stats = main.map(|t| t.stats(&costs)).unwrap_or_default();
    let counts = scene.shape_counts();
    // EPO needs each primitive's area inside a box: triangles and cuboids only. Over
    // the scene's own primitives (a mesh's triangles live in its own space).
    let epo = match (counts.spheres, accel.tree()) {
        (0, Some(tree)) if !scene.primitives.is_empty() => {
            Some(canopy_bvh::epo(tree.view(), &costs, |prim, region| {
                scene.primitives[prim as usize]
                    .shape
                    .area_in_box(region)
                    .unwrap_or(0.0)
            }))
        }
        _ => None,
    };
    TreeReport {
        builder: settings.builder.name().into(),
        primitives: scene.primitives.len(),
        instances: scene.instances.len(),
        width: settings.width.children(),
        max_leaf_size: settings.max_leaf_size,
        fast_triangles: settings.triangle_test == canopy_bvh::TriangleTest::Fast,
        build_ms: accel.build_time.as_secs_f64() * 1e3,
        sah: stats.sah_cost,
        epo,
        depth: stats.max_depth,
        nodes: stats.nodes,
        leaves: stats.leaves,
        memory_bytes: trees.iter().map(|t| t.stats(&costs).memory_bytes).sum(),
        structures: accel.world().blases().len(),
        top_tree: accel.world().tree().is_some(),
    }
}

fn read(session: &Session) -> RwLockReadGuard<'_, Scene> {
    session.scene.read().unwrap_or_else(|e| e.into_inner())
}

/// Sets the scene's camera and settings to `view`'s, at `size` (the full image's when
/// `None`).
fn apply_view(session: &Session, view: &ViewSettings, size: Option<(u32, u32)>) {
    let mut scene = session.scene.write().unwrap_or_else(|e| e.into_inner());
    scene.camera = view.camera;
    let s = &mut scene.settings;
    (s.width, s.height) = size.unwrap_or((session.width, session.height));
    s.spp = view.spp;
    s.max_depth = view.max_depth;
    s.integrator = view.integrator;
    s.seed = view.seed;
    s.russian_roulette = view.russian_roulette;
    s.sampler = view.sampler;
}

fn heatmap(session: &Session, control: &Control, accel: &Accel) {
    let start = Instant::now();
    let map = render_heatmap(&read(session), accel);
    let info = FrameInfo {
        sequence: session.next_sequence(),
        generation: control.view_generation,
        mode: Mode::Heatmap,
        preview: false,
        width: map.film.width,
        height: map.film.height,
        spp: 1,
        target_spp: 1,
        continued_from: 0,
        seconds: start.elapsed().as_secs_f64(),
        mrays_per_second: 0.0,
        memory_bytes: resident_bytes(),
    };
    let jpeg = encode(map.film.clone(), 0.0, None);
    session.publish_shown(Shown {
        film: map.film,
        exposure: 0.0,
    });
    session.publish_frame(Frame { info, jpeg });
}

/// Renders the view: a preview unless continuing from `resume`, then the full image.
/// Returns the samples it has (to continue from) and whether the target is reached; a
/// job that cannot run (an image too large for the memory left, say) is told to the
/// pages and counts as done, so that it is not tried again until the view changes.
fn render(
    session: &Session,
    control: &Control,
    accel: &Arc<Accel>,
    stage: Option<&mut GpuStage<'_>>,
    resume: Option<Accumulator>,
) -> (Option<Accumulator>, bool) {
    let start = Instant::now();
    // Uploaded with the scene at its full size: the sums' buffer holds the full image.
    let gpu = match stage.map(|s| s.renderer(&read(session), accel)).transpose() {
        Ok(gpu) => gpu,
        Err(message) => {
            session.notify(ServerMessage::Error { message });
            return (None, true);
        }
    };
    if resume.is_none() {
        let size = (
            (session.width / PREVIEW_DIVISOR).max(1),
            (session.height / PREVIEW_DIVISOR).max(1),
        );
        apply_view(
            session,
            &ViewSettings {
                spp: 1,
                ..control.view.clone()
            },
            Some(size),
        );
        let preview = run_job(session, control, accel, gpu, None, start, true);
        apply_view(session, &control.view, None);
        if let Err(message) = preview {
            session.notify(ServerMessage::Error { message });
            return (None, true);
        }
    }
    match run_job(session, control, accel, gpu, resume, start, false) {
        Ok(outcome) => (Some(outcome.accumulator), outcome.complete),
        Err(message) => {
            session.notify(ServerMessage::Error { message });
            (None, true)
        }
    }
}

/// One job over the scene as it is set now (on `gpu`'s upload where given), publishing a
/// frame after each pass; why it could not run, if it could not.
fn run_job(
    session: &Session,
    control: &Control,
    accel: &Arc<Accel>,
    gpu: Option<&GpuRenderer<'_>>,
    resume: Option<Accumulator>,
    start: Instant,
    preview: bool,
) -> Result<canopy_job::Outcome, String> {
    let scene = read(session);
    let mut job = RenderJob::new(&scene, scene.name.clone());
    job.structure = Structure {
        kind: AccelKind::Bvh(control.tree.builder),
        width: control.tree.width,
        params: control.tree.params(),
        triangle_test: control.tree.triangle_test,
        ..Structure::default()
    };
    job.schedule = control.view.schedule;
    job.resume = resume;
    job.aovs = control.view.mode.aovs();
    let samples_before = job.resume.as_ref().map_or(0, |a| a.samples);
    let prepared = match gpu {
        None => job.prepare_with(accel.clone()),
        Some(renderer) => {
            job.device = Device::Gpu;
            job.prepare_on(accel.clone(), renderer)
        }
    }
    .map_err(|e| format!("cannot render the view: {e}"))?;
    let mut observer = FrameObserver {
        session,
        control,
        accel,
        start,
        preview,
        rays_before: job.resume.as_ref().map_or(0, |a| a.rays),
        samples_before,
        passes_started: Instant::now(),
    };
    let outcome = prepared
        .run(&mut observer)
        .map_err(|e| format!("the render stopped: {e}"))?;
    // Samples continued at their target (a new exposure, say) make no pass, yet the
    // page waits for the image they make now.
    if outcome.accumulator.samples == samples_before && samples_before > 0 {
        observer.pass_samples(&outcome.accumulator);
    }
    Ok(outcome)
}

/// Publishes each pass as a frame, and stops the job when the view changes or the last
/// page closes.
struct FrameObserver<'a> {
    session: &'a Session,
    control: &'a Control,
    accel: &'a Accel,
    start: Instant,
    preview: bool,
    rays_before: u64,
    /// Samples the render continued from (0: it started afresh).
    samples_before: u32,
    passes_started: Instant,
}

impl Observer for FrameObserver<'_> {
    fn keep_going(&mut self) -> bool {
        self.session.still_current(self.control)
    }

    // A moved camera must not wait for a whole pass of the old view: the pass in flight
    // is dropped between rows (the samples before it are kept, for a change that keeps
    // them).
    fn abandons_passes(&self) -> bool {
        true
    }

    fn abandon_pass(&self) -> bool {
        !self.session.still_current(self.control)
    }

    fn pass_samples(&mut self, accumulator: &Accumulator) {
        let view = &self.control.view;
        let film = shown_film(accumulator, view.mode);
        let rays = accumulator.rays - self.rays_before;
        let info = FrameInfo {
            sequence: self.session.next_sequence(),
            generation: self.control.view_generation,
            mode: view.mode,
            preview: self.preview,
            width: film.width,
            height: film.height,
            spp: accumulator.samples,
            target_spp: view.spp,
            continued_from: self.samples_before,
            seconds: self.start.elapsed().as_secs_f64(),
            mrays_per_second: rays as f64 / self.passes_started.elapsed().as_secs_f64() / 1e6,
            memory_bytes: resident_bytes(),
        };
        let overlay = match (view.mode, self.accel.tree()) {
            (Mode::Boxes, Some(tree)) => Some(Overlay {
                tree,
                camera: &view.camera,
                levels: view.levels,
            }),
            _ => None,
        };
        let jpeg = encode(film.clone(), view.exposure, overlay);
        self.session.publish_shown(Shown {
            film,
            exposure: view.exposure,
        });
        self.session.publish_frame(Frame { info, jpeg });
    }
}

/// The image of `accumulator` that `mode` shows: the render, or an AOV layer.
fn shown_film(accumulator: &Accumulator, mode: Mode) -> Film {
    let film = accumulator.film();
    if mode.aovs().is_empty() {
        return film;
    }
    let layers = accumulator.aovs.resolved(accumulator.samples);
    let pixels = match mode {
        Mode::Albedo => layers.albedo,
        // Each axis from -1..1 to 0..1, as the colour shown (sRGB-encoded).
        Mode::Normal => layers
            .normal
            .iter()
            .map(|n| {
                (*n * 0.5 + 0.5)
                    .clamp(Vec3::ZERO, Vec3::ONE)
                    .map(srgb_to_linear)
            })
            .collect(),
        Mode::Render | Mode::Boxes | Mode::Heatmap => return film,
    };
    Film { pixels, ..film }
}
