//! `SceneInfo.contents()`: what a loaded scene holds, as arrays and plain dicts, for
//! programs that hand it to another renderer (bench/mitsuba_compare.py does) or inspect it.

use canopy_render::geometry::Shape;
use canopy_render::material::Material;
use canopy_render::{Background, Scene};
use glam::Vec3;
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

/// A material in the table form `add_material` takes (textures left out: factors only).
pub fn material_to_dict<'py>(py: Python<'py>, material: &Material) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    match *material {
        Material::Lambertian { albedo } => {
            d.set_item("type", "lambertian")?;
            d.set_item("albedo", albedo.to_array())?;
        }
        Material::Metal { albedo, fuzz } => {
            d.set_item("type", "metal")?;
            d.set_item("albedo", albedo.to_array())?;
            d.set_item("fuzz", fuzz)?;
        }
        Material::Dielectric { ior } => {
            d.set_item("type", "dielectric")?;
            d.set_item("ior", ior)?;
        }
        Material::Emissive { radiance } => {
            d.set_item("type", "emissive")?;
            d.set_item("radiance", radiance.to_array())?;
        }
        Material::Pbr(p) => {
            d.set_item("type", "pbr")?;
            d.set_item("base_color", p.base_color.to_array())?;
            d.set_item("metallic", p.metallic)?;
            d.set_item("roughness", p.roughness)?;
            d.set_item("emission", p.emission.to_array())?;
        }
    }
    Ok(d)
}

fn rows(values: impl ExactSizeIterator<Item = Vec3>) -> Array2<f32> {
    let n = values.len();
    let flat: Vec<f32> = values.flat_map(|v| v.to_array()).collect();
    Array2::from_shape_vec((n, 3), flat).expect("three values a row")
}

/// Every part of `scene`: camera, background, materials, spheres, cuboids, and every
/// triangle in world space (mesh instances baked), each shape with its material index.
pub fn contents<'py>(py: Python<'py>, scene: &Scene) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);

    let c = &scene.camera;
    let camera = PyDict::new(py);
    camera.set_item("look_from", c.look_from.to_array())?;
    camera.set_item("look_at", c.look_at.to_array())?;
    camera.set_item("up", c.up.to_array())?;
    camera.set_item("vfov", c.vfov)?;
    camera.set_item("aperture", c.aperture)?;
    camera.set_item("focus_distance", c.focus_distance)?;
    camera.set_item("ortho_height", c.ortho_height)?;
    d.set_item("camera", camera)?;

    let background = PyDict::new(py);
    match &scene.background {
        Background::Sky => background.set_item("type", "sky")?,
        Background::Constant(radiance) => {
            background.set_item("type", "constant")?;
            background.set_item("radiance", radiance.to_array())?;
        }
        Background::Environment(map) => {
            background.set_item("type", "environment")?;
            background.set_item("source", &map.source)?;
            let (w, h) = map.size();
            let pixels = rows(map.pixels().iter().copied())
                .into_shape_with_order((h, w, 3))
                .expect("the map's pixels fill it");
            background.set_item("pixels", pixels.into_pyarray(py))?;
            let r = map.to_world();
            background.set_item(
                "to_world",
                [r.x_axis, r.y_axis, r.z_axis].map(|c| c.to_array()),
            )?;
        }
    }
    d.set_item("background", background)?;

    let materials = PyList::empty(py);
    for m in &scene.materials {
        materials.append(material_to_dict(py, m)?)?;
    }
    d.set_item("materials", materials)?;

    let (mut centers, mut radii, mut sphere_materials) = (vec![], vec![], vec![]);
    let (mut box_min, mut box_max, mut box_rotation, mut box_translation, mut box_materials) =
        (vec![], vec![], vec![], vec![], vec![]);
    let (mut corners, mut normals, mut smooth, mut triangle_materials) =
        (vec![], vec![], vec![], vec![]);
    for p in scene.primitives.iter() {
        match &p.shape {
            Shape::Sphere(s) => {
                centers.push(s.center);
                radii.push(s.radius);
                sphere_materials.push(p.material);
            }
            Shape::Cuboid(c) => {
                box_min.push(c.local.min);
                box_max.push(c.local.max);
                // Rows of the rotation, so that numpy's `rotation @ p` turns a point.
                let t = c.rotation().transpose();
                box_rotation.extend([t.x_axis, t.y_axis, t.z_axis]);
                box_translation.push(c.translation);
                box_materials.push(p.material);
            }
            Shape::Triangle(t) => {
                corners.extend(t.v);
                let n = scene.vertex_normals.get(t.normals as usize);
                smooth.push(n.is_some());
                normals.extend(n.copied().unwrap_or([Vec3::ZERO; 3]));
                triangle_materials.push(p.material);
            }
        }
    }
    for instance in &scene.instances {
        let mesh = &scene.meshes[instance.mesh as usize];
        for prim in 0..mesh.mesh.indices().len() as u32 {
            corners.extend(scene.instance_triangle(instance, prim).v);
            let n = scene.instance_normals(instance, prim);
            smooth.push(n.is_some());
            normals.extend(n.unwrap_or([Vec3::ZERO; 3]));
            triangle_materials.push(instance.material);
        }
    }

    let spheres = PyDict::new(py);
    spheres.set_item("centers", rows(centers.into_iter()).into_pyarray(py))?;
    spheres.set_item("radii", Array1::from(radii).into_pyarray(py))?;
    spheres.set_item("materials", Array1::from(sphere_materials).into_pyarray(py))?;
    d.set_item("spheres", spheres)?;

    let cuboids = PyDict::new(py);
    let n = box_min.len();
    cuboids.set_item("min", rows(box_min.into_iter()).into_pyarray(py))?;
    cuboids.set_item("max", rows(box_max.into_iter()).into_pyarray(py))?;
    let rotation: Array3<f32> = rows(box_rotation.into_iter())
        .into_shape_with_order((n, 3, 3))
        .expect("three rows a rotation");
    cuboids.set_item("rotation", rotation.into_pyarray(py))?;
    cuboids.set_item(
        "translation",
        rows(box_translation.into_iter()).into_pyarray(py),
    )?;
    cuboids.set_item("materials", Array1::from(box_materials).into_pyarray(py))?;
    d.set_item("cuboids", cuboids)?;

    let triangles = PyDict::new(py);
    let n = smooth.len();
    let as_triples = |v: Vec<Vec3>| -> Array3<f32> {
        rows(v.into_iter())
            .into_shape_with_order((n, 3, 3))
            .expect("three corners a triangle")
    };
    triangles.set_item("vertices", as_triples(corners).into_pyarray(py))?;
    triangles.set_item("normals", as_triples(normals).into_pyarray(py))?;
    triangles.set_item("smooth", Array1::from(smooth).into_pyarray(py))?;
    triangles.set_item(
        "materials",
        Array1::from(triangle_materials).into_pyarray(py),
    )?;
    d.set_item("triangles", triangles)?;
    d.set_item("punctual_lights", scene.lights.len())?;
    d.set_item("textured_materials", scene.textured_materials())?;
    Ok(d)
}
