//! The render job: regions that put together give the whole image bit for bit, passes
//! that an observer sees and stops, checkpoints kept and resumed into the same image,
//! and jobs that contradict themselves refused before any work.

use canopy_bvh::TriangleTest;
use canopy_job::{CheckpointPolicy, Device, JobError, Observer, RenderJob, Resumed};
use canopy_render::checkpoint::Checkpoint;
use canopy_render::{load_scene, AccelKind, Accumulator, Film, Region, Scene};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

fn small(name: &str, width: u32, height: u32, spp: u32) -> Scene {
    let mut scene = load_scene(name).unwrap();
    scene.settings.width = width;
    scene.settings.height = height;
    scene.settings.spp = spp;
    scene
}

fn pixels_of(film: &Film, region: Region) -> Vec<glam::Vec3> {
    (region.y..region.y + region.height)
        .flat_map(|y| (region.x..region.x + region.width).map(move |x| film.pixel(x, y)))
        .collect()
}

/// Records what it is told, and stops the render after `stop_after` passes.
#[derive(Default)]
struct Recorder {
    rows: AtomicU64,
    passes: Vec<(u32, u32)>,
    stop_after: Option<usize>,
    warnings: Vec<String>,
}

impl Observer for Recorder {
    fn rows_done(&self, rows: u64) {
        self.rows.fetch_add(rows, Ordering::Relaxed);
    }
    fn keep_going(&mut self) -> bool {
        self.stop_after.is_none_or(|n| self.passes.len() < n)
    }
    fn pass_done(&mut self, samples: u32, spp: u32) {
        self.passes.push((samples, spp));
    }
    fn warning(&mut self, message: String) {
        self.warnings.push(message);
    }
}

fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("canopy-job-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn tiles_put_together_are_the_whole_image_bit_for_bit() {
    // Spheres, boxes and lights (cornell), and instanced meshes (teapots).
    for (name, threads) in [
        ("cornell", Some(1)),
        ("teapots", Some(2)),
        ("paper-3", None),
    ] {
        let scene = small(name, 29, 21, 2);
        let mut job = RenderJob::new(&scene, name);
        job.threads = threads;
        let whole = job.prepare().unwrap().run(&mut ()).unwrap();
        assert!(whole.complete && whole.saved.is_none());
        let whole = whole.accumulator.film();
        assert!(
            whole.pixels.iter().any(|p| p.length() > 0.0),
            "{name}: black"
        );
        for tile in Region::full(29, 21).tiles(8) {
            let mut job = RenderJob::new(&scene, name);
            job.region = tile;
            job.threads = Some(2);
            let part = job.prepare().unwrap().run(&mut ()).unwrap();
            assert_eq!(part.accumulator.region, tile);
            assert_eq!(
                part.accumulator.film().pixels,
                pixels_of(&whole, tile),
                "{name}: tile {tile}"
            );
        }
    }
}

#[test]
fn an_observer_sees_every_pass_and_row() {
    let scene = small("paper-1", 16, 9, 3);
    let mut job = RenderJob::new(&scene, "paper-1");
    job.region = Region {
        x: 2,
        y: 1,
        width: 10,
        height: 5,
    };
    let mut seen = Recorder::default();
    let outcome = job.prepare().unwrap().run(&mut seen).unwrap();
    assert!(outcome.complete);
    assert_eq!(seen.passes, [(1, 3), (2, 3), (3, 3)]);
    assert_eq!(seen.rows.load(Ordering::Relaxed), 3 * 5);
    assert_eq!(outcome.accumulator.samples, 3);
    assert!(outcome.stats.rays >= 3 * 50, "{:?}", outcome.stats);
}

