//! Wavefront OBJ through tobj: every object and group merged into one mesh.

use super::{MeshData, MeshError};
use glam::Vec3;

pub(super) fn parse(bytes: &[u8]) -> Result<MeshData, MeshError> {
    check_lines(bytes)?;
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

/// Checks every line tobj reads, so that a broken file is reported with its line (tobj's
/// own errors name none), and what tobj accepts silently: every face has at least three
/// vertices, every reference names a vertex that exists, and either every face gives
/// vertex normals or none does.
fn check_lines(bytes: &[u8]) -> Result<(), MeshError> {
    let mut counts = Counts::default();
    // The first face's line, and whether it gave normals.
    let mut first: Option<(usize, bool)> = None;
    for (i, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let line = i + 1;
        let at = |message: String| MeshError::AtLine { line, message };
        let text = std::str::from_utf8(raw).map_err(|_| at("the line is not UTF-8 text".into()))?;
        let mut words = text.split_whitespace();
        match words.next() {
            Some("v") => {
                check_vertex(words).map_err(at)?;
                counts.read[0] += 1;
            }
            Some("vt") => {
                check_numbers(&mut words, 2, "a texture coordinate", "u v").map_err(at)?;
                counts.read[1] += 1;
            }
            Some("vn") => {
                check_numbers(&mut words, 3, "a normal", "x y z").map_err(at)?;
                counts.read[2] += 1;
            }
            Some("o" | "g") => counts.end_object()?,
            Some(kind @ ("f" | "l")) => {
                let refs: Vec<&str> = words.collect();
                if kind == "f" && refs.len() < 3 {
                    return Err(at(format!(
                        "a face needs at least 3 vertices, this one has {}",
                        refs.len()
                    )));
                }
                for r in &refs {
                    counts.check_reference(r, line)?;
                }
                if kind == "l" {
                    continue;
                }
                let with = refs
                    .iter()
                    .filter(|r| r.split('/').nth(2).is_some_and(|n| !n.is_empty()))
                    .count();
                check_normals_agree(&mut first, line, with, refs.len())?;
            }
            _ => {}
        }
    }
    counts.end_object()
}

/// `v//vn` or `v/vt/vn` give a normal; `v` and `v/vt` do not. A face gives normals at
/// all its vertices or at none, and so does every face of the file.
fn check_normals_agree(
    first: &mut Option<(usize, bool)>,
    line: usize,
    with: usize,
    of: usize,
) -> Result<(), MeshError> {
    let at = |message: String| MeshError::AtLine { line, message };
    if with != 0 && with != of {
        return Err(at(
            "some vertices of this face give a normal and some do not".into(),
        ));
    }
    match *first {
        None => *first = Some((line, with != 0)),
        Some((first_line, normals)) if normals != (with != 0) => {
            let (this, that) = if normals {
                ("no vertex normals", "does")
            } else {
                ("vertex normals", "does not")
            };
            return Err(at(format!(
                "this face gives {this} but the face on line {first_line} {that}; give normals for every face or for none"
            )));
        }
        Some(_) => {}
    }
    Ok(())
}

/// The first `n` words are finite numbers (tobj reads the rest, if any, as a weight or
/// a colour).
fn check_numbers<'a>(
    words: &mut impl Iterator<Item = &'a str>,
    n: usize,
    what: &str,
    names: &str,
) -> Result<(), String> {
    for k in 0..n {
        let Some(word) = words.next() else {
            return Err(format!(
                "{what} needs {n} numbers ({names}), this one has {k}"
            ));
        };
        match word.parse::<f32>() {
            Ok(v) if v.is_finite() => {}
            Ok(_) => return Err(format!("{what} has a non-finite coordinate `{word}`")),
            Err(_) => return Err(format!("{what}: `{word}` is not a number")),
        }
    }
    Ok(())
}

/// A vertex: `x y z`, then nothing, a non-zero weight `w` or a colour `r g b`.
fn check_vertex<'a>(mut words: impl Iterator<Item = &'a str>) -> Result<(), String> {
    check_numbers(&mut words, 3, "a vertex", "x y z")?;
    let rest: Vec<&str> = words.collect();
    match rest[..] {
        [] | [_, _, _] => Ok(()),
        [w] => match w.parse::<f32>() {
            Ok(w) if w != 0.0 && w.is_finite() => Ok(()),
            _ => Err(format!("a vertex's weight `{w}` must be a non-zero number")),
        },
        _ => Err(format!(
            "a vertex has x y z and then a weight w or a colour r g b, not {} more numbers",
            rest.len()
        )),
    }
}

