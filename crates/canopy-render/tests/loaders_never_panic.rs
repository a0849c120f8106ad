//! Loaders return an error or a valid result for broken input; they never panic.
//! Mutations (overwritten bytes, truncation) of real files, and hand-picked hostile cases.

use canopy_render::mesh::{parse_mesh, MeshFormat};
use canopy_render::scene_file::{parse_scene, Assets};
use proptest::prelude::*;

struct NoAssets;

impl Assets for NoAssets {
    fn read(&self, path: &str) -> Result<Vec<u8>, String> {
        Err(format!("{path}: no files in this test"))
    }
}

const OBJ: &[u8] = include_bytes!("../../../scenes/meshes/teapot.obj");
const PLY: &[u8] = include_bytes!("../../../scenes/meshes/teapot.ply");
const TOML: &str = include_str!("../../../scenes/cornell.toml");

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
    #![proptest_config(ProptestConfig::with_cases(1000))]

    #[test]
    fn mutated_obj(edits in edits(), keep in any::<usize>()) {
        let _ = parse_mesh(&mutate(OBJ, &edits, keep), MeshFormat::Obj);
    }

    #[test]
    fn mutated_binary_ply(edits in edits(), keep in any::<usize>()) {
        if let Ok(mesh) = parse_mesh(&mutate(PLY, &edits, keep), MeshFormat::Ply) {
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
fn hostile_obj_files_are_errors() {
    let cases = [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n", "out of bounds"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -5 1 2\n", "out of bounds"),
        ("v 0 0 0\nf 0 0 0\n", "out of bounds"),
        (
            "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            "vertex 0 has a non-finite coordinate",
        ),
        (
            "v 1e39 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            "vertex 0 has a non-finite coordinate",
        ),
        ("f\n", "invalid polygon"),
        ("", "no faces"),
    ];
    for (src, expected) in cases {
        let err = parse_mesh(src.as_bytes(), MeshFormat::Obj)
            .unwrap_err()
            .to_string();
        assert!(err.contains(expected), "{src:?}: {err}");
    }
}
