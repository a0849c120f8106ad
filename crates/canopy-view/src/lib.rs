//! canopy-view: `canopy view`, an interactive view of a scene in the browser.
//!
//! [`ViewServer::start`] serves a page (built into the binary) on a local address and
//! renders the scene progressively while a page is open: a quick preview at once, then
//! the full image pass by pass through canopy-job, each pass sent as a frame over a
//! WebSocket. The page moves the camera, changes the settings, rebuilds the tree with
//! another builder, width or leaf size (its statistics shown), shows the traversal-cost
//! heat map or the tree's boxes, walks a clicked pixel's primary ray through the tree,
//! descends the tree node by node and saves the image. Where given a way to load the
//! scene again, the viewer follows its files and shows each saved version. Every request
//! needs the random token in the printed address.
//!
//! The library never prints: the caller shows [`ViewServer::url`].
//!
//! ```no_run
//! let scene = canopy_render::load_scene("paper-1").unwrap();
//! let server = canopy_view::ViewServer::start(scene, canopy_view::ViewOptions::default()).unwrap();
//! println!("{}", server.url());
//! server.wait();
//! ```

mod frame;
pub mod protocol;
mod renderer;
pub mod save;
mod server;
mod session;
pub mod settings;
pub mod tree_view;
pub mod walk;
mod watcher;

pub use settings::{Mode, TreeSettings, ViewSettings};
pub use watcher::Reload;

use axum::serve::ListenerExt;
use canopy_job::{Device, RenderOptions};
use canopy_render::Scene;
use session::Session;
use std::net::{SocketAddr, TcpListener};
use std::path::PathBuf;
use std::sync::Arc;
use std::thread::JoinHandle;
use thiserror::Error;

/// Kernel send buffer of each connection: about one large frame. The kernel's own
/// (up to megabytes) would hold a slow page's frames for seconds; with this one a send
/// waits instead, and frames made meanwhile are replaced by the latest.
const SEND_BUFFER_BYTES: usize = 128 * 1024;

/// How a viewer is served.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// Where to listen: loopback, a free port, by default. Another address exposes the
    /// viewer (still behind its token) on purpose.
    pub bind: SocketAddr,
    /// The render options to start with, canopy's as `canopy render` takes them: the
    /// scene's settings (size, spp, ...) overridden, the tree (builder, width, leaf size,
    /// triangle test), the device (the GPU renders through binary trees, testing
    /// triangles watertight), the schedule, and the worker threads (every core by
    /// default).
    pub render: RenderOptions,
    /// Where the page's "save" writes images.
    pub save_dir: PathBuf,
    /// Loads the scene again when one of its files ([`Scene::inputs`]) changes on disk;
    /// `None`: the scene is not followed (a built-in scene, a scene built in code).
    pub reload: Option<Reload>,
}

impl Default for ViewOptions {
    fn default() -> Self {
        Self {
            bind: SocketAddr::from(([127, 0, 0, 1], 0)),
            render: RenderOptions::default(),
            save_dir: PathBuf::from("."),
            reload: None,
        }
    }
}