/// Vertices, texture coordinates and normals read so far, and the largest absolute
/// reference of the current object's faces with its line: tobj resolves a positive
/// reference when the object ends (at `o`, `g` or the end of the file), a negative one
/// against what was read before the face.
#[derive(Default)]
struct Counts {
    read: [usize; 3],
    /// Per kind: the largest positive reference of this object, and its line.
    pending: [(usize, usize); 3],
}

const KINDS: [&str; 3] = ["vertex", "texture coordinate", "normal"];

impl Counts {
    /// One `v`, `v/vt`, `v//vn` or `v/vt/vn` reference of a face on `line`.
    fn check_reference(&mut self, reference: &str, line: usize) -> Result<(), MeshError> {
        let at = |message: String| MeshError::AtLine { line, message };
        let parts: Vec<&str> = reference.split('/').collect();
        if parts.len() > 3 || parts[0].is_empty() {
            return Err(at(format!("`{reference}` is not a vertex reference")));
        }
        for (kind, part) in parts.iter().enumerate() {
            if part.is_empty() {
                continue;
            }
            let Ok(index) = part.parse::<i64>() else {
                return Err(at(format!("`{reference}` is not a vertex reference")));
            };
            let read = self.read[kind];
            let name = KINDS[kind];
            // tobj ignores texture and normal references in a file without any.
            if kind > 0 && read == 0 && index < 0 {
                continue;
            }
            match index {
                0 => {
                    return Err(at(format!(
                        "{name} index 0 is out of bounds (OBJ counts from 1)"
                    )))
                }
                i if i < 0 && i.unsigned_abs() as usize > read => {
                    return Err(at(format!(
                        "{name} index {i} is out of bounds: only {read} were read before it"
                    )))
                }
                i if i > 0 && i as usize > self.pending[kind].0 => {
                    self.pending[kind] = (i as usize, line)
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// The object's faces referred to what exists when it ends.
    fn end_object(&mut self) -> Result<(), MeshError> {
        let pending = std::mem::take(&mut self.pending);
        for (kind, ((index, line), (name, read))) in pending
            .into_iter()
            .zip(KINDS.iter().zip(self.read))
            .enumerate()
        {
            // tobj ignores texture and normal references in a file without any.
            let ignored = kind > 0 && read == 0;
            if index > read && !ignored {
                return Err(MeshError::AtLine {
                    line,
                    message: format!(
                        "{name} index {index} is out of bounds: the file has {read} {}",
                        if kind == 0 { "vertices" } else { "of them" }
                    ),
                });
            }
        }
        Ok(())
    }
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

    #[test]
    fn broken_lines_are_reported_with_their_line() {
        let cases: [(&[u8], &str); 10] = [
            (
                b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
                "line 4: vertex index 9 is out of bounds: the file has 3 vertices",
            ),
            (
                b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -5 1 2\n",
                "line 4: vertex index -5 is out of bounds",
            ),
            (
                b"v 0 0 0\nf 0 1 1\n",
                "line 2: vertex index 0 is out of bounds",
            ),
            (
                b"v 0 0 0\nv 1 x 0\n",
                "line 2: a vertex: `x` is not a number",
            ),
            (
                b"v 0 0 0\nv 1 nan 0\n",
                "line 2: a vertex has a non-finite coordinate `nan`",
            ),
            (
                b"v 0 0 0\nv 1 1e39 0\n",
                "line 2: a vertex has a non-finite coordinate",
            ),
            (
                b"v 0 0\n",
                "line 1: a vertex needs 3 numbers (x y z), this one has 2",
            ),
            (
                b"v 0 0 0 0\n",
                "line 1: a vertex's weight `0` must be a non-zero number",
            ),
            (
                b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3/x\n",
                "line 4: `3/x` is not a vertex reference",
            ),
            (
                b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//2\n",
                "line 5: normal index 2 is out of bounds: the file has 1 of them",
            ),
        ];
        for (src, expected) in cases {
            let e = parse(src).unwrap_err().to_string();
            assert!(e.contains(expected), "{expected}: {e}");
        }
        // A reference to a vertex read later in the same object is what tobj accepts.
        assert!(parse(b"f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n").is_ok());
        // Texture references in a file without texture coordinates are ignored, as
        // tobj ignores them.
        assert!(parse(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2/1 3/-1\n").is_ok());
    }
}
