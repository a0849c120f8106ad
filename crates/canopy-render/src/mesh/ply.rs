//! PLY (Stanford polygon format), ASCII and binary of either byte order.
//!
//! Reads `vertex` x/y/z (and nx/ny/nz when present) and the `face` index lists
//! (`vertex_indices` or `vertex_index`), fan-triangulating polygons; other elements and
//! properties are skipped. Declared counts are checked against the bytes left in the
//! file before anything is allocated from them, so a hostile header cannot make the
//! reader allocate gigabytes.

use super::{MeshData, MeshError};
use glam::Vec3;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Debug)]
enum Property {
    Scalar {
        name: String,
        ty: Scalar,
    },
    List {
        name: String,
        count: Scalar,
        item: Scalar,
    },
}

impl Property {
    fn name(&self) -> &str {
        match self {
            Property::Scalar { name, .. } | Property::List { name, .. } => name,
        }
    }

    /// Fewest bytes (binary) one value of this property can take.
    fn min_size(&self) -> usize {
        match self {
            Property::Scalar { ty, .. } => ty.size(),
            Property::List { count, .. } => count.size(),
        }
    }
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Encoding {
    Ascii,
    LittleEndian,
    BigEndian,
}

struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    /// Byte offset of the body.
    body_start: usize,
    /// Number of header lines (ASCII body line numbers continue from here).
    lines: usize,
}

fn at_line(line: usize, message: impl Into<String>) -> MeshError {
    MeshError::AtLine {
        line,
        message: message.into(),
    }
}

fn parse_header(bytes: &[u8]) -> Result<Header, MeshError> {
    let mut pos = 0;
    let mut line_no = 0;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(len) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            return Err(MeshError::Invalid(
                "PLY header has no `end_header` line".into(),
            ));
        };
        line_no += 1;
        let raw = &bytes[pos..pos + len];
        pos += len + 1;
        let line = std::str::from_utf8(raw)
            .map_err(|_| at_line(line_no, "PLY header is not text"))?
            .trim_end_matches('\r');
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["ply"] if line_no == 1 => {}
            _ if line_no == 1 => {
                return Err(at_line(1, "not a PLY file (first line must be `ply`)"))
            }
            ["format", format, _version] => {
                encoding = Some(match *format {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::LittleEndian,
                    "binary_big_endian" => Encoding::BigEndian,
                    other => return Err(at_line(line_no, format!("unknown PLY format `{other}`"))),
                });
            }
            ["comment", ..] | ["obj_info", ..] | [] => {}
            ["element", name, count] => {
                let count = count
                    .parse()
                    .map_err(|_| at_line(line_no, format!("bad element count `{count}`")))?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    properties: Vec::new(),
                });
            }
            ["property", "list", count, item, name] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| at_line(line_no, "property before any element"))?;
                let ty = |t: &str| {
                    Scalar::parse(t)
                        .ok_or_else(|| at_line(line_no, format!("unknown property type `{t}`")))
                };
                element.properties.push(Property::List {
                    name: name.to_string(),
                    count: ty(count)?,
                    item: ty(item)?,
                });
            }
            ["property", ty, name] => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| at_line(line_no, "property before any element"))?;
                let ty = Scalar::parse(ty)
                    .ok_or_else(|| at_line(line_no, format!("unknown property type `{ty}`")))?;
                element.properties.push(Property::Scalar {
                    name: name.to_string(),
                    ty,
                });
            }
            ["end_header"] => break,
            _ => return Err(at_line(line_no, format!("unexpected header line `{line}`"))),
        }
    }
    let encoding =
        encoding.ok_or_else(|| MeshError::Invalid("PLY header has no `format` line".into()))?;
    Ok(Header {
        encoding,
        elements,
        body_start: pos,
        lines: line_no,
    })
}

/// Reads the values of the body one at a time, in either encoding.
struct Body<'a> {
    bytes: &'a [u8],
    pos: usize,
    encoding: Encoding,
    line: usize,
}