#[test]
fn a_stopped_render_saves_its_state_and_resumes_into_the_same_image() {
    let dir = temp_dir("resume");
    let checkpoint = dir.join("part.checkpoint");
    let scene = small("cornell", 20, 14, 5);
    let region = Region {
        x: 4,
        y: 3,
        width: 9,
        height: 8,
    };
    let mut whole = RenderJob::new(&scene, "cornell");
    whole.region = region;
    let uninterrupted = whole.prepare().unwrap().run(&mut ()).unwrap().accumulator;

    let mut job = RenderJob::new(&scene, "cornell");
    job.region = region;
    job.checkpoint = CheckpointPolicy {
        periodic: None,
        every: Duration::ZERO,
        on_interrupt: Some(checkpoint.clone()),
    };
    let mut stopper = Recorder {
        stop_after: Some(2),
        ..Recorder::default()
    };
    let stopped = job.prepare().unwrap().run(&mut stopper).unwrap();
    assert!(!stopped.complete);
    assert_eq!(stopped.accumulator.samples, 2);
    assert_eq!(stopped.saved.as_deref(), Some(checkpoint.as_path()));
    let saved = Checkpoint::load(&checkpoint).unwrap();
    assert_eq!(saved.accumulator, stopped.accumulator);

    // Resumed (scene found again by its name), it goes on from sample 2 to the same image,
    // then removes its checkpoint.
    let resumed = Resumed::load(&checkpoint, &[]).unwrap();
    let mut seen = Recorder::default();
    let done = resumed.job().prepare().unwrap().run(&mut seen).unwrap();
    assert_eq!(seen.passes, [(3, 5), (4, 5), (5, 5)]);
    assert!(done.complete);
    assert_eq!(done.accumulator.sums, uninterrupted.sums);
    assert_eq!(done.accumulator.region, region);
    assert!(
        !checkpoint.exists(),
        "a complete render keeps no checkpoint"
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_resumed_render_goes_on_in_its_checkpoints_triangle_test() {
    let dir = temp_dir("resume-fast");
    let checkpoint = dir.join("fast.checkpoint");
    let scene = small("paper-3", 16, 12, 4);
    let fast_job = || {
        let mut job = RenderJob::new(&scene, "paper-3");
        job.structure.triangle_test = TriangleTest::Fast;
        job
    };
    let uninterrupted = fast_job().prepare().unwrap().run(&mut ()).unwrap();
    let mut job = fast_job();
    job.checkpoint.on_interrupt = Some(checkpoint.clone());
    let prepared = job.prepare().unwrap();
    assert_eq!(prepared.triangle_test(), TriangleTest::Fast);
    let mut stopper = Recorder {
        stop_after: Some(2),
        ..Recorder::default()
    };
    assert!(!prepared.run(&mut stopper).unwrap().complete);
    assert_eq!(
        Checkpoint::load(&checkpoint).unwrap().triangle_test,
        TriangleTest::Fast
    );

    let resumed = Resumed::load(&checkpoint, &[]).unwrap();
    assert_eq!(resumed.triangle_test, TriangleTest::Fast);
    // On the GPU (whose test is watertight) it would mix two modes' samples: refused
    // before any GPU is opened.
    let mut on_gpu = resumed.job();
    on_gpu.device = Device::Gpu;
    match on_gpu.prepare() {
        Err(JobError::Invalid(why)) => assert!(why.contains("fast one"), "{why}"),
        Err(e) => panic!("{e}"),
        Ok(_) => panic!("a fast-mode render resumed on the GPU"),
    }
    let job = resumed.job();
    let prepared = job.prepare().unwrap();
    assert_eq!(prepared.triangle_test(), TriangleTest::Fast);
    let done = prepared.run(&mut ()).unwrap();
    assert!(done.complete);
    assert_eq!(done.accumulator.sums, uninterrupted.accumulator.sums);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn periodic_checkpoints_hold_the_passes_so_far() {
    let dir = temp_dir("periodic");
    let checkpoint = dir.join("periodic.checkpoint");
    let scene = small("paper-3", 12, 8, 4);
    let mut job = RenderJob::new(&scene, "paper-3");
    job.checkpoint = CheckpointPolicy {
        periodic: Some(checkpoint.clone()),
        every: Duration::ZERO,
        on_interrupt: None,
    };
    // Stopped after 3 passes with nowhere to save on interrupt: the periodic save after
    // the third pass holds them.
    let mut stopper = Recorder {
        stop_after: Some(3),
        ..Recorder::default()
    };
    let stopped = job.prepare().unwrap().run(&mut stopper).unwrap();
    assert!(!stopped.complete && stopped.saved.is_none());
    assert_eq!(
        Checkpoint::load(&checkpoint).unwrap().accumulator,
        stopped.accumulator
    );

    // A periodic save that fails is a warning, and the render goes on.
    let mut blocked = job.clone();
    blocked.checkpoint.periodic = Some(dir.join("no-such-dir").join("ck"));
    let mut seen = Recorder::default();
    let outcome = blocked.prepare().unwrap().run(&mut seen).unwrap();
    assert!(outcome.complete);
    assert_eq!(seen.warnings.len(), 1, "{:?}", seen.warnings);
    assert!(
        seen.warnings[0].contains("rendering goes on"),
        "{:?}",
        seen.warnings
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn contradictory_jobs_are_refused_before_any_work() {
    let scene = small("cornell", 10, 10, 2);
    let refuse = |job: RenderJob, words: &str| match job.prepare() {
        Err(e @ JobError::Invalid(_)) => {
            assert!(e.to_string().contains(words), "{e}");
        }
        Err(e) => panic!("{e}"),
        Ok(_) => panic!("accepted a job that should be refused ({words})"),
    };
    let mut outside = RenderJob::new(&scene, "cornell");
    outside.region = Region {
        x: 5,
        y: 5,
        width: 6,
        height: 1,
    };
    refuse(outside, "beyond the 10x10 image");
    let mut empty = RenderJob::new(&scene, "cornell");
    empty.region.height = 0;
    refuse(empty, "no pixels");
    let mut threads = RenderJob::new(&scene, "cornell");
    threads.threads = Some(0);
    refuse(threads, "threads must be");
    let mut brute_gpu = RenderJob::new(&scene, "cornell");
    brute_gpu.device = Device::Gpu;
    brute_gpu.structure.kind = AccelKind::None;
    refuse(brute_gpu, "choose a builder");
    let mut too_many = RenderJob::new(&scene, "cornell");
    let mut done = Accumulator::new(10, 10);
    done.samples = 3;
    too_many.resume = Some(done);
    refuse(too_many, "more than the 2 asked for");
    assert_eq!("gpu".parse::<Device>(), Ok(Device::Gpu));
    assert!("tpu"
        .parse::<Device>()
        .unwrap_err()
        .contains("\"cpu\" or \"gpu\""));
}

#[test]
fn on_the_gpu_a_region_is_the_whole_images_pixels_too() {
    let scene = small("teapots", 24, 16, 2);
    let mut whole = RenderJob::new(&scene, "teapots");
    whole.device = Device::Gpu;
    let prepared = match whole.prepare() {
        Ok(prepared) => prepared,
        Err(JobError::Gpu(e @ canopy_gpu::GpuError::NoAdapter(_))) => {
            eprintln!("SKIPPED: no GPU adapter: {e}");
            return;
        }
        Err(e) => panic!("{e}"),
    };
    assert_eq!(prepared.width(), canopy_render::BvhWidth::Two);
    assert_ne!(prepared.device_name(), "cpu");
    let mut seen = Recorder::default();
    let image = prepared.run(&mut seen).unwrap().accumulator.film();
    assert_eq!(seen.rows.load(Ordering::Relaxed), 2 * 16);
    assert!(image.pixels.iter().any(|p| p.length() > 0.0), "black");
    let region = Region {
        x: 5,
        y: 3,
        width: 11,
        height: 9,
    };
    let mut part = RenderJob::new(&scene, "teapots");
    part.device = Device::Gpu;
    part.region = region;
    let part = part
        .prepare()
        .unwrap()
        .run(&mut ())
        .unwrap()
        .accumulator
        .film();
    assert_eq!(part.pixels, pixels_of(&image, region));
}

#[test]
fn a_checkpoint_never_goes_over_an_input_or_a_users_file() {
    let dir = temp_dir("inputs");
    let scene_file = dir.join("s.toml");
    std::fs::write(
        &scene_file,
        "[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n[render]\nwidth = 4\nheight = 4\nspp = 2\n[[spheres]]\ncenter = [0, 0, 0]\nradius = 1\nmaterial = { type = \"lambertian\", albedo = [0.5, 0.5, 0.5] }\n",
    )
    .unwrap();
    let notes = dir.join("notes.txt");
    std::fs::write(&notes, "my notes").unwrap();
    let scene = load_scene(scene_file.to_str().unwrap()).unwrap();
    for (path, words) in [
        (scene_file.clone(), "over an input of the scene"),
        (dir.join(".").join("s.toml"), "over an input of the scene"),
        (notes.clone(), "is not a canopy checkpoint"),
    ] {
        for periodic in [true, false] {
            let mut job = RenderJob::new(&scene, "s.toml");
            if periodic {
                job.checkpoint.periodic = Some(path.clone());
            } else {
                job.checkpoint.on_interrupt = Some(path.clone());
            }
            match job.prepare() {
                Err(e @ JobError::Invalid(_)) => assert!(e.to_string().contains(words), "{e}"),
                Err(e) => panic!("{e}"),
                Ok(_) => panic!("{}: accepted", path.display()),
            }
        }
    }
    assert!(std::fs::read_to_string(&scene_file)
        .unwrap()
        .starts_with("[camera]"));
    assert_eq!(std::fs::read_to_string(&notes).unwrap(), "my notes");
    std::fs::remove_dir_all(dir).unwrap();
}

/// Two renders given one checkpoint path: a second render started over the first's
/// checkpoint is refused before any work, and when both were started while the path was
/// free, the one that saves second neither replaces nor (finishing first) removes the
/// other's checkpoint: each only ever touches its own, or the one it continues.
#[test]
fn two_renders_sharing_a_checkpoint_path_never_destroy_each_others_work() {
    let dir = temp_dir("shared");
    let ck = dir.join("shared.checkpoint");
    let scene = small("cornell", 10, 8, 6);
    let policy = CheckpointPolicy {
        periodic: Some(ck.clone()),
        every: Duration::ZERO,
        on_interrupt: Some(ck.clone()),
    };
    let mut first = RenderJob::new(&scene, "cornell");
    first.checkpoint = policy.clone();
    let second = first.clone();
    // Both prepared while the path is free.
    let (first, second) = (first.prepare().unwrap(), second.prepare().unwrap());
    let mut stop = Recorder {
        stop_after: Some(2),
        ..Recorder::default()
    };
    let stopped = first.run(&mut stop).unwrap();
    assert_eq!(stopped.saved.as_deref(), Some(ck.as_path()));
    let saved = Checkpoint::load(&ck).unwrap();

    // The second runs to the end: its saves are refused (a warning, once), and its end
    // does not remove the first's checkpoint.
    let mut seen = Recorder::default();
    let done = second.run(&mut seen).unwrap();
    assert!(done.complete);
    assert_eq!(seen.warnings.len(), 1, "{:?}", seen.warnings);
    assert!(
        seen.warnings[0].contains("another render"),
        "{:?}",
        seen.warnings
    );
    assert_eq!(
        Checkpoint::load(&ck).unwrap(),
        saved,
        "the first render's work is kept"
    );

    // A third render started over it is refused before any work ...
    let mut third = RenderJob::new(&scene, "cornell");
    third.checkpoint = policy;
    let refused = third.prepare().err().expect("refused");
    assert!(refused.to_string().contains("another render"), "{refused}");
    // ... and the render that continues it may save over it and remove it.
    let resumed = Resumed::load(&ck, &[]).unwrap();
    let finished = resumed.job().prepare().unwrap().run(&mut ()).unwrap();
    assert!(finished.complete && !ck.exists());
    std::fs::remove_dir_all(dir).unwrap();
}

/// A render stopped before its first sample has nothing to keep: no checkpoint is
/// written (it would only hold someone's place at the path).
#[test]
fn a_render_stopped_before_its_first_sample_saves_nothing() {
    let dir = temp_dir("nothing");
    let ck = dir.join("ck");
    let scene = small("cornell", 8, 6, 4);
    let mut job = RenderJob::new(&scene, "cornell");
    job.checkpoint.on_interrupt = Some(ck.clone());
    let mut stop_at_once = Recorder {
        stop_after: Some(0),
        ..Recorder::default()
    };
    let outcome = job.prepare().unwrap().run(&mut stop_at_once).unwrap();
    assert_eq!(outcome.accumulator.samples, 0);
    assert!(!outcome.complete && outcome.saved.is_none());
    assert!(!ck.exists());
    std::fs::remove_dir_all(dir).unwrap();
}

/// A checkpoint is a file anyone can craft: one that names a file that is no scene (a
/// password file, say) is refused without reading it, and one that names a scene file
/// which does not load is refused without quoting a word of it.
#[test]
fn a_crafted_checkpoint_never_shows_the_file_it_names() {
    let dir = std::env::temp_dir().join(format!("canopy-crafted-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let secret = "root:x:0:0:secret-word";
    let scene = small("cornell", 4, 4, 1);
    for (named, expected) in [
        ("passwd", "neither a built-in scene nor a scene file"),
        ("passwd.toml", "this scene does not load; `canopy check"),
    ] {
        let target = dir.join(named);
        std::fs::write(&target, format!("{secret}\n[camera]\n")).unwrap();
        let checkpoint = dir.join(format!("{named}.checkpoint"));
        Checkpoint::new(target.to_str().unwrap(), &scene, Accumulator::new(4, 4))
            .save(&checkpoint)
            .unwrap();
        let error = match Resumed::load(&checkpoint, &[]) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("{named}: resumed"),
        };
        assert!(error.contains(expected), "{named}: {error}");
        assert!(
            !error.contains("secret") && !error.contains("root"),
            "{named}: {error}"
        );
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn aovs_survive_a_checkpoint_and_resume_bit_for_bit() {
    let dir = temp_dir("aovs");
    let checkpoint = dir.join("aovs.checkpoint");
    let scene = small("paper-3", 18, 12, 4);
    let all = canopy_render::AovSet::of(&canopy_render::Aov::ALL);
    let mut whole = RenderJob::new(&scene, "paper-3");
    whole.aovs = all;
    let uninterrupted = whole.prepare().unwrap().run(&mut ()).unwrap().accumulator;
    assert_eq!(uninterrupted.aovs.set, all);

    let mut job = RenderJob::new(&scene, "paper-3");
    job.aovs = all;
    job.checkpoint.on_interrupt = Some(checkpoint.clone());
    let mut stopper = Recorder {
        stop_after: Some(1),
        ..Recorder::default()
    };
    let stopped = job.prepare().unwrap().run(&mut stopper).unwrap();
    assert_eq!(stopped.accumulator.samples, 1);
    let resumed = Resumed::load(&checkpoint, &[]).unwrap();
    let done = resumed.job().prepare().unwrap().run(&mut ()).unwrap();
    assert_eq!(done.accumulator, uninterrupted);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_resumed_render_must_ask_for_the_aovs_it_holds() {
    let scene = small("paper-1", 8, 6, 3);
    let mut held =
        Accumulator::for_region(Region::full(8, 6)).with_aovs(canopy_render::AovSet::DENOISING);
    held.samples = 1;
    let mut job = RenderJob::new(&scene, "paper-1");
    job.resume = Some(held);
    let Err(JobError::Invalid(message)) = job.prepare().map(|_| ()) else {
        panic!("a resume without the AOVs it holds was accepted");
    };
    assert!(message.contains("[albedo,normal]"), "{message}");
}

#[test]
fn on_the_gpu_aovs_are_the_cpus() {
    let scene = small("cornell", 16, 12, 2);
    let mut gpu = RenderJob::new(&scene, "cornell");
    gpu.device = Device::Gpu;
    gpu.aovs = canopy_render::AovSet::of(&canopy_render::Aov::ALL);
    let prepared = match gpu.prepare() {
        Ok(prepared) => prepared,
        Err(JobError::Gpu(e @ canopy_gpu::GpuError::NoAdapter(_))) => {
            eprintln!("SKIPPED: no GPU adapter: {e}");
            return;
        }
        Err(e) => panic!("{e}"),
    };
    let on_gpu = prepared.run(&mut ()).unwrap().accumulator;
    let mut cpu = RenderJob::new(&scene, "cornell");
    cpu.aovs = gpu.aovs;
    // The same binary tree the GPU walks.
    cpu.structure.width = canopy_render::BvhWidth::Two;
    let on_cpu = cpu.prepare().unwrap().run(&mut ()).unwrap().accumulator;
    assert_eq!(on_gpu.aovs, on_cpu.aovs);
    assert!(on_gpu.aovs.albedo.iter().any(|a| a.length() > 0.0));
}

/// Abandons the pass in flight once `rows_before_abandoning` rows of pass
/// `abandoned_pass` (0-based) are done, and sees every pass's samples.
struct Abandoner {
    rows: AtomicU64,
    passes: u32,
    abandoned_pass: u32,
    rows_before_abandoning: u64,
    shown: Vec<u32>,
}

impl Observer for Abandoner {
    fn rows_done(&self, rows: u64) {
        self.rows.fetch_add(rows, Ordering::SeqCst);
    }
    fn abandons_passes(&self) -> bool {
        true
    }
    fn abandon_pass(&self) -> bool {
        self.passes == self.abandoned_pass
            && self.rows.load(Ordering::SeqCst) >= self.rows_before_abandoning
    }
    fn pass_done(&mut self, _samples: u32, _spp: u32) {
        self.passes += 1;
        self.rows.store(0, Ordering::SeqCst);
    }
    fn pass_samples(&mut self, accumulator: &Accumulator) {
        self.shown.push(accumulator.samples);
    }
}

#[test]
fn an_abandoned_pass_leaves_the_passes_before_it_bit_for_bit() {
    let scene = small("cornell", 40, 30, 6);
    let mut two_passes = RenderJob::new(&scene, "cornell");
    two_passes.threads = Some(2);
    let mut scene_of_two = scene.clone();
    scene_of_two.settings.spp = 2;
    two_passes.scene = &scene_of_two;
    let reference = two_passes.prepare().unwrap().run(&mut ()).unwrap();

    let mut job = RenderJob::new(&scene, "cornell");
    job.threads = Some(2);
    // Dropped mid-pass: after 10 of the third pass's 30 rows.
    let mut observer = Abandoner {
        rows: AtomicU64::new(0),
        passes: 0,
        abandoned_pass: 2,
        rows_before_abandoning: 10,
        shown: Vec::new(),
    };
    let outcome = job.prepare().unwrap().run(&mut observer).unwrap();
    assert!(!outcome.complete);
    assert_eq!(
        observer.shown,
        [1, 2],
        "each whole pass was shown, no torn one"
    );
    assert_eq!(outcome.accumulator.samples, 2);
    assert_eq!(outcome.accumulator.sums, reference.accumulator.sums);
    assert_eq!(outcome.accumulator.rays, reference.accumulator.rays);

    // An observer that never abandons sees every pass to the end.
    let mut whole = Abandoner {
        abandoned_pass: u32::MAX,
        ..observer
    };
    whole.shown.clear();
    let outcome = job.prepare().unwrap().run(&mut whole).unwrap();
    assert!(outcome.complete);
    assert_eq!(whole.shown, [1, 2, 3, 4, 5, 6]);
}

#[test]
fn a_job_traces_through_a_structure_given_only_if_it_is_over_its_scene() {
    let scene = small("cornell", 16, 16, 2);
    let accel = std::sync::Arc::new(canopy_render::Accel::default_for(&scene));
    let job = RenderJob::new(&scene, "cornell");
    let reused = job
        .prepare_with(accel.clone())
        .unwrap()
        .run(&mut ())
        .unwrap();
    let built = job.prepare().unwrap().run(&mut ()).unwrap();
    assert_eq!(reused.accumulator.sums, built.accumulator.sums);
    // The same geometry loaded again is another scene: its structure is refused.
    let other = small("cornell", 16, 16, 2);
    let foreign = RenderJob::new(&other, "cornell");
    assert!(matches!(
        foreign.prepare_with(accel.clone()),
        Err(JobError::Invalid(_))
    ));
    // A wide tree for the GPU is refused before the GPU is opened.
    let mut gpu = RenderJob::new(&scene, "cornell");
    gpu.device = Device::Gpu;
    assert!(matches!(gpu.prepare_with(accel), Err(JobError::Invalid(m)) if m.contains("binary")));
}

#[test]
fn a_kept_gpu_upload_renders_each_jobs_view_as_a_fresh_upload_does() {
    let mut scene = small("teapots", 24, 16, 2);
    let binary = canopy_render::Accel::for_scene(
        &scene,
        AccelKind::default(),
        canopy_render::BvhWidth::Two,
        &Default::default(),
        None,
    );
    let accel = std::sync::Arc::new(binary);
    let gpu = match canopy_gpu::Gpu::new() {
        Ok(gpu) => gpu,
        Err(e @ canopy_gpu::GpuError::NoAdapter(_)) => {
            eprintln!("SKIPPED: no GPU adapter: {e}");
            return;
        }
        Err(e) => panic!("{e}"),
    };
    let kept = canopy_gpu::Renderer::for_accel(&gpu, &scene, &accel).unwrap();
    // A viewer's next views: the camera moved, then a preview at a quarter of the size.
    scene.camera.look_from += glam::Vec3::new(1.5, 0.5, 0.0);
    for (width, height) in [(24, 16), (6, 4)] {
        (scene.settings.width, scene.settings.height) = (width, height);
        let mut job = RenderJob::new(&scene, "teapots");
        job.device = Device::Gpu;
        let on_kept = job.prepare_on(accel.clone(), &kept).unwrap();
        assert_ne!(on_kept.device_name(), "cpu");
        let on_kept = on_kept.run(&mut ()).unwrap().accumulator;
        let uploaded = job.prepare_with(accel.clone()).unwrap();
        let uploaded = uploaded.run(&mut ()).unwrap().accumulator;
        assert_eq!(on_kept.sums, uploaded.sums, "{width}x{height}");
        assert_eq!(on_kept.samples, 2);
    }
    // Not on the GPU, or with another estimator than the upload's: refused by name.
    let cpu = RenderJob::new(&scene, "teapots");
    assert!(
        matches!(cpu.prepare_on(accel.clone(), &kept), Err(JobError::Invalid(m)) if m.contains("CPU"))
    );
    let mut bsdf = scene.clone();
    bsdf.settings.integrator = canopy_render::Integrator::Bsdf;
    let mut other = RenderJob::new(&bsdf, "teapots");
    other.device = Device::Gpu;
    assert!(
        matches!(other.prepare_on(accel, &kept), Err(JobError::Invalid(m)) if m.contains("bsdf"))
    );
}
