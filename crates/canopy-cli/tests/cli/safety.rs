//! canopy never destroys a user's file, never hangs on special files, refuses what it
//! cannot do before doing any work, and tells scripts what happened by its exit status.

use crate::common;

use common::{canopy, canopy_within, outputs, scratch, spawn, stderr};
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::Command;
use std::time::Duration;

const CAMERA: &str = "[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n";
const TINY: [&str; 4] = ["--size", "8x8", "--spp", "1"];

fn sphere_scene(extra: &str) -> String {
    format!(
        "{extra}{CAMERA}[[spheres]]\ncenter = [0, 0, 0]\nradius = 1\nmaterial = {{ type = \"lambertian\", albedo = [0.5, 0.5, 0.5] }}\n"
    )
}

fn render(dir: &Path, args: &[&str]) -> std::process::Output {
    let mut all = vec!["render"];
    all.extend_from_slice(args);
    canopy_within(&all, dir, Duration::from_secs(120))
}

#[test]
fn a_failed_image_write_keeps_the_render_as_a_checkpoint() {
    let dir = scratch("image-fails");
    // A path that names a directory is refused before any work.
    let out = render(
        &dir,
        &["cornell", "-o", "out.png/", "--size", "8x8", "--spp", "2"],
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("names a directory"),
        "{}",
        stderr(&out)
    );
    assert_eq!(outputs(&dir), Vec::<String>::new());

    // The image's directory vanishes while the render runs (a full or lost disk): the
    // interrupted render has saved its checkpoint before the image, which then fails,
    // and the error says how to get the image from the checkpoint. Driven by events:
    // the directory goes once the first periodic checkpoint is on disk.
    std::fs::create_dir(dir.join("images")).unwrap();
    let mut child = spawn(
        &[
            "render",
            "cornell",
            "--size",
            "8x8",
            "--spp",
            "1000000",
            "-o",
            "images/o.png",
            "--checkpoint",
            "ck",
            "--every",
            "0s",
        ],
        &dir,
    );
    let start = std::time::Instant::now();
    while !dir.join("ck").exists() {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no checkpoint appeared"
        );
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the render ended early: {status}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    std::fs::remove_dir_all(dir.join("images")).unwrap();
    let sent = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("the render is saved") && err.contains("--resume ck"),
        "{err}"
    );
    let saved = std::fs::read(dir.join("ck")).unwrap();
    assert!(saved.starts_with(b"CANOPYCK"), "the checkpoint is whole");
    assert_eq!(outputs(&dir), ["ck"]);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_checkpoint_path_holding_a_user_file_is_refused_and_the_file_kept() {
    let dir = scratch("notes");
    std::fs::write(dir.join("notes.txt"), "my notes").unwrap();
    let out = render(
        &dir,
        &[
            &["cornell", "-o", "a.png", "--checkpoint", "notes.txt"],
            &TINY[..],
        ]
        .concat(),
    );
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("notes.txt: exists and is not a canopy checkpoint"),
        "{}",
        stderr(&out)
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("notes.txt")).unwrap(),
        "my notes"
    );
    assert_eq!(outputs(&dir), ["notes.txt"]);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn the_scene_and_its_meshes_are_never_written_over() {
    let dir = scratch("inputs");
    std::fs::write(
        dir.join("m.ply"),
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    )
    .unwrap();
    let scene = sphere_scene("")
        + "[[meshes]]\nfile = \"m.ply\"\nmaterial = { type = \"lambertian\", albedo = [1, 1, 1] }\n";
    std::fs::write(dir.join("s.toml"), &scene).unwrap();
    // A scene file whose name ends in .png must not be rendered over itself.
    std::fs::write(dir.join("scene.png"), &scene).unwrap();
    let cases: [&[&str]; 4] = [
        &["s.toml", "--checkpoint", "s.toml"],
        &["s.toml", "--checkpoint", "./m.ply"],
        &["scene.png", "-o", "scene.png"],
        &["s.toml", "-o", "x.png", "--checkpoint", "x.png"],
    ];
    for args in cases {
        let out = render(&dir, &[args, &TINY[..]].concat());
        assert_eq!(out.status.code(), Some(1), "{args:?}: {}", stderr(&out));
        let err = stderr(&out);
        assert!(
            err.contains("refusing to write") || err.contains("cannot be the same file"),
            "{args:?}: {err}"
        );
    }
    assert_eq!(std::fs::read_to_string(dir.join("s.toml")).unwrap(), scene);
    assert_eq!(
        std::fs::read_to_string(dir.join("scene.png")).unwrap(),
        scene
    );
    assert!(std::fs::read(dir.join("m.ply"))
        .unwrap()
        .starts_with(b"ply"));
    // `bench lights --out` is checked against the inputs of every scene it loads.
    for target in ["s.toml", "m.ply"] {
        let out = canopy_within(
            &[
                "bench",
                "lights",
                "s.toml",
                "--out",
                target,
                "--seconds",
                "1",
            ],
            &dir,
            Duration::from_secs(120),
        );
        assert_eq!(out.status.code(), Some(1), "{target}: {}", stderr(&out));
        assert!(
            stderr(&out).contains("refusing to write the table"),
            "{}",
            stderr(&out)
        );
    }
    assert_eq!(std::fs::read_to_string(dir.join("s.toml")).unwrap(), scene);
    assert!(std::fs::read(dir.join("m.ply"))
        .unwrap()
        .starts_with(b"ply"));
    let mut left = outputs(&dir);
    left.retain(|f| f != "scene.png");
    assert!(left.is_empty(), "{left:?}");
    std::fs::remove_dir_all(dir).unwrap();
}