impl Body<'_> {
    fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    fn error(&self, what: &str) -> MeshError {
        match self.encoding {
            Encoding::Ascii => at_line(self.line, what),
            _ => MeshError::Invalid(format!("{} (at byte {})", what, self.pos)),
        }
    }

    fn read(&mut self, ty: Scalar) -> Result<f64, MeshError> {
        match self.encoding {
            Encoding::Ascii => self.read_ascii(ty),
            _ => self.read_binary(ty),
        }
    }

    fn read_binary(&mut self, ty: Scalar) -> Result<f64, MeshError> {
        let size = ty.size();
        if self.remaining() < size {
            return Err(self.error("file ends in the middle of the data"));
        }
        let mut b = [0u8; 8];
        b[..size].copy_from_slice(&self.bytes[self.pos..self.pos + size]);
        self.pos += size;
        if self.encoding == Encoding::BigEndian {
            b[..size].reverse();
        }
        Ok(match ty {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
            Scalar::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
            Scalar::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::F64 => f64::from_le_bytes(b),
        })
    }

    fn read_ascii(&mut self, ty: Scalar) -> Result<f64, MeshError> {
        while let Some(&c) = self.bytes.get(self.pos) {
            if !c.is_ascii_whitespace() {
                break;
            }
            if c == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
        let start = self.pos;
        while self
            .bytes
            .get(self.pos)
            .is_some_and(|c| !c.is_ascii_whitespace())
        {
            self.pos += 1;
        }
        if start == self.pos {
            return Err(self.error("file ends in the middle of the data"));
        }
        let token = std::str::from_utf8(&self.bytes[start..self.pos]).unwrap_or("?");
        let value: f64 = token
            .parse()
            .map_err(|_| self.error(&format!("`{token}` is not a number")))?;
        let integral = !matches!(ty, Scalar::F32 | Scalar::F64);
        if integral && value.fract() != 0.0 {
            return Err(self.error(&format!("`{token}` is not an integer")));
        }
        Ok(value)
    }

    /// A list length or vertex index: a non-negative integer.
    fn read_index(&mut self, ty: Scalar) -> Result<u32, MeshError> {
        let v = self.read(ty)?;
        if !(0.0..=u32::MAX as f64).contains(&v) || v.fract() != 0.0 {
            return Err(self.error(&format!("{v} is not a valid index or count")));
        }
        Ok(v as u32)
    }
}

/// Where the mesh's data sits within an element's properties.
fn property_index(element: &Element, names: &[&str]) -> Option<usize> {
    element
        .properties
        .iter()
        .position(|p| names.contains(&p.name()))
}

pub(super) fn parse(bytes: &[u8]) -> Result<MeshData, MeshError> {
    let header = parse_header(bytes)?;
    let mut body = Body {
        bytes,
        pos: header.body_start,
        encoding: header.encoding,
        line: header.lines + 1,
    };
    let mut mesh = MeshData::default();
    let mut saw_vertices = false;
    let mut saw_faces = false;
    for element in &header.elements {
        // Each element needs at least this many bytes (ASCII: a digit and a separator
        // per value); a count the file cannot hold is refused before allocating.
        let min_bytes_each = match header.encoding {
            Encoding::Ascii => 2 * element.properties.len(),
            _ => element.properties.iter().map(Property::min_size).sum(),
        };
        if element.count.saturating_mul(min_bytes_each) > body.remaining() {
            return Err(MeshError::Invalid(format!(
                "header declares {} `{}` elements, but only {} bytes follow",
                element.count,
                element.name,
                body.remaining()
            )));
        }
        match element.name.as_str() {
            "vertex" => {
                saw_vertices = true;
                read_vertices(element, &mut body, &mut mesh)?;
            }
            "face" => {
                saw_faces = true;
                read_faces(element, &mut body, &mut mesh)?;
            }
            _ => skip_element(element, &mut body)?,
        }
    }
    if !saw_vertices || !saw_faces {
        return Err(MeshError::Invalid(
            "PLY file needs both a `vertex` and a `face` element".into(),
        ));
    }
    Ok(mesh)
}

fn read_vertices(element: &Element, body: &mut Body, mesh: &mut MeshData) -> Result<(), MeshError> {
    let find = |names: &[&str]| property_index(element, names);
    let (Some(x), Some(y), Some(z)) = (find(&["x"]), find(&["y"]), find(&["z"])) else {
        return Err(MeshError::Invalid(
            "`vertex` element lacks x, y or z".into(),
        ));
    };
    let normal = match (find(&["nx"]), find(&["ny"]), find(&["nz"])) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    mesh.positions.reserve_exact(element.count);
    if normal.is_some() {
        mesh.normals.reserve_exact(element.count);
    }
    let mut values = vec![0.0f64; element.properties.len()];
    for _ in 0..element.count {
        for (value, property) in values.iter_mut().zip(&element.properties) {
            *value = match property {
                Property::Scalar { ty, .. } => body.read(*ty)?,
                Property::List { .. } => {
                    return Err(body.error("list properties on vertices are not supported"));
                }
            };
        }
        let v = |i: usize| values[i] as f32;
        mesh.positions.push(Vec3::new(v(x), v(y), v(z)));
        if let Some([a, b, c]) = normal {
            mesh.normals.push(Vec3::new(v(a), v(b), v(c)));
        }
    }
    Ok(())
}

