//! What the server's connections and the render thread share: the scene, the structure
//! rendered through, the settings the pages ask for, and the latest frame and tree
//! report, which every connection sends on as it can (a slow one skips frames; nothing
//! queues).

use crate::protocol::{FrameInfo, ServerMessage, TreeReport};
use crate::settings::{TreeSettings, ViewSettings};
use canopy_job::Device;
use canopy_render::{Accel, Film, Scene};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, RwLock};
use std::time::Duration;
use tokio::sync::watch;

/// The image last shown, as the renderer made it (before exposure and boxes), to save.
#[derive(Debug)]
pub struct Shown {
    pub film: Film,
    pub exposure: f32,
}

/// A frame ready to send: what it shows, and its image.
#[derive(Debug)]
pub struct Frame {
    pub info: FrameInfo,
    pub jpeg: Vec<u8>,
}

/// What the pages asked for, and counters that tell the render thread it changed.
#[derive(Clone, Debug)]
pub(crate) struct Control {
    pub view: ViewSettings,
    pub tree: TreeSettings,
    /// Bumped at every change of the view (the render restarts or resumes).
    pub view_generation: u64,
    /// Bumped at every rebuild asked for.
    pub tree_generation: u64,
    pub shutdown: bool,
}

pub(crate) struct Session {
    /// The scene; the render thread sets its camera and settings between jobs (the
    /// write lock), jobs and picks read it.
    pub scene: RwLock<Scene>,
    /// The scene's name and full image size, fixed.
    pub name: String,
    pub width: u32,
    pub height: u32,
    /// Where it renders, fixed; and that device in words (the GPU adapter's).
    pub device: Device,
    pub device_name: String,
    /// The structure rendered through (`None` until the first build).
    pub accel: Mutex<Option<Arc<Accel>>>,
    /// A scene loaded again after its files changed, for the render thread to take up.
    pending_scene: Mutex<Option<Scene>>,
    /// The image last shown.
    pub shown: Mutex<Option<Arc<Shown>>>,
    control: Mutex<Control>,
    changed: Condvar,
    clients: AtomicUsize,
    /// Whether the render thread is at work (not waiting for a page or a change).
    busy: AtomicBool,
    /// Frames made over the session's life.
    sequence: AtomicU64,
    pub frames: watch::Sender<Option<Arc<Frame>>>,
    pub trees: watch::Sender<Option<Arc<TreeReport>>>,
    /// News for every page (a reload, a reload that failed).
    pub notices: watch::Sender<Option<Arc<ServerMessage>>>,
}

impl Session {
    pub fn new(
        scene: Scene,
        view: ViewSettings,
        tree: TreeSettings,
        device: Device,
        device_name: String,
    ) -> Self {
        Self {
            name: scene.name.clone(),
            width: scene.settings.width,
            height: scene.settings.height,
            device,
            device_name,
            scene: RwLock::new(scene),
            accel: Mutex::new(None),
            pending_scene: Mutex::new(None),
            shown: Mutex::new(None),
            control: Mutex::new(Control {
                view,
                tree,
                view_generation: 0,
                tree_generation: 0,
                shutdown: false,
            }),
            changed: Condvar::new(),
            clients: AtomicUsize::new(0),
            busy: AtomicBool::new(false),
            sequence: AtomicU64::new(0),
            frames: watch::channel(None).0,
            trees: watch::channel(None).0,
            notices: watch::channel(None).0,
        }
    }

    fn lock(&self) -> MutexGuard<'_, Control> {
        // A panic elsewhere while holding it leaves plain data behind: still usable.
        self.control.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub fn control(&self) -> Control {
        self.lock().clone()
    }

    /// Applies a change of the view.
    pub fn set_view(&self, view: ViewSettings) {
        let mut c = self.lock();
        c.view = view;
        c.view_generation += 1;
        self.changed.notify_all();
    }

    /// Applies new settings: the view, and the tree, built again where it changed. One
    /// change under one lock, so the render thread never sees the new tree with the old
    /// view.
    pub fn set_settings(&self, view: ViewSettings, tree: TreeSettings) {
        let mut c = self.lock();
        if c.tree != tree {
            c.tree = tree;
            c.tree_generation += 1;
        }
        c.view = view;
        c.view_generation += 1;
        self.changed.notify_all();
    }

    /// Replaces the scene (loaded again from its changed files): the render thread takes
    /// it up, rebuilds the tree and renders the view again, the camera kept.
    pub fn replace_scene(&self, scene: Scene) {
        *self.pending_scene.lock().unwrap_or_else(|e| e.into_inner()) = Some(scene);
        let mut c = self.lock();
        c.tree_generation += 1;
        c.view_generation += 1;
        self.changed.notify_all();
    }

    /// The scene loaded again, if there is one to take up.
    pub fn take_pending_scene(&self) -> Option<Scene> {
        self.pending_scene
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take()
    }

    pub fn notify(&self, message: ServerMessage) {
        self.notices.send_replace(Some(Arc::new(message)));
    }

    /// Waits `time`, or less if the session shuts down; whether it is still running.
    pub fn sleep(&self, time: Duration) -> bool {
        let c = self.lock();
        let (c, _) = self
            .changed
            .wait_timeout_while(c, time, |c| !c.shutdown)
            .unwrap_or_else(|e| e.into_inner());
        !c.shutdown
    }

    pub fn shut_down(&self) {
        self.lock().shutdown = true;
        self.changed.notify_all();
    }

    pub fn client_joined(&self) {
        let _guard = self.lock();
        self.clients.fetch_add(1, Ordering::SeqCst);
        self.changed.notify_all();
    }

    pub fn client_left(&self) {
        let _guard = self.lock();
        self.clients.fetch_sub(1, Ordering::SeqCst);
        self.changed.notify_all();
    }

    pub fn clients(&self) -> usize {
        self.clients.load(Ordering::SeqCst)
    }

    /// Waits until some page is open and `has_work` says there is work, or until shut
    /// down (`None`).
    pub fn wait_for_work(&self, has_work: impl Fn(&Control) -> bool) -> Option<Control> {
        let mut c = self.lock();
        self.busy.store(false, Ordering::SeqCst);
        loop {
            if c.shutdown {
                return None;
            }
            if self.clients() > 0 && has_work(&c) {
                self.busy.store(true, Ordering::SeqCst);
                return Some(c.clone());
            }
            c = self.changed.wait(c).unwrap_or_else(|e| e.into_inner());
        }
    }

    /// Whether the render thread is at work.
    pub fn busy(&self) -> bool {
        self.busy.load(Ordering::SeqCst)
    }

    /// The next frame's number; also how many frames were made so far.
    pub fn next_sequence(&self) -> u64 {
        self.sequence.fetch_add(1, Ordering::SeqCst)
    }

    pub fn frames_made(&self) -> u64 {
        self.sequence.load(Ordering::SeqCst)
    }

    /// Whether a job started under `started` should go on: nothing changed, some page
    /// is open, no shutdown.
    pub fn still_current(&self, started: &Control) -> bool {
        let c = self.lock();
        !c.shutdown
            && self.clients() > 0
            && c.view_generation == started.view_generation
            && c.tree_generation == started.tree_generation
    }

    pub fn publish_shown(&self, shown: Shown) {
        *self.shown.lock().unwrap_or_else(|e| e.into_inner()) = Some(Arc::new(shown));
    }

    pub fn publish_frame(&self, frame: Frame) {
        self.frames.send_replace(Some(Arc::new(frame)));
    }

    pub fn publish_tree(&self, report: TreeReport) {
        self.trees.send_replace(Some(Arc::new(report)));
    }
}
