//! Errors the renderer returns; each names the file, line or object at fault.
//!
//! Each message is complete on its own (the underlying cause is part of it), so callers
//! print it once rather than walking a source chain.

use crate::mesh::MeshError;
use std::path::PathBuf;
use thiserror::Error;

/// A scene that could not be loaded.
#[derive(Debug, Error)]
pub enum SceneError {
    #[error("{file}: cannot read the file: {cause}")]
    Read { file: String, cause: std::io::Error },
    #[error("{file}:{line}:{column}: {message}\n    | {text}")]
    Syntax {
        file: String,
        line: usize,
        column: usize,
        message: String,
        text: String,
    },
    #[error("{file}:{line}: {message}")]
    Invalid {
        file: String,
        line: usize,
        message: String,
    },
    #[error("{file}:{line}: mesh `{mesh}`: {cause}")]
    Mesh {
        file: String,
        line: usize,
        mesh: String,
        cause: MeshError,
    },
    /// A bare mesh file given as the scene: the error names the file (and, where the
    /// format has lines, the line) of the mesh itself.
    #[error("{file}: {cause}")]
    MeshFile { file: String, cause: MeshError },
    /// A model file (glTF) given as the scene: the error names the file and the object
    /// in it at fault.
    #[error("{file}: {message}")]
    Model { file: String, message: String },
    #[error("unknown scene `{0}`: neither a built-in scene (see `canopy scenes`) nor a file")]
    Unknown(String),
    /// An error in a file named by someone other than the user, told without its text.
    #[error("{file}{}: this scene does not load; `canopy check {file}` says why", line.map(|l| format!(":{l}")).unwrap_or_default())]
    Withheld { file: String, line: Option<usize> },
    /// A setting of how the scene is read (a folder it may read from) is wrong.
    #[error("{0}")]
    Usage(String),
}

impl SceneError {
    /// The error without anything read from the file (its lines, keys, values): for a
    /// file that someone other than the user named (a checkpoint names its scene), whose
    /// contents must never be shown. It says where, and how the user can see why.
    pub fn withholding_text(self) -> Self {
        let (file, line) = match &self {
            SceneError::Syntax { file, line, .. }
            | SceneError::Invalid { file, line, .. }
            | SceneError::Mesh { file, line, .. } => (file.clone(), Some(*line)),
            SceneError::MeshFile { file, .. } | SceneError::Model { file, .. } => {
                (file.clone(), None)
            }
            _ => return self,
        };
        SceneError::Withheld { file, line }
    }
}

/// An image that could not be written.
#[derive(Debug, Error)]
pub enum OutputError {
    #[error("{}: unsupported image format (use .png or .exr)", path.display())]
    UnsupportedFormat { path: PathBuf },
    #[error("{}: cannot write the image: {cause}", path.display())]
    Write {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("{}: AOVs are written as layers of an OpenEXR image; name an .exr output", path.display())]
    LayersNeedExr { path: PathBuf },
    #[error("{}: cannot encode the image: {cause}", path.display())]
    Encode {
        path: PathBuf,
        cause: image::ImageError,
    },
}
