//! The viewer's messages over its WebSocket, as JSON text; each frame's image follows
//! its [`ServerMessage::Frame`] as one binary message (JPEG).
//!
//! A command from the page is checked whole before it changes anything: a message that
//! is not JSON, names no known command, or holds a value out of range gets an
//! [`ServerMessage::Error`] reply and changes nothing.

use crate::settings::{with_options, Mode, TreeSettings, ViewSettings};
use canopy_job::{Device, RenderOptions};
use canopy_render::camera::CameraSpec;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// Longest command a page may send (every command is far shorter); a longer one gets
/// an error reply.
pub const MAX_MESSAGE_BYTES: usize = 16 * 1024;

/// Longest message the socket takes at all: past this the connection is closed.
pub const MAX_SOCKET_MESSAGE_BYTES: usize = 1 << 20;

/// What the page asks for.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum Command {
    /// Look from here at there: restarts accumulation.
    Camera {
        look_from: [f32; 3],
        look_at: [f32; 3],
        #[serde(default = "up_y")]
        up: [f32; 3],
        vfov: f32,
    },
    /// Settings; a field left out keeps its value. `render` holds canopy's render
    /// options (those of `canopy render` and Python's `render()`, by the same names):
    /// a change of the tree's (`bvh`, `width`, `max_leaf_size`, `fast_triangles`)
    /// rebuilds it, any other restarts accumulation (or continues it where the samples
    /// stay valid). `size`, `device` and `threads` are fixed while the viewer runs.
    Settings {
        #[serde(default)]
        render: RenderOptions,
        exposure: Option<f32>,
        mode: Option<Mode>,
        /// The tree levels the `boxes` mode draws, first and last (the root is 0).
        levels: Option<[u32; 2]>,
    },
    /// The walk of the primary ray through pixel (x, y) of the full-size image.
    Pick { x: u32, y: u32 },
    /// Write the image shown (`png`, as shown, or `exr`, linear) into the viewer's folder.
    Save { format: String },
    /// The children of a node (`None`: the root) of a tree (`None`: the one over the
    /// scene's own primitives), for the tree's view.
    Node {
        #[serde(default)]
        tree: Option<TreeRef>,
        index: Option<usize>,
    },
}

/// One of the structure's trees: the top one over the instances (`"top"`), or the tree
/// of structure `n` (`{"structure": n}`; 0 holds the scene's own primitives, the meshes
/// follow in order).
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum TreeRef {
    Top,
    Structure(u32),
}

impl Default for TreeRef {
    fn default() -> Self {
        TreeRef::Structure(0)
    }
}

fn up_y() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}

/// What a checked command changes.
#[derive(Clone, Debug, PartialEq)]
pub enum Change {
    View(ViewSettings),
    /// New settings, and the tree to render through (built again where it changed).
    Settings {
        view: ViewSettings,
        tree: TreeSettings,
    },
    Pick {
        x: u32,
        y: u32,
    },
    Save(crate::save::SaveFormat),
    Node {
        tree: TreeRef,
        index: Option<usize>,
    },
}

impl Command {
    /// Parses a message from the page.
    pub fn parse(text: &str) -> Result<Command, String> {
        if text.len() > MAX_MESSAGE_BYTES {
            return Err(format!(
                "message of {} bytes, more than {MAX_MESSAGE_BYTES}",
                text.len()
            ));
        }
        serde_json::from_str(text).map_err(|e| format!("not a command: {e}"))
    }

    /// What the command changes in the `current` view and `tree` of a viewer on
    /// `device`, or why it cannot be done (`width` and `height` are the image's, for
    /// picks).
    pub fn apply(
        self,
        current: &ViewSettings,
        tree: &TreeSettings,
        device: Device,
        (width, height): (u32, u32),
    ) -> Result<Change, String> {
        match self {
            Command::Camera {
                look_from,
                look_at,
                up,
                vfov,
            } => {
                let camera = CameraSpec {
                    look_from: finite_vec("look_from", look_from)?,
                    look_at: finite_vec("look_at", look_at)?,
                    up: finite_vec("up", up)?,
                    vfov,
                    ..current.camera
                };
                check_camera(&camera)?;
                Ok(Change::View(ViewSettings {
                    camera,
                    ..current.clone()
                }))
            }
            Command::Settings {
                render,
                exposure,
                mode,
                levels,
            } => {
                let (mut next, tree) = with_options(current, tree, &render, device)?;
                if let Some(exposure) = exposure {
                    if !(-20.0..=20.0).contains(&exposure) {
                        return Err(format!(
                            "exposure must be in -20..=20 stops, not {exposure}"
                        ));
                    }
                    next.exposure = exposure;
                }
                if let Some(mode) = mode {
                    next.mode = mode;
                }
                if let Some([first, last]) = levels {
                    if first > last || last > 64 {
                        return Err(format!(
                            "levels must be first <= last <= 64, not {first}..{last}"
                        ));
                    }
                    next.levels = [first, last];
                }
                Ok(Change::Settings { view: next, tree })
            }
            Command::Pick { x, y } => {
                if x >= width || y >= height {
                    return Err(format!(
                        "pixel ({x}, {y}) is outside the {width}x{height} image"
                    ));
                }
                Ok(Change::Pick { x, y })
            }
            Command::Save { format } => Ok(Change::Save(crate::save::SaveFormat::parse(&format)?)),
            Command::Node { tree, index } => Ok(Change::Node {
                tree: tree.unwrap_or_default(),
                index,
            }),
        }
    }
}

