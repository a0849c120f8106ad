//! What the viewer renders: the view (camera, samples, estimator, what is shown) and the
//! tree (builder, width, leaf size). A change of the view restarts accumulation; a change
//! of the tree rebuilds it first.

use canopy_bvh::{BuildParams, Builder, BvhWidth};
use canopy_render::camera::CameraSpec;
use canopy_render::{AovSet, Integrator, Scene};
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
            exposure: 0.0,
            mode: Mode::Render,
            levels: [0, 3],
        }
    }

    /// Whether going from `self` to `next` leaves the accumulated samples valid: only
    /// the exposure, the target spp, the boxes drawn over the render or their levels, or
    /// the layer shown of the same layers changed (the caller checks that the samples
    /// are not more than the new target).
    pub fn keeps_samples(&self, next: &ViewSettings) -> bool {
        self.camera == next.camera
            && self.max_depth == next.max_depth
            && self.integrator == next.integrator
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
}

impl Default for TreeSettings {
    fn default() -> Self {
        Self {
            builder: Builder::default(),
            width: BvhWidth::default(),
            max_leaf_size: BuildParams::default().max_leaf_size,
        }
    }
}

impl TreeSettings {
    /// A tree of `builder` with a width and a leaf size as a page or a caller gives
    /// them (children per node; primitives), or why there is none such.
    pub fn new(builder: Builder, width: u32, max_leaf_size: u32) -> Result<Self, String> {
        let width: BvhWidth = width.to_string().parse()?;
        if !(1..=256).contains(&max_leaf_size) {
            return Err(format!(
                "max_leaf_size must be in 1..=256, not {max_leaf_size}"
            ));
        }
        Ok(Self {
            builder,
            width,
            max_leaf_size,
        })
    }

    pub fn params(&self) -> BuildParams {
        BuildParams {
            max_leaf_size: self.max_leaf_size,
            ..BuildParams::default()
        }
    }
}
