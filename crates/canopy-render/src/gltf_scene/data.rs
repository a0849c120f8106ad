//! The bytes behind a glTF file's accessors: its buffers (the GLB's binary chunk, data
//! URIs, files beside it), and accessors checked against them before anything is read,
//! so that a damaged or hostile file is refused with the object at fault named instead
//! of reading past a buffer or allocating what it declares.

use crate::scene_file::Assets;
use base64::Engine;
use gltf::accessor::{DataType, Dimensions};
use gltf::Accessor;

/// Every buffer's bytes, by index, and the files they were read from.
pub(super) struct Buffers(pub Vec<Vec<u8>>, pub Vec<std::path::PathBuf>);

impl Buffers {
    /// Loads every buffer of `document`: the GLB's binary chunk (`blob`), a base64 data
    /// URI, or a file relative to the glTF file's directory (through `assets`).
    pub fn load(
        document: &gltf::Document,
        blob: Option<Vec<u8>>,
        assets: &dyn Assets,
    ) -> Result<Self, String> {
        let mut blob = blob;
        let mut all = Vec::new();
        let mut files = Vec::new();
        for buffer in document.buffers() {
            let named = format!("buffer {}", describe(buffer.index(), buffer.name()));
            let bytes = match buffer.source() {
                gltf::buffer::Source::Bin => blob
                    .take()
                    .ok_or_else(|| format!("{named}: the file has no binary chunk"))?,
                gltf::buffer::Source::Uri(uri) => match uri.strip_prefix("data:") {
                    Some(data) => decode_data_uri(data).map_err(|e| format!("{named}: {e}"))?,
                    None => {
                        let path = percent_decoded(uri);
                        files.extend(assets.locate(&path));
                        assets.read(&path).map_err(|e| format!("{named}: {e}"))?
                    }
                },
            };
            if bytes.len() < buffer.length() {
                return Err(format!(
                    "{named}: declares {} bytes but holds {} (truncated?)",
                    buffer.length(),
                    bytes.len()
                ));
            }
            all.push(bytes);
        }
        Ok(Self(all, files))
    }

    /// The bytes of buffer `index`, for the reader.
    pub fn get(&self, buffer: gltf::Buffer<'_>) -> Option<&[u8]> {
        self.0.get(buffer.index()).map(Vec::as_slice)
    }
}

/// `index` with the object's name where it has one: `3 ("wheel")`.
pub(super) fn describe(index: usize, name: Option<&str>) -> String {
    match name {
        Some(name) => format!("{index} (\"{name}\")"),
        None => index.to_string(),
    }
}

/// The bytes of a `data:` URI's body (`[<mime>];base64,<data>`).
pub(super) fn decode_data_uri(data: &str) -> Result<Vec<u8>, String> {
    let (header, body) = data.split_once(',').ok_or("a data URI without a comma")?;
    if !header.ends_with(";base64") {
        return Err("only base64 data URIs are supported".into());
    }
    base64::engine::general_purpose::STANDARD
        .decode(body)
        .map_err(|e| format!("its data URI is not valid base64: {e}"))
}

