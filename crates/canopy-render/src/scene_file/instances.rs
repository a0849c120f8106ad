//! Meshes stored once and placed many times: `[geometry.NAME]` tables name meshes,
//! `[[instances]]` place them by a transform (and, with `grid`, many copies at once).
//!
//! ```toml
//! [geometry.bunny]
//! file = "bunny.ply"
//! smooth = true
//!
//! [[instances]]
//! geometry = "bunny"
//! material = "gold"
//! scale = 2.0
//! rotate = [0, 45, 0]
//! translate = [0, 0, -3]
//! grid = { count = [10, 1, 10], step = [1.5, 0, 1.5] }  # 100 copies, offset by step
//!
//! [[instances]]
//! geometry = "bunny"
//! material = "gold"
//! places = [{ translate = [4, 0, 0] }, { rotate = [0, 90, 0], translate = [6, 0, 0] }]
//! ```

use super::{
    apply_smooth, checked_scale, in_range, rotation, Assets, ScaleDoc, SceneBuilder, MAX_COORDINATE,
};
use crate::error::SceneError;
use crate::geometry::Triangle;
use crate::scene::{MeshInstance, SceneMesh};
use canopy_bvh::TriangleMesh;
use glam::{Affine3A, Vec3};
use serde::Deserialize;
use std::sync::Arc;
use toml::Spanned;

/// Most instances a scene may place (each costs about 200 bytes in the scene and its
/// top-level structure).
pub const MAX_INSTANCES: u64 = 1 << 22;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct GeometryDoc {
    file: String,
    /// As for `[[meshes]]`: interpolate vertex normals (from the file, or computed).
    smooth: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct InstanceDoc {
    geometry: String,
    material: Spanned<toml::Value>,
    scale: Option<ScaleDoc>,
    #[serde(default)]
    rotate: [f32; 3],
    #[serde(default)]
    translate: [f32; 3],
    grid: Option<GridDoc>,
    /// One copy per entry, each moved by the entry after the instance's own transform.
    places: Option<Vec<PlaceDoc>>,
}

/// A transform: scale, then rotate (degrees about x, then y, then z), then translate.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PlaceDoc {
    scale: Option<ScaleDoc>,
    #[serde(default)]
    rotate: [f32; 3],
    #[serde(default)]
    translate: [f32; 3],
}

impl PlaceDoc {
    /// The transform, if its numbers are finite and its scale non-zero.
    fn transform(
        scale: &Option<ScaleDoc>,
        rotate: [f32; 3],
        translate: [f32; 3],
    ) -> Option<Affine3A> {
        let scale = checked_scale(scale, rotate, translate)?;
        Some(Affine3A::from_scale_rotation_translation(
            scale,
            rotation(rotate),
            translate.into(),
        ))
    }
}

/// `count[0] × count[1] × count[2]` copies, copy `(i, j, k)` moved by `(i, j, k) * step`
/// after the instance's own transform.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct GridDoc {
    count: [u32; 3],
    step: [f32; 3],
}

