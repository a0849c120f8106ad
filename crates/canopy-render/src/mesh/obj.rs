//! Wavefront OBJ through tobj: every object and group merged into one mesh.

use super::{MeshData, MeshError};
use glam::Vec3;

pub(super) fn parse(bytes: &[u8]) -> Result<MeshData, MeshError> {
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..tobj::LoadOptions::default()
    };
    let mut reader = std::io::BufReader::new(bytes);
    // Materials come from the scene, not from .mtl files, so none are loaded.
    let (models, _) = tobj::load_obj_buf(&mut reader, &options, |_| {
        Err(tobj::LoadError::OpenFileFailed)
    })
    .map_err(|e| MeshError::Invalid(format!("not a valid OBJ file: {e}")))?;

    let mut mesh = MeshData::default();
    let with_normals = models.iter().all(|m| !m.mesh.normals.is_empty());
    for model in &models {
        let m = &model.mesh;
        let base = mesh.positions.len() as u32;
        mesh.positions
            .extend(m.positions.chunks_exact(3).map(Vec3::from_slice));
        if with_normals {
            mesh.normals
                .extend(m.normals.chunks_exact(3).map(Vec3::from_slice));
        }
        mesh.triangles.extend(
            m.indices
                .chunks_exact(3)
                .map(|t| [base + t[0], base + t[1], base + t[2]]),
        );
    }
    if mesh.triangles.is_empty() {
        return Err(MeshError::Invalid("OBJ file has no faces".into()));
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quad_is_triangulated() {
        let src = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";
        let m = parse(src).unwrap();
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.triangles.len(), 2);
    }

    #[test]
    fn normals_are_kept() {
        let src = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n";
        let m = parse(src).unwrap();
        assert_eq!(m.normals, vec![Vec3::Z; 3]);
    }

    #[test]
    fn file_without_faces_is_an_error() {
        assert!(parse(b"v 0 0 0\n").is_err());
    }

    #[test]
    fn garbage_is_an_error_not_a_panic() {
        assert!(parse(b"f 1 2 3\n").is_err());
        assert!(parse(&[0xff, 0xfe, 0x00, 0x12]).is_err());
    }
}
