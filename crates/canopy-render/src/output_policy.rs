//! The one output policy every writer of every front end follows (the CLI, Python, the
//! Ray driver and its CLI, benchmark tables, resume folders, animation frames): an output
//! is checked before any work starts, and written through [`crate::output`]'s atomic
//! writer (a new temporary file of an unpredictable name, created exclusively, synced,
//! then renamed).
//!
//! Before work, a path to be written must:
//! - be of a format its writer knows (images: `.png`, `.exr`);
//! - name a file, not a folder (`o.png/`), in a folder that exists and is writable;
//! - be none of the files the scene reads — by identity, so that a link, a hard link or
//!   another spelling of an input counts as that input;
//! - not hold a canopy checkpoint: that is a render's unfinished work, whatever its name
//!   (a checkpoint itself may replace only its own render's, see
//!   [`crate::checkpoint::Checkpoint::check_owned_slot`]).

use crate::checkpoint::{Checkpoint, Slot};
use crate::files::{directory_of, same_file};
use std::path::{Path, PathBuf};

/// What is written, which decides the formats allowed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputKind {
    /// An image: `.png` or `.exr`.
    Image,
    /// A render's checkpoint: a free path, or one of the render's own checkpoints.
    Checkpoint,
    /// Any other file canopy makes (a table, a JSON record): any name.
    Data,
}

/// Why `what` (the image, the table, ...) of kind `kind` may not be written to `path`
/// by a render whose scene reads `inputs`, if it may not. Makes no change on disk but a
/// probe file of a fresh name, removed at once.
pub fn check_output(
    path: &Path,
    what: &str,
    kind: OutputKind,
    inputs: &[PathBuf],
) -> Result<(), String> {
    if kind == OutputKind::Image {
        crate::output::image_format(path).map_err(|e| e.to_string())?;
    }
    check_not_an_input(path, what, inputs)?;
    match (kind, Checkpoint::slot(path)) {
        (OutputKind::Checkpoint, Slot::Other) => {
            let refused = Checkpoint::check_slot(path).expect_err("another file is there");
            return Err(format!("{refused} (choose another path for the {what})"));
        }
        (OutputKind::Image | OutputKind::Data, Slot::Checkpoint { .. }) => {
            return Err(format!(
                "{}: holds a canopy checkpoint, a render's unfinished work, which the {what} would replace: resume it (`canopy render --resume {}`) or choose another path",
                path.display(),
                path.display()
            ))
        }
        _ => {}
    }
    check_writable_folder(path, what)
}

/// Why `what` may not be written to `path`, if it is one of `inputs` (the files a scene
/// was read from), compared by identity.
pub fn check_not_an_input(path: &Path, what: &str, inputs: &[PathBuf]) -> Result<(), String> {
    match inputs.iter().find(|i| same_file(path, i)) {
        Some(input) => Err(format!(
            "{}: refusing to write the {what} over an input of the scene ({})",
            path.display(),
            input.display()
        )),
        None => Ok(()),
    }
}

/// Fails unless a file can be created at `path`: it names no folder, and its folder
/// exists and is writable. Found at the start, not after the work.
pub fn check_writable_folder(path: &Path, what: &str) -> Result<(), String> {
    let fail = |why: String| {
        Err(format!(
            "{}: cannot write the {what}: {why}",
            path.display()
        ))
    };
    // `o.png/` names a directory: no file can ever be renamed to it.
    if path
        .as_os_str()
        .to_string_lossy()
        .ends_with(std::path::is_separator)
    {
        return fail("the path ends with a separator, so it names a directory".into());
    }
    let dir = directory_of(path);
    if !dir.is_dir() {
        return fail(format!("directory {} does not exist", dir.display()));
    }
    if std::fs::metadata(path).is_ok_and(|m| m.is_dir()) {
        return fail("it is a directory".into());
    }
    // A probe of a fresh name (never an existing file: it is created exclusively),
    // removed at once.
    match crate::output::create_temporary_sibling(path) {
        Ok((probe, file)) => {
            drop(file);
            let _ = std::fs::remove_file(probe);
            Ok(())
        }
        Err(e) => fail(format!("{e} (in {})", dir.display())),
    }
}