/// A relative URI with its `%XX` escapes decoded (spaces in file names are common).
pub(super) fn percent_decoded(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        match (
            bytes[i],
            bytes.get(i + 1).copied().and_then(hex),
            bytes.get(i + 2).copied().and_then(hex),
        ) {
            (b'%', Some(high), Some(low)) => {
                out.push((high * 16 + low) as u8);
                i += 3;
            }
            (b, _, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// What an accessor must be for the attribute it is read as.
pub(super) struct Expect {
    pub what: &'static str,
    pub types: &'static [DataType],
    pub dimensions: Dimensions,
}

pub(super) const POSITIONS: Expect = Expect {
    what: "positions",
    types: &[DataType::F32],
    dimensions: Dimensions::Vec3,
};

pub(super) const NORMALS: Expect = Expect {
    what: "normals",
    types: &[DataType::F32],
    dimensions: Dimensions::Vec3,
};

pub(super) const TANGENTS: Expect = Expect {
    what: "tangents",
    types: &[DataType::F32],
    dimensions: Dimensions::Vec4,
};

pub(super) const TEXCOORDS: Expect = Expect {
    what: "texture coordinates",
    types: &[DataType::F32, DataType::U8, DataType::U16],
    dimensions: Dimensions::Vec2,
};

pub(super) const INDICES: Expect = Expect {
    what: "indices",
    types: &[DataType::U8, DataType::U16, DataType::U32],
    dimensions: Dimensions::Scalar,
};

/// Checks that `accessor` is of the kind `expect` names and that every element it
/// declares lies inside its buffer view, and the view inside its buffer: what the
/// reader relies on.
pub(super) fn check_accessor(
    accessor: &Accessor<'_>,
    expect: &Expect,
    buffers: &Buffers,
) -> Result<(), String> {
    let named = format!(
        "{} accessor {}",
        expect.what,
        describe(accessor.index(), accessor.name())
    );
    if !expect.types.contains(&accessor.data_type()) || accessor.dimensions() != expect.dimensions {
        return Err(format!(
            "{named} is {:?} {:?}, where {:?} of {:?} is needed",
            accessor.dimensions(),
            accessor.data_type(),
            expect.dimensions,
            expect.types
        ));
    }
    let count = accessor.count();
    if count == 0 {
        return Err(format!("{named} has no elements"));
    }
    let size = accessor.size();
    match accessor.view() {
        Some(view) => check_elements(&named, &view, accessor.offset(), count, size, buffers)?,
        // Only a sparse accessor may leave out its view (its base is zeros), and its
        // declared count must then fit in memory.
        None if accessor.sparse().is_some() => {
            let needed = (count as u64).saturating_mul(size as u64 + 16);
            crate::files::check_memory(needed, crate::files::available_memory(), &named)?;
        }
        None => return Err(format!("{named} has no buffer view (no data)")),
    }
    match accessor.sparse() {
        Some(sparse) => check_sparse(&named, &sparse, count, size, buffers),
        None => Ok(()),
    }
}

/// Checks that `count` elements of `size` bytes from byte `offset` of `view` lie
/// inside it, and the view inside its buffer.
fn check_elements(
    named: &str,
    view: &gltf::buffer::View<'_>,
    offset: usize,
    count: usize,
    size: usize,
    buffers: &Buffers,
) -> Result<(), String> {
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(format!(
            "{named}: its view's stride {stride} is shorter than an element ({size} bytes)"
        ));
    }
    let end = (count - 1)
        .checked_mul(stride)
        .and_then(|span| span.checked_add(offset))
        .and_then(|span| span.checked_add(size));
    match end {
        Some(end) if end <= view.length() => {}
        _ => {
            return Err(format!(
            "{named}: {count} elements from byte {offset} overrun its buffer view {} of {} bytes",
            view.index(),
            view.length()
        ))
        }
    }
    let held = buffers.0.get(view.buffer().index()).map_or(0, Vec::len);
    match view.offset().checked_add(view.length()) {
        Some(end) if end <= held => Ok(()),
        _ => Err(format!(
            "{named}: buffer view {} (bytes {}..+{}) overruns buffer {} of {held} bytes",
            view.index(),
            view.offset(),
            view.length(),
            view.buffer().index()
        )),
    }
}

/// Checks a sparse accessor's substitutions (of an accessor of `count` elements of
/// `size` bytes): both arrays inside their views, and the indices strictly increasing
/// and below `count`, as the specification requires (the reader relies on it).
fn check_sparse(
    named: &str,
    sparse: &gltf::accessor::sparse::Sparse<'_>,
    count: usize,
    size: usize,
    buffers: &Buffers,
) -> Result<(), String> {
    let substituted = sparse.count();
    if substituted == 0 || substituted > count {
        return Err(format!(
            "{named}: its sparse count {substituted} is not within 1..={count}"
        ));
    }
    let indices = sparse.indices();
    let index_size = indices.index_type().size();
    let (index_view, values) = (indices.view(), sparse.values());
    let what = format!("{named}: its sparse indices");
    check_elements(
        &what,
        &index_view,
        indices.offset(),
        substituted,
        index_size,
        buffers,
    )?;
    let what = format!("{named}: its sparse values");
    check_elements(
        &what,
        &values.view(),
        values.offset(),
        substituted,
        size,
        buffers,
    )?;
    let buffer = &buffers.0[index_view.buffer().index()];
    let stride = index_view.stride().unwrap_or(index_size);
    let mut previous = None;
    for k in 0..substituted {
        let at = index_view.offset() + indices.offset() + k * stride;
        let bytes = &buffer[at..at + index_size];
        let index = bytes
            .iter()
            .rev()
            .fold(0usize, |value, &byte| (value << 8) | byte as usize);
        if index >= count || previous.is_some_and(|p| index <= p) {
            return Err(format!(
                "{named}: sparse index {k} is {index}; the indices must rise strictly and stay below {count}"
            ));
        }
        previous = Some(index);
    }
    Ok(())
}