fn finite_vec(name: &str, v: [f32; 3]) -> Result<Vec3, String> {
    match v.iter().all(|c| c.is_finite() && c.abs() < 1e30) {
        true => Ok(Vec3::from(v)),
        false => Err(format!("{name} must be three finite numbers, not {v:?}")),
    }
}

/// A camera the renderer can use: apart eye and target, an up that is not along the
/// view, a field of view strictly between 0 and 180 degrees.
fn check_camera(camera: &CameraSpec) -> Result<(), String> {
    let forward = camera.look_at - camera.look_from;
    if forward.length() <= 1e-6 * camera.look_from.abs().max_element().max(1.0) {
        return Err("look_from and look_at must be apart".into());
    }
    if forward
        .normalize()
        .cross(camera.up.normalize_or_zero())
        .length()
        < 1e-4
    {
        return Err("up must not be along the viewing direction".into());
    }
    if !(camera.vfov > 0.01 && camera.vfov < 179.0) {
        return Err(format!(
            "vfov must be between 0.01 and 179 degrees, not {}",
            camera.vfov
        ));
    }
    Ok(())
}

/// A camera as the page holds it.
#[derive(Clone, Debug, Serialize)]
pub struct CameraState {
    pub look_from: [f32; 3],
    pub look_at: [f32; 3],
    pub up: [f32; 3],
    pub vfov: f32,
}

impl From<&CameraSpec> for CameraState {
    fn from(c: &CameraSpec) -> Self {
        Self {
            look_from: c.look_from.to_array(),
            look_at: c.look_at.to_array(),
            up: c.up.to_array(),
            vfov: c.vfov,
        }
    }
}

/// A builder the page may choose.
#[derive(Clone, Debug, Serialize)]
pub struct BuilderInfo {
    pub name: &'static str,
    pub description: &'static str,
}

/// The tree being rendered through, and what it cost.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct TreeReport {
    pub builder: String,
    /// Primitives of the scene's own and mesh instances, for telling a reload.
    pub primitives: usize,
    pub instances: usize,
    pub width: u32,
    pub max_leaf_size: u32,
    /// Triangles tested without the watertight test's double-precision step.
    pub fast_triangles: bool,
    pub build_ms: f64,
    /// SAH cost with the root's area as 1 (the scene's own primitives' tree).
    pub sah: f32,
    /// EPO with the scene's area as 1, where the scene has no spheres.
    pub epo: Option<f32>,
    pub depth: usize,
    pub nodes: usize,
    pub leaves: usize,
    /// Bytes of every structure: the primitives' tree, each mesh's and the top one.
    pub memory_bytes: usize,
    /// Structures with a tree of their own (the scene's primitives', then each mesh's),
    /// and whether a top tree over the instances is there: the trees the tree's view
    /// offers.
    pub structures: usize,
    pub top_tree: bool,
}

/// A box as the page takes it: min and max corners.
pub(crate) fn corners(b: &canopy_bvh::Aabb) -> [[f32; 3]; 2] {
    [b.min.to_array(), b.max.to_array()]
}

