//! The boxes of a BVH drawn over an image as wireframes, coloured by depth, with a legend
//! (the report's Figure 4).

use super::colormap::turbo;
use super::draw::Canvas;
use super::font::text_width;
use crate::camera::Camera;
use crate::film::Film;
use canopy_bvh::{Aabb, Tree};
use glam::Vec3;
use std::str::FromStr;

/// Tree levels to draw, inclusive; the root is level 0.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LevelRange {
    pub first: usize,
    pub last: usize,
}

impl LevelRange {
    pub const ALL: LevelRange = LevelRange {
        first: 0,
        last: usize::MAX,
    };

    pub fn contains(&self, level: usize) -> bool {
        (self.first..=self.last).contains(&level)
    }
}

impl FromStr for LevelRange {
    type Err = String;

    /// `a..b` (inclusive), `a..` or a single level `a`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let level = |t: &str| {
            t.trim()
                .parse::<usize>()
                .map_err(|_| format!("`{s}` is not a level range like 2..5"))
        };
        let (first, last) = match s.split_once("..") {
            Some((a, "")) => (level(a)?, usize::MAX),
            Some((a, b)) => (level(a)?, level(b.trim_start_matches('='))?),
            None => (level(s)?, level(s)?),
        };
        if first > last {
            return Err(format!("level range `{s}` is empty"));
        }
        Ok(Self { first, last })
    }
}

/// Every node box of the tree whose level is in `levels`, with its level, shallowest first
/// (for a wide tree, a node's children are one level below it).
pub fn boxes_at_levels(tree: &Tree, levels: LevelRange) -> Vec<(Aabb, usize)> {
    tree.boxes_at_levels(levels.first, levels.last)
}

/// The twelve edges of a box, as pairs of corners.
fn edges(b: &Aabb) -> [(Vec3, Vec3); 12] {
    let c = |i: usize| {
        Vec3::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        )
    };
    let pairs = [
        (0, 1),
        (2, 3),
        (4, 5),
        (6, 7),
        (0, 2),
        (1, 3),
        (4, 6),
        (5, 7),
        (0, 4),
        (1, 5),
        (2, 6),
        (3, 7),
    ];
    pairs.map(|(i, j)| (c(i), c(j)))
}

/// Draws the boxes of the requested levels over `film`, and a legend of the level
/// colours; returns how many boxes were drawn.
pub fn draw_bvh(film: &mut Film, camera: &Camera, tree: &Tree, levels: LevelRange) -> usize {
    draw_boxes(film, camera, &boxes_at_levels(tree, levels), levels.first)
}

/// Draws boxes tagged with their tree level (from [`boxes_at_levels`]), coloured from level `first` to the deepest, with a legend.
pub fn draw_boxes(
    film: &mut Film,
    camera: &Camera,
    boxes: &[(Aabb, usize)],
    first: usize,
) -> usize {
    let Some(deepest) = boxes.iter().map(|&(_, l)| l).max() else {
        return 0;
    };
    // Turbo's first tenth is nearly black; start above it so the root stays visible.
    let colour =
        |level: usize| turbo(0.1 + 0.9 * (level - first) as f32 / (deepest - first).max(1) as f32);
    let mut canvas = Canvas::new(film);
    for (b, level) in boxes {
        for (a, z) in edges(b) {
            if let Some((pa, pz)) = project_segment(camera, a, z) {
                canvas.line(pa, pz, colour(*level), 0.85);
            }
        }
    }
    draw_legend(&mut canvas, first, deepest, colour);
    boxes.len()
}

/// A 3D segment in pixel coordinates, cut where it passes just in front of the camera.
fn project_segment(camera: &Camera, a: Vec3, z: Vec3) -> Option<((f32, f32), (f32, f32))> {
    const NEAR: f32 = 1e-4;
    let (da, dz) = (camera.depth(a), camera.depth(z));
    let cut = |inside: Vec3, outside: Vec3, di: f32, d_out: f32| {
        inside + (outside - inside) * ((di - NEAR) / (di - d_out))
    };
    let (a, z) = match (da >= NEAR, dz >= NEAR) {
        (true, true) => (a, z),
        (true, false) => (a, cut(a, z, da, dz)),
        (false, true) => (cut(z, a, dz, da), z),
        (false, false) => return None,
    };
    Some((camera.project(a)?, camera.project(z)?))
}