impl SceneBuilder<'_> {
    /// A named mesh, stored once: its zero-area triangles left out (and counted).
    pub(super) fn geometry(
        &mut self,
        name: &str,
        doc: &Spanned<GeometryDoc>,
        assets: &dyn Assets,
    ) -> Result<(), SceneError> {
        let g = doc.get_ref();
        let mut data = self.read_mesh(&g.file, doc.span(), assets)?;
        if let Some(i) = data.positions.iter().position(|p| !in_range(&p.to_array())) {
            return self.cx.invalid(
                doc.span(),
                format!(
                    "geometry `{name}`: vertex {i} lies at {}, beyond ±{MAX_COORDINATE:e}",
                    data.positions[i]
                ),
            );
        }
        apply_smooth(&mut data, g.smooth);
        let before = data.triangles.len();
        let positions = &data.positions;
        // A triangle without area can never be hit (the same test as `[[meshes]]`).
        data.triangles.retain(|t| {
            let [a, b, c] = t.map(|i| positions[i as usize]);
            Triangle::new(a, b, c).area() != 0.0
        });
        self.scene.skipped_degenerate += before - data.triangles.len();
        let mesh =
            TriangleMesh::new(data.positions, data.triangles).map_err(|e| SceneError::Invalid {
                file: self.cx.file.to_owned(),
                line: self.cx.line_of(doc.span().start),
                message: format!("geometry `{name}` (`{}`): {e}", g.file),
            })?;
        self.geometry_index
            .insert(name.to_owned(), self.scene.meshes.len() as u32);
        self.scene.meshes.push(SceneMesh {
            name: name.to_owned(),
            mesh: Arc::new(mesh),
            normals: data.normals,
            uvs: Vec::new(),
            tangents: Vec::new(),
        });
        Ok(())
    }

    /// One `[[instances]]` entry: one placement, a grid of them, or a list.
    pub(super) fn instances(&mut self, doc: &Spanned<InstanceDoc>) -> Result<(), SceneError> {
        let d = doc.get_ref();
        let Some(&mesh) = self.geometry_index.get(&d.geometry) else {
            let known: Vec<&str> = self.geometry_index.keys().map(String::as_str).collect();
            return self.cx.invalid(
                doc.span(),
                format!(
                    "instance of unknown geometry `{}` (defined: {})",
                    d.geometry,
                    if known.is_empty() {
                        "none".into()
                    } else {
                        known.join(", ")
                    }
                ),
            );
        };
        let bad_transform = "instance: transform numbers must be finite and `scale` non-zero";
        let Some(base) = PlaceDoc::transform(&d.scale, d.rotate, d.translate) else {
            return self.cx.invalid(doc.span(), bad_transform);
        };
        // Each copy: its name in errors, and the transform applied after `base`.
        let mut moves: Vec<(String, Affine3A)> = Vec::new();
        match (&d.grid, &d.places) {
            (Some(_), Some(_)) => {
                return self
                    .cx
                    .invalid(doc.span(), "instance: give `grid` or `places`, not both");
            }
            (Some(g), None) => {
                let step = Vec3::from(g.step);
                let copies = g.count.iter().map(|&c| c as u64).product::<u64>();
                let total = self.scene.instances.len() as u64 + copies;
                if !step.is_finite() || copies == 0 || total > MAX_INSTANCES {
                    return self.cx.invalid(
                        doc.span(),
                        format!(
                            "instance: `grid` places {copies} copies (step {step}); a scene holds 1 to {MAX_INSTANCES} instances, steps are finite"
                        ),
                    );
                }
                for k in 0..g.count[2] {
                    for j in 0..g.count[1] {
                        for i in 0..g.count[0] {
                            let offset = Vec3::new(i as f32, j as f32, k as f32) * step;
                            moves.push((
                                format!("({i}, {j}, {k})"),
                                Affine3A::from_translation(offset),
                            ));
                        }
                    }
                }
            }
            (None, Some(places)) => {
                let total = self.scene.instances.len() + places.len();
                if places.is_empty() || total as u64 > MAX_INSTANCES {
                    return self.cx.invalid(
                        doc.span(),
                        format!(
                            "instance: `places` lists {} copies; a scene holds 1 to {MAX_INSTANCES} instances",
                            places.len()
                        ),
                    );
                }
                for (n, p) in places.iter().enumerate() {
                    let Some(t) = PlaceDoc::transform(&p.scale, p.rotate, p.translate) else {
                        return self
                            .cx
                            .invalid(doc.span(), format!("{bad_transform} (place {n})"));
                    };
                    moves.push((format!("place {n}"), t));
                }
            }
            (None, None) => moves.push(("0".into(), Affine3A::IDENTITY)),
        }
        let material = self.material_ref(&d.material)?;
        let local = self.scene.meshes[mesh as usize].mesh.bounding_box();
        for (name, moved) in moves {
            let to_world = moved * base;
            if let Err(e) = crate::scene_build::check_placement(local, to_world) {
                return self.cx.invalid(
                    doc.span(),
                    format!("instance {name} of `{}`: {e}", d.geometry),
                );
            }
            self.scene.instances.push(MeshInstance {
                mesh,
                to_world,
                material,
            });
        }
        Ok(())
    }
}
