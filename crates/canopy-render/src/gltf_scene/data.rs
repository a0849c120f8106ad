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
    if accessor.sparse().is_some() {
        return Err(format!("{named} is sparse, which is not supported yet"));
    }
    let Some(view) = accessor.view() else {
        return Err(format!("{named} has no buffer view (no data)"));
    };
    let count = accessor.count();
    if count == 0 {
        return Err(format!("{named} has no elements"));
    }
    let size = accessor.size();
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(format!(
            "{named}: its view's stride {stride} is shorter than an element ({size} bytes)"
        ));
    }
    let end = (count - 1)
        .checked_mul(stride)
        .and_then(|span| span.checked_add(accessor.offset()))
        .and_then(|span| span.checked_add(size));
    match end {
        Some(end) if end <= view.length() => {}
        _ => {
            return Err(format!(
                "{named}: {count} elements from byte {} overrun its buffer view {} of {} bytes",
                accessor.offset(),
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