/// Why a viewer could not start.
#[derive(Debug, Error)]
pub enum ViewError {
    #[error("cannot listen on {addr}: {cause}")]
    Bind {
        addr: SocketAddr,
        cause: std::io::Error,
    },
    #[error("cannot start the viewer's threads: {0}")]
    Threads(String),
    #[error("{0}")]
    Scene(String),
    #[error("{0}")]
    Options(String),
    #[error("cannot render on the GPU: {0}")]
    Gpu(#[from] canopy_gpu::GpuError),
}

/// A running viewer: its server and render thread. Dropping it shuts both down.
pub struct ViewServer {
    addr: SocketAddr,
    token: Arc<str>,
    session: Arc<Session>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    server: Option<JoinHandle<()>>,
    renderer: Option<JoinHandle<()>>,
    watcher: Option<JoinHandle<()>>,
}

impl ViewServer {
    /// Checks the scene, listens on `options.bind` and starts serving and rendering
    /// (rendering waits for the first page).
    pub fn start(mut scene: Scene, options: ViewOptions) -> Result<ViewServer, ViewError> {
        scene.validate().map_err(ViewError::Scene)?;
        options
            .render
            .apply_to_settings(&mut scene.settings)
            .map_err(ViewError::Options)?;
        let (view, tree, device) =
            settings::starting_options(&ViewSettings::of_scene(&scene), &options.render)
                .map_err(ViewError::Options)?;
        // Opened now, so that a machine without one is told before anything listens.
        let gpu = match device {
            Device::Cpu => None,
            Device::Gpu => Some(canopy_gpu::Gpu::new()?),
        };
        let bind_error = |cause| ViewError::Bind {
            addr: options.bind,
            cause,
        };
        let listener = TcpListener::bind(options.bind).map_err(bind_error)?;
        listener.set_nonblocking(true).map_err(bind_error)?;
        let addr = listener.local_addr().map_err(bind_error)?;
        let token: Arc<str> = new_token().into();
        let inputs = scene.inputs.clone();
        let device_name = gpu.as_ref().map_or("cpu".into(), |gpu| gpu.describe());
        let session = Arc::new(Session::new(scene, view, tree, device, device_name));

        let pool = match options.render.threads {
            Some(n) => Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .map_err(|e| ViewError::Threads(e.to_string()))?,
            ),
            None => None,
        };
        let renderer = {
            let session = session.clone();
            std::thread::Builder::new()
                .name("canopy-view-render".into())
                .spawn(move || match pool {
                    Some(pool) => pool.install(|| renderer::run(&session, gpu.as_ref())),
                    None => renderer::run(&session, gpu.as_ref()),
                })
                .map_err(|e| ViewError::Threads(e.to_string()))?
        };
        let watcher = match options.reload {
            Some(reload) if !inputs.is_empty() => {
                let session = session.clone();
                Some(
                    std::thread::Builder::new()
                        .name("canopy-view-watch".into())
                        .spawn(move || watcher::run(&session, &reload, inputs))
                        .map_err(|e| ViewError::Threads(e.to_string()))?,
                )
            }
            _ => None,
        };
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .map_err(|e| ViewError::Threads(e.to_string()))?;
        let app = server::App {
            session: session.clone(),
            token: token.clone(),
            save_dir: Arc::new(options.save_dir),
        };
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let server = std::thread::Builder::new()
            .name("canopy-view-server".into())
            .spawn(move || {
                runtime.block_on(async move {
                    let Ok(listener) = tokio::net::TcpListener::from_std(listener) else {
                        return;
                    };
                    let listener = listener.tap_io(|stream| {
                        let _ = stream.set_nodelay(true);
                        let _ = socket2::SockRef::from(&*stream)
                            .set_send_buffer_size(SEND_BUFFER_BYTES);
                    });
                    let _ = axum::serve(listener, server::router(app))
                        .with_graceful_shutdown(async {
                            let _ = stopped.await;
                        })
                        .await;
                });
                // Open sockets' tasks are not waited for.
                runtime.shutdown_background();
            })
            .map_err(|e| ViewError::Threads(e.to_string()))?;
        Ok(ViewServer {
            addr,
            token,
            session,
            stop: Some(stop),
            server: Some(server),
            renderer: Some(renderer),
            watcher,
        })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The token every request needs (in the query: `?token=...`).
    pub fn token(&self) -> &str {
        &self.token
    }

    /// The page's address, token included.
    pub fn url(&self) -> String {
        let host = match self.addr.ip() {
            ip if ip.is_unspecified() => "127.0.0.1".to_string(),
            std::net::IpAddr::V6(ip) => format!("[{ip}]"),
            ip => ip.to_string(),
        };
        format!("http://{host}:{}/?token={}", self.addr.port(), self.token)
    }

    /// Pages connected now.
    pub fn clients(&self) -> usize {
        self.session.clients()
    }

    /// Whether the render thread is at work now (it waits while no page is open and
    /// once the view has all its samples).
    pub fn is_rendering(&self) -> bool {
        self.session.busy()
    }

    /// Frames made so far (each sent to every page that can take it).
    pub fn frames_made(&self) -> u64 {
        self.session.frames_made()
    }

    /// Blocks until the server ends (it runs until the process ends or
    /// [`shutdown`](Self::shutdown) is called from elsewhere).
    pub fn wait(mut self) {
        if let Some(server) = self.server.take() {
            let _ = server.join();
        }
    }

    /// Stops serving and rendering: the render thread ends after the pass in flight.
    pub fn shutdown(mut self) {
        self.stop_all();
    }

    fn stop_all(&mut self) {
        self.session.shut_down();
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(server) = self.server.take() {
            let _ = server.join();
        }
        for thread in [self.renderer.take(), self.watcher.take()]
            .into_iter()
            .flatten()
        {
            let _ = thread.join();
        }
    }
}

impl Drop for ViewServer {
    fn drop(&mut self) {
        self.stop_all();
    }
}

/// 128 random bits in hex: unguessable by another local user or a web page.
fn new_token() -> String {
    let a = canopy_render::files::random_u64();
    let b = canopy_render::files::random_u64();
    format!("{a:016x}{b:016x}")
}
