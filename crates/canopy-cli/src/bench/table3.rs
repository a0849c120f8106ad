//! The report's Table 3: for scenes 5 and 6, a picture of each method's BVH (its top
//! levels drawn over the render), labelled, in one image.

use super::plots::write_png;
use super::Method;
use canopy_bvh::BuildParams;
use canopy_render::camera::Camera;
use canopy_render::visualize::{boxes_at_levels, draw_boxes, LevelRange};
use canopy_render::{render, Accel, BuiltinScene, BvhWidth, Film};
use plotters::prelude::*;
use std::path::Path;

/// Levels drawn: the top of each tree, to about the same depth in binary levels (one
/// 4-wide level spans two binary ones, an 8-wide level three).
fn levels(width: BvhWidth) -> LevelRange {
    let last = match width {
        BvhWidth::Two => 6,
        BvhWidth::Four => 3,
        BvhWidth::Eight => 2,
    };
    LevelRange { first: 0, last }
}

/// One picture: `scene` rendered at `size` and `spp`, with `method`'s boxes over it.
fn picture(
    scene_name: &str,
    method: &Method,
    size: u32,
    spp: u32,
    params: &BuildParams,
) -> anyhow::Result<Film> {
    let mut scene = BuiltinScene::find(scene_name)
        .expect("paper scenes are built in")
        .load()?;
    scene.settings.width = size;
    scene.settings.height = size;
    scene.settings.spp = spp;
    let accel = Accel::for_scene(&scene, method.kind, method.width, params, None);
    let (mut film, _) = render(&scene, &accel, &|| {});
    if let Some(tree) = accel.tree() {
        let levels = levels(method.width);
        let boxes = boxes_at_levels(tree, levels);
        let camera = Camera::new(&scene.camera, size, size);
        draw_boxes(&mut film, &camera, &boxes, levels.first);
    }
    Ok(film)
}

/// A grid: rows are methods (with a BVH), columns scenes 5 and 6.
pub fn write_table3(
    path: &Path,
    methods: &[Method],
    size: u32,
    spp: u32,
    params: &BuildParams,
) -> anyhow::Result<()> {
    let scenes = ["paper-5", "paper-6"];
    let rows: Vec<&Method> = methods
        .iter()
        .filter(|m| m.report_row.is_some_and(|r| r > 0))
        .collect();
    let mut films = Vec::new();
    for method in &rows {
        for scene in scenes {
            films.push(picture(scene, method, size, spp, params)?);
        }
    }
    let (label_w, header_h, gap) = (200u32, 40u32, 6u32);
    let width = label_w + 2 * (size + gap);
    let height = header_h + rows.len() as u32 * (size + gap);
    write_png(path, (width, height), |root| {
        root.fill(&WHITE)?;
        for (c, scene) in scenes.iter().enumerate() {
            let x = (label_w + c as u32 * (size + gap) + size / 2 - 40) as i32;
            root.draw(&Text::new(scene.to_string(), (x, 10), ("sans-serif", 20)))?;
        }
        for (r, method) in rows.iter().enumerate() {
            let top = header_h + r as u32 * (size + gap);
            root.draw(&Text::new(
                method.label.clone(),
                (8, (top + size / 2 - 10) as i32),
                ("sans-serif", 18),
            ))?;
            for c in 0..scenes.len() {
                let film = &films[r * scenes.len() + c];
                let pixels = film.to_srgb8();
                let left = label_w + c as u32 * (size + gap);
                for y in 0..size {
                    for x in 0..size {
                        let i = 3 * (y * size + x) as usize;
                        let colour = RGBColor(pixels[i], pixels[i + 1], pixels[i + 2]);
                        root.draw_pixel(((left + x) as i32, (top + y) as i32), &colour)?;
                    }
                }
            }
        }
        Ok(())
    })
}
