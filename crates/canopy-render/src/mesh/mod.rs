//! Triangle meshes from files: OBJ (via tobj) and PLY (ASCII and binary).

mod obj;
mod ply;
pub mod tangents;

use glam::{Mat4, Vec3};
use thiserror::Error;

/// An indexed triangle mesh as read from a file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshData {
    pub positions: Vec<Vec3>,
    /// Per-vertex normals: empty, or one per position.
    pub normals: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
}

/// What is wrong with a mesh file. The caller adds the file name.
#[derive(Debug, Error, PartialEq)]
pub enum MeshError {
    #[error("unsupported mesh format `{0}` (expected .obj or .ply)")]
    UnsupportedFormat(String),
    #[error("line {line}: {message}")]
    AtLine { line: usize, message: String },
    #[error("{0}")]
    Invalid(String),
}

/// Mesh file formats canopy reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    Obj,
    Ply,
}

impl MeshFormat {
    /// The format named by a file's extension.
    pub fn from_path(path: &str) -> Result<Self, MeshError> {
        let ext = std::path::Path::new(path)
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        match ext.as_str() {
            "obj" => Ok(MeshFormat::Obj),
            "ply" => Ok(MeshFormat::Ply),
            _ => Err(MeshError::UnsupportedFormat(ext)),
        }
    }
}

impl MeshFormat {
    /// Most bytes of memory loading a file of this format takes per byte of it, at the
    /// peak: the file's bytes, the parser's own records and the mesh it makes, for the
    /// files that cost the most per byte (fans of one-character references; PLY
    /// one-byte counts and indices). Measured by `tests/memory_bounds.rs`, with room.
    pub fn load_bytes_per_file_byte(self) -> u64 {
        match self {
            // Measured: 27 (a fan), 22 (one-digit triangles), 15 (short vertices).
            MeshFormat::Obj => 40,
            // Measured: 18 (binary fans of one-byte indices), 13 (an ASCII fan).
            MeshFormat::Ply => 28,
        }
    }
}

/// Parses a mesh from the bytes of a file and checks it.
pub fn parse_mesh(bytes: &[u8], format: MeshFormat) -> Result<MeshData, MeshError> {
    crate::files::check_memory(
        (bytes.len() as u64).saturating_mul(format.load_bytes_per_file_byte()),
        crate::files::available_memory(),
        &format!("loading a mesh file of {} MiB", bytes.len() >> 20),
    )
    .map_err(MeshError::Invalid)?;
    let mesh = match format {
        MeshFormat::Obj => obj::parse(bytes)?,
        MeshFormat::Ply => ply::parse(bytes)?,
    };
    mesh.validate()?;
    Ok(mesh)
}

impl MeshData {
    /// Checks what every consumer relies on: finite coordinates, indices in range,
    /// normals absent or one per vertex.
    pub fn validate(&self) -> Result<(), MeshError> {
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::Invalid(format!(
                "vertex {i} has a non-finite coordinate {:?}",
                self.positions[i].to_array()
            )));
        }
        if !self.normals.is_empty() && self.normals.len() != self.positions.len() {
            return Err(MeshError::Invalid(format!(
                "{} normals for {} vertices",
                self.normals.len(),
                self.positions.len()
            )));
        }
        let n = self.positions.len();
        for (f, tri) in self.triangles.iter().enumerate() {
            if let Some(&i) = tri.iter().find(|&&i| i as usize >= n) {
                return Err(MeshError::Invalid(format!(
                    "face {f} refers to vertex {i}, but there are only {n} vertices"
                )));
            }
        }
        Ok(())
    }

    /// Applies an affine transform to positions and (by the inverse transpose) normals.
    pub fn transform(&mut self, m: &Mat4) {
        for p in &mut self.positions {
            *p = m.transform_point3(*p);
        }
        let normal_matrix = m.inverse().transpose();
        for n in &mut self.normals {
            *n = normal_matrix.transform_vector3(*n).normalize_or_zero();
        }
    }

    /// Area-weighted vertex normals, for smooth shading of meshes that have none.
    pub fn compute_vertex_normals(&mut self) {
        let mut normals = vec![Vec3::ZERO; self.positions.len()];
        for &[a, b, c] in &self.triangles {
            let [pa, pb, pc] = [a, b, c].map(|i| self.positions[i as usize]);
            // Cross product length is twice the area: an area weight for free.
            let n = (pb - pa).cross(pc - pa);
            for i in [a, b, c] {
                normals[i as usize] += n;
            }
        }
        self.normals = normals.into_iter().map(Vec3::normalize_or_zero).collect();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> MeshData {
        MeshData {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
            normals: vec![],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    #[test]
    fn index_out_of_range_is_reported_with_face_number() {
        let mut m = quad();
        m.triangles[1][2] = 9;
        let err = m.validate().unwrap_err().to_string();
        assert!(err.contains("face 1") && err.contains("vertex 9"), "{err}");
    }

    #[test]
    fn nan_vertex_is_reported() {
        let mut m = quad();
        m.positions[2].x = f32::NAN;
        assert!(m.validate().unwrap_err().to_string().contains("vertex 2"));
    }

    #[test]
    fn vertex_normals_of_a_flat_quad_point_along_z() {
        let mut m = quad();
        m.compute_vertex_normals();
        assert!(m.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-6));
    }

    #[test]
    fn format_follows_extension() {
        assert_eq!(MeshFormat::from_path("a/b.OBJ"), Ok(MeshFormat::Obj));
        assert_eq!(MeshFormat::from_path("b.ply"), Ok(MeshFormat::Ply));
        assert!(MeshFormat::from_path("b.stl").is_err());
    }
}
