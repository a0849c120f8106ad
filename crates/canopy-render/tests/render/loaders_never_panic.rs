//! Loaders return an error or a valid result for broken input; they never panic, hang or
//! allocate from a count the file cannot back. Mutations (overwritten bytes, truncation)
//! of valid files in every format, arbitrary bytes, and a corpus of hostile files
//! (`tests/corpus/`) kept as regression tests.
//!
//! `CANOPY_FUZZ_CASES=100000 cargo test --release -p canopy-render --test
//! loaders_never_panic` runs the generated cases longer than CI does (1000 per property).

use canopy_render::mesh::{parse_mesh, MeshFormat};
use canopy_render::scene_file::{parse_scene, Assets};
use proptest::prelude::*;

struct NoAssets;

impl Assets for NoAssets {
    fn read(&self, path: &str) -> Result<Vec<u8>, String> {
        Err(format!("{path}: no files in this test"))
    }
}

const OBJ: &[u8] = include_bytes!("../../../../scenes/meshes/teapot.obj");
const PLY: &[u8] = include_bytes!("../../../../scenes/meshes/teapot.ply");
const TOML: &str = include_str!("../../../../scenes/cornell.toml");

/// A small valid PLY in each encoding: ASCII with normals and an extra element, and
/// binary big-endian (the teapot above is little-endian).
fn ply_seeds() -> [Vec<u8>; 2] {
    let ascii = b"ply\nformat ascii 1.0\ncomment seed\nelement vertex 4\nproperty float x\nproperty float y\n\
property float z\nproperty float nx\nproperty float ny\nproperty float nz\nelement face 2\n\
property list uchar int vertex_indices\nelement edge 1\nproperty int a\nproperty int b\nend_header\n\
0 0 0 0 0 1\n1 0 0 0 0 1\n1 1 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n4 0 1 2 3\n0 1\n"
        .to_vec();
    let mut big = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\n\
property double z\nelement face 1\nproperty list uchar ushort vertex_indices\nend_header\n"
        .to_vec();
    for c in [0.0f64, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        big.extend(c.to_be_bytes());
    }
    big.push(3);
    for i in [0u16, 1, 2] {
        big.extend(i.to_be_bytes());
    }
    [ascii, big]
}

/// Generated cases per property: `CANOPY_FUZZ_CASES`, else 1000.
fn cases() -> u32 {
    std::env::var("CANOPY_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1000)
}

/// `base` with some bytes overwritten, then cut to at most `keep` bytes.
fn mutate(base: &[u8], edits: &[(usize, u8)], keep: usize) -> Vec<u8> {
    let mut v = base.to_vec();
    let n = v.len();
    for &(i, b) in edits {
        v[i % n] = b;
    }
    v.truncate(keep % (n + 1));
    v
}

fn edits() -> impl Strategy<Value = Vec<(usize, u8)>> {
    prop::collection::vec((any::<usize>(), any::<u8>()), 0..8)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    #[test]
    fn mutated_obj(edits in edits(), keep in any::<usize>()) {
        // Every broken OBJ file is reported with its line, or as having no faces.
        if let Err(e) = parse_mesh(&mutate(OBJ, &edits, keep), MeshFormat::Obj) {
            let named = matches!(e, canopy_render::mesh::MeshError::AtLine { .. });
            prop_assert!(named || e.to_string().contains("no faces"), "{e}");
        }
    }

    #[test]
    fn mutated_binary_ply(edits in edits(), keep in any::<usize>()) {
        if let Ok(mesh) = parse_mesh(&mutate(PLY, &edits, keep), MeshFormat::Ply) {
            prop_assert!(mesh.validate().is_ok());
        }
    }

    #[test]
    fn mutated_ascii_and_big_endian_ply(edits in edits(), keep in any::<usize>(), which in 0usize..2) {
        let seed = &ply_seeds()[which];
        if let Ok(mesh) = parse_mesh(&mutate(seed, &edits, keep), MeshFormat::Ply) {
            prop_assert!(mesh.validate().is_ok());
        }
    }

    #[test]
    fn mutated_scene(edits in edits(), keep in any::<usize>()) {
        if let Ok(text) = String::from_utf8(mutate(TOML.as_bytes(), &edits, keep)) {
            let _ = parse_scene(&text, "mutated.toml", &NoAssets);
        }
    }

    #[test]
    fn arbitrary_bytes(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        let _ = parse_mesh(&bytes, MeshFormat::Obj);
        let _ = parse_mesh(&bytes, MeshFormat::Ply);
        let mut with_header = b"ply\nformat binary_little_endian 1.0\n".to_vec();
        with_header.extend(&bytes);
        let _ = parse_mesh(&with_header, MeshFormat::Ply);
    }
}

#[test]
fn seeds_are_valid() {
    for seed in ply_seeds() {
        let mesh = parse_mesh(&seed, MeshFormat::Ply).unwrap();
        assert!(!mesh.triangles.is_empty());
    }
}

/// The corpus of nasty files, each with (part of) the error it must give.
#[test]
fn corpus_files_give_their_errors() {
    let corpus = [
        (
            "huge-vertex-count.ply",
            "header declares 4000000000 `vertex` elements",
        ),
        ("huge-list-length.ply", "past the end of the file"),
        ("index-out-of-range.ply", "refers to vertex 7"),
        ("nan-coordinate.ply", "non-finite coordinate"),
        ("inf-coordinate-big-endian.ply", "non-finite coordinate"),
        ("truncated-body.ply", "ends in the middle"),
        (
            "wrong-property-type.ply",
            "unknown property type `quaternion`",
        ),
        ("negative-index-ascii.ply", "not a valid index"),
        ("fractional-count-ascii.ply", "not an integer"),
        ("non-utf8-header.ply", "not text"),
        ("empty.ply", "no `end_header`"),
        ("no-faces.ply", "needs both"),
        ("unknown-format.ply", "unknown PLY format"),
        ("empty.obj", "no faces"),
        (
            "index-out-of-range.obj",
            "line 4: vertex index 9 is out of bounds",
        ),
        (
            "nan-vertex.obj",
            "line 1: a vertex has a non-finite coordinate `nan`",
        ),
        ("non-utf8.obj", "not UTF-8"),
    ];
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        corpus.len(),
        "every corpus file is listed here"
    );
    for (name, expected) in corpus {
        let bytes = std::fs::read(dir.join(name)).unwrap();
        let format = MeshFormat::from_path(name).unwrap();
        let err = parse_mesh(&bytes, format)
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(err.contains(expected), "{name}: {err}");
    }
}