/// Top-left panel: one swatch per level (at most 16, evenly spaced), labelled.
fn draw_legend(canvas: &mut Canvas, first: usize, last: usize, colour: impl Fn(usize) -> Vec3) {
    let scale = if canvas.height() >= 400 { 2 } else { 1 };
    let row = 7 * scale as i32;
    let shown: Vec<usize> = if last - first < 16 {
        (first..=last).collect()
    } else {
        (0..16).map(|i| first + i * (last - first) / 15).collect()
    };
    let label_width = text_width(&last.to_string(), scale) as i32;
    let (x, y) = (4, 4);
    let panel_width = 2 * row + 2 + label_width;
    canvas.fill_rect(
        x - 2,
        y - 2,
        panel_width + 4,
        row * shown.len() as i32 + 2,
        Vec3::ZERO,
        0.6,
    );
    for (i, &level) in shown.iter().enumerate() {
        let top = y + i as i32 * row;
        canvas.fill_rect(x, top, 2 * row - 2, row - 2, colour(level), 1.0);
        canvas.text(&level.to_string(), x + 2 * row + 2, top, scale, Vec3::ONE);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::CameraSpec;
    use canopy_bvh::{build, BuildParams, Builder};

    fn tree(n: usize) -> (Vec<Aabb>, canopy_bvh::Bvh2) {
        let boxes: Vec<Aabb> = (0..n)
            .map(|i| Aabb::new(Vec3::splat(i as f32), Vec3::splat(i as f32 + 0.5)))
            .collect();
        let params = BuildParams {
            max_leaf_size: 1,
            ..BuildParams::default()
        };
        let bvh = build(Builder::SortAxis(0), &boxes, &params);
        (boxes, bvh)
    }

    #[test]
    fn level_ranges_parse() {
        assert_eq!("2..5".parse(), Ok(LevelRange { first: 2, last: 5 }));
        assert_eq!("3".parse(), Ok(LevelRange { first: 3, last: 3 }));
        assert_eq!(
            "1..".parse(),
            Ok(LevelRange {
                first: 1,
                last: usize::MAX
            })
        );
        assert!("5..2".parse::<LevelRange>().is_err());
        assert!("x".parse::<LevelRange>().is_err());
    }

    #[test]
    fn wide_levels_match_the_binary_tree_they_collapse() {
        // A complete binary tree of 8 leaves collapsed 4-wide: level 1 holds the four
        // grandchildren of the binary root, level 2 the eight leaves.
        let (_, bvh) = tree(8);
        let wide = Tree::new(bvh.clone(), canopy_bvh::BvhWidth::Four);
        let count = |s: &str| boxes_at_levels(&wide, s.parse().unwrap()).len();
        assert_eq!(
            (count("0"), count("1"), count("2"), count("3..")),
            (1, 4, 8, 0)
        );
        assert_eq!(boxes_at_levels(&wide, LevelRange::ALL)[0].0, bvh.bounds());
    }

    #[test]
    fn one_node_tree_gives_one_box() {
        let (boxes, bvh) = tree(1);
        assert_eq!(
            boxes_at_levels(&Tree::Binary(bvh), LevelRange::ALL),
            vec![(boxes[0], 0)]
        );
    }

    #[test]
    fn levels_select_exactly_their_nodes() {
        // 8 primitives in leaves of one: a complete tree of 15 nodes on levels 0..=3.
        let (_, bvh) = tree(8);
        let bvh = Tree::Binary(bvh);
        let count = |s: &str| boxes_at_levels(&bvh, s.parse().unwrap()).len();
        assert_eq!(count("0"), 1);
        assert_eq!(count("1"), 2);
        assert_eq!(count("3"), 8);
        assert_eq!(count("1..2"), 6);
        assert_eq!(count("0.."), 15);
        assert_eq!(count("4.."), 0);
    }

    #[test]
    fn drawing_one_box_lights_its_outline_only() {
        let (boxes, bvh) = tree(1);
        let spec = CameraSpec {
            look_from: Vec3::new(0.25, 0.25, 5.0),
            look_at: Vec3::splat(0.25),
            ..CameraSpec::default()
        };
        let camera = Camera::new(&spec, 64, 64);
        let mut film = Film::new(64, 64);
        assert_eq!(
            draw_bvh(&mut film, &camera, &Tree::Binary(bvh), LevelRange::ALL),
            1
        );
        // Head-on, the box is a square around the centre: the edge through its far corner
        // is lit, its inside and the image's far corner are not.
        let far_corner = camera.project(Vec3::new(0.5, 0.0, 0.5)).unwrap();
        let (cx, cy) = camera.project(boxes[0].center()).unwrap();
        assert_eq!(
            film.pixel(cx as u32, cy as u32),
            Vec3::ZERO,
            "inside stays dark"
        );
        let lit = (-1..=1).any(|d: i32| {
            let (x, y) = (
                (far_corner.0 as i32 + d) as u32,
                (far_corner.1 as i32 - 1) as u32,
            );
            film.pixel(x, y) != Vec3::ZERO
        });
        assert!(lit, "edge near {far_corner:?} is drawn");
        assert_eq!(film.pixel(63, 63), Vec3::ZERO);
    }
}
