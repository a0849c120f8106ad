//! What the viewer renders: the view (camera, samples, estimator, sampler, what is shown)
//! and the tree (builder, width, leaf size, triangle test), and how canopy's render
//! options (`canopy_job::RenderOptions`, the settings of every front end) are put into
//! them. A change of the view restarts accumulation; a change of the tree rebuilds it
//! first.

use canopy_bvh::{BuildParams, Builder, BvhWidth, TriangleTest};
use canopy_job::{Device, RenderOptions};
use canopy_render::camera::CameraSpec;
use canopy_render::{AccelKind, AovSet, Integrator, Sampler, Scene, Schedule};
use serde::{Deserialize, Serialize};

/// What the image shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// The path-traced image, refining pass by pass.
    #[default]
    Render,
    /// Each pixel's primary-ray traversal cost (node visits plus primitive tests).
    Heatmap,
    /// The render with the tree's boxes of the chosen levels drawn over it.
    Boxes,
    /// The albedo a denoiser takes: the first surface past mirrors and glass.
    Albedo,
    /// The shading normal there, as colour (x, y, z from -1..1 to 0..1).
    Normal,
}

impl Mode {
    pub const ALL: [Mode; 5] = [
        Mode::Render,
        Mode::Heatmap,
        Mode::Boxes,
        Mode::Albedo,
        Mode::Normal,
    ];

    /// The AOV layers a render of this mode accumulates.
    pub fn aovs(self) -> AovSet {
        match self {
            Mode::Albedo | Mode::Normal => AovSet::DENOISING,
            Mode::Render | Mode::Heatmap | Mode::Boxes => AovSet::NONE,
        }
    }
}

/// The view: changing any of it restarts accumulation.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewSettings {
    pub camera: CameraSpec,
    /// Samples per pixel to refine to.
    pub spp: u32,
    pub max_depth: u32,
    pub integrator: Integrator,
    pub seed: u64,
    pub russian_roulette: bool,
    pub sampler: Sampler,
    /// The order paths are traced in (the image is the same in each).
    pub schedule: Schedule,
    /// Stops of exposure applied to the image shown (not to the samples).
    pub exposure: f32,
    pub mode: Mode,
    /// Tree levels drawn in [`Mode::Boxes`], first and last.
    pub levels: [u32; 2],
}

impl ViewSettings {
    /// The scene's own camera and settings.
    pub fn of_scene(scene: &Scene) -> Self {
        let s = scene.settings;
        Self {
            camera: scene.camera,
            spp: s.spp,
            max_depth: s.max_depth,
            integrator: s.integrator,
            seed: s.seed,
            russian_roulette: s.russian_roulette,
            sampler: s.sampler,
            schedule: Schedule::default(),
            exposure: 0.0,
            mode: Mode::Render,
            levels: [0, 3],
        }
    }

    /// Whether going from `self` to `next` leaves the accumulated samples valid: only
    /// the exposure, the target spp, the schedule, the boxes drawn over the render or
    /// their levels, or the layer shown of the same layers changed (the caller checks
    /// that the samples are not more than the new target).
    pub fn keeps_samples(&self, next: &ViewSettings) -> bool {
        self.camera == next.camera
            && self.max_depth == next.max_depth
            && self.integrator == next.integrator
            && self.seed == next.seed
            && self.russian_roulette == next.russian_roulette
            && self.sampler == next.sampler
            && self.mode != Mode::Heatmap
            && next.mode != Mode::Heatmap
            && self.mode.aovs() == next.mode.aovs()
    }
}

/// The tree rendered through.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TreeSettings {
    pub builder: Builder,
    pub width: BvhWidth,
    pub max_leaf_size: u32,
    pub triangle_test: TriangleTest,
}

impl Default for TreeSettings {
    fn default() -> Self {
        Self {
            builder: Builder::default(),
            width: BvhWidth::default(),
            max_leaf_size: BuildParams::default().max_leaf_size,
            triangle_test: TriangleTest::default(),
        }
    }
}

impl TreeSettings {
    /// The tree a viewer on `device` starts with: the default, binary on the GPU
    /// (which walks binary trees).
    pub fn on(device: Device) -> Self {
        let default = Self::default();
        match device {
            Device::Cpu => default,
            Device::Gpu => Self {
                width: BvhWidth::Two,
                ..default
            },
        }
    }

