//! glTF 2.0 models: every model under `scenes/gltf/` loads and renders; hostile files
//! (truncated buffers, accessors past their data, indices past the vertices, huge
//! counts, cycles, required extensions, missing buffers) are errors that name the file
//! and the object at fault, never panics.

use canopy_render::accel::Accel;
use canopy_render::gltf_scene::parse_gltf;
use canopy_render::scene_file::Assets;
use canopy_render::{integrator, load_scene};
use std::path::{Path, PathBuf};

fn models() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/gltf")
}

/// Mean of a small render of `path` (and whether every pixel is finite).
fn render_small(path: &Path) -> f32 {
    let mut scene = load_scene(path.to_str().unwrap()).unwrap();
    (
        scene.settings.width,
        scene.settings.height,
        scene.settings.spp,
    ) = (24, 24, 2);
    let film = render_film(&scene);
    let mut sum = 0.0;
    for y in 0..24 {
        for x in 0..24 {
            let p = film.pixel(x, y);
            assert!(p.is_finite(), "{}: pixel {x},{y} is {p}", path.display());
            sum += p.element_sum() / 3.0;
        }
    }
    sum / (24.0 * 24.0)
}

#[test]
fn every_model_loads_and_renders() {
    let mut seen = 0;
    for entry in std::fs::read_dir(models()).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "glb") {
            let mean = render_small(&path);
            assert!(
                mean > 0.01,
                "{}: the render is black ({mean})",
                path.display()
            );
            seen += 1;
        }
    }
    assert_eq!(seen, 6, "the six models of scenes/gltf");
}

#[test]
fn nodes_become_instances_of_meshes_stored_once() {
    let truck = load_scene(models().join("CesiumMilkTruck.glb").to_str().unwrap()).unwrap();
    assert!(
        truck.instances.len() > truck.meshes.len(),
        "the wheels' mesh is placed twice: {} instances of {} meshes",
        truck.instances.len(),
        truck.meshes.len()
    );
    let nested = load_scene(models().join("nested.glb").to_str().unwrap()).unwrap();
    let placed: std::collections::HashSet<_> = nested
        .instances
        .iter()
        .map(|i| i.to_world.translation.to_array().map(f32::to_bits))
        .collect();
    assert!(placed.len() > 1, "nested nodes are placed apart");
}

#[test]
fn a_camera_in_the_file_is_used_alpha_modes_are_read_and_what_is_not_is_named() {
    let duck = load_scene(models().join("Duck.glb").to_str().unwrap()).unwrap();
    let camera = duck.camera;
    let toward = (camera.look_at - camera.look_from).normalize();
    let to_duck = (duck.bounds().center() - camera.look_from).normalize();
    assert!(
        toward.dot(to_duck) > 0.9,
        "the file's camera looks at the duck"
    );
    let alpha = load_scene(models().join("AlphaBlendModeTest.glb").to_str().unwrap()).unwrap();
    // The bed's normal map is read, with tangents generated for its mesh.
    assert!(alpha.material_maps.iter().any(|m| m.normal.is_some()));
    assert!(alpha.meshes.iter().any(|m| !m.tangents.is_empty()));
    // Its alpha modes are read: one blended material, masks with three cutoffs.
    use canopy_render::texture::Coverage;
    let coverages: Vec<Coverage> = alpha
        .material_maps
        .iter()
        .filter_map(|m| m.coverage)
        .collect();
    let blends = coverages
        .iter()
        .filter(|c| matches!(c, Coverage::Blend { .. }))
        .count();
    let mut cutoffs: Vec<f32> = coverages
        .iter()
        .filter_map(|c| match c {
            Coverage::Mask { cutoff, .. } => Some(*cutoff),
            _ => None,
        })
        .collect();
    cutoffs.sort_by(f32::total_cmp);
    cutoffs.dedup();
    assert_eq!(
        (blends, cutoffs),
        (1, vec![0.25, 0.5, 0.75]),
        "{coverages:?}"
    );
}

struct NoFiles;

impl Assets for NoFiles {
    fn read(&self, path: &str) -> Result<Vec<u8>, String> {
        Err(format!("cannot read {path}: no such file"))
    }
}

/// One triangle: positions (36 bytes) then u16 indices (6 bytes, padded to 8).
fn triangle_bin(indices: [u16; 3]) -> Vec<u8> {
    let mut bin = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        bin.extend(v.to_le_bytes());
    }
    for i in indices {
        bin.extend(i.to_le_bytes());
    }
    bin.extend([0, 0]);
    bin
}

const TRIANGLE: &str = r#"{"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],
"nodes":[{"mesh":0}],
"meshes":[{"name":"tri","primitives":[{"attributes":{"POSITION":0},"indices":1}]}],
"buffers":[{"byteLength":44}],
"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":6}],
"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]},
{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}]}"#;