/// One node of a primary ray's walk, in the order visited.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct WalkStep {
    /// The tree the node is in: `None`, the top tree over the instances; `Some(k)`, the
    /// tree of instance `k`'s structure (0: the scene's own primitives; from 1, the mesh
    /// instances).
    pub instance: Option<u32>,
    /// Level from the top of the whole walk (the top tree's root is 0; an instance's
    /// tree starts one below the top tree's leaf that holds it).
    pub level: u32,
    /// The node's box in the world, min and max corners (a box of an instance's tree is
    /// the world box of its placed corners).
    pub bounds: [[f32; 3]; 2],
    /// A leaf: what it holds, in order — instances in the top tree, primitives (tested)
    /// in an instance's tree.
    pub leaf: Option<Vec<u32>>,
    /// An inner node: how many of its children the ray entered and skipped.
    pub entered: u32,
    pub skipped: u32,
}

/// Where a picked ray hit.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct PickHit {
    pub t: f32,
    pub instance: u32,
    pub primitive: u32,
    pub material: Option<String>,
}

/// The first message on a socket: the scene and everything the controls offer.
#[derive(Clone, Debug, Serialize)]
pub struct Hello {
    pub scene: String,
    pub width: u32,
    pub height: u32,
    pub camera: CameraState,
    pub settings: ViewSettingsState,
    /// Where it renders: `cpu` or `gpu`, and the device in words.
    pub device: String,
    pub device_name: String,
    pub builders: Vec<BuilderInfo>,
    /// The tree widths the device renders through (the GPU's: 2), and whether it
    /// offers the fast triangle test (the CPU).
    pub widths: Vec<u32>,
    pub fast_triangles: bool,
    pub modes: Vec<Mode>,
    pub integrators: Vec<String>,
    pub samplers: Vec<String>,
}

/// What the server tells the page.
#[derive(Clone, Debug, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ServerMessage {
    /// First message on a socket: the scene and everything the controls offer.
    Hello(Box<Hello>),
    /// The tree after a build.
    Tree(TreeReport),
    /// An image follows as the next (binary) message.
    Frame(FrameInfo),
    /// The walk of a picked pixel's primary ray.
    Walk {
        x: u32,
        y: u32,
        /// Some structure the ray reached has no tree to show.
        partial: bool,
        steps: Vec<WalkStep>,
        primitives_tested: u32,
        hit: Option<PickHit>,
    },
    /// The image was written here.
    Saved { path: String },
    /// The scene's files changed on disk and it was loaded again (the camera kept).
    Reloaded { primitives: usize, instances: usize },
    /// A node of the tree and its children, for the tree's view.
    Node(NodeReport),
    /// A command that changed nothing, or a reload that failed, and why.
    Error { message: String },
}

/// A node of the tree and its children, each with what it costs.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct NodeReport {
    pub tree: TreeRef,
    /// `None`: the root.
    pub index: Option<usize>,
    pub bounds: [[f32; 3]; 2],
    pub children: Vec<NodeChild>,
}

/// One child of a node in the tree's view.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct NodeChild {
    /// The index to ask for its children; `None` for a leaf.
    pub index: Option<usize>,
    pub bounds: [[f32; 3]; 2],
    /// Primitive references below it.
    pub primitives: usize,
    /// Inner nodes and leaves below it, itself included.
    pub nodes: usize,
    pub leaves: usize,
    /// Its share of the tree's SAH cost: the cost of its subtree (nodes visited and
    /// primitives tested, weighted by the chance that a ray through the root's box
    /// enters each box) over the whole tree's.
    pub sah_share: f32,
    /// A leaf of the top tree: the structures its instances place (each a tree to
    /// descend into); empty otherwise.
    pub structures: Vec<u32>,
}

/// The settings as the page shows them: the render options the viewer changes (the
/// others left out), and what only the viewer has.
#[derive(Clone, Debug, Serialize)]
pub struct ViewSettingsState {
    pub render: RenderOptions,
    pub exposure: f32,
    pub mode: Mode,
    pub levels: [u32; 2],
}

/// What a frame shows.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct FrameInfo {
    /// Counts frames since the server started.
    pub sequence: u64,
    /// Counts restarts of accumulation (camera or settings changes).
    pub generation: u64,
    pub mode: Mode,
    /// A quick image at reduced size, shown until the first full-size pass.
    pub preview: bool,
    pub width: u32,
    pub height: u32,
    /// Samples per pixel in the image, and the target.
    pub spp: u32,
    pub target_spp: u32,
    /// The samples this accumulation continued from, kept over a change that leaves
    /// them valid (exposure, a higher target, another tree); 0 when it started afresh.
    pub continued_from: u32,
    /// Since accumulation restarted.
    pub seconds: f64,
    pub mrays_per_second: f64,
    /// The process's resident memory, where the system tells it.
    pub memory_bytes: Option<u64>,
}