#[test]
fn hostile_obj_files_are_errors() {
    let cases = [
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n",
            "line 4: vertex index 99 is out of bounds",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -5 1 2\n",
            "line 4: vertex index -5 is out of bounds",
        ),
        (
            "v 0 0 0\nf 0 0 0\n",
            "line 2: vertex index 0 is out of bounds",
        ),
        (
            "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            "line 1: a vertex has a non-finite coordinate",
        ),
        (
            "v 1e39 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            "line 1: a vertex has a non-finite coordinate",
        ),
        (
            "f\n",
            "line 1: a face needs at least 3 vertices, this one has 0",
        ),
        (
            "v 0 0 0\nv 1 0 0\nf 1 2\n",
            "line 3: a face needs at least 3 vertices, this one has 2",
        ),
        ("", "no faces"),
    ];
    for (src, expected) in cases {
        let err = parse_mesh(src.as_bytes(), MeshFormat::Obj)
            .unwrap_err()
            .to_string();
        assert!(err.contains(expected), "{src:?}: {err}");
    }
}

/// The fuzzers' committed seeds of the binary formats are valid files of today's readers
/// (a seed that no longer reads teaches the fuzzer nothing: an old checkpoint seed had
/// rotted into a version this canopy refuses).
#[test]
fn fuzz_seeds_read() {
    let seeds = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/seeds");
    let files = |target: &str| {
        let mut found: Vec<_> = std::fs::read_dir(seeds.join(target))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        found.sort();
        assert!(!found.is_empty(), "no seeds for {target}");
        found
    };
    for path in files("checkpoint") {
        let bytes = std::fs::read(&path).unwrap();
        canopy_render::checkpoint::Checkpoint::from_bytes(&bytes)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    }
    for path in files("gltf") {
        let bytes = std::fs::read(&path).unwrap();
        canopy_render::gltf_scene::parse_gltf(&bytes, &NoAssets, "seed")
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    }
    for target in ["environment_hdr", "environment_exr"] {
        for path in files(target) {
            let bytes = std::fs::read(&path).unwrap();
            let name = path.file_name().unwrap().to_string_lossy();
            canopy_render::background::decode_environment(&name, &bytes, glam::Mat3::IDENTITY, 1.0)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        }
    }
}