/// A GLB of `json` and the binary chunk `bin`.
fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let pad = |mut v: Vec<u8>, with: u8| {
        while !v.len().is_multiple_of(4) {
            v.push(with);
        }
        v
    };
    let json = pad(json.as_bytes().to_vec(), b' ');
    let bin = pad(bin.to_vec(), 0);
    let mut out = b"glTF".to_vec();
    out.extend(2u32.to_le_bytes());
    out.extend(((12 + 8 + json.len() + 8 + bin.len()) as u32).to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    out
}

#[test]
fn a_hand_made_triangle_loads() {
    let scene = parse_gltf(&glb(TRIANGLE, &triangle_bin([0, 1, 2])), &NoFiles, "tri").unwrap();
    assert_eq!((scene.meshes.len(), scene.instances.len()), (1, 1));
    assert_eq!(scene.meshes[0].mesh.indices(), &[[0, 1, 2]]);
    // Strips, fans and a line primitive beside the triangles.
    let strip = TRIANGLE.replace(
        r#""indices":1}"#,
        r#""indices":1,"mode":5},{"attributes":{"POSITION":0},"mode":1}"#,
    );
    let scene = parse_gltf(&glb(&strip, &triangle_bin([0, 1, 2])), &NoFiles, "tri").unwrap();
    assert_eq!(scene.meshes.len(), 1);
    assert!(scene
        .warnings()
        .iter()
        .any(|w| w.contains("mesh 0 (\"tri\") primitive 1: Lines are not rendered")));
}

