//! Tangent frames for normal maps: MikkTSpace (through the `mikktspace` crate), the
//! convention Blender and glTF's sample models bake normal maps in, so that a baked map
//! shades as its author saw it. One tangent per triangle corner: the generator may give a
//! shared vertex different tangents on either side of a UV seam.
//!
//! glTF's texture coordinates grow downwards in the image while a normal map's +Y points
//! up it (glTF 2.0, 3.9.3), so the generator is given `(u, 1 − v)`: its bitangent then
//! follows the map's +Y, as glTF's `bitangent = cross(normal, tangent.xyz) · tangent.w`
//! expects.

use glam::{Vec2, Vec3, Vec4};

/// Unit tangent (xyz) and bitangent sign (w) at every corner of every triangle, from
/// positions, per-vertex normals (empty: each face's own) and texture coordinates;
/// `None` where the generator fails (no triangle has usable texture coordinates).
pub fn generate(
    positions: &[Vec3],
    normals: &[Vec3],
    uvs: &[Vec2],
    triangles: &[[u32; 3]],
) -> Option<Vec<[Vec4; 3]>> {
    let mut mesh = Corners {
        positions,
        normals,
        uvs,
        triangles,
        tangents: vec![[Vec4::new(1.0, 0.0, 0.0, 1.0); 3]; triangles.len()],
    };
    mikktspace::generate_tangents(&mut mesh).then_some(mesh.tangents)
}

struct Corners<'a> {
    positions: &'a [Vec3],
    normals: &'a [Vec3],
    uvs: &'a [Vec2],
    triangles: &'a [[u32; 3]],
    tangents: Vec<[Vec4; 3]>,
}

impl Corners<'_> {
    fn vertex(&self, face: usize, vert: usize) -> usize {
        self.triangles[face][vert] as usize
    }
}

impl mikktspace::Geometry for Corners<'_> {
    fn num_faces(&self) -> usize {
        self.triangles.len()
    }

    fn num_vertices_of_face(&self, _face: usize) -> usize {
        3
    }

    fn position(&self, face: usize, vert: usize) -> [f32; 3] {
        self.positions[self.vertex(face, vert)].to_array()
    }

    fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
        if let Some(n) = self.normals.get(self.vertex(face, vert)) {
            return n.to_array();
        }
        let [a, b, c] = self.triangles[face].map(|i| self.positions[i as usize]);
        (b - a).cross(c - a).normalize_or_zero().to_array()
    }

    fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
        let uv = self.uvs[self.vertex(face, vert)];
        [uv.x, 1.0 - uv.y]
    }

    fn set_tangent_encoded(&mut self, tangent: [f32; 4], face: usize, vert: usize) {
        self.tangents[face][vert] = Vec4::from(tangent);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quad_mapped_along_its_axes_has_tangent_x() {
        // u grows along +x and v along −y (glTF's v points down the image, so the map's
        // +Y, up the image, is +y).
        let positions = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        let uvs = [
            Vec2::new(0.0, 1.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(1.0, 0.0),
            Vec2::ZERO,
        ];
        let tangents = generate(&positions, &[], &uvs, &[[0, 1, 2], [0, 2, 3]]).unwrap();
        for corner in tangents.iter().flatten() {
            assert!((corner.truncate() - Vec3::X).length() < 1e-5, "{corner}");
            // The bitangent, w · (n × t) = w · (z × x) = w · y, is the map's +Y: +y.
            assert_eq!(corner.w, 1.0, "{corner}");
        }
    }
}