    /// Why `device` cannot render through this tree, if it cannot: the GPU walks
    /// binary trees and tests triangles watertight.
    pub fn check_for(&self, device: Device) -> Result<(), String> {
        match device {
            Device::Gpu if self.width != BvhWidth::Two => Err(format!(
                "`width` {} is for the CPU: the GPU walks binary trees (width 2)",
                self.width.children()
            )),
            Device::Gpu if self.triangle_test == TriangleTest::Fast => {
                Err("`fast_triangles` is for the CPU: the GPU's triangle test is watertight".into())
            }
            _ => Ok(()),
        }
    }

    /// The tree widths `device` renders through, and whether it offers the fast
    /// triangle test: what [`check_for`](Self::check_for) lets through, for the page.
    pub fn offered_on(device: Device) -> (Vec<u32>, bool) {
        let base = Self::on(device);
        let widths = BvhWidth::ALL
            .into_iter()
            .filter(|&width| Self { width, ..base }.check_for(device).is_ok())
            .map(BvhWidth::children)
            .collect();
        let fast = Self {
            triangle_test: TriangleTest::Fast,
            ..base
        };
        (widths, fast.check_for(device).is_ok())
    }

    pub fn params(&self) -> BuildParams {
        BuildParams {
            max_leaf_size: self.max_leaf_size,
            ..BuildParams::default()
        }
    }
}

/// Options a running viewer cannot change: they are given when it starts.
const FIXED_OPTIONS: [&str; 3] = ["size", "device", "threads"];

/// The view and tree with `options` put in, or why they cannot be: an option out of
/// range, one the viewer cannot change while it runs (`size`, `device`, `threads`), a
/// tree `device` cannot render through, or no tree (`bvh = "none"`: the viewer walks a
/// tree).
pub fn with_options(
    view: &ViewSettings,
    tree: &TreeSettings,
    options: &RenderOptions,
    device: Device,
) -> Result<(ViewSettings, TreeSettings), String> {
    if let Some(name) = options
        .given()
        .into_iter()
        .find(|n| FIXED_OPTIONS.contains(n))
    {
        return Err(format!(
            "`{name}` is set when the viewer starts and cannot change while it runs"
        ));
    }
    put_in(view, tree, options, device)
}

/// The view, tree and device a viewer starts with: `view` (the scene's) with
/// `options` put in, as [`with_options`] does, where the size and threads are the
/// caller's to apply.
pub fn starting_options(
    view: &ViewSettings,
    options: &RenderOptions,
) -> Result<(ViewSettings, TreeSettings, Device), String> {
    let device = options.device.unwrap_or_default();
    let (view, tree) = put_in(view, &TreeSettings::on(device), options, device)?;
    Ok((view, tree, device))
}

fn put_in(
    view: &ViewSettings,
    tree: &TreeSettings,
    options: &RenderOptions,
    device: Device,
) -> Result<(ViewSettings, TreeSettings), String> {
    options.check()?;
    let mut settings = canopy_render::RenderSettings {
        spp: view.spp,
        max_depth: view.max_depth,
        seed: view.seed,
        integrator: view.integrator,
        russian_roulette: view.russian_roulette,
        sampler: view.sampler,
        ..canopy_render::RenderSettings::default()
    };
    let without_size = RenderOptions {
        size: None,
        ..options.clone()
    };
    without_size.apply_to_settings(&mut settings)?;
    let next_view = ViewSettings {
        spp: settings.spp,
        max_depth: settings.max_depth,
        seed: settings.seed,
        integrator: settings.integrator,
        russian_roulette: settings.russian_roulette,
        sampler: settings.sampler,
        schedule: options.schedule.unwrap_or(view.schedule),
        ..view.clone()
    };
    let builder = match options.bvh {
        None => tree.builder,
        Some(AccelKind::Bvh(builder)) => builder,
        Some(AccelKind::None) => {
            return Err("the viewer renders through a tree: choose a builder, not `none`".into())
        }
    };
    let next_tree = TreeSettings {
        builder,
        width: options.width.unwrap_or(tree.width),
        max_leaf_size: options.max_leaf_size.unwrap_or(tree.max_leaf_size),
        triangle_test: match options.fast_triangles {
            None => tree.triangle_test,
            Some(true) => TriangleTest::Fast,
            Some(false) => TriangleTest::Watertight,
        },
    };
    next_tree.check_for(device)?;
    Ok((next_view, next_tree))
}