fn read_faces(element: &Element, body: &mut Body, mesh: &mut MeshData) -> Result<(), MeshError> {
    let indices = property_index(element, &["vertex_indices", "vertex_index"])
        .ok_or_else(|| MeshError::Invalid("`face` element lacks `vertex_indices`".into()))?;
    mesh.triangles.reserve(element.count);
    let mut polygon = Vec::new();
    for face in 0..element.count {
        for (i, property) in element.properties.iter().enumerate() {
            match property {
                Property::List { count, item, .. } if i == indices => {
                    let n = body.read_index(*count)? as usize;
                    if n < 3 {
                        return Err(
                            body.error(&format!("face {face} has {n} vertices (needs 3 or more)"))
                        );
                    }
                    // Every index takes at least one byte.
                    if n > body.remaining() {
                        return Err(body.error(&format!(
                            "face {face} declares {n} vertices past the end of the file"
                        )));
                    }
                    polygon.clear();
                    for _ in 0..n {
                        polygon.push(body.read_index(*item)?);
                    }
                    // Fan triangulation of convex polygons.
                    for k in 1..n - 1 {
                        mesh.triangles
                            .push([polygon[0], polygon[k], polygon[k + 1]]);
                    }
                }
                other => skip_property(other, body)?,
            }
        }
    }
    Ok(())
}

fn skip_property(property: &Property, body: &mut Body) -> Result<(), MeshError> {
    match property {
        Property::Scalar { ty, .. } => {
            body.read(*ty)?;
        }
        Property::List { count, item, .. } => {
            let n = body.read_index(*count)?;
            for _ in 0..n {
                body.read(*item)?;
            }
        }
    }
    Ok(())
}

fn skip_element(element: &Element, body: &mut Body) -> Result<(), MeshError> {
    for _ in 0..element.count {
        for property in &element.properties {
            skip_property(property, body)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const ASCII_QUAD: &str = "ply\nformat ascii 1.0\ncomment a unit square\nelement vertex 4\n\
        property float x\nproperty float y\nproperty float z\nelement face 1\n\
        property list uchar int vertex_indices\nend_header\n\
        0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";

    fn binary_triangle(big_endian: bool) -> Vec<u8> {
        let format = if big_endian {
            "binary_big_endian"
        } else {
            "binary_little_endian"
        };
        let mut bytes = format!(
            "ply\nformat {format} 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nproperty uchar red\nelement face 1\n\
             property list uchar uint vertex_indices\nend_header\n"
        )
        .into_bytes();
        let f = |v: f32| {
            if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        for p in [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0f32]] {
            for c in p {
                bytes.extend(f(c));
            }
            bytes.push(255);
        }
        bytes.push(3);
        for i in [0u32, 1, 2] {
            bytes.extend(if big_endian {
                i.to_be_bytes()
            } else {
                i.to_le_bytes()
            });
        }
        bytes
    }

    #[test]
    fn ascii_quad_is_read_and_triangulated() {
        let m = parse(ASCII_QUAD.as_bytes()).unwrap();
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn binary_both_byte_orders_agree() {
        let le = parse(&binary_triangle(false)).unwrap();
        let be = parse(&binary_triangle(true)).unwrap();
        assert_eq!(le, be);
        assert_eq!(le.positions[1], Vec3::X);
        assert_eq!(le.triangles, vec![[0, 1, 2]]);
    }

    #[test]
    fn truncated_binary_file_is_an_error() {
        let bytes = binary_triangle(false);
        for cut in [bytes.len() - 1, bytes.len() - 5, bytes.len() - 20] {
            assert!(parse(&bytes[..cut]).is_err());
        }
    }

    #[test]
    fn huge_declared_count_is_refused_before_allocating() {
        let src = ASCII_QUAD.replace("element vertex 4", "element vertex 4000000000000");
        let err = parse(src.as_bytes()).unwrap_err().to_string();
        assert!(err.contains("4000000000000"), "{err}");
    }

    #[test]
    fn ascii_error_names_the_line() {
        let src = ASCII_QUAD.replace("1 1 0\n", "1 oops 0\n");
        let err = parse(src.as_bytes()).unwrap_err();
        assert_eq!(err, at_line(13, "`oops` is not a number"));
    }

    #[test]
    fn missing_end_header_is_an_error() {
        assert!(parse(b"ply\nformat ascii 1.0\nelement vertex 0\n").is_err());
    }

    #[test]
    fn not_a_ply_file() {
        let err = parse(b"solid cube\nend_header\n").unwrap_err().to_string();
        assert!(err.contains("not a PLY file"), "{err}");
    }

    #[test]
    fn degenerate_face_is_reported() {
        let src = ASCII_QUAD.replace("4 0 1 2 3", "2 0 1");
        assert!(parse(src.as_bytes())
            .unwrap_err()
            .to_string()
            .contains("face 0"));
    }
}
