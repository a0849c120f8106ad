//! Wavefront OBJ through tobj: every object and group merged into one mesh.

use super::{MeshData, MeshError};
use glam::Vec3;

pub(super) fn parse(bytes: &[u8]) -> Result<MeshData, MeshError> {
    check_faces(bytes)?;
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

/// Checks what tobj accepts silently: every face has at least three vertices, and
/// either every face gives vertex normals or none does.
fn check_faces(bytes: &[u8]) -> Result<(), MeshError> {
    // The first face's line, and whether it gave normals.
    let mut first: Option<(usize, bool)> = None;
    for (i, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let line = i + 1;
        let text = String::from_utf8_lossy(raw);
        let mut words = text.split_whitespace();
        if words.next() != Some("f") {
            continue;
        }
        let refs: Vec<&str> = words.take_while(|w| !w.starts_with('#')).collect();
        if refs.len() < 3 {
            return Err(MeshError::AtLine {
                line,
                message: format!(
                    "a face needs at least 3 vertices, this one has {}",
                    refs.len()
                ),
            });
        }
        // `v//vn` or `v/vt/vn` give a normal; `v` and `v/vt` do not.
        let with = refs
            .iter()
            .filter(|r| r.split('/').nth(2).is_some_and(|n| !n.is_empty()))
            .count();
        if with != 0 && with != refs.len() {
            return Err(MeshError::AtLine {
                line,
                message: "some vertices of this face give a normal and some do not".into(),
            });
        }
        match first {
            None => first = Some((line, with != 0)),
            Some((first_line, normals)) if normals != (with != 0) => {
                let (this, that) = if normals {
                    ("no vertex normals", "does")
                } else {
                    ("vertex normals", "does not")
                };
                return Err(MeshError::AtLine {
                    line,
                    message: format!(
                        "this face gives {this} but the face on line {first_line} {that}; give normals for every face or for none"
                    ),
                });
            }
            Some(_) => {}
        }
    }
    Ok(())
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

    #[test]
    fn a_face_of_two_vertices_is_reported_with_its_line() {
        let src = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\n";
        assert_eq!(
            parse(src),
            Err(MeshError::AtLine {
                line: 5,
                message: "a face needs at least 3 vertices, this one has 2".into()
            })
        );
    }

    #[test]
    fn faces_mixing_normals_are_reported_with_both_lines() {
        let src = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\nf 1 2 3\n";
        let e = parse(src).unwrap_err().to_string();
        assert!(
            e.contains("line 6")
                && e.contains("line 5")
                && e.contains("for every face or for none"),
            "{e}"
        );
        let src = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2 3//1\n";
        let e = parse(src).unwrap_err().to_string();
        assert!(e.contains("line 5") && e.contains("some vertices"), "{e}");
        // Texture coordinates alone are not normals.
        let src = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1\nf 1 2 3\n";
        assert!(parse(src).is_ok());
    }
}
