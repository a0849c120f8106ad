//! Runs the `canopy` binary as a user would: a tiny render, and bad inputs that must give
//! one clear message, a non-zero exit and no output file.

use crate::common;

use common::{canopy, outputs, scratch, stderr};
use std::process::Command;

const CAMERA: &str = "[camera]\nlook_from = [0, 0, 5]\nlook_at = [0, 0, 0]\n";

/// Writes a scene file and renders it; the render must fail with `expected` in stderr.
fn assert_scene_fails(name: &str, scene: &str, expected: &[&str]) {
    let dir = scratch(name);
    std::fs::write(dir.join("bad.toml"), scene).unwrap();
    let out = canopy(
        &[
            "render", "bad.toml", "-o", "out.png", "--size", "8x8", "--spp", "1",
        ],
        &dir,
    );
    let err = stderr(&out);
    assert!(!out.status.success(), "{name}: should fail");
    for e in expected {
        assert!(err.contains(e), "{name}: `{e}` not in: {err}");
    }
    assert!(!err.contains("panicked"), "{name}: {err}");
    assert_eq!(
        outputs(&dir),
        Vec::<String>::new(),
        "{name}: left files behind"
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn tiny_render_writes_a_png_and_a_summary() {
    let dir = scratch("tiny");
    let out = canopy(
        &[
            "render",
            "paper-1",
            "-o",
            "tiny.png",
            "--size",
            "32x24",
            "--spp",
            "2",
            "--threads",
            "2",
        ],
        &dir,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let summary = String::from_utf8_lossy(&out.stdout);
    for key in [
        "primitives  485",
        "bvh         binned-sah",
        "render",
        "Mrays/s",
    ] {
        assert!(
            summary.contains(key),
            "`{key}` missing from summary:\n{summary}"
        );
    }
    let img = image::open(dir.join("tiny.png")).unwrap();
    assert_eq!((img.width(), img.height()), (32, 24));
    assert_eq!(
        outputs(&dir),
        vec!["tiny.png".to_string()],
        "no temporary files left"
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn exr_output_and_brute_force_mode() {
    let dir = scratch("exr");
    let out = canopy(
        &[
            "render", "cornell", "-o", "c.exr", "--size", "8x8", "--spp", "1", "--bvh", "none",
        ],
        &dir,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("bvh         none"));
    assert_eq!(image::open(dir.join("c.exr")).unwrap().width(), 8);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_region_renders_exactly_those_pixels_of_the_whole_image() {
    let dir = scratch("region");
    let render = |extra: &[&str]| {
        let args = [
            &[
                "render", "cornell", "--size", "20x12", "--spp", "2", "--json",
            ][..],
            extra,
        ]
        .concat();
        let out = canopy(&args, &dir);
        assert!(out.status.success(), "{}", stderr(&out));
        serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()
    };
    let whole = render(&["-o", "whole.exr"]);
    assert_eq!(whole["region"], serde_json::Value::Null);
    let part = render(&["-o", "part.exr", "--region", "3,4,9x5"]);
    assert_eq!(part["region"], "3,4,9x5");
    let whole = image::open(dir.join("whole.exr")).unwrap().into_rgb32f();
    let part = image::open(dir.join("part.exr")).unwrap().into_rgb32f();
    assert_eq!((part.width(), part.height()), (9, 5));
    for (x, y, p) in part.enumerate_pixels() {
        assert_eq!(
            p,
            whole.get_pixel(x + 3, y + 4),
            "pixel ({x}, {y}) of the region"
        );
    }
    // A region beyond the image, or written wrongly: one clear message, no output.
    for (region, words) in [
        ("15,0,6x2", "beyond the 20x12 image"),
        ("3x4", "X,Y,WIDTHxHEIGHT"),
    ] {
        let out = canopy(
            &[
                "render", "cornell", "--size", "20x12", "--spp", "1", "-o", "bad.png", "--region",
                region,
            ],
            &dir,
        );
        assert!(!out.status.success());
        assert!(stderr(&out).contains(words), "{region}: {}", stderr(&out));
        assert!(!dir.join("bad.png").exists());
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn integrator_options_choose_the_estimator_and_are_reported() {
    let dir = scratch("integrator");
    let run = |extra: &[&str]| {
        let args = [
            &["render", "cornell", "--size", "8x8", "--spp", "2", "--json"][..],
            extra,
        ]
        .concat();
        let out = canopy(&args, &dir);
        assert!(out.status.success(), "{}", stderr(&out));
        serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()
    };
    let path = run(&["-o", "path.png"]);
    assert_eq!(path["integrator"], "path");
    assert_eq!(path["russian_roulette"], true);
    assert!(path["shadow_rays"].as_u64().unwrap() > 0);
    let bsdf = run(&["-o", "bsdf.png", "--integrator", "bsdf"]);
    assert_eq!(bsdf["integrator"], "bsdf");
    assert_eq!(bsdf["shadow_rays"], 0);
    let no_rr = run(&["-o", "no_rr.png", "--no-roulette"]);
    assert_eq!(no_rr["russian_roulette"], false);
    // The sampler: Sobol points unless told, and a different image when told.
    assert_eq!(path["sampler"], "sobol");
    let independent = run(&["-o", "independent.png", "--sampler", "independent"]);
    assert_eq!(independent["sampler"], "independent");
    let image = |name: &str| std::fs::read(dir.join(name)).unwrap();
    assert_ne!(image("path.png"), image("independent.png"));
    let out = canopy(
        &[
            "render",
            "cornell",
            "--integrator",
            "photons",
            "-o",
            "x.png",
        ],
        &dir,
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("expected one of: path, bsdf"),
        "{}",
        stderr(&out)
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn scenes_lists_every_builtin() {
    let out = canopy(&["scenes"], &std::env::temp_dir());
    let list = String::from_utf8_lossy(&out.stdout);
    for name in ["paper-1", "paper-6", "rtiow-final", "cornell"] {
        assert!(list.contains(name), "{list}");
    }
}

#[test]
fn devices_lists_adapters_or_says_there_are_none() {
    // A machine without a display (a server, CI): drivers' layers must not print either.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_canopy"))
        .arg("devices")
        .current_dir(std::env::temp_dir())
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    let (list, err) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(!err.contains("panicked"), "{err}");
    match out.status.code() {
        // One line per adapter, with its backend.
        Some(0) => {
            assert!(
                !list.trim().is_empty() && list.lines().all(|l| l.contains('(')),
                "{list}"
            );
            assert!(err.is_empty(), "a listing prints nothing else: {err}");
        }
        Some(1) => assert!(err.contains("no GPU adapter"), "{err}"),
        other => panic!("exit {other:?}: {err}"),
    }
}

/// `--device gpu` renders the same image as the CPU where an adapter exists (the software
/// one in CI): the same random streams give the same paths, so pixels differ only by
/// rounding. Without an adapter, it is a clear error and no image is left behind.
#[test]
fn the_gpu_renders_what_the_cpu_renders() {
    let dir = scratch("gpu");
    let args = |device: &'static str, out: &'static str| {
        [
            "render", "paper-3", "--size", "48x48", "--spp", "4", "--device", device, "-o", out,
        ]
    };
    let cpu = canopy(&args("cpu", "cpu.png"), &dir);
    assert_eq!(cpu.status.code(), Some(0), "{}", stderr(&cpu));
    let gpu = canopy(&args("gpu", "gpu.png"), &dir);
    let err = stderr(&gpu);
    assert!(!err.contains("panicked"), "{err}");
    if gpu.status.code() == Some(1) && err.contains("no GPU adapter") {
        eprintln!("SKIPPED: no GPU adapter: {err}");
        assert!(!dir.join("gpu.png").exists());
        return;
    }
    assert_eq!(gpu.status.code(), Some(0), "{err}");
    let (a, b) = (
        image::open(dir.join("cpu.png")).unwrap().to_rgb8(),
        image::open(dir.join("gpu.png")).unwrap().to_rgb8(),
    );
    let differing = a
        .pixels()
        .zip(b.pixels())
        .filter(|(p, q)| p.0.iter().zip(q.0).any(|(x, y)| x.abs_diff(y) > 2))
        .count();
    assert!(differing * 100 <= (48 * 48), "{differing} pixels differ");
    // What the GPU cannot do yet is refused before any work, naming the way out.
    for (extra, words) in [
        (&["--bvh", "none"][..], "--bvh"),
        (&["--heatmap"][..], "--heatmap"),
    ] {
        let mut a = vec![
            "render", "paper-3", "--size", "8x8", "--spp", "1", "--device", "gpu",
        ];
        a.extend_from_slice(extra);
        a.extend(["-o", "refused.png"]);
        let out = canopy(&a, &dir);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{a:?}: {err}");
        assert!(
            err.contains(words) || err.contains("no GPU adapter"),
            "{a:?}: {err}"
        );
        assert!(!dir.join("refused.png").exists());
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn bench_gpu_times_both_devices_on_the_same_scene() {
    let out = canopy(
        &["bench", "gpu", "paper-1", "--size", "16x16", "--spp", "2"],
        &std::env::temp_dir(),
    );
    let (table, err) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(!err.contains("panicked"), "{err}");
    if out.status.code() == Some(1) && err.contains("no GPU adapter") {
        eprintln!("SKIPPED: no GPU adapter: {err}");
        return;
    }
    assert_eq!(out.status.code(), Some(0), "{err}");
    let rows: Vec<&str> = table.lines().filter(|l| l.starts_with("paper-1")).collect();
    assert_eq!(rows.len(), 2, "{table}");
    assert!(rows[0].contains("CPU") && rows[1].contains('x'), "{table}");
}

#[test]
fn unknown_key_is_reported_with_file_line_and_key() {
    let scene = format!("{CAMERA}[[spheres]]\ncenter = [0, 0, 0]\nradus = 1\n");
    assert_scene_fails("key", &scene, &["bad.toml:6:", "radus"]);
}

#[test]
fn unknown_material_is_reported_with_its_line() {
    let scene =
        format!("{CAMERA}[[spheres]]\ncenter = [0, 0, 0]\nradius = 1\nmaterial = \"chrome\"\n");
    assert_scene_fails(
        "material",
        &scene,
        &["bad.toml:7:", "unknown material `chrome`"],
    );
}

#[test]
fn toml_syntax_error_is_reported() {
    assert_scene_fails(
        "syntax",
        "[camera\nlook_from = [0, 0, 5]\n",
        &["bad.toml:1:"],
    );
}

#[test]
fn missing_mesh_file_is_named() {
    let scene = format!("{CAMERA}[[meshes]]\nfile = \"nowhere.ply\"\nmaterial = {{ type = \"lambertian\", albedo = [1, 1, 1] }}\n");
    assert_scene_fails("missing-mesh", &scene, &["bad.toml:4:", "nowhere.ply"]);
}

#[test]
fn malformed_mesh_is_named_with_what_is_wrong() {
    let dir_name = "malformed-mesh";
    let scene = format!("{CAMERA}[[meshes]]\nfile = \"broken.ply\"\nmaterial = {{ type = \"lambertian\", albedo = [1, 1, 1] }}\n");
    let dir = scratch(dir_name);
    std::fs::write(dir.join("broken.ply"), "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n").unwrap();
    std::fs::write(dir.join("bad.toml"), scene).unwrap();
    let out = canopy(
        &["render", "bad.toml", "-o", "out.png", "--size", "8x8"],
        &dir,
    );
    let err = stderr(&out);
    assert!(!out.status.success());
    assert!(
        err.contains("broken.ply") && err.contains("vertex 7"),
        "{err}"
    );
    assert_eq!(outputs(&dir), Vec::<String>::new());
    std::fs::remove_dir_all(dir).unwrap();
}

/// A bare mesh's errors name the mesh file itself (not a line of a scene the user never
/// wrote), and a mesh with no triangle of any area is refused by `check` and `render`
/// alike: nothing to render and nothing to frame (its camera was NaN).
#[test]
fn bare_meshes_are_named_by_themselves_and_empty_ones_are_refused() {
    let dir = scratch("bare-mesh");
    let header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    std::fs::write(
        dir.join("broken.ply"),
        format!("{header}0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n"),
    )
    .unwrap();
    std::fs::write(
        dir.join("flat.ply"),
        format!("{header}0 0 0\n1 1 1\n2 2 2\n3 0 1 2\n"),
    )
    .unwrap();
    std::fs::write(dir.join("bad.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
    let cases = [
        ("broken.ply", "error: broken.ply: face 0 refers to vertex 7"),
        ("flat.ply", "error: flat.ply: no triangle with any area"),
        (
            "bad.obj",
            "error: bad.obj: line 4: vertex index 9 is out of bounds: the file has 3 vertices",
        ),
    ];
    for (mesh, expected) in cases {
        for command in ["check", "render"] {
            let out = canopy(
                &[command, mesh, "--size", "8x8", "--spp", "1"]
                    [..if command == "check" { 2 } else { 6 }],
                &dir,
            );
            assert_eq!(out.status.code(), Some(1), "{command} {mesh}");
            let err = stderr(&out);
            assert!(err.starts_with(expected), "{command} {mesh}: {err}");
            let cites_a_line = (0..10).any(|d| err.contains(&format!("{mesh}:{d}")));
            assert!(
                !cites_a_line,
                "{command} {mesh} cites a line of a generated scene: {err}"
            );
            assert!(!err.contains("NaN") && !err.contains("panicked"), "{err}");
        }
    }
    assert_eq!(outputs(&dir), Vec::<String>::new());
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn unknown_scene_and_bad_options_fail_cleanly() {
    let dir = scratch("options");
    let cases: [(&[&str], &str); 4] = [
        (
            &["render", "no-such-scene"],
            "unknown scene `no-such-scene`",
        ),
        (
            &["render", "paper-1", "-o", "out.bmp"],
            "unsupported image format",
        ),
        (
            &["render", "paper-1", "--bvh", "octree"],
            "unknown BVH builder `octree`",
        ),
        (
            &["render", "paper-1", "--size", "0x10"],
            "width and height must be whole numbers in 1..=65536",
        ),
    ];
    for (args, expected) in cases {
        let out = canopy(args, &dir);
        assert!(!out.status.success(), "{args:?}");
        assert!(
            stderr(&out).contains(expected),
            "{args:?}: {}",
            stderr(&out)
        );
    }
    assert_eq!(outputs(&dir), Vec::<String>::new());
    std::fs::remove_dir_all(dir).unwrap();
}

/// The bunny shipped with the scenes, as a bare mesh input.
fn bunny() -> String {
    concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/meshes/bunny.ply").to_string()
}

#[test]
fn bvh_table_lists_every_builder_and_width() {
    let out = canopy(
        &["bvh", &bunny(), "--width", "2,8", "--runs", "1"],
        &std::env::temp_dir(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(table.contains("3674 primitives"), "{table}");
    for builder in [
        "sort-x",
        "morton-median",
        "lbvh",
        "binned-sah",
        "sweep-sah",
        "agglomerative",
        "aac",
        "ploc",
    ] {
        let rows = table.lines().filter(|l| l.starts_with(builder)).count();
        assert_eq!(rows, 2, "{builder} at widths 2 and 8:\n{table}");
    }
}

#[test]
fn bvh_json_is_machine_readable_and_consistent() {
    let out = canopy(
        &[
            "bvh",
            "paper-3",
            "--bvh",
            "lbvh,ploc",
            "--width",
            "4",
            "--runs",
            "1",
            "--json",
        ],
        &std::env::temp_dir(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let json = String::from_utf8_lossy(&out.stdout);
    // A light check without a JSON dependency: both rows, their width, plausible numbers.
    assert!(json.contains("\"primitives\": 995"), "{json}");
    assert_eq!(json.matches("\"width\": 4").count(), 2, "{json}");
    assert!(json.contains("\"builder\": \"lbvh\"") && json.contains("\"builder\": \"ploc\""));
    assert!(json.contains("\"max_leaf_size\": "));
}

#[test]
fn bvh_rejects_an_unknown_builder() {
    let out = canopy(
        &["bvh", "paper-1", "--bvh", "lbvh,kd-tree"],
        &std::env::temp_dir(),
    );
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("unknown BVH builder `kd-tree`"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn wide_render_matches_binary_render() {
    let dir = scratch("wide");
    let args = |out: &'static str, width: &'static str| {
        [
            "render", "paper-3", "-o", out, "--size", "24x24", "--spp", "2", "--bvh", "ploc",
            "--width", width,
        ]
    };
    for (out, width) in [("w2.png", "2"), ("w8.png", "8")] {
        let run = canopy(&args(out, width), &dir);
        assert!(run.status.success(), "{}", stderr(&run));
    }
    let a = image::open(dir.join("w2.png")).unwrap().to_rgb8();
    let b = image::open(dir.join("w8.png")).unwrap().to_rgb8();
    assert_eq!(a, b);
    std::fs::remove_dir_all(dir).unwrap();
}

/// `--fast-triangles` changes only rays within rounding of an edge: a mesh renders to
/// the same image but for a few pixels, each by little.
#[test]
fn fast_triangles_render_the_mesh_as_the_watertight_test_does() {
    let dir = scratch("fast-triangles");
    let bunny = bunny();
    let args = |out: &'static str| {
        vec![
            "render",
            bunny.as_str(),
            "-o",
            out,
            "--size",
            "32x32",
            "--spp",
            "4",
            "--threads",
            "2",
        ]
    };
    let run = canopy(&args("watertight.png"), &dir);
    assert!(run.status.success(), "{}", stderr(&run));
    let mut fast = args("fast.png");
    fast.push("--fast-triangles");
    let run = canopy(&fast, &dir);
    assert!(run.status.success(), "{}", stderr(&run));
    let a = image::open(dir.join("watertight.png")).unwrap().to_rgb8();
    let b = image::open(dir.join("fast.png")).unwrap().to_rgb8();
    let differing = a.pixels().zip(b.pixels()).filter(|(p, q)| p != q).count();
    assert!(differing <= 32, "{differing} of 1024 pixels differ");
    assert!(a.pixels().any(|p| p.0 != [0, 0, 0]), "the bunny is in view");
    // The GPU's kernels have one mode: asking for the other there is refused before work.
    let mut gpu = fast.clone();
    gpu[3] = "gpu.png";
    gpu.extend(["--device", "gpu"]);
    let run = canopy(&gpu, &dir);
    assert!(!run.status.success(), "{}", stderr(&run));
    assert!(
        stderr(&run).contains("drop --device gpu"),
        "{}",
        stderr(&run)
    );
    assert!(!dir.join("gpu.png").exists());
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn heatmap_and_bvh_overlay_write_images() {
    let dir = scratch("pictures");
    let heat = canopy(
        &[
            "render",
            "paper-3",
            "-o",
            "heat.png",
            "--size",
            "40x30",
            "--heatmap",
        ],
        &dir,
    );
    assert!(heat.status.success(), "{}", stderr(&heat));
    assert!(String::from_utf8_lossy(&heat.stdout).contains("heatmap     primary-ray cost: mean"));
    let overlay = canopy(
        &[
            "render",
            "paper-3",
            "-o",
            "boxes.png",
            "--size",
            "40x30",
            "--spp",
            "1",
            "--show-bvh",
            "--levels",
            "0",
        ],
        &dir,
    );
    assert!(overlay.status.success(), "{}", stderr(&overlay));
    assert!(String::from_utf8_lossy(&overlay.stdout)
        .contains("overlay     1 boxes of tree levels 0..0"));
    for name in ["heat.png", "boxes.png"] {
        assert_eq!(image::open(dir.join(name)).unwrap().width(), 40);
    }
    let no_bvh = canopy(
        &[
            "render",
            "paper-3",
            "-o",
            "x.png",
            "--bvh",
            "none",
            "--show-bvh",
        ],
        &dir,
    );
    assert!(!no_bvh.status.success());
    assert!(
        stderr(&no_bvh).contains("--show-bvh needs a BVH"),
        "{}",
        stderr(&no_bvh)
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn bench_paper_quick_writes_consistent_tables() {
    let dir = scratch("bench");
    let out = canopy(
        &[
            "bench",
            "paper",
            "--quick",
            "--scenes",
            "1,3",
            "--methods",
            "report",
            "--out",
            "results",
        ],
        &dir,
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let read = |name: &str| std::fs::read_to_string(dir.join("results").join(name)).unwrap();
    let (md, csv) = (read("results.md"), read("results.csv"));
    let json: serde_json::Value = serde_json::from_str(&read("results.json")).unwrap();
    let measurements = json["measurements"].as_array().unwrap();
    assert_eq!(
        measurements.len(),
        2 * 6,
        "2 scenes x the report's 6 methods"
    );
    let csv_rows: Vec<&str> = csv.lines().skip(1).collect();
    assert_eq!(csv_rows.len(), measurements.len());
    for (m, row) in measurements.iter().zip(&csv_rows) {
        let (scene, method) = (m["scene"].as_str().unwrap(), m["method"].as_str().unwrap());
        let mean = m["mean_s"].as_f64().unwrap();
        assert_eq!(m["seconds"].as_array().unwrap().len(), 2, "two runs");
        // Speedup is the no-BVH mean over this mean, in the same scene.
        let none = measurements
            .iter()
            .find(|n| n["scene"] == scene && n["method"] == "No BVH")
            .unwrap();
        let expected = none["mean_s"].as_f64().unwrap() / mean;
        assert!((m["speedup"].as_f64().unwrap() - expected).abs() < 1e-9 * expected);
        // The CSV row and the Markdown table carry the same mean.
        let fields: Vec<&str> = row.split(',').collect();
        assert_eq!((fields[0], fields[1]), (scene, method));
        let mean_text = fields[5];
        assert!(
            (mean_text.parse::<f64>().unwrap() - mean).abs() <= 1e-3 * mean,
            "{mean_text} vs {mean}"
        );
        let table_row = md
            .lines()
            .find(|l| l.starts_with(&format!("| {method} |")))
            .unwrap();
        assert!(
            table_row.contains(&format!("{mean_text} ± ")),
            "`{mean_text}` not in `{table_row}`"
        );
        assert!(m["report_speedup"].as_f64().unwrap() >= 1.0);
    }
    assert!(md.contains("## Table 2: speedup over no BVH"));
    for plot in [
        "render_time.png",
        "speedup.png",
        "build_vs_sah.png",
        "table3.png",
    ] {
        let image =
            image::open(dir.join("results").join(plot)).unwrap_or_else(|e| panic!("{plot}: {e}"));
        assert!(image.width() > 100, "{plot}");
    }
    // The tables and plots can be remade from the JSON alone.
    let again = canopy(
        &[
            "bench",
            "paper",
            "--from",
            "results/results.json",
            "--out",
            "again",
        ],
        &dir,
    );
    assert!(again.status.success(), "{}", stderr(&again));
    assert_eq!(
        std::fs::read_to_string(dir.join("again/results.md")).unwrap(),
        md
    );
    // Every file a run writes is all there is, and none can be the input of a remake:
    // a results.json copied over one of them is refused and kept.
    let mut written: Vec<String> = std::fs::read_dir(dir.join("again"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    written.sort();
    assert_eq!(
        written,
        [
            "build_vs_sah.png",
            "render_time.png",
            "results.csv",
            "results.md",
            "speedup.png",
            "table3.png"
        ]
    );
    let json_text = read("results.json");
    std::fs::write(dir.join("again/results.csv"), &json_text).unwrap();
    let over = canopy(
        &[
            "bench",
            "paper",
            "--from",
            "again/results.csv",
            "--out",
            "again",
        ],
        &dir,
    );
    assert_eq!(over.status.code(), Some(1));
    assert!(
        stderr(&over).contains("refusing to write the benchmark output over an input"),
        "{}",
        stderr(&over)
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("again/results.csv")).unwrap(),
        json_text
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn bench_paper_renders_and_records_the_triangle_test_asked_for() {
    let dir = scratch("bench-triangles");
    for (flag, name) in [(Some("--fast-triangles"), "fast"), (None, "watertight")] {
        let mut args = vec![
            "bench",
            "paper",
            "--quick",
            "--scenes",
            "3",
            "--method",
            "binned-sah x8",
            "--json-only",
            "--out",
            name,
        ];
        args.extend(flag);
        let out = canopy(&args, &dir);
        assert!(out.status.success(), "{}", stderr(&out));
        let text = std::fs::read_to_string(dir.join(name).join("results.json")).unwrap();
        let json: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(json["config"]["triangles"], name);
        let settings = json["settings"].as_str().unwrap();
        assert!(
            settings.contains(&format!("{name} triangle test")),
            "{settings}"
        );
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn check_describes_a_valid_scene_without_rendering() {
    let dir = scratch("check");
    let out = canopy(&["check", "paper-5"], &dir);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    for line in [
        "primitives  1477 (485 spheres, 992 triangles, 0 cuboids)",
        "render      480x480, 128 spp, depth 4",
        "ok          paper-5 is valid",
    ] {
        assert!(text.contains(line), "`{line}` missing:\n{text}");
    }
    assert_eq!(outputs(&dir), Vec::<String>::new(), "check writes nothing");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn check_reports_degenerate_triangles_and_bad_settings() {
    let dir = scratch("check-bad");
    std::fs::write(
        dir.join("m.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 2\n",
    )
    .unwrap();
    let scene = format!("{CAMERA}[[meshes]]\nfile = \"m.obj\"\nmaterial = {{ type = \"lambertian\", albedo = [1, 1, 1] }}\n");
    std::fs::write(dir.join("s.toml"), &scene).unwrap();
    let out = canopy(&["check", "s.toml"], &dir);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("warning: 1 zero-area mesh triangles were left out"),
        "{}",
        stderr(&out)
    );

    std::fs::write(
        dir.join("deep.toml"),
        format!("{CAMERA}[render]\nmax_depth = 5000\n"),
    )
    .unwrap();
    let out = canopy(&["check", "deep.toml"], &dir);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("deep.toml:4: render: max_depth 5000 is outside 1..=1024"),
        "{}",
        stderr(&out)
    );
    std::fs::remove_dir_all(dir).unwrap();
}

/// Arguments of a render long enough (~1 s) to interrupt, checkpointing after every pass.
fn interruptible(output: &str) -> Vec<String> {
    [
        "render",
        "paper-5",
        "--size",
        "128x128",
        "--spp",
        "96",
        "--threads",
        "2",
        "-o",
        output,
        "--checkpoint",
        "ck",
        "--every",
        "0",
    ]
    .map(String::from)
    .to_vec()
}

#[test]
fn a_killed_render_always_leaves_a_valid_checkpoint_that_resumes_to_the_same_image() {
    let dir = scratch("kill");
    let full = canopy(
        &[
            "render", "paper-5", "--size", "128x128", "--spp", "96", "-o", "full.png",
        ],
        &dir,
    );
    assert!(full.status.success(), "{}", stderr(&full));
    let expected = std::fs::read(dir.join("full.png")).unwrap();
    let mut resumed = 0;
    // Killed once the checkpoint on disk holds at least this many samples (by state, not
    // by time): wherever the kill lands, in a pass or in a save, the file is whole.
    for at_least in [1, 5, 20, 50] {
        let _ = std::fs::remove_file(dir.join("ck"));
        let mut child = Command::new(env!("CARGO_BIN_EXE_canopy"))
            .args(interruptible("killed.png"))
            .current_dir(&dir)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let ck = dir.join("ck");
        let saved_samples = || {
            canopy_render::checkpoint::Checkpoint::load(&ck).map_or(0, |c| c.accumulator.samples)
        };
        while saved_samples() < at_least && child.try_wait().unwrap().is_none() {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        child.kill().unwrap(); // SIGKILL: no chance to clean up
        child.wait().unwrap();
        if !ck.exists() {
            continue; // finished (and removed it) first
        }
        let checkpoint = canopy_render::checkpoint::Checkpoint::load(&ck)
            .unwrap_or_else(|e| panic!("killed at {at_least} samples: {e}"));
        assert!(checkpoint.accumulator.samples < 96);
        let out = canopy(&["render", "--resume", "ck", "-o", "resumed.png"], &dir);
        assert!(out.status.success(), "{}", stderr(&out));
        assert!(
            std::fs::read(dir.join("resumed.png")).unwrap() == expected,
            "killed at {at_least} samples: resumed image differs"
        );
        resumed += 1;
    }
    assert!(
        resumed > 0,
        "no kill landed mid-render; the render is too fast for this test"
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn ctrl_c_writes_the_partial_image_and_a_checkpoint_then_resumes() {
    interrupt_and_resume("INT");
}

#[test]
fn sigterm_saves_the_work_as_ctrl_c_does() {
    interrupt_and_resume("TERM");
}

#[test]
fn sighup_saves_the_work_as_ctrl_c_does() {
    interrupt_and_resume("HUP");
}

/// Sends `signal` to a render in progress: the partial image and a checkpoint must be
/// written, the exit status must be 130, and resuming must give the full image.
fn interrupt_and_resume(signal: &str) {
    let dir = scratch(&format!("sig{signal}"));
    let full = canopy(
        &[
            "render", "paper-5", "--size", "128x128", "--spp", "96", "-o", "full.png",
        ],
        &dir,
    );
    assert!(full.status.success());
    let mut child = Command::new(env!("CARGO_BIN_EXE_canopy"))
        .args(interruptible("partial.png"))
        .current_dir(&dir)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Signalled once the first checkpoint is on disk (by state, not by time).
    while !dir.join("ck").exists() && child.try_wait().unwrap().is_none() {
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    let sent = Command::new("kill")
        .args([format!("-{signal}"), child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let out = child.wait_with_output().unwrap();
    if out.status.success() {
        // The render beat the signal; nothing to check on this machine.
        std::fs::remove_dir_all(dir).unwrap();
        return;
    }
    assert_eq!(
        out.status.code(),
        Some(130),
        "SIG{signal}: {}",
        stderr(&out)
    );
    assert!(
        stderr(&out).contains("interrupted; the render so far is saved"),
        "{}",
        stderr(&out)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("partial     "));
    assert!(
        image::open(dir.join("partial.png")).is_ok(),
        "the partial image is written"
    );
    let resumed = canopy(&["render", "--resume", "ck", "-o", "resumed.png"], &dir);
    assert!(resumed.status.success(), "{}", stderr(&resumed));
    assert!(
        std::fs::read(dir.join("resumed.png")).unwrap()
            == std::fs::read(dir.join("full.png")).unwrap()
    );
    assert!(
        !dir.join("ck").exists(),
        "a finished render removes its checkpoint"
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn resuming_a_damaged_checkpoint_is_a_clear_error() {
    let dir = scratch("damaged");
    std::fs::write(dir.join("ck"), b"CANOPYCK not really").unwrap();
    let out = canopy(&["render", "--resume", "ck"], &dir);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("ck: not a canopy checkpoint, or a damaged one"),
        "{}",
        stderr(&out)
    );
    std::fs::remove_dir_all(dir).unwrap();
}

/// A scene of named meshes placed by instances: `render` and `check` report the
/// instances and the triangles they place; `bvh` measures one tree over every placed
/// triangle; an instance of an unknown geometry names its line.
#[test]
fn instanced_scenes_render_check_and_measure() {
    let dir = scratch("instances");
    std::fs::write(
        dir.join("quad.obj"),
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n",
    )
    .unwrap();
    let scene = format!(
        "{CAMERA}[geometry.quad]\nfile = \"quad.obj\"\n\
         [[instances]]\ngeometry = \"quad\"\nmaterial = {{ type = \"lambertian\", albedo = [0.5, 0.5, 0.5] }}\n\
         translate = [-1.5, -1, 0]\nscale = [1, 1, -1]\ngrid = {{ count = [3, 2, 1], step = [1.1, 1.1, 0] }}\n"
    );
    std::fs::write(dir.join("s.toml"), scene).unwrap();
    let json = |args: &[&str]| {
        let out = canopy(args, &dir);
        assert!(out.status.success(), "{}", stderr(&out));
        serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()
    };
    let rendered = json(&[
        "render", "s.toml", "-o", "s.png", "--size", "16x16", "--spp", "1", "--json",
    ]);
    assert_eq!(rendered["instances"], 6);
    assert_eq!(rendered["instanced_triangles"], 12);
    assert_eq!(rendered["primitives"], 0);
    let checked = json(&["check", "s.toml", "--json"]);
    assert_eq!(checked["instances"], 6);
    let measured = json(&["bvh", "s.toml", "--bvh", "lbvh", "--json"]);
    assert_eq!(
        measured["primitives"], 12,
        "the instances baked into one tree"
    );
    let bad = "[[instances]]\ngeometry = \"quads\"\nmaterial = { type = \"lambertian\", albedo = [1, 1, 1] }\n";
    assert_scene_fails(
        "unknown-geometry",
        &format!("{CAMERA}{bad}"),
        &["bad.toml:4", "unknown geometry `quads` (defined: none)"],
    );
    std::fs::remove_dir_all(dir).unwrap();
}
