//! Plots of a `canopy bench paper` run (plotters, drawing with the DejaVu Sans font that
//! ships with canopy, so no system fonts are needed).

use super::Measurement;
use anyhow::{anyhow, Context};
use canopy_render::visualize::turbo;
use plotters::prelude::*;
use std::path::Path;
use std::sync::Once;

const FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

/// Makes "sans-serif" resolve to the bundled font (once per process).
fn register_font() {
    static REGISTER: Once = Once::new();
    REGISTER.call_once(|| {
        // The bytes are a valid TrueType font, checked by the plots test.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

/// Distinct colours for `n` series along the Turbo map.
pub fn series_colour(i: usize, n: usize) -> RGBColor {
    let c = turbo(0.08 + 0.84 * i as f32 / (n.max(2) - 1) as f32);
    RGBColor(
        (c.x * 255.0) as u8,
        (c.y * 255.0) as u8,
        (c.z * 255.0) as u8,
    )
}

/// Scenes and methods in first-seen order.
fn axes(measurements: &[Measurement]) -> (Vec<String>, Vec<String>) {
    let mut scenes = Vec::new();
    let mut methods = Vec::new();
    for m in measurements {
        if !scenes.contains(&m.scene) {
            scenes.push(m.scene.clone());
        }
        if !methods.contains(&m.method) {
            methods.push(m.method.clone());
        }
    }
    (scenes, methods)
}

/// Renders a chart into an RGB buffer and writes it as a PNG (temp file, then rename).
pub fn write_png(
    path: &Path,
    (w, h): (u32, u32),
    draw: impl FnOnce(DrawingArea<BitMapBackend, plotters::coord::Shift>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    register_font();
    let mut buffer = vec![255u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        draw(root.clone())?;
        root.present()
            .map_err(|e| anyhow!("drawing {}: {e}", path.display()))?;
    }
    let image = image::RgbImage::from_raw(w, h, buffer).expect("buffer holds w * h pixels");
    let mut png = std::io::Cursor::new(Vec::new());
    image
        .write_to(&mut png, image::ImageFormat::Png)
        .with_context(|| format!("cannot encode {}", path.display()))?;
    canopy_render::output::write_atomically(path, |w| std::io::Write::write_all(w, png.get_ref()))
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Grouped bars: one group per scene, one bar per method.
fn grouped_bars(
    path: &Path,
    measurements: &[Measurement],
    title: &str,
    y_label: &str,
    log: bool,
    value: impl Fn(&Measurement) -> Option<f64>,
) -> anyhow::Result<()> {
    let (scenes, methods) = axes(measurements);
    let values: Vec<f64> = measurements
        .iter()
        .filter_map(&value)
        .filter(|v| *v > 0.0)
        .collect();
    let (lo, hi) = values
        .iter()
        .fold((f64::INFINITY, 0f64), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    if values.is_empty() {
        return Ok(());
    }
    let width = 1400;
    write_png(path, (width, 700), |root| {
        root.fill(&WHITE)?;
        let (chart_area, legend_area) = root.split_horizontally(width - 230);
        let x_range = 0f64..scenes.len() as f64;
        let mut builder = ChartBuilder::on(&chart_area);
        builder
            .caption(title, ("sans-serif", 26))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(80);
        let slot = 0.85 / methods.len() as f64;
        let (scenes, methods) = (&scenes, &methods);
        let bar = |chart_bottom: f64| {
            measurements.iter().filter_map(move |m| {
                let v = value(m)?;
                let s = scenes.iter().position(|s| *s == m.scene)? as f64;
                let i = methods.iter().position(|x| *x == m.method)?;
                let x0 = s + 0.075 + i as f64 * slot;
                Some(Rectangle::new(
                    [(x0, chart_bottom), (x0 + slot * 0.9, v)],
                    series_colour(i, methods.len()).filled(),
                ))
            })
        };
        if log {
            let mut chart =
                builder.build_cartesian_2d(x_range, (lo * 0.8..hi * 1.25).log_scale())?;
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_label_formatter(&|_| String::new())
                .y_desc(y_label)
                .label_style(("sans-serif", 16))
                .draw()?;
            chart.draw_series(bar(lo * 0.8))?;
            label_groups(&root, scenes, |s| chart.backend_coord(&(s + 0.5, lo * 0.8)))?;
        } else {
            let mut chart = builder.build_cartesian_2d(x_range, 0f64..hi * 1.1)?;
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_label_formatter(&|_| String::new())
                .y_desc(y_label)
                .label_style(("sans-serif", 16))
                .draw()?;
            chart.draw_series(bar(0.0))?;
            label_groups(&root, scenes, |s| chart.backend_coord(&(s + 0.5, 0.0)))?;
        }
        for (i, method) in methods.iter().enumerate() {
            let y = 60 + i as i32 * 26;
            legend_area.draw(&Rectangle::new(
                [(10, y), (30, y + 16)],
                series_colour(i, methods.len()).filled(),
            ))?;
            legend_area.draw(&Text::new(method.clone(), (38, y), ("sans-serif", 16)))?;
        }
        Ok(())
    })
}

/// Writes each scene's name under the middle of its group of bars.
fn label_groups(
    root: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    scenes: &[String],
    at: impl Fn(f64) -> (i32, i32),
) -> anyhow::Result<()> {
    for (s, name) in scenes.iter().enumerate() {
        let (x, y) = at(s as f64);
        root.draw(&Text::new(
            name.clone(),
            (x - 4 * name.len() as i32, y + 8),
            ("sans-serif", 16),
        ))?;
    }
    Ok(())
}

/// Build time against SAH cost, one panel per scene, one point per method with a BVH.
fn build_vs_sah(path: &Path, measurements: &[Measurement]) -> anyhow::Result<()> {
    let (scenes, methods) = axes(measurements);
    let cols = scenes.len().min(3);
    let rows = scenes.len().div_ceil(cols.max(1));
    write_png(path, (1500, 480 * rows as u32 + 60), |root| {
        root.fill(&WHITE)?;
        let (title, body) = root.split_vertically(60);
        title.draw(&Text::new(
            "Build time vs SAH cost (lower left is better)",
            (20, 18),
            ("sans-serif", 26),
        ))?;
        for (panel, scene) in body.split_evenly((rows, cols)).iter().zip(&scenes) {
            let points: Vec<(&Measurement, usize)> = measurements
                .iter()
                .filter(|m| &m.scene == scene && m.builder != "none")
                .map(|m| (m, methods.iter().position(|x| *x == m.method).unwrap_or(0)))
                .collect();
            if points.is_empty() {
                continue;
            }
            let (x_lo, x_hi) = points.iter().fold((f64::INFINITY, 0f64), |(a, b), (m, _)| {
                (a.min(m.build_ms), b.max(m.build_ms))
            });
            let (y_lo, y_hi) = points.iter().fold((f64::INFINITY, 0f64), |(a, b), (m, _)| {
                (a.min(m.sah_cost as f64), b.max(m.sah_cost as f64))
            });
            let mut chart = ChartBuilder::on(panel)
                .caption(scene, ("sans-serif", 20))
                .margin(10)
                .x_label_area_size(36)
                .y_label_area_size(60)
                .build_cartesian_2d(
                    (x_lo.max(1e-3) * 0.7..x_hi * 1.5).log_scale(),
                    y_lo * 0.95..y_hi * 1.05,
                )?;
            chart
                .configure_mesh()
                .x_desc("build ms")
                .y_desc("SAH cost")
                .label_style(("sans-serif", 14))
                .draw()?;
            chart.draw_series(points.iter().map(|(m, i)| {
                Circle::new(
                    (m.build_ms.max(1e-3), m.sah_cost as f64),
                    6,
                    series_colour(*i, methods.len()).filled(),
                )
            }))?;
            chart.draw_series(points.iter().filter(|(m, _)| m.width == 2).map(|(m, _)| {
                Text::new(
                    m.builder.clone(),
                    (m.build_ms.max(1e-3), m.sah_cost as f64),
                    ("sans-serif", 12),
                )
            }))?;
        }
        Ok(())
    })
}

/// Writes render_time.png, speedup.png and build_vs_sah.png into `dir`.
pub fn write_plots(dir: &Path, measurements: &[Measurement]) -> anyhow::Result<()> {
    grouped_bars(
        &dir.join("render_time.png"),
        measurements,
        "Render time per scene and method",
        "seconds (log)",
        true,
        |m| Some(m.mean_s),
    )?;
    grouped_bars(
        &dir.join("speedup.png"),
        measurements,
        "Speedup over no BVH",
        "speedup",
        false,
        |m| m.speedup,
    )?;
    build_vs_sah(&dir.join("build_vs_sah.png"), measurements)
}