/// A scene's name made into a plain file name (the default image of `canopy render`,
/// the viewer's saved images): path separators, `..`, control and other unusual
/// characters become `_`.
pub fn file_stem_from_name(name: &str) -> String {
    let cleaned: String = name
        .chars()
        .map(|c| match c {
            'a'..='z' | 'A'..='Z' | '0'..='9' | '-' | '_' | '.' => c,
            _ => '_',
        })
        .take(100)
        .collect();
    // No hidden files, no `.` or `..`.
    let cleaned = cleaned.trim_start_matches('.');
    if cleaned.chars().all(|c| c == '_') {
        "render".to_owned()
    } else {
        cleaned.to_owned()
    }
}

/// Where the samples of a render whose output could not be written are kept instead,
/// in order: beside the output, in the working directory, in the temporary directory.
/// `name` is the file name to use (`<image>.checkpoint`).
pub fn fallback_places(output: &Path, name: &str) -> Vec<PathBuf> {
    let mut places = vec![directory_of(output).join(name)];
    if let Ok(here) = std::env::current_dir() {
        places.push(here.join(name));
    }
    places.push(std::env::temp_dir().join(name));
    places.dedup_by(|a, b| same_file(a, b));
    places
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_become_plain_file_names() {
        assert_eq!(file_stem_from_name("cornell"), "cornell");
        assert_eq!(file_stem_from_name("../x"), "_x");
        assert_eq!(file_stem_from_name("/etc/passwd"), "_etc_passwd");
        assert_eq!(file_stem_from_name(".."), "render");
        assert_eq!(file_stem_from_name(""), "render");
        assert_eq!(file_stem_from_name("my scene\n"), "my_scene_");
        assert_eq!(file_stem_from_name(&"a".repeat(500)).len(), 100);
    }

    fn scratch(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("canopy-policy-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn an_output_is_checked_before_the_work() {
        let dir = scratch("checks");
        let scene = dir.join("scene.toml");
        std::fs::write(&scene, "scene").unwrap();
        let inputs = vec![scene.clone()];
        let ok = |p: &Path, kind| check_output(p, "image", kind, &inputs);
        assert!(ok(&dir.join("a.png"), OutputKind::Image).is_ok());
        assert!(ok(&dir.join("a.bmp"), OutputKind::Image)
            .unwrap_err()
            .contains("unsupported image format"));
        assert!(ok(&dir.join("a.bmp"), OutputKind::Data).is_ok());
        assert!(ok(&dir.join("gone").join("a.png"), OutputKind::Image)
            .unwrap_err()
            .contains("does not exist"));
        assert!(ok(
            Path::new(&format!("{}/", dir.join("a.png").display())),
            OutputKind::Image
        )
        .unwrap_err()
        .contains("names a directory"));
        // The scene, by any spelling: itself, a symbolic link, a hard link.
        std::os::unix::fs::symlink(&scene, dir.join("link.toml")).unwrap();
        std::fs::hard_link(&scene, dir.join("hard.toml")).unwrap();
        for name in ["scene.toml", "link.toml", "hard.toml"] {
            let e = ok(&dir.join(name), OutputKind::Data).unwrap_err();
            assert!(e.contains("over an input of the scene"), "{name}: {e}");
        }
        // Nothing was left behind by the probes.
        let mut names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        assert_eq!(names, ["hard.toml", "link.toml", "scene.toml"]);
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn a_checkpoint_is_never_replaced_by_an_output_whatever_its_name() {
        let dir = scratch("checkpoint");
        let scene = crate::load_scene("cornell").unwrap();
        let checkpoint = Checkpoint::new(
            "cornell",
            &scene,
            crate::Accumulator::new(scene.settings.width, scene.settings.height),
        );
        let named_as_image = dir.join("render.png");
        checkpoint.save(&named_as_image).unwrap();
        for kind in [OutputKind::Image, OutputKind::Data] {
            let e = check_output(&named_as_image, "image", kind, &[]).unwrap_err();
            assert!(e.contains("holds a canopy checkpoint"), "{e}");
        }
        std::fs::write(dir.join("notes.txt"), "mine").unwrap();
        let e = check_output(
            &dir.join("notes.txt"),
            "checkpoint",
            OutputKind::Checkpoint,
            &[],
        )
        .unwrap_err();
        assert!(e.contains("exists and is not a canopy checkpoint"), "{e}");
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn samples_fall_back_beside_the_output_then_here_then_the_temporary_folder() {
        let places = fallback_places(Path::new("/nowhere/out.png"), "out.png.checkpoint");
        assert_eq!(places[0], Path::new("/nowhere/out.png.checkpoint"));
        assert_eq!(
            places.last().unwrap(),
            &std::env::temp_dir().join("out.png.checkpoint")
        );
    }
}
