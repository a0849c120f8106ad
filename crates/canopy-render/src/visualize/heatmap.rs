//! Per-pixel traversal cost of primary rays (node visits plus primitive tests) as a
//! false-colour image with a scale bar.

use super::colormap::turbo;
use super::draw::Canvas;
use super::font::text_width;
use crate::accel::Accel;
use crate::camera::Camera;
use crate::film::Film;
use crate::scene::Scene;
use canopy_bvh::RayQuery;
use glam::Vec3;
use rayon::prelude::*;

pub struct Heatmap {
    pub film: Film,
    /// Traversal cost of every pixel's primary ray, row by row from the top.
    pub costs: Vec<u32>,
    pub max_cost: u32,
    pub mean_cost: f64,
}

/// Traces one ray through the centre of every pixel and colours it by its cost, from 0
/// (dark blue) to the image's maximum (dark red); a scale bar runs along the bottom.
pub fn render_heatmap(scene: &Scene, accel: &Accel) -> Heatmap {
    let s = scene.settings;
    let width = s.width as usize;
    let camera = Camera::new(&scene.camera, s.width, s.height);
    let costs: Vec<u32> = (0..width * s.height as usize)
        .into_par_iter()
        .map(|i| {
            let ray = camera.pixel_centre_ray((i % width) as u32, (i / width) as u32, s.seed);
            let work = accel.traversal_cost(&ray);
            (work.nodes_visited + work.primitives_tested) as u32
        })
        .collect();
    let max_cost = costs.iter().copied().max().unwrap_or(0);
    let mean_cost = costs.iter().map(|&c| c as f64).sum::<f64>() / costs.len().max(1) as f64;
    let mut film = Film::new(s.width, s.height);
    let mut canvas = Canvas::new(&mut film);
    let norm = max_cost.max(1) as f32;
    for (i, &c) in costs.iter().enumerate() {
        canvas.blend(
            (i % width) as i32,
            (i / width) as i32,
            turbo(c as f32 / norm),
            1.0,
        );
    }
    draw_scale_bar(&mut canvas, max_cost);
    Heatmap {
        film,
        costs,
        max_cost,
        mean_cost,
    }
}

/// A gradient from 0 to `max` along the bottom edge, labelled at both ends.
fn draw_scale_bar(canvas: &mut Canvas, max: u32) {
    let scale = if canvas.height() >= 400 { 2 } else { 1 };
    let bar_height = 6 * scale as i32;
    let margin = 4;
    let label = max.to_string();
    let x0 = margin + text_width("0", scale) as i32 + 4;
    let x1 = canvas.width() - margin - text_width(&label, scale) as i32 - 4;
    let y = canvas.height() - margin - bar_height;
    canvas.fill_rect(
        0,
        y - 3,
        canvas.width(),
        bar_height + 6 + margin,
        Vec3::ZERO,
        0.7,
    );
    for x in x0..x1 {
        let t = (x - x0) as f32 / (x1 - x0 - 1).max(1) as f32;
        canvas.fill_rect(x, y, 1, bar_height, turbo(t), 1.0);
    }
    let text_y = y + (bar_height - 5 * scale as i32) / 2;
    canvas.text("0", margin, text_y, scale, Vec3::ONE);
    canvas.text(&label, x1 + 4, text_y, scale, Vec3::ONE);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::AccelKind;
    use crate::BuiltinScene;
    use canopy_bvh::BuildParams;
    use canopy_bvh::BvhWidth;

    #[test]
    fn brute_force_costs_every_primitive_for_every_pixel() {
        let mut scene = BuiltinScene::find("paper-3").unwrap().load().unwrap();
        scene.settings.width = 16;
        scene.settings.height = 12;
        let none = Accel::build(
            AccelKind::None,
            BvhWidth::Two,
            &scene.primitives,
            &BuildParams::default(),
        );
        let map = render_heatmap(&scene, &none);
        assert!(map
            .costs
            .iter()
            .all(|&c| c as usize == scene.primitives.len()));
        let bvh = Accel::build(
            AccelKind::default(),
            BvhWidth::Two,
            &scene.primitives,
            &BuildParams::default(),
        );
        let map = render_heatmap(&scene, &bvh);
        assert!(
            map.mean_cost < scene.primitives.len() as f64 / 10.0,
            "mean {}",
            map.mean_cost
        );
        assert!(map.costs.iter().any(|&c| c != map.costs[0]), "costs vary");
    }
}
