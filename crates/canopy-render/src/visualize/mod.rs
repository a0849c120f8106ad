//! Pictures of BVHs: the tree's boxes drawn over a render, and per-pixel traversal cost
//! as a heat map (the report's Figures 4–8, and what it lacked).

mod colormap;
mod draw;
mod font;
mod heatmap;
mod wireframe;

pub use colormap::turbo;
pub use heatmap::{render_heatmap, Heatmap};
pub use wireframe::{boxes_at_levels, draw_boxes, draw_bvh, LevelRange};
