//! Follows the scene's files: when one changes on disk (its length or modification time),
//! the scene is loaded again and the view renders it with the camera kept. A scene that
//! no longer loads is reported to the pages, and the last one that did stays on screen.

use crate::protocol::ServerMessage;
use crate::session::Session;
use canopy_render::Scene;
use std::fmt;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, SystemTime};

/// How often the files are looked at.
const POLL: Duration = Duration::from_millis(250);

/// Loads the scene again, as it was loaded first (same file, same folders allowed).
#[derive(Clone)]
pub struct Reload(Arc<dyn Fn() -> Result<Scene, String> + Send + Sync>);

impl Reload {
    pub fn new(load: impl Fn() -> Result<Scene, String> + Send + Sync + 'static) -> Self {
        Self(Arc::new(load))
    }
}

impl fmt::Debug for Reload {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Reload")
    }
}

/// What tells a file changed, without reading it.
type Signature = Vec<Option<(u64, Option<SystemTime>)>>;

fn signature(files: &[PathBuf]) -> Signature {
    files
        .iter()
        .map(|f| {
            std::fs::metadata(f)
                .ok()
                .map(|m| (m.len(), m.modified().ok()))
        })
        .collect()
}

/// Watches `files` until the session shuts down.
pub(crate) fn run(session: &Session, reload: &Reload, mut files: Vec<PathBuf>) {
    let mut seen = signature(&files);
    while session.sleep(POLL) {
        let now = signature(&files);
        if now == seen {
            continue;
        }
        seen = now;
        match (reload.0)().and_then(|scene| scene.validate().map(|()| scene)) {
            Ok(scene) => {
                files = scene.inputs.clone();
                seen = signature(&files);
                let message = ServerMessage::Reloaded {
                    primitives: scene.primitives.len(),
                    instances: scene.instances.len(),
                };
                session.replace_scene(scene);
                session.notify(message);
            }
            Err(cause) => session.notify(ServerMessage::Error {
                message: format!(
                    "the scene changed on disk but does not load ({cause}); showing the last version that did"
                ),
            }),
        }
    }
}