/// A render resumed goes on in the triangle test its checkpoint was rendered with: the
/// flag cannot contradict it, and the GPU (watertight only) refuses a fast-mode render.
#[test]
fn a_resumed_render_keeps_its_checkpoints_triangle_test() {
    let dir = scratch("fastck");
    let mut scene = canopy_render::load_scene("paper-3").unwrap();
    (
        scene.settings.width,
        scene.settings.height,
        scene.settings.spp,
    ) = (8, 8, 2);
    canopy_render::checkpoint::Checkpoint::new(
        "paper-3",
        &scene,
        canopy_render::Accumulator::new(8, 8),
    )
    .with_triangle_test(canopy_bvh::TriangleTest::Fast)
    .save(&dir.join("ck"))
    .unwrap();
    let before = std::fs::read(dir.join("ck")).unwrap();
    let flagged = render(&dir, &["--resume", "ck", "--fast-triangles", "-o", "a.png"]);
    assert_eq!(flagged.status.code(), Some(2), "{}", stderr(&flagged));
    assert!(
        stderr(&flagged).contains("cannot be used with"),
        "{}",
        stderr(&flagged)
    );
    let on_gpu = render(&dir, &["--resume", "ck", "--device", "gpu", "-o", "a.png"]);
    assert_eq!(on_gpu.status.code(), Some(1), "{}", stderr(&on_gpu));
    assert!(
        stderr(&on_gpu).contains("fast mode, which the GPU does not have"),
        "{}",
        stderr(&on_gpu)
    );
    assert_eq!(std::fs::read(dir.join("ck")).unwrap(), before, "kept");
    let out = render(&dir, &["--resume", "ck", "-o", "a.png", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(summary["triangles"], "fast");
    // A render started afresh is watertight unless told.
    let fresh = render(
        &dir,
        &[
            "paper-3", "-o", "b.png", "--json", "--size", "8x8", "--spp", "1",
        ],
    );
    assert!(fresh.status.success(), "{}", stderr(&fresh));
    let summary: serde_json::Value = serde_json::from_slice(&fresh.stdout).unwrap();
    assert_eq!(summary["triangles"], "watertight");
    std::fs::remove_dir_all(dir).unwrap();
}

/// A checkpoint belongs to the render that wrote it: a new render given its path is
/// refused before any work (that checkpoint is someone's unfinished render) and the file
/// is kept; the render that continues it (`--resume`) finishes and removes it.
#[test]
fn another_renders_checkpoint_is_refused_and_kept_and_only_its_own_render_removes_it() {
    let dir = scratch("oldck");
    // An earlier render, interrupted: its checkpoint is on disk.
    let earlier = canopy_render::checkpoint::Checkpoint::new(
        "cornell",
        &{
            let mut scene = canopy_render::load_scene("cornell").unwrap();
            scene.settings.width = 8;
            scene.settings.height = 8;
            scene.settings.spp = 2;
            scene
        },
        canopy_render::Accumulator::new(8, 8),
    )
    .owned_by(42);
    earlier.save(&dir.join("ck")).unwrap();
    let before = std::fs::read(dir.join("ck")).unwrap();
    let out = render(
        &dir,
        &[&["paper-5", "-o", "b.png", "--checkpoint", "ck"], &TINY[..]].concat(),
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("holds the checkpoint of another render"),
        "{}",
        stderr(&out)
    );
    assert!(stderr(&out).contains("--resume ck"), "{}", stderr(&out));
    assert_eq!(
        std::fs::read(dir.join("ck")).unwrap(),
        before,
        "kept as it was"
    );
    assert!(!dir.join("b.png").exists());
    // The render it holds continues and then removes it.
    let out = render(&dir, &["--resume", "ck", "-o", "a.png"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!dir.join("ck").exists());
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn special_files_are_refused_without_hanging() {
    let dir = scratch("special");
    std::os::unix::fs::symlink("/dev/zero", dir.join("zero.ply")).unwrap();
    std::os::unix::fs::symlink("/dev/urandom", dir.join("random.obj")).unwrap();
    let fifo = Command::new("mkfifo")
        .arg(dir.join("fifo.ply"))
        .status()
        .is_ok_and(|s| s.success());
    let mut meshes = vec!["zero.ply", "random.obj"];
    if fifo {
        meshes.push("fifo.ply");
    }
    for mesh in meshes {
        let scene = sphere_scene("") + &format!(
            "[[meshes]]\nfile = \"{mesh}\"\nmaterial = {{ type = \"lambertian\", albedo = [1, 1, 1] }}\n"
        );
        std::fs::write(dir.join("s.toml"), scene).unwrap();
        // The links lead out of the scene's folder: allowed there, they are refused as
        // special files.
        for command in [
            &["render", "s.toml", "-o", "x.png", "--allow-path", "/dev"][..],
            &["check", "s.toml", "--allow-path", "/dev"],
        ] {
            let out = canopy_within(command, &dir, Duration::from_secs(30));
            assert_eq!(out.status.code(), Some(1), "{mesh}: {}", stderr(&out));
            assert!(
                stderr(&out).contains("not a regular file"),
                "{mesh}: {}",
                stderr(&out)
            );
        }
        // A bare mesh argument too.
        let out = canopy_within(&["check", mesh], &dir, Duration::from_secs(30));
        assert_eq!(out.status.code(), Some(1), "{mesh}: {}", stderr(&out));
    }
    for scene in ["/dev/zero", "/dev/urandom"] {
        let out = canopy_within(&["render", scene], &dir, Duration::from_secs(30));
        assert!(
            stderr(&out).contains("not a regular file"),
            "{}",
            stderr(&out)
        );
        let out = canopy_within(
            &["render", "--resume", scene],
            &dir,
            Duration::from_secs(30),
        );
        assert!(
            stderr(&out).contains("not a regular file"),
            "{}",
            stderr(&out)
        );
    }
    assert!(!dir.join("x.png").exists());
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn numbers_out_of_range_are_usage_errors_that_name_the_option_and_range() {
    let dir = scratch("ranges");
    let cases: [(&[&str], &str); 8] = [
        (
            &["render", "paper-1", "--ploc-radius", "100000000"],
            "--ploc-radius",
        ),
        (&["render", "paper-1", "--threads", "8192"], "--threads"),
        (&["render", "paper-1", "--threads", "0"], "--threads"),
        (&["render", "paper-1", "--spp", "0"], "--spp"),
        (&["render", "paper-1", "--depth", "0"], "--depth"),
        (
            &["render", "paper-1", "--sah-traversal", "nan"],
            "--sah-traversal",
        ),
        (
            &["bvh", "paper-1", "--max-leaf-size", "0"],
            "--max-leaf-size",
        ),
        (&["bvh", "paper-1", "--runs=-1"], "--runs"),
    ];
    for (args, option) in cases {
        let out = canopy_within(args, &dir, Duration::from_secs(30));
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(option), "{args:?}: {}", stderr(&out));
        assert!(
            stderr(&out).contains("1..=") || stderr(&out).contains("(0, 1e6]"),
            "{args:?} names no range: {}",
            stderr(&out)
        );
    }
    assert!(outputs(&dir).is_empty());
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn an_output_that_cannot_be_written_fails_before_the_render() {
    let dir = scratch("nodir");
    // paper-1 at a million samples per pixel would take days: the refusal must come first,
    // or the watchdog of `render` fails the test (an event, not a guess at a speed).
    let out = render(
        &dir,
        &["paper-1", "--spp", "1000000", "-o", "missing/out.png"],
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("directory missing does not exist"),
        "{}",
        stderr(&out)
    );
    assert!(!String::from_utf8_lossy(&out.stdout).contains("render "));
    let out = render(&dir, &["paper-1", "--checkpoint", "missing/ck"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(outputs(&dir).is_empty(), "{:?}", outputs(&dir));
    std::fs::remove_dir_all(dir).unwrap();
}

/// A periodic save that fails (a full disk, the directory gone) is a warning, once, and
/// the render goes on; when it is then interrupted and its checkpoint cannot be saved
/// either, the image of the samples so far is still written and the error says the
/// render cannot be resumed. Driven by events: the first checkpoint on disk, then the
/// warning on stderr.
#[test]
fn a_failed_checkpoint_save_warns_and_the_render_goes_on() {
    let dir = scratch("diskfull");
    std::fs::create_dir(dir.join("cks")).unwrap();
    let mut child = spawn(
        &[
            "render",
            "paper-5",
            "--size",
            "32x32",
            "--spp",
            "1000000",
            "-o",
            "out.png",
            "--checkpoint",
            "cks/ck",
            "--every",
            "0",
        ],
        &dir,
    );
    wait_until("the first checkpoint", &mut child, || {
        dir.join("cks/ck").exists()
    });
    // The checkpoint's directory turns into a file: every later save fails, as on a
    // full disk (and unlike permissions, this holds for root too).
    std::fs::rename(dir.join("cks"), dir.join("gone")).unwrap();
    std::fs::write(dir.join("cks"), "in the way").unwrap();
    let mut err = String::new();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    for line in lines.by_ref() {
        let line = line.unwrap();
        err.push_str(&line);
        err.push('\n');
        if line.contains("rendering goes on") {
            break;
        }
    }
    assert!(err.contains("cannot write the checkpoint"), "{err}");
    signal(&child, "INT");
    for line in lines {
        err.push_str(&line.unwrap());
        err.push('\n');
    }
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(1), "{err}");
    assert_eq!(err.matches("rendering goes on").count(), 1, "{err}");
    assert!(err.contains("the render cannot be resumed"), "{err}");
    assert!(
        image::open(dir.join("out.png")).is_ok(),
        "the image is written: {err}"
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_scene_name_cannot_send_the_image_elsewhere() {
    let dir = scratch("names");
    std::fs::create_dir(dir.join("work")).unwrap();
    for (name, expected) in [("../escaped", "_escaped.png"), ("/tmp/abs", "_tmp_abs.png")] {
        std::fs::write(
            dir.join("work/s.toml"),
            sphere_scene(&format!("name = {name:?}\n")),
        )
        .unwrap();
        let out = render(&dir.join("work"), &[&["s.toml"], &TINY[..]].concat());
        assert!(out.status.success(), "{}", stderr(&out));
        assert!(dir.join("work").join(expected).exists(), "{name}");
    }
    assert!(!dir.join("escaped.png").exists());
    assert!(!Path::new("/tmp/abs.png").exists() || cfg!(not(unix)));
    std::fs::remove_dir_all(dir).unwrap();
}

/// Scene, mesh and a render long enough to interrupt.
fn interruptible_scene(dir: &Path, smooth: bool) {
    std::fs::write(
        dir.join("tet.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
    )
    .unwrap();
    let scene = sphere_scene("")
        + &format!("[[meshes]]\nfile = \"tet.obj\"\nsmooth = {smooth}\nmaterial = {{ type = \"metal\", albedo = [0.9, 0.9, 0.9] }}\n");
    std::fs::write(dir.join("s.toml"), scene).unwrap();
}

#[test]
fn a_checkpoint_resumes_from_another_directory_and_refuses_a_changed_scene() {
    let dir = scratch("resume");
    let scenes = dir.join("scenes");
    std::fs::create_dir(&scenes).unwrap();
    interruptible_scene(&scenes, false);
    let child = spawn(
        &[
            "render",
            "s.toml",
            "--size",
            "64x64",
            "--spp",
            "3000",
            "-o",
            "part.png",
            "--checkpoint",
            "ck",
            "--every",
            "0",
        ],
        &scenes,
    );
    let mut child = child;
    wait_until("the first checkpoint", &mut child, || {
        scenes.join("ck").exists()
    });
    signal(&child, "INT");
    let out = child.wait_with_output().unwrap();
    if out.status.success() {
        std::fs::remove_dir_all(dir).unwrap();
        return; // finished before the signal: nothing to resume on this machine
    }
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    let ck = scenes.join("ck");
    let saved = canopy_render::checkpoint::Checkpoint::load(&ck).unwrap();
    let scene_path = std::fs::canonicalize(scenes.join("s.toml")).unwrap();
    assert_eq!(Path::new(&saved.scene), scene_path);

    // Changing the mesh's shading makes the checkpoint belong to another image.
    interruptible_scene(&scenes, true);
    let ck_arg = ck.to_str().unwrap();
    let out = render(&dir, &["--resume", ck_arg, "-o", "resumed.png"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("made for a different scene or settings"),
        "{}",
        stderr(&out)
    );
    // Back as it was, it resumes from the parent directory.
    interruptible_scene(&scenes, false);
    let out = render(&dir, &["--resume", ck_arg, "-o", "resumed.png", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(summary["samples"], 3000);
    assert_eq!(summary["interrupted"], false);
    assert!(dir.join("resumed.png").exists());
    assert!(!ck.exists());
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn meaningless_scenes_fail_check_and_render() {
    let dir = scratch("nonsense");
    let lambert = "material = { type = \"lambertian\", albedo = [0.5, 0.5, 0.5] }\n";
    std::fs::write(dir.join("m.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let cases = [
        (sphere_scene("") + "[render]\nmax_depth = 0\n", "max_depth 0 is outside 1..=1024"),
        (
            format!("[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\naperture = 1e30\n[[spheres]]\ncenter = [0, 0, 0]\nradius = 1\n{lambert}"),
            "camera: every number must be finite and within",
        ),
        (
            format!("{CAMERA}[[spheres]]\ncenter = [0, 0, 0]\nradius = 1e38\n{lambert}"),
            "sphere: `center` must be within",
        ),
        (
            format!("{CAMERA}[[meshes]]\nfile = \"m.obj\"\nscale = 1e38\n{lambert}"),
            "beyond ±1e12",
        ),
        (
            format!("{CAMERA}[[spheres]]\ncenter = [0, 0, 0]\nradius = 1\nmaterial = {{ type = \"lambertian\", albedo = [2, 0.5, 0.5] }}\n"),
            "`albedo` components must be in [0, 1]",
        ),
        (
            format!("{CAMERA}[[spheres]]\ncenter = [0, 0, 0]\nradius = 1\nmaterial = {{ type = \"emissive\", radiance = [1e38, 1, 1] }}\n"),
            "`radiance` components must be in [0, 1e12]",
        ),
        (
            // Passed `check`, then panicked in `render` building the top-level tree.
            format!("{CAMERA}[geometry.m]\nfile = \"m.obj\"\n[[instances]]\ngeometry = \"m\"\nscale = 1e-13\n{lambert}"),
            "instance 0 of `m`: the transform is not invertible",
        ),
        (
            sphere_scene("background = [1, 1e30, 1]\n"),
            "background: expected \"sky\", an [r, g, b] colour with each number in [0, 1e12]",
        ),
    ];
    for (scene, expected) in cases {
        std::fs::write(dir.join("s.toml"), &scene).unwrap();
        for command in [
            &["check", "s.toml"][..],
            &["render", "s.toml", "-o", "x.png"],
        ] {
            let out = canopy_within(command, &dir, Duration::from_secs(30));
            assert_eq!(out.status.code(), Some(1), "{scene}");
            assert!(
                stderr(&out).contains(expected),
                "{expected}: {}",
                stderr(&out)
            );
        }
    }
    assert!(!dir.join("x.png").exists());
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn obj_faces_of_two_vertices_are_reported_like_ply_does() {
    let dir = scratch("obj2");
    std::fs::write(
        dir.join("m.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\n",
    )
    .unwrap();
    let out = canopy(&["check", "m.obj"], &dir);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("line 5: a face needs at least 3 vertices, this one has 2"),
        "{}",
        stderr(&out)
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn summaries_are_json_on_request_and_warnings_go_to_stderr() {
    let dir = scratch("json");
    std::fs::write(
        dir.join("dark.toml"),
        sphere_scene("background = [0, 0, 0]\n"),
    )
    .unwrap();
    let out = render(
        &dir,
        &[&["dark.toml", "-o", "d.png", "--json"], &TINY[..]].concat(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stdout)));
    assert_eq!(summary["width"], 8);
    assert_eq!(summary["spheres"], 1);
    assert_eq!(summary["image"], "d.png");
    assert!(summary["rays"].as_u64().unwrap() >= 64);
    assert!(summary["warnings"][0]
        .as_str()
        .unwrap()
        .contains("no light"));
    assert!(stderr(&out).contains("warning: no light"));

    let out = canopy(&["check", "dark.toml", "--json"], &dir);
    assert!(out.status.success());
    let description: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(description["primitives"], 1);
    assert!(stderr(&out).contains("warning: no light"));
    std::fs::remove_dir_all(dir).unwrap();
}

/// A second Ctrl-C ends the render at once: no image, no checkpoint, although the pass
/// in flight (seconds long) has not finished. Driven by state: the signals go once the
/// render has printed its summary, that is once its passes are about to start.
#[test]
fn a_second_ctrl_c_ends_the_render_at_once() {
    let dir = scratch("twice");
    let mut child = spawn(
        &[
            "render",
            "paper-1",
            "--size",
            "1600x1600",
            "--spp",
            "8",
            "--depth",
            "50",
            "-o",
            "out.png",
            "--threads",
            "1",
        ],
        &dir,
    );
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    while !line.starts_with("bvh") {
        line.clear();
        assert!(
            stdout.read_line(&mut line).unwrap() > 0,
            "no summary printed"
        );
    }
    signal(&child, "INT");
    let mut err = BufReader::new(child.stderr.take().unwrap());
    wait_for_line(&mut err, "stopping after the pass in flight");
    signal(&child, "INT");
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130));
    assert_eq!(
        outputs(&dir),
        Vec::<String>::new(),
        "nothing after a second Ctrl-C"
    );
    std::fs::remove_dir_all(dir).unwrap();
}

/// A signal while the scene loads or its BVH is built ends canopy with status 130 (not
/// the signal's own 143 or 129), writing nothing. Driven by state: each signal is sent
/// once the process has its handler, during a build that takes seconds.
#[cfg(target_os = "linux")]
#[test]
fn a_signal_while_loading_or_building_exits_130_and_writes_nothing() {
    let dir = scratch("early-signal");
    write_grid_obj(&dir.join("grid.obj"), 250);
    for (name, number) in [("INT", 2), ("TERM", 15), ("HUP", 1)] {
        let mut child = spawn(
            &[
                "render",
                "grid.obj",
                "--bvh",
                "agglomerative",
                "--size",
                "8x8",
                "--spp",
                "1",
                "-o",
                "o.png",
                "--checkpoint",
                "ck",
            ],
            &dir,
        );
        let pid = child.id();
        wait_until("the signal handler", &mut child, || handles(pid, number));
        signal(&child, name);
        let out = child.wait_with_output().unwrap();
        assert_eq!(out.status.code(), Some(130), "SIG{name}: {}", stderr(&out));
        // Signalled within seconds of a 5-second build, the render has not begun: nothing
        // is written (had the test thread stalled that long, the interrupted render would
        // have saved its work instead, as a render should).
        if !String::from_utf8_lossy(&out.stdout).contains("bvh ") {
            assert_eq!(outputs(&dir), Vec::<String>::new(), "SIG{name}");
        }
        for left in outputs(&dir) {
            std::fs::remove_file(dir.join(left)).unwrap();
        }
    }
    std::fs::remove_dir_all(dir).unwrap();
}

/// A second signal while the finished image is being written ends canopy at once and
/// leaves no temporary file behind. Driven by state: the signals go when the temporary
/// file appears (if the write wins the race, the whole image is there instead).
#[test]
fn a_second_signal_during_the_final_write_leaves_no_temporary_file() {
    let dir = scratch("final-write");
    let mut child = spawn(
        &[
            "render",
            "cornell",
            "--size",
            "3000x3000",
            "--spp",
            "1",
            "--depth",
            "1",
            "-o",
            "big.exr",
        ],
        &dir,
    );
    let temporary = || {
        std::fs::read_dir(&dir)
            .unwrap()
            .any(|e| e.unwrap().file_name().to_string_lossy().ends_with(".tmp"))
    };
    wait_until("the image's temporary file", &mut child, temporary);
    signal(&child, "TERM");
    let mut err = BufReader::new(child.stderr.take().unwrap());
    // The write may win the race and the process end first (then the image is whole).
    if saw_line(&mut err, "stopping after the pass in flight") {
        let _ = Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .status();
    }
    let status = child.wait().unwrap();
    assert!(!temporary(), "a temporary file is left behind");
    match status.code() {
        Some(130) => assert_eq!(outputs(&dir), Vec::<String>::new()),
        Some(0) => assert!(image::open(dir.join("big.exr")).is_ok()),
        other => panic!("exit {other:?}"),
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_closed_stdout_neither_panics_nor_loses_the_image() {
    let dir = scratch("pipe");
    let mut child = spawn(
        &[
            "render", "cornell", "--size", "8x8", "--spp", "1", "-o", "out.png",
        ],
        &dir,
    );
    drop(child.stdout.take()); // as `| head -0` would
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!stderr(&out).contains("panicked"), "{}", stderr(&out));
    assert!(image::open(dir.join("out.png")).is_ok());
    std::fs::remove_dir_all(dir).unwrap();
}

/// Reads lines from `reader` until one contains `text`.
fn wait_for_line(reader: &mut impl BufRead, text: &str) {
    assert!(saw_line(reader, text), "no line saying {text:?}");
}

/// Reads lines from `reader` until one contains `text` (true) or the stream ends (false).
fn saw_line(reader: &mut impl BufRead, text: &str) -> bool {
    let mut line = String::new();
    while !line.contains(text) {
        line.clear();
        if reader.read_line(&mut line).unwrap() == 0 {
            return false;
        }
    }
    true
}

/// Sends `SIG<name>` to the child.
fn signal(child: &std::process::Child, name: &str) {
    let sent = Command::new("kill")
        .args([&format!("-{name}"), &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success(), "kill -{name}");
}

/// Waits (polling, at most two minutes) until `ready` holds; fails if the child ends
/// first.
fn wait_until(what: &str, child: &mut std::process::Child, mut ready: impl FnMut() -> bool) {
    let start = std::time::Instant::now();
    while !ready() {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the render ended ({status}) before {what}");
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no sign of {what}"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// Whether process `pid` catches signal `number` (Linux: the SigCgt mask in
/// /proc/PID/status).
fn handles(pid: u32, number: u32) -> bool {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("SigCgt:"))
        .and_then(|mask| u64::from_str_radix(mask.trim(), 16).ok())
        .is_some_and(|mask| mask & (1 << (number - 1)) != 0)
}

/// An OBJ grid of `n` x `n` squares (2n² triangles), slightly bumpy.
fn write_grid_obj(path: &Path, n: u32) {
    let mut text = String::new();
    for j in 0..=n {
        for i in 0..=n {
            let z = ((i * 7 + j * 13) % 17) as f32 / 170.0;
            text += &format!("v {} {} {z}\n", i as f32 / n as f32, j as f32 / n as f32);
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i + 1;
            let (b, c) = (a + 1, a + n + 1);
            text += &format!("f {a} {b} {}\nf {a} {} {c}\n", c + 1, c + 1);
        }
    }
    std::fs::write(path, text).unwrap();
}

/// A scene reads only the files in its own folder: `../`, absolute paths, links that lead
/// out and percent-encoded `..` in a glTF model's URIs are refused before anything is
/// read (so nothing of the file can show in an error), unless `--allow-path` allows the
/// folder they lead to.
#[test]
fn a_scene_reads_only_files_in_its_own_folder() {
    let dir = scratch("confined");
    let (scenes, outside) = (dir.join("scenes"), dir.join("outside"));
    std::fs::create_dir_all(&scenes).unwrap();
    std::fs::create_dir_all(&outside).unwrap();
    let secret = "v 0 0 0 secret-word\n";
    std::fs::write(
        outside.join("m.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    std::fs::write(outside.join("secret.obj"), secret).unwrap();
    std::os::unix::fs::symlink(outside.join("secret.obj"), scenes.join("link.obj")).unwrap();
    let lambert = "material = { type = \"lambertian\", albedo = [0.5, 0.5, 0.5] }\n";
    let mesh_scene = |file: &str| format!("{CAMERA}[[meshes]]\nfile = \"{file}\"\n{lambert}");
    let absolute = outside.join("secret.obj").display().to_string();
    for file in ["../outside/secret.obj", absolute.as_str(), "link.obj"] {
        std::fs::write(scenes.join("s.toml"), mesh_scene(file)).unwrap();
        for command in [
            &["check", "s.toml"][..],
            &["render", "s.toml", "-o", "x.png"],
        ] {
            let out = canopy_within(command, &scenes, Duration::from_secs(30));
            let err = stderr(&out);
            assert_eq!(out.status.code(), Some(1), "{file}: {err}");
            assert!(
                err.contains("leads out of the scene's folder"),
                "{file}: {err}"
            );
            assert!(!err.contains("secret-word"), "{file}: {err}");
        }
    }
    // Allowed, the folder's files are read.
    std::fs::write(scenes.join("s.toml"), mesh_scene("../outside/m.obj")).unwrap();
    let allow = outside.display().to_string();
    let out = canopy(&["check", "s.toml", "--allow-path", &allow], &scenes);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let out = canopy(&["check", "s.toml", "--allow-path", "no-such-dir"], &scenes);
    assert!(
        stderr(&out).contains("no-such-dir: an allowed path must be an existing folder"),
        "{}",
        stderr(&out)
    );

    // A glTF model's buffers, however their URIs spell the way out.
    std::fs::write(outside.join("buffer.bin"), [0u8; 44]).unwrap();
    let gltf = |uri: &str| {
        format!(
            r#"{{"asset":{{"version":"2.0"}},"nodes":[{{"mesh":0}}],"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
"buffers":[{{"byteLength":36,"uri":"{uri}"}}],"bufferViews":[{{"buffer":0,"byteLength":36}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}]}}"#
        )
    };
    let absolute = outside.join("buffer.bin").display().to_string();
    for uri in [
        "../outside/buffer.bin",
        "%2e%2e/outside/buffer.bin",
        "%2E%2E%2Foutside%2Fbuffer.bin",
        absolute.as_str(),
    ] {
        std::fs::write(scenes.join("model.gltf"), gltf(uri)).unwrap();
        let out = canopy(&["check", "model.gltf"], &scenes);
        assert_eq!(out.status.code(), Some(1), "{uri}");
        assert!(
            stderr(&out).contains("leads out of the scene's folder"),
            "{uri}: {}",
            stderr(&out)
        );
    }
    std::fs::remove_dir_all(dir).unwrap();
}