/// Meshes (and primitives) that share their accessors are decoded once and stored
/// once: 400 meshes over one accessor pair made 400 copies, 1.9 GB from 3.6 MB of files.
/// A file without a scene places every node that is no other's child, found in one pass.
#[test]
fn meshes_sharing_accessors_are_decoded_once_and_sceneless_files_find_their_roots() {
    let n = 400;
    let meshes: Vec<String> = (0..n)
        .map(|i| {
            format!(r#"{{"name":"copy{i}","primitives":[{{"attributes":{{"POSITION":0}},"indices":1}},{{"attributes":{{"POSITION":0}},"indices":1}}]}}"#)
        })
        .collect();
    // Node 0 is a parent of node 1; nodes 2.. are roots; no scene is listed.
    let mut nodes = vec![r#"{"mesh":0,"children":[1]}"#.to_string()];
    nodes.extend((1..n).map(|i| format!(r#"{{"mesh":{i},"translation":[{i},0,0]}}"#)));
    let json = TRIANGLE
        .replace(r#""scene":0,"scenes":[{"nodes":[0]}],"#, "")
        .replace(
            r#""nodes":[{"mesh":0}]"#,
            &format!(r#""nodes":[{}]"#, nodes.join(",")),
        )
        .replace(
            r#""meshes":[{"name":"tri","primitives":[{"attributes":{"POSITION":0},"indices":1}]}]"#,
            &format!(r#""meshes":[{}]"#, meshes.join(",")),
        );
    let scene = parse_gltf(&glb(&json, &triangle_bin([0, 1, 2])), &NoFiles, "shared").unwrap();
    assert_eq!(scene.meshes.len(), 1, "one mesh for one set of accessors");
    assert_eq!(
        scene.instances.len(),
        2 * n,
        "every primitive of every node placed"
    );
    // Node 1 is placed once, under node 0 (it is no root of its own).
    let at_one = scene
        .instances
        .iter()
        .filter(|i| i.to_world.translation.x == 1.0)
        .count();
    assert_eq!(at_one, 2);
}

#[test]
fn hostile_files_are_errors_that_name_the_object() {
    let good = triangle_bin([0, 1, 2]);
    let cases: Vec<(String, Vec<u8>, &str)> = vec![
        (TRIANGLE.into(), good[..20].to_vec(), "buffer 0: declares 44 bytes but holds 20"),
        (TRIANGLE.replace(r#""count":3,"type":"VEC3""#, r#""count":1000,"type":"VEC3""#), good.clone(),
         "mesh 0 (\"tri\") primitive 0: positions accessor 0: 1000 elements from byte 0 overrun its buffer view 0 of 36 bytes"),
        (TRIANGLE.replace(r#""count":3,"type":"VEC3""#, r#""count":4294967295,"type":"VEC3""#), good.clone(),
         "positions accessor 0: 4294967295 elements"),
        (TRIANGLE.into(), triangle_bin([0, 1, 7]), "mesh 0 (\"tri\") primitive 0: index 7 is past the last of its 3 vertices"),
        (TRIANGLE.replace(r#""byteOffset":36,"byteLength":6"#, r#""byteOffset":36,"byteLength":6000"#), good.clone(),
         "indices accessor 1: buffer view 1 (bytes 36..+6000) overruns buffer 0"),
        (TRIANGLE.replace(r#""componentType":5123"#, r#""componentType":5126"#), good.clone(),
         "indices accessor 1 is Scalar F32"),
        (TRIANGLE.replace(r#""nodes":[{"mesh":0}]"#, r#""nodes":[{"mesh":0,"children":[1]},{"children":[0]}]"#), good.clone(),
         "reached twice"),
        (TRIANGLE.replace(r#""asset":{"version":"2.0"}"#, r#""asset":{"version":"2.0"},"extensionsRequired":["KHR_draco_mesh_compression"],"extensionsUsed":["KHR_draco_mesh_compression"]"#), good.clone(),
         "KHR_draco_mesh_compression"),
        (TRIANGLE.replace(r#""buffers":[{"byteLength":44}]"#, r#""buffers":[{"byteLength":44,"uri":"gone.bin"}]"#), vec![],
         "buffer 0: cannot read gone.bin"),
        (TRIANGLE.replace(r#""nodes":[{"mesh":0}]"#, r#""nodes":[{"mesh":0,"matrix":[1,0,0,1, 0,1,0,0, 0,0,1,0, 0,0,0,1]}]"#), good.clone(),
         "node 0: its transform is not a finite affine matrix"),
        (TRIANGLE.replace(r#""attributes":{"POSITION":0},"indices":1"#, r#""attributes":{"POSITION":0},"indices":1,"mode":0"#), good.clone(),
         "places no triangles"),
    ];
    for (json, bin, expected) in cases {
        let file = glb(&json, &bin);
        let err = parse_gltf(&file, &NoFiles, "hostile")
            .map(|_| ())
            .unwrap_err();
        assert!(err.contains(expected), "expected {expected:?} in: {err}");
        // Cut short anywhere, the file is refused without a panic.
        for cut in [0, 11, 12, 20, file.len() / 2, file.len() - 1] {
            let _ = parse_gltf(&file[..cut], &NoFiles, "cut");
        }
    }
}

#[test]
fn errors_through_the_loader_name_the_file() {
    let dir = std::env::temp_dir().join(format!("canopy-gltf-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("broken.glb");
    std::fs::write(&path, glb(TRIANGLE, &triangle_bin([0, 1, 9]))).unwrap();
    let err = load_scene(path.to_str().unwrap())
        .map(|_| ())
        .unwrap_err()
        .to_string();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(
        err.contains("broken.glb: node 0: mesh 0 (\"tri\") primitive 0: index 9"),
        "{err}"
    );
}

#[test]
fn scene_files_place_models_and_read_buffers_beside_them() {
    let dir = std::env::temp_dir().join(format!("canopy-gltf-scene-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("models")).unwrap();
    // A .gltf whose buffer is a file beside it, and a .glb, both under models/.
    let external = TRIANGLE.replace(
        r#""buffers":[{"byteLength":44}]"#,
        r#""buffers":[{"byteLength":44,"uri":"tri%20angle.bin"}]"#,
    );
    std::fs::write(dir.join("models/tri.gltf"), external).unwrap();
    std::fs::write(dir.join("models/tri angle.bin"), triangle_bin([0, 1, 2])).unwrap();
    std::fs::copy(models().join("nested.glb"), dir.join("models/nested.glb")).unwrap();
    let scene_file = dir.join("scene.toml");
    std::fs::write(
        &scene_file,
        "camera = { look_from = [0, 0, 10], look_at = [0, 0, 0] }\n\n\
         [[gltf]]\nfile = \"models/tri.gltf\"\ntranslate = [5, 0, 0]\n\n\
         [[gltf]]\nfile = \"models/nested.glb\"\nscale = 2\n",
    )
    .unwrap();
    let scene = load_scene(scene_file.to_str().unwrap()).unwrap();
    let alone = load_scene(models().join("nested.glb").to_str().unwrap()).unwrap();
    assert_eq!(scene.instances.len(), 1 + alone.instances.len());
    assert_eq!(
        scene.instances[0].to_world.translation.x, 5.0,
        "placed by its entry"
    );
    assert_eq!(
        scene.camera.look_from.z, 10.0,
        "the scene file's camera stays"
    );
    for input in [
        "scene.toml",
        "models/tri.gltf",
        "models/tri angle.bin",
        "models/nested.glb",
    ] {
        assert!(
            scene.inputs.iter().any(|p| p.ends_with(input)),
            "{input} in {:?}",
            scene.inputs
        );
    }
    std::fs::write(&scene_file, "camera = { look_from = [0, 0, 10], look_at = [0, 0, 0] }\n\n[[gltf]]\nfile = \"models/gone.glb\"\n").unwrap();
    let err = load_scene(scene_file.to_str().unwrap())
        .map(|_| ())
        .unwrap_err()
        .to_string();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(
        err.contains("scene.toml:3: gltf `models/gone.glb`: cannot read"),
        "{err}"
    );
}

/// Files the fuzz target found (`fuzz/run.sh gltf`), kept as regressions: each is an
/// error naming what is wrong, never a panic.
#[test]
fn the_fuzzers_finds_are_errors() {
    let corpus = [(
        "missing-position-accessor.glb",
        "mesh 0 primitive 0 names accessor",
    )];
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/gltf-corpus");
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        corpus.len(),
        "every file is listed"
    );
    for (name, expected) in corpus {
        let bytes = std::fs::read(dir.join(name)).unwrap();
        let err = parse_gltf(&bytes, &NoFiles, name).map(|_| ()).unwrap_err();
        assert!(err.contains(expected), "{name}: {err}");
    }
}

/// A 2x2 PNG of `texels`, row by row from the top.
fn png_of(texels: [[u8; 4]; 4]) -> Vec<u8> {
    let mut png = Vec::new();
    image::RgbaImage::from_fn(2, 2, |x, y| image::Rgba(texels[(y * 2 + x) as usize]))
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    png
}

/// A 2x2 PNG: red, green on the top row; blue, white below.
fn quadrants_png() -> Vec<u8> {
    png_of([
        [255, 0, 0, 255],
        [0, 255, 0, 255],
        [0, 0, 255, 255],
        [255, 255, 255, 255],
    ])
}

/// The triangle with texture coordinates equal to its x and y, textured by `image`
/// (an `images` entry) through a sampler and an optional `KHR_texture_transform`.
fn textured_triangle(image: &str, texture_info_extra: &str) -> (String, Vec<u8>) {
    let mut bin = triangle_bin([0, 1, 2]);
    for v in [0.0f32, 0.0, 1.0, 0.0, 0.0, 1.0] {
        bin.extend(v.to_le_bytes());
    }
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
"extensionsUsed":["KHR_texture_transform"],
"nodes":[{{"mesh":0}}],
"meshes":[{{"name":"tri","primitives":[{{"attributes":{{"POSITION":0,"TEXCOORD_0":2}},"indices":1,"material":0}}]}}],
"materials":[{{"name":"paint","pbrMetallicRoughness":{{"baseColorFactor":[1,1,0.5,1],"baseColorTexture":{{"index":0{texture_info_extra}}}}}}}],
"textures":[{{"source":0,"sampler":0}}],
"samplers":[{{"wrapS":33071,"wrapT":33648}}],
"images":[{image}],
"buffers":[{{"byteLength":68}}],
"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36}},{{"buffer":0,"byteOffset":36,"byteLength":6}},{{"buffer":0,"byteOffset":44,"byteLength":24}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
{{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}},
{{"bufferView":2,"componentType":5126,"count":3,"type":"VEC2"}}]}}"#
    );
    (json, bin)
}

fn data_uri(png: &[u8]) -> String {
    use base64::Engine;
    let body = base64::engine::general_purpose::STANDARD.encode(png);
    format!(r#"{{"uri":"data:image/png;base64,{body}"}}"#)
}

fn accel_of(scene: &canopy_render::Scene) -> Accel {
    Accel::default_for(scene)
}

/// The ray straight down the z axis onto (x, y) of the triangle, and its hit.
fn from_above(scene: &canopy_render::Scene, x: f32, y: f32) -> (canopy_bvh::Ray, canopy_bvh::Hit) {
    use canopy_bvh::RayQuery;
    let ray = canopy_bvh::Ray::new(
        glam::Vec3::new(x, y, 1.0),
        -glam::Vec3::Z,
        0.0,
        f32::INFINITY,
    );
    let hit = accel_of(scene)
        .intersect(&ray)
        .expect("the ray meets the triangle");
    (ray, hit)
}

/// The base colour where a ray straight down the z axis meets (x, y) of the triangle.
fn base_colour_at(scene: &canopy_render::Scene, x: f32, y: f32) -> glam::Vec3 {
    let (ray, hit) = from_above(scene, x, y);
    match scene.shade(&ray, &hit).1 {
        canopy_render::material::Material::Pbr(p) => p.base_color,
        other => panic!("{other:?}"),
    }
}

#[test]
fn base_colour_textures_are_read_with_their_sampler_and_transform() {
    let (json, bin) = textured_triangle(&data_uri(&quadrants_png()), "");
    let scene = parse_gltf(&glb(&json, &bin), &NoFiles, "tri").unwrap();
    assert_eq!(scene.images.len(), 1);
    assert_eq!(scene.meshes[0].uvs.len(), 3);
    // Texel centres, times the factor (1, 1, 0.5); UV (0, 0) is the image's top left.
    let close = |a: glam::Vec3, b: glam::Vec3| (a - b).abs().max_element() < 1e-4;
    assert!(close(
        base_colour_at(&scene, 0.25, 0.25),
        glam::Vec3::new(1.0, 0.0, 0.0)
    ));
    assert!(close(
        base_colour_at(&scene, 0.75, 0.2),
        glam::Vec3::new(0.0, 1.0, 0.0)
    ));
    assert!(close(
        base_colour_at(&scene, 0.2, 0.75),
        glam::Vec3::new(0.0, 0.0, 0.5)
    ));
    // Between red and green: halfway in linear light.
    assert!(close(
        base_colour_at(&scene, 0.5, 0.25),
        glam::Vec3::new(0.5, 0.5, 0.0)
    ));
    // An offset of half the image in u: red's place now shows green (clamped at the edge).
    let (json, bin) = textured_triangle(
        &data_uri(&quadrants_png()),
        r#","extensions":{"KHR_texture_transform":{"offset":[0.5,0]}}"#,
    );
    let shifted = parse_gltf(&glb(&json, &bin), &NoFiles, "tri").unwrap();
    assert!(close(
        base_colour_at(&shifted, 0.25, 0.25),
        glam::Vec3::new(0.0, 1.0, 0.0)
    ));
    assert!(close(
        base_colour_at(&shifted, 0.7, 0.25),
        glam::Vec3::new(0.0, 1.0, 0.0)
    ));
    // A second set of texture coordinates is not read: the texture is left out, named.
    let (json, bin) = textured_triangle(&data_uri(&quadrants_png()), r#","texCoord":1"#);
    let second = parse_gltf(&glb(&json, &bin), &NoFiles, "tri").unwrap();
    assert!(close(
        base_colour_at(&second, 0.25, 0.25),
        glam::Vec3::new(1.0, 1.0, 0.5)
    ));
    assert!(
        second.warnings().iter().any(|w| w.contains("TEXCOORD_1")),
        "{:?}",
        second.warnings()
    );
}

#[test]
fn missing_and_broken_images_are_errors_that_name_them() {
    let cases = [
        (
            r#"{"uri":"textures/gone.png"}"#.to_owned(),
            "material 0 (\"paint\"): image 0: cannot read textures/gone.png",
        ),
        (data_uri(b"\x89PNG\r\n\x1a\n broken"), "image 0: cannot"),
        (data_uri(&quadrants_png()[..40]), "image 0: cannot"),
        (
            r#"{"name":"logo","bufferView":9,"mimeType":"image/png"}"#.to_owned(),
            "not a valid glTF",
        ),
    ];
    for (image, expected) in cases {
        let (json, bin) = textured_triangle(&image, "");
        let err = parse_gltf(&glb(&json, &bin), &NoFiles, "tri")
            .map(|_| ())
            .unwrap_err();
        assert!(err.contains(expected), "expected {expected:?} in: {err}");
    }
}

#[test]
fn textured_models_show_their_textures() {
    // The textured box's faces show the Cesium logo: blue, green and white texels,
    // where its factor alone would be one colour.
    let scene = load_scene(models().join("BoxTextured.glb").to_str().unwrap()).unwrap();
    assert!(scene.is_textured());
    let accel = accel_of(&scene);
    let camera = canopy_render::camera::Camera::new(&scene.camera, 64, 64);
    let mut colours = Vec::new();
    for y in 0..64 {
        for x in 0..64 {
            use canopy_bvh::RayQuery;
            let (s, t) = ((x as f32 + 0.5) / 64.0, (y as f32 + 0.5) / 64.0);
            let ray = camera.ray(s, t, &mut canopy_render::rng::Rng::for_sample(0, 0, 0));
            if let Some(hit) = accel.intersect(&ray) {
                if let canopy_render::material::Material::Pbr(p) = scene.shade(&ray, &hit).1 {
                    colours.push(p.base_color);
                }
            }
        }
    }
    let blue = colours
        .iter()
        .filter(|c| c.z > 2.0 * c.x && c.z > c.y)
        .count();
    let green = colours
        .iter()
        .filter(|c| c.y > 2.0 * c.x && c.y > c.z)
        .count();
    let white = colours.iter().filter(|c| c.min_element() > 0.7).count();
    assert!(
        blue > 50 && green > 50 && white > 50,
        "{blue} {green} {white} of {}",
        colours.len()
    );
}

/// The textured triangle with alpha mode `mode` (and `cutoff`), base colour alpha
/// `alpha`, and its texture's alpha 1 in the top half and 0 in the bottom half.
fn see_through_triangle(mode: &str, alpha: f32) -> canopy_render::Scene {
    let png = png_of([
        [255, 0, 0, 255],
        [0, 255, 0, 255],
        [0, 0, 255, 0],
        [255, 255, 255, 0],
    ]);
    let (json, bin) = textured_triangle(&data_uri(&png), "");
    let json = json
        .replace("[1,1,0.5,1]", &format!("[1,1,0.5,{alpha}]"))
        .replace(r#""name":"paint","#, &format!(r#""name":"paint",{mode}"#));
    let mut scene = parse_gltf(&glb(&json, &bin), &NoFiles, "tri").unwrap();
    (
        scene.settings.width,
        scene.settings.height,
        scene.settings.spp,
    ) = (32, 32, 16);
    scene
}

fn render_film(scene: &canopy_render::Scene) -> canopy_render::Film {
    integrator::render(scene, &accel_of(scene), &|| {}).0
}

#[test]
fn masked_surfaces_are_cut_out_by_their_alpha() {
    let masked = see_through_triangle(r#""alphaMode":"MASK","alphaCutoff":0.5,"#, 1.0);
    assert!(masked.has_see_through() && masked.warnings().iter().all(|w| !w.contains("alpha")));
    // The texture's top half stops rays, its bottom half does not (no number drawn).
    let stops = |x, y| masked.stops_ray(&from_above(&masked, x, y).1, || unreachable!());
    assert!(stops(0.25, 0.25) && !stops(0.2, 0.75));
    // Cut out everywhere (alpha factor 0), the triangle leaves the image it would have
    // without it, bit for bit, with light sampling's shadow rays and without.
    for integrator in canopy_render::Integrator::ALL {
        let mut cut = see_through_triangle(r#""alphaMode":"MASK","#, 0.0);
        cut.settings.integrator = integrator;
        let mut empty = cut.clone();
        empty.instances.clear();
        assert_eq!(
            render_film(&cut).pixels,
            render_film(&empty).pixels,
            "{integrator}"
        );
    }
}

#[test]
fn blended_surfaces_stop_a_fraction_alpha_of_rays() {
    // Half-transparent: each pixel is on average halfway between the image without the
    // triangle and the image with it opaque (top half of the texture, alpha 1 there).
    let mean_of = |scene: &canopy_render::Scene| {
        let film = render_film(scene);
        film.pixels
            .iter()
            .map(|p| p.element_sum() as f64)
            .sum::<f64>()
            / film.pixels.len() as f64
    };
    let opaque = see_through_triangle("", 1.0);
    let mut empty = opaque.clone();
    empty.instances.clear();
    let mut blended = see_through_triangle(r#""alphaMode":"BLEND","#, 0.5);
    blended.settings.spp = 256;
    // Only the opaque top half of the texture is blended at 0.5; the bottom is alpha 0.
    let mut top_opaque = see_through_triangle(r#""alphaMode":"MASK","#, 1.0);
    top_opaque.settings.spp = 256;
    let (without, with, half) = (mean_of(&empty), mean_of(&top_opaque), mean_of(&blended));
    let expected = 0.5 * (without + with);
    assert!(
        (with - without).abs() > 0.05,
        "the triangle shows: {with} vs {without}"
    );
    assert!(
        (half - expected).abs() < 0.02 * expected,
        "{half} vs {expected} ({without}, {with})"
    );
    assert!(mean_of(&opaque).is_finite());
}

#[test]
fn punctual_lights_are_placed_by_their_nodes() {
    let json = TRIANGLE
        .replace(
            r#""asset":{"version":"2.0"},"#,
            r#""asset":{"version":"2.0"},"extensionsUsed":["KHR_lights_punctual"],
"extensions":{"KHR_lights_punctual":{"lights":[{"name":"lamp","type":"spot","color":[1,0.5,0.25],"intensity":8,
"spot":{"innerConeAngle":0.2,"outerConeAngle":0.6}},{"type":"point","intensity":2,"range":5}]}},"#,
        )
        .replace(r#""scenes":[{"nodes":[0]}]"#, r#""scenes":[{"nodes":[0,1,2]}]"#)
        .replace(
            r#""nodes":[{"mesh":0}]"#,
            r#""nodes":[{"mesh":0},{"translation":[0,3,0],"rotation":[-0.70710677,0,0,0.70710677],"extensions":{"KHR_lights_punctual":{"light":0}}},
{"translation":[1,2,3],"extensions":{"KHR_lights_punctual":{"light":1}}}]"#,
        );
    let scene = parse_gltf(&glb(&json, &triangle_bin([0, 1, 2])), &NoFiles, "lit").unwrap();
    use canopy_render::lights::PunctualLight;
    let [PunctualLight::Spot {
        position,
        direction,
        intensity,
        cos_inner,
        cos_outer,
    }, PunctualLight::Point { position: p, .. }] = scene.lights[..]
    else {
        panic!("{:?}", scene.lights);
    };
    assert!((position - glam::Vec3::new(0.0, 3.0, 0.0)).length() < 1e-6);
    assert!(
        (direction - glam::Vec3::NEG_Y).length() < 1e-6,
        "shines down its node's −z: {direction}"
    );
    assert_eq!(intensity, glam::Vec3::new(8.0, 4.0, 2.0));
    assert!((cos_inner - 0.2f32.cos()).abs() < 1e-6 && (cos_outer - 0.6f32.cos()).abs() < 1e-6);
    assert_eq!(p, glam::Vec3::new(1.0, 2.0, 3.0));
    let warnings = scene.warnings().join("\n");
    assert!(
        warnings.contains("light 1: its range is not used"),
        "{warnings}"
    );
    // A spot light whose cones are the wrong way round is refused, named.
    let bad = json.replace(r#""innerConeAngle":0.2"#, r#""innerConeAngle":0.7"#);
    let err = parse_gltf(&glb(&bad, &triangle_bin([0, 1, 2])), &NoFiles, "lit")
        .map(|_| ())
        .unwrap_err();
    assert!(
        err.contains("node 1: light 0 (\"lamp\"): a spot light's outer cone"),
        "{err}"
    );
}

/// The textured triangle (u along +x, v along +y) with a normal map of one `texel`
/// everywhere; returns the shading normal a ray from above meets.
fn normal_mapped_at_centre(texel: [u8; 4], tangents: bool) -> glam::Vec3 {
    let (json, mut bin) = textured_triangle(&data_uri(&png_of([texel; 4])), "");
    let mut json = json.replace(
        r#""pbrMetallicRoughness":"#,
        r#""normalTexture":{"index":0,"scale":1},"pbrMetallicRoughness":"#,
    );
    if tangents {
        // The file's own tangents, as an exporter writes them for this triangle: +x (u),
        // and handedness −1, since cross(normal, tangent) = +y is down the image here.
        for _ in 0..3 {
            for v in [1.0f32, 0.0, 0.0, -1.0] {
                bin.extend(v.to_le_bytes());
            }
        }
        json = json
            .replace(r#""TEXCOORD_0":2}"#, r#""TEXCOORD_0":2,"TANGENT":3}"#)
            .replace(r#""byteLength":68}]"#, r#""byteLength":116}]"#)
            .replace(
                r#"{"buffer":0,"byteOffset":44,"byteLength":24}]"#,
                r#"{"buffer":0,"byteOffset":44,"byteLength":24},{"buffer":0,"byteOffset":68,"byteLength":48}]"#,
            )
            .replace(
                r#""count":3,"type":"VEC2"}]"#,
                r#""count":3,"type":"VEC2"},{"bufferView":3,"componentType":5126,"count":3,"type":"VEC4"}]"#,
            );
    }
    let scene = parse_gltf(&glb(&json, &bin), &NoFiles, "tri").unwrap();
    assert_eq!(
        scene.meshes[0].tangents.len(),
        1,
        "tangents for the one triangle"
    );
    let (ray, hit) = from_above(&scene, 0.25, 0.25);
    scene.shade(&ray, &hit).0.shading_normal
}

#[test]
fn normal_maps_bend_the_shading_normal_in_the_tangent_frame() {
    for tangents in [false, true] {
        // A flat map leaves the normal as it is.
        let flat = normal_mapped_at_centre([128, 128, 255, 255], tangents);
        assert!((flat - glam::Vec3::Z).length() < 0.01, "{flat}");
        // +X of the map is the tangent: along +u, here +x.
        let along_u = normal_mapped_at_centre([218, 128, 218, 255], tangents);
        assert!(
            along_u.x > 0.5 && along_u.y.abs() < 0.01 && along_u.z > 0.5,
            "{along_u}"
        );
        // +Y of the map points up its image, towards smaller v: here −y.
        let up_image = normal_mapped_at_centre([128, 218, 218, 255], tangents);
        assert!(
            up_image.y < -0.5 && up_image.x.abs() < 0.01,
            "{tangents}: {up_image}"
        );
    }
}

#[test]
fn emission_is_its_factor_times_strength_times_texture_beside_reflection() {
    let (json, bin) = textured_triangle(&data_uri(&quadrants_png()), "");
    let json = json
        .replace(
            r#""name":"paint","#,
            r#""name":"paint","emissiveFactor":[1,0.5,0.25],"emissiveTexture":{"index":0},
"extensions":{"KHR_materials_emissive_strength":{"emissiveStrength":4}},"#,
        )
        .replace(
            r#""extensionsUsed":["KHR_texture_transform"]"#,
            r#""extensionsUsed":["KHR_texture_transform","KHR_materials_emissive_strength"]"#,
        );
    let scene = parse_gltf(&glb(&json, &bin), &NoFiles, "glow").unwrap();
    assert!(
        scene.warnings().iter().all(|w| !w.contains("emissi")),
        "{:?}",
        scene.warnings()
    );
    // Red and green quadrants of the texture (clamped in s, mirrored in t).
    for (x, y, expected) in [(0.2, 0.2, [4.0, 0.0, 0.0]), (0.75, 0.1, [0.0, 2.0, 0.0])] {
        let (ray, hit) = from_above(&scene, x, y);
        let (_, material) = scene.shade(&ray, &hit);
        assert_eq!(
            material.emitted(),
            glam::Vec3::from(expected),
            "at ({x}, {y})"
        );
        // It still reflects: a metallic-roughness surface that also glows.
        assert!(matches!(
            material,
            canopy_render::material::Material::Pbr(_)
        ));
        // Light sampling reads the same emission at the same point.
        let index = scene.material_index(&hit);
        let sampled = scene.emitted_at(index, hit.inst, hit.prim, hit.u, hit.v);
        assert_eq!(sampled, material.emitted());
    }
}

#[test]
fn orthographic_cameras_are_used() {
    let json = TRIANGLE.replace(
        r#""scenes":[{"nodes":[0]}],
"nodes":[{"mesh":0}],"#,
        r#""scenes":[{"nodes":[0,1]}],
"nodes":[{"mesh":0},{"camera":0,"translation":[0.3,0.3,5]}],
"cameras":[{"type":"orthographic","orthographic":{"xmag":1,"ymag":0.5,"znear":0.01,"zfar":100}}],"#,
    );
    assert_ne!(json, TRIANGLE);
    let scene = parse_gltf(&glb(&json, &triangle_bin([0, 1, 2])), &NoFiles, "ortho").unwrap();
    let camera = scene.camera;
    assert_eq!(camera.ortho_height, Some(1.0));
    assert_eq!(camera.look_from, glam::Vec3::new(0.3, 0.3, 5.0));
    assert_eq!(
        (camera.look_at - camera.look_from).normalize(),
        -glam::Vec3::Z
    );
    // The image takes the view's aspect (xmag / ymag).
    let settings = scene.settings;
    assert_eq!(settings.width, 2 * settings.height);
    // Every camera ray runs straight down -z: the middle one meets the triangle at
    // (0.3, 0.3), a corner ray misses it.
    let view = canopy_render::camera::Camera::new(&camera, settings.width, settings.height);
    let mut rng = canopy_render::rng::Rng::for_sample(0, 0, 0);
    let accel = accel_of(&scene);
    use canopy_bvh::RayQuery;
    let middle = view.ray(0.5, 0.5, &mut rng);
    assert_eq!(middle.dir, -glam::Vec3::Z);
    let hit = accel
        .intersect(&middle)
        .expect("the middle ray meets the triangle");
    assert!((middle.at(hit.t) - glam::Vec3::new(0.3, 0.3, 0.0)).length() < 1e-5);
    assert!(accel.intersect(&view.ray(0.95, 0.5, &mut rng)).is_none());
}

/// The triangle with its positions' accessor made sparse: `sparse` is the accessor's
/// "sparse" member, `base_view` whether it keeps its dense view; the binary chunk adds
/// u16 sparse indices `indices` (bytes 44..) and vec3 values (bytes 48.. then).
fn sparse_triangle(sparse: &str, base_view: bool, indices: &[u16], values: &[[f32; 3]]) -> Vec<u8> {
    let mut bin = triangle_bin([0, 1, 2]);
    for i in indices {
        bin.extend(i.to_le_bytes());
    }
    while bin.len() < 48 {
        bin.push(0);
    }
    for v in values.iter().flatten() {
        bin.extend(v.to_le_bytes());
    }
    let base = match base_view {
        true => r#""bufferView":0,"#,
        false => "",
    };
    let json = TRIANGLE
        .replace(r#""byteLength":44}]"#, &format!(r#""byteLength":{}}}]"#, bin.len()))
        .replace(
            r#"{"buffer":0,"byteOffset":36,"byteLength":6}]"#,
            &format!(
                r#"{{"buffer":0,"byteOffset":36,"byteLength":6}},{{"buffer":0,"byteOffset":44,"byteLength":{}}},{{"buffer":0,"byteOffset":48,"byteLength":{}}}]"#,
                (indices.len() * 2).max(1),
                (values.len() * 12).max(1)
            ),
        )
        .replace(
            r#""accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}"#,
            &format!(
                r#""accessors":[{{{base}"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,2,0],"sparse":{sparse}}}"#
            ),
        );
    glb(&json, &bin)
}

const ONE_SUBSTITUTION: &str =
    r#"{"count":1,"indices":{"bufferView":2,"componentType":5123},"values":{"bufferView":3}}"#;

#[test]
fn sparse_accessors_substitute_their_values() {
    let vertices = |file: Vec<u8>| {
        let scene = parse_gltf(&file, &NoFiles, "sparse").unwrap();
        scene.meshes[0].mesh.vertices().to_vec()
    };
    // Vertex 2 of the dense positions moved up.
    let moved = sparse_triangle(ONE_SUBSTITUTION, true, &[2], &[[0.0, 2.0, 0.0]]);
    assert_eq!(
        vertices(moved),
        [
            glam::Vec3::ZERO,
            glam::Vec3::X,
            glam::Vec3::new(0.0, 2.0, 0.0)
        ]
    );
    // Without a dense view the base is zeros.
    let two = ONE_SUBSTITUTION.replace(r#""count":1"#, r#""count":2"#);
    let zeros = sparse_triangle(&two, false, &[1, 2], &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    assert_eq!(
        vertices(zeros),
        [glam::Vec3::ZERO, glam::Vec3::X, glam::Vec3::Y]
    );
}

#[test]
fn broken_sparse_accessors_are_errors_that_name_them() {
    let error = |file: Vec<u8>| {
        parse_gltf(&file, &NoFiles, "sparse")
            .unwrap_err()
            .to_string()
    };
    let two = ONE_SUBSTITUTION.replace(r#""count":1"#, r#""count":2"#);
    let cases = [
        // An index past the accessor's three elements.
        (
            sparse_triangle(ONE_SUBSTITUTION, true, &[3], &[[0.0; 3]]),
            "sparse index 0 is 3",
        ),
        // Indices that do not rise.
        (
            sparse_triangle(&two, true, &[2, 1], &[[0.0; 3]; 2]),
            "sparse index 1 is 1",
        ),
        // More substitutions than elements.
        (
            sparse_triangle(
                &ONE_SUBSTITUTION.replace(r#""count":1"#, r#""count":4"#),
                true,
                &[0, 1, 2, 3],
                &[[0.0; 3]; 4],
            ),
            "sparse count 4 is not within 1..=3",
        ),
        // Values past their view.
        (
            sparse_triangle(&two, true, &[0, 1], &[[0.0; 3]]),
            "sparse values: 2 elements",
        ),
    ];
    for (file, expected) in cases {
        let message = error(file);
        assert!(
            message.contains("positions accessor 0") && message.contains(expected),
            "{message}"
        );
    }
}