/// The options a page shows: every one the viewer changes, as they are now.
pub fn current_options(view: &ViewSettings, tree: &TreeSettings) -> RenderOptions {
    RenderOptions {
        spp: Some(view.spp),
        max_depth: Some(view.max_depth),
        seed: Some(view.seed),
        integrator: Some(view.integrator),
        russian_roulette: Some(view.russian_roulette),
        sampler: Some(view.sampler),
        bvh: Some(AccelKind::Bvh(tree.builder)),
        width: Some(tree.width),
        max_leaf_size: Some(tree.max_leaf_size),
        fast_triangles: Some(tree.triangle_test == TriangleTest::Fast),
        schedule: Some(view.schedule),
        ..RenderOptions::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn start() -> (ViewSettings, TreeSettings) {
        let scene = canopy_render::load_scene("paper-1").unwrap();
        (ViewSettings::of_scene(&scene), TreeSettings::default())
    }

    #[test]
    fn options_a_running_viewer_cannot_change_are_refused_by_name() {
        let (view, tree) = start();
        for name in FIXED_OPTIONS {
            let options = RenderOptions::from_json(&match name {
                "size" => r#"{"size": [8, 8]}"#.to_string(),
                "device" => r#"{"device": "cpu"}"#.to_string(),
                _ => format!(r#"{{"{name}": 1}}"#),
            })
            .unwrap();
            let e = with_options(&view, &tree, &options, Device::Cpu).unwrap_err();
            assert!(e.contains(name), "{e}");
        }
    }

    #[test]
    fn what_changes_the_samples_restarts_them_and_the_tree_options_go_to_the_tree() {
        let (view, tree) = start();
        let change = |json: &str| {
            let options = RenderOptions::from_json(json).unwrap();
            with_options(&view, &tree, &options, Device::Cpu).unwrap()
        };
        for restarts in [
            r#"{"seed": 5}"#,
            r#"{"sampler": "independent"}"#,
            r#"{"russian_roulette": false}"#,
            r#"{"max_depth": 2}"#,
        ] {
            let (next, next_tree) = change(restarts);
            assert!(!view.keeps_samples(&next), "{restarts}");
            assert_eq!(next_tree, tree, "{restarts}");
        }
        let (next, next_tree) = change(r#"{"spp": 99, "schedule": "depth"}"#);
        assert!(view.keeps_samples(&next));
        assert_eq!((next.spp, next.schedule), (99, Schedule::Depth));
        assert_eq!(next_tree, tree);
        let (next, next_tree) = change(r#"{"bvh": "lbvh", "fast_triangles": true}"#);
        assert_eq!(next, view);
        assert_eq!(next_tree.builder, Builder::Lbvh);
        assert_eq!(next_tree.triangle_test, TriangleTest::Fast);
        // What the page is shown reads back as the same view and tree.
        let shown = current_options(&next, &next_tree);
        assert_eq!(
            with_options(&view, &tree, &shown, Device::Cpu).unwrap(),
            (next, next_tree)
        );
    }

    #[test]
    fn a_viewer_on_the_gpu_walks_binary_watertight_trees() {
        let (view, _) = start();
        let (_, tree, device) = starting_options(
            &view,
            &RenderOptions::from_json(r#"{"device": "gpu", "bvh": "lbvh"}"#).unwrap(),
        )
        .unwrap();
        assert_eq!(device, Device::Gpu);
        assert_eq!((tree.builder, tree.width), (Builder::Lbvh, BvhWidth::Two));
        for (json, named) in [
            (r#"{"device": "gpu", "width": 8}"#, "width"),
            (
                r#"{"device": "gpu", "fast_triangles": true}"#,
                "fast_triangles",
            ),
        ] {
            let options = RenderOptions::from_json(json).unwrap();
            let e = starting_options(&view, &options).unwrap_err();
            assert!(e.contains(named), "{json}: {e}");
        }
        // And while it runs: another builder or leaf size is built, a wider tree or
        // the fast test refused by name.
        let change = |json: &str| {
            let options = RenderOptions::from_json(json).unwrap();
            with_options(&view, &tree, &options, Device::Gpu)
        };
        let (_, next) = change(r#"{"bvh": "ploc", "max_leaf_size": 2}"#).unwrap();
        assert_eq!((next.builder, next.max_leaf_size), (Builder::Ploc, 2));
        assert!(change(r#"{"width": 4}"#).unwrap_err().contains("width"));
        assert!(change(r#"{"fast_triangles": true}"#)
            .unwrap_err()
            .contains("fast_triangles"));
        assert!(change(r#"{"width": 2, "fast_triangles": false}"#).is_ok());
    }
}
