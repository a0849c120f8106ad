//! `canopy view`: the interactive viewer (canopy-view) on a local address, until Ctrl-C;
//! the scene is loaded again whenever its files change.

use crate::limits;
use canopy_bvh::{BuildParams, Builder};
use canopy_job::{Device, RenderOptions};
use canopy_render::{AccelKind, BvhWidth};
use canopy_view::{Reload, ViewOptions, ViewServer};
use clap::Args;
use std::net::SocketAddr;
use std::path::PathBuf;

#[derive(Args)]
pub struct ViewArgs {
    /// Built-in scene name (see `canopy scenes`), scene file, glTF model, or OBJ/PLY mesh.
    scene: String,
    /// Where to listen. The default is this machine only, on a free port; another
    /// address (`0.0.0.0:8700`) exposes the viewer on purpose, still behind its token.
    #[arg(long, default_value = "127.0.0.1:0")]
    bind: SocketAddr,
    /// Open the page in the default browser.
    #[arg(long)]
    open: bool,
    /// Image size as WIDTHxHEIGHT, each 1 to 65536 [default: from the scene].
    #[arg(long, value_parser = limits::size)]
    size: Option<(u32, u32)>,
    /// Samples per pixel to refine to, 1 to 16777216 [default: from the scene].
    #[arg(long, value_parser = limits::spp())]
    spp: Option<u32>,
    /// Maximum ray segments per path, 1 to 1024 [default: from the scene].
    #[arg(long, value_parser = limits::depth())]
    depth: Option<u32>,
    /// Where to render: `cpu` (all cores) or `gpu` (the first adapter wgpu finds; see
    /// `canopy devices`). The GPU renders through binary trees; the heat map, the
    /// albedo and normal views and the explorer's walks are traced on the CPU.
    #[arg(long, default_value = "cpu", value_parser = crate::render::parse_device)]
    device: Device,
    /// Worker threads, 1 to 1024 [default: all cores].
    #[arg(long, value_parser = limits::threads())]
    threads: Option<u32>,
    /// The BVH builder to start with (the page rebuilds with others).
    #[arg(long, default_value = "binned-sah")]
    bvh: Builder,
    /// Children per node to start with: 2, 4 or 8 [default: 8; 2 on the GPU, which
    /// walks binary trees].
    #[arg(long)]
    width: Option<BvhWidth>,
    /// Most primitives in a leaf to start with (1 to 256).
    #[arg(long, default_value_t = BuildParams::default().max_leaf_size, value_parser = limits::leaf_size())]
    max_leaf_size: u32,
    /// A folder the scene may also read files from (see `canopy render --allow-path`).
    #[arg(long, value_name = "DIR")]
    allow_path: Vec<PathBuf>,
    /// Where the page's "Save" writes images, as `<scene>-<n>.png` or `.exr` under new
    /// names [default: the current folder].
    #[arg(long, value_name = "DIR", default_value = ".")]
    output_dir: PathBuf,
    /// Do not load the scene again when its files change on disk.
    #[arg(long)]
    no_reload: bool,
}

impl ViewArgs {
    /// The render options the viewer starts with, as the flags give them.
    fn options(&self) -> RenderOptions {
        RenderOptions {
            size: self.size.map(|(width, height)| [width, height]),
            spp: self.spp,
            max_depth: self.depth,
            bvh: Some(AccelKind::Bvh(self.bvh)),
            width: self.width,
            device: Some(self.device),
            max_leaf_size: Some(self.max_leaf_size),
            threads: self.threads.map(|n| n as usize),
            ..RenderOptions::default()
        }
    }
}

pub fn run(args: &ViewArgs) -> anyhow::Result<()> {
    let scene = canopy_render::load_scene_allowing(&args.scene, &args.allow_path)?;
    // Found now, not at the first save (a folder that is not writable is told then).
    if !args.output_dir.is_dir() {
        anyhow::bail!(
            "{}: --output-dir must be an existing folder",
            args.output_dir.display()
        );
    }
    let reload = (!args.no_reload).then(|| {
        let (name, allowed) = (args.scene.clone(), args.allow_path.clone());
        Reload::new(move || {
            canopy_render::load_scene_allowing(&name, &allowed).map_err(|e| e.to_string())
        })
    });
    let options = ViewOptions {
        bind: args.bind,
        save_dir: args.output_dir.clone(),
        reload,
        render: args.options(),
    };
    let server = ViewServer::start(scene, options)?;
    let url = server.url();
    outln!("canopy view: {} at", args.scene);
    outln!("  {url}");
    outln!("Ctrl-C stops the server.");
    if args.open {
        if let Err(e) = open_browser(&url) {
            eprintln!("warning: could not open a browser ({e}); open the address above");
        }
    }
    server.wait();
    Ok(())
}

/// Hands the address to the desktop's opener.
fn open_browser(url: &str) -> std::io::Result<()> {
    let mut command = match std::env::consts::OS {
        "macos" => std::process::Command::new("open"),
        "windows" => {
            let mut c = std::process::Command::new("cmd");
            c.args(["/C", "start", ""]);
            c
        }
        _ => std::process::Command::new("xdg-open"),
    };
    command
        .arg(url)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .map(drop)
}
