//! Scenes from glTF 2.0 files (`.glb`, `.gltf` with embedded or external buffers),
//! through the `gltf` crate: the default scene's node hierarchy becomes instances of
//! meshes stored once (a mesh primitive used by several nodes is one structure), the
//! first camera, perspective or orthographic (or a framing of the whole model), the camera, and each
//! material canopy's nearest ([`materials`]). Every accessor is checked against its
//! buffer before it is read ([`data`]); errors name the file and the object at fault.
//!
//! Not read yet (each named in the scene's warnings where a file uses it): lights'
//! ranges, a second set of texture coordinates.

mod data;
mod materials;
mod textures;

use crate::camera::CameraSpec;
use crate::scene::Scene;
use crate::scene_file::Assets;
use data::{check_accessor, describe, Buffers, INDICES, NORMALS, POSITIONS, TANGENTS, TEXCOORDS};
use glam::{Affine3A, Mat4, Vec2, Vec3};
use gltf::mesh::Mode;
use std::collections::HashMap;

/// Extensions whose use is read (or knowingly left out with a note); any other one a
/// file uses is named in a warning, and one it requires is refused by the parser.
const KNOWN_EXTENSIONS: &[&str] = &[
    "KHR_materials_transmission",
    "KHR_materials_ior",
    "KHR_materials_emissive_strength",
    "KHR_lights_punctual",
    "KHR_texture_transform",
];

/// Deepest node hierarchy followed (a cycle, which the specification forbids, is caught
/// before this; the bound keeps the walk's stack small).
const MAX_DEPTH: usize = 256;

/// The scene of glTF file `bytes`, its buffers found through `assets`, named `name`:
/// the model, seen by its first perspective camera (else framed from the front), under
/// the default sky.
pub fn parse_gltf(bytes: &[u8], assets: &dyn Assets, name: &str) -> Result<Scene, String> {
    let mut scene = Scene {
        name: name.to_owned(),
        ..Scene::default()
    };
    match add_gltf(&mut scene, bytes, assets, Affine3A::IDENTITY)? {
        Some(camera) => {
            let aspect = camera.aspect;
            scene.set_camera(camera.spec)?;
            if let Some(aspect) = aspect {
                let height = scene.settings.height as f32;
                scene.settings.width = (height * aspect).round().clamp(1.0, 16384.0) as u32;
            }
        }
        None => crate::frame_from_front(&mut scene)?,
    }
    Ok(scene)
}

/// A camera a model holds, placed in the world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelCamera {
    pub spec: CameraSpec,
    /// Width over height, where the file gives it.
    pub aspect: Option<f32>,
}

/// Adds glTF file `bytes` (its buffers found through `assets`) to `scene`, the whole
/// model placed by `to_world`: its meshes, materials and instances, and a note in
/// [`Scene::notes`] for each thing it uses that canopy does not read yet. Returns the
/// model's first perspective camera, placed, if it has one. On an error the scene may
/// hold part of the model.
pub fn add_gltf(
    scene: &mut Scene,
    bytes: &[u8],
    assets: &dyn Assets,
    to_world: Affine3A,
) -> Result<Option<ModelCamera>, String> {
    let (document, blob) = read_document(bytes)?;
    let buffers = Buffers::load(&document, blob, assets)?;
    scene.inputs.extend(buffers.1.iter().cloned());
    let placed_before = scene.instances.len();
    let mut loader = Loader {
        buffers: &buffers,
        assets,
        images: textures::Images::default(),
        scene,
        meshes: HashMap::new(),
        materials: HashMap::new(),
        camera: None,
    };
    for extension in document.extensions_used() {
        if !KNOWN_EXTENSIONS.contains(&extension) {
            loader.note(format!("extension {extension} is not read"));
        }
    }
    let roots: Vec<gltf::Node<'_>> = match document.default_scene().or(document.scenes().next()) {
        Some(scene) => scene.nodes().collect(),
        // No scene: every node that is no other's child (one pass over the links: a
        // search of a list of children per node took 16 s for 300k nodes).
        None => {
            let mut is_child = vec![false; document.nodes().len()];
            for child in document.nodes().flat_map(|n| n.children()) {
                is_child[child.index()] = true;
            }
            document.nodes().filter(|n| !is_child[n.index()]).collect()
        }
    };
    check_decoded_memory(&document, &buffers)?;
    let mut visited = vec![false; document.nodes().len()];
    for root in roots {
        loader.place(&root, to_world, 0, &mut visited)?;
    }
    if loader.scene.instances.len() == placed_before {
        return Err("the file places no triangles: nothing to render".into());
    }
    loader.camera.map(placed_camera).transpose()
}

/// What a canopy mesh is decoded from: a primitive's accessors, how they are assembled
/// and whether its material needs tangents. Primitives with the same source (in one mesh
/// or in many) become one mesh, stored once.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
struct MeshSource {
    mode: u32,
    positions: Option<usize>,
    normals: Option<usize>,
    uvs: Option<usize>,
    indices: Option<usize>,
    tangents: Option<usize>,
    normal_mapped: bool,
}

impl MeshSource {
    fn of(primitive: &gltf::Primitive<'_>) -> Self {
        let accessor = |semantic| primitive.get(&semantic).map(|a| a.index());
        Self {
            mode: primitive.mode().as_gl_enum(),
            positions: accessor(gltf::Semantic::Positions),
            normals: accessor(gltf::Semantic::Normals),
            uvs: accessor(gltf::Semantic::TexCoords(0)),
            indices: primitive.indices().map(|a| a.index()),
            tangents: accessor(gltf::Semantic::Tangents),
            normal_mapped: primitive.material().normal_texture().is_some(),
        }
    }

    /// Most bytes decoding this source allocates, with its share of the BVH: every
    /// vertex attribute as floats (read, then kept), and every index with its triangle's
    /// pack and nodes. An upper bound, so that the check before decoding never passes a
    /// model that then runs out of memory.
    fn bytes(&self, primitive: &gltf::Primitive<'_>) -> u64 {
        let vertices = primitive
            .get(&gltf::Semantic::Positions)
            .map_or(0, |a| a.count() as u64);
        let indices = primitive.indices().map_or(vertices, |a| a.count() as u64);
        // Position and normal twice (read, then the mesh's own), texture coordinates
        // twice, tangents per triangle corner.
        let per_vertex = 2 * (12 + 12 + 8);
        // The index read, the triangle it makes (three) and the triangle's pack, node
        // and bounds shares (at most one triangle per index of a fan or strip).
        let per_index = 4 + 12 + 160 + if self.normal_mapped { 3 * 16 } else { 0 };
        vertices * per_vertex + indices * per_index
    }
}

/// Fails before any mesh is decoded when the model's distinct meshes (each decoded once,
/// however many nodes and meshes share its accessors) need more memory than is available.
/// A primitive whose accessors are broken is left to the walk that reads it, which names
/// it in its error.
fn check_decoded_memory(document: &gltf::Document, buffers: &Buffers) -> Result<(), String> {
    let mut sources = HashMap::new();
    for mesh in document.nodes().filter_map(|n| n.mesh()) {
        for primitive in mesh.primitives() {
            if accessors_hold_their_data(&primitive, buffers) {
                let source = MeshSource::of(&primitive);
                sources.insert(source, source.bytes(&primitive));
            }
        }
    }
    let needed: u64 = sources.values().sum();
    crate::files::check_memory(
        needed,
        crate::files::available_memory(),
        &format!("decoding the model's {} distinct meshes", sources.len()),
    )
}

/// Whether every accessor of `primitive` is of its kind and lies inside its buffer.
fn accessors_hold_their_data(primitive: &gltf::Primitive<'_>, buffers: &Buffers) -> bool {
    let semantic_ok = |semantic, expect| {
        primitive
            .get(&semantic)
            .is_none_or(|a| check_accessor(&a, expect, buffers).is_ok())
    };
    semantic_ok(gltf::Semantic::Positions, &POSITIONS)
        && semantic_ok(gltf::Semantic::Normals, &NORMALS)
        && semantic_ok(gltf::Semantic::TexCoords(0), &TEXCOORDS)
        && semantic_ok(gltf::Semantic::Tangents, &TANGENTS)
        && primitive
            .indices()
            .is_none_or(|a| check_accessor(&a, &INDICES, buffers).is_ok())
}

/// The document and binary chunk of `bytes`, validated. gltf 1.4's validation indexes
/// a primitive's POSITION accessor before checking that it exists (a panic the fuzz
/// target found), so every attribute's accessor is checked here first.
fn read_document(bytes: &[u8]) -> Result<(gltf::Document, Option<Vec<u8>>), String> {
    let invalid = |e: gltf::Error| format!("not a valid glTF 2.0 file: {e}");
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(invalid)?;
    let json = document.into_json();
    for (m, mesh) in json.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            for index in primitive.attributes.values() {
                if index.value() >= json.accessors.len() {
                    return Err(format!(
                        "not a valid glTF 2.0 file: mesh {m} primitive {p} names accessor {}, \
                         but there are {}",
                        index.value(),
                        json.accessors.len()
                    ));
                }
            }
        }
    }
    Ok((gltf::Document::from_json(json).map_err(invalid)?, blob))
}

/// The camera `camera` placed by `world`, checked.
fn placed_camera((camera, world): (gltf::Camera<'_>, Affine3A)) -> Result<ModelCamera, String> {
    let look_from = world.transform_point3(Vec3::ZERO);
    let forward = world.transform_vector3(-Vec3::Z).normalize_or_zero();
    let placed = CameraSpec {
        look_from,
        look_at: look_from + forward,
        up: world.transform_vector3(Vec3::Y).normalize_or_zero(),
        ..CameraSpec::default()
    };
    let (spec, aspect) = match camera.projection() {
        gltf::camera::Projection::Perspective(p) => (
            CameraSpec {
                vfov: p.yfov().to_degrees(),
                ..placed
            },
            p.aspect_ratio(),
        ),
        // xmag and ymag are half the view's width and height.
        gltf::camera::Projection::Orthographic(o) => (
            CameraSpec {
                ortho_height: Some(2.0 * o.ymag().abs()),
                ..placed
            },
            Some(o.xmag().abs() / o.ymag().abs()),
        ),
    };
    spec.check()
        .map_err(|e| format!("camera {}: {e}", describe(camera.index(), camera.name())))?;
    let aspect = aspect.filter(|a| a.is_finite() && *a > 0.0);
    Ok(ModelCamera { spec, aspect })
}

struct Loader<'a, 's> {
    buffers: &'a Buffers,
    assets: &'a dyn Assets,
    images: textures::Images,
    scene: &'s mut Scene,
    /// canopy's mesh of each set of accessors already read: primitives of different
    /// meshes that share their accessors share one mesh (decoded once).
    meshes: HashMap<MeshSource, Option<u32>>,
    /// canopy's material of each glTF material (`None`: the default material).
    materials: HashMap<Option<usize>, u32>,
    /// The first camera met, placed.
    camera: Option<(gltf::Camera<'a>, Affine3A)>,
}

impl<'a> Loader<'a, '_> {
    /// Something the file uses that canopy leaves out, said once.
    fn note(&mut self, note: String) {
        if !self.scene.notes.contains(&note) {
            self.scene.notes.push(note);
        }
    }

    /// Places `node` (and its children) under `parent`, its world transform.
    fn place(
        &mut self,
        node: &gltf::Node<'a>,
        parent: Affine3A,
        depth: usize,
        visited: &mut [bool],
    ) -> Result<(), String> {
        let named = format!("node {}", describe(node.index(), node.name()));
        if std::mem::replace(&mut visited[node.index()], true) {
            return Err(format!(
                "{named} is reached twice in the hierarchy (a cycle, or a node with two parents)"
            ));
        }
        if depth > MAX_DEPTH {
            return Err(format!("{named} is nested more than {MAX_DEPTH} deep"));
        }
        let local = Mat4::from_cols_array_2d(&node.transform().matrix());
        if !local.is_finite() || local.row(3) != glam::Vec4::W {
            return Err(format!(
                "{named}: its transform is not a finite affine matrix"
            ));
        }
        let world = parent * Affine3A::from_mat4(local);
        if let Some(camera) = node.camera() {
            if self.camera.is_none() {
                self.camera = Some((camera, world));
            }
        }
        if let Some(light) = node.light() {
            self.place_light(&light, world)
                .map_err(|e| format!("{named}: {e}"))?;
        }
        if let Some(mesh) = node.mesh() {
            if world.matrix3.determinant() == 0.0 {
                // A zero scale hides a node (a common way to switch parts off).
                self.note(format!("{named} is scaled to nothing: left out"));
            } else {
                self.place_mesh(&mesh, world)
                    .map_err(|e| format!("{named}: {e}"))?;
            }
        }
        for child in node.children() {
            self.place(&child, world, depth + 1, visited)?;
        }
        Ok(())
    }

    /// Places a `KHR_lights_punctual` light by `world` (it shines down its local −z).
    fn place_light(
        &mut self,
        light: &gltf::khr_lights_punctual::Light<'a>,
        world: Affine3A,
    ) -> Result<(), String> {
        use crate::lights::PunctualLight;
        use gltf::khr_lights_punctual::Kind;
        let named = format!("light {}", describe(light.index(), light.name()));
        let strength = Vec3::from(light.color()) * light.intensity();
        let position = world.transform_point3(Vec3::ZERO);
        let direction = world.transform_vector3(-Vec3::Z).normalize_or_zero();
        if light.range().is_some() {
            self.note(format!(
                "{named}: its range is not used (light falls off with the square of distance)"
            ));
        }
        let placed = match light.kind() {
            Kind::Point => PunctualLight::Point {
                position,
                intensity: strength,
            },
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => PunctualLight::Spot {
                position,
                direction,
                intensity: strength,
                cos_inner: inner_cone_angle.cos(),
                cos_outer: outer_cone_angle.cos(),
            },
            Kind::Directional => PunctualLight::Directional {
                direction,
                irradiance: strength,
            },
        };
        self.scene
            .add_light(placed)
            .map_err(|e| format!("{named}: {e}"))
    }

    /// Places every primitive of `mesh` by `world`.
    fn place_mesh(&mut self, mesh: &gltf::Mesh<'a>, world: Affine3A) -> Result<(), String> {
        for primitive in mesh.primitives() {
            let key = MeshSource::of(&primitive);
            let index = match self.meshes.get(&key) {
                Some(&index) => index,
                None => {
                    let named = format!(
                        "mesh {} primitive {}",
                        describe(mesh.index(), mesh.name()),
                        primitive.index()
                    );
                    let index = self
                        .read_primitive(&primitive, &named)
                        .map_err(|e| format!("{named}: {e}"))?;
                    self.meshes.insert(key, index);
                    index
                }
            };
            let Some(index) = index else { continue };
            let material = self.material(&primitive.material())?;
            self.scene.add_instance(index, world, material)?;
        }
        Ok(())
    }

    /// canopy's mesh of one primitive, or `None` for one that is not made of triangles.
    fn read_primitive(
        &mut self,
        primitive: &gltf::Primitive<'a>,
        named: &str,
    ) -> Result<Option<u32>, String> {
        let mode = primitive.mode();
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            self.note(format!(
                "{named}: {mode:?} are not rendered (only triangles)"
            ));
            return Ok(None);
        }
        let buffers = self.buffers;
        let reader = primitive.reader(|b| buffers.get(b));
        let positions_accessor = primitive
            .get(&gltf::Semantic::Positions)
            .ok_or("it has no POSITION attribute")?;
        check_accessor(&positions_accessor, &POSITIONS, buffers)?;
        let positions: Vec<Vec3> = reader
            .read_positions()
            .ok_or("its positions cannot be read")?
            .map(Vec3::from)
            .collect();
        let normals: Vec<Vec3> = match primitive.get(&gltf::Semantic::Normals) {
            Some(accessor) => {
                check_accessor(&accessor, &NORMALS, buffers)?;
                if accessor.count() != positions.len() {
                    return Err(format!(
                        "{} normals for {} positions",
                        accessor.count(),
                        positions.len()
                    ));
                }
                let normals = reader.read_normals().ok_or("its normals cannot be read")?;
                normals.map(Vec3::from).collect()
            }
            // The specification asks for flat shading where normals are not given.
            None => Vec::new(),
        };
        let uvs: Vec<Vec2> = match primitive.get(&gltf::Semantic::TexCoords(0)) {
            Some(accessor) => {
                check_accessor(&accessor, &TEXCOORDS, buffers)?;
                let integer = accessor.data_type() != gltf::accessor::DataType::F32;
                if integer && !accessor.normalized() {
                    return Err(format!(
                        "texture coordinates accessor {} holds integers that are not normalized",
                        accessor.index()
                    ));
                }
                if accessor.count() != positions.len() {
                    return Err(format!(
                        "{} texture coordinates for {} positions",
                        accessor.count(),
                        positions.len()
                    ));
                }
                let uvs = reader
                    .read_tex_coords(0)
                    .ok_or("its texture coordinates cannot be read")?;
                uvs.into_f32().map(Vec2::from).collect()
            }
            None => Vec::new(),
        };
        let vertices: Vec<u32> = match primitive.indices() {
            Some(accessor) => {
                check_accessor(&accessor, &INDICES, buffers)?;
                let indices = reader.read_indices().ok_or("its indices cannot be read")?;
                let indices: Vec<u32> = indices.into_u32().collect();
                if let Some(&past) = indices.iter().find(|&&i| i as usize >= positions.len()) {
                    return Err(format!(
                        "index {past} is past the last of its {} vertices",
                        positions.len()
                    ));
                }
                indices
            }
            None => (0..positions.len() as u32).collect(),
        };
        let triangles = assemble(mode, &vertices);
        let name = named.to_owned();
        let mesh = self
            .scene
            .add_mesh(&name, positions, triangles, normals, false)?;
        if !uvs.is_empty() {
            if primitive.material().normal_texture().is_some() {
                self.tangents(primitive, mesh, &uvs)?;
            }
            self.scene.set_mesh_uvs(mesh, uvs)?;
        }
        Ok(Some(mesh))
    }

    /// Tangents of mesh `mesh` (read from `primitive`) for its material's normal map:
    /// the file's `TANGENT` attribute, or MikkTSpace's.
    fn tangents(
        &mut self,
        primitive: &gltf::Primitive<'a>,
        mesh: u32,
        uvs: &[Vec2],
    ) -> Result<(), String> {
        let buffers = self.buffers;
        let target = &self.scene.meshes[mesh as usize];
        let triangles = target.mesh.indices();
        let tangents = match primitive.get(&gltf::Semantic::Tangents) {
            Some(accessor) => {
                check_accessor(&accessor, &TANGENTS, buffers)?;
                let count = target.mesh.vertices().len();
                if accessor.count() != count {
                    return Err(format!(
                        "{} tangents for {count} positions",
                        accessor.count()
                    ));
                }
                let reader = primitive.reader(|b| buffers.get(b));
                let per_vertex: Vec<glam::Vec4> = reader
                    .read_tangents()
                    .ok_or("its tangents cannot be read")?
                    .map(glam::Vec4::from)
                    .collect();
                triangles
                    .iter()
                    .map(|t| t.map(|i| per_vertex[i as usize]))
                    .collect()
            }
            None => crate::mesh::tangents::generate(
                target.mesh.vertices(),
                &target.normals,
                uvs,
                triangles,
            )
            .ok_or("its tangents cannot be generated from its texture coordinates")?,
        };
        self.scene.meshes[mesh as usize].tangents = tangents;
        Ok(())
    }

    /// canopy's material for `material`, converted once.
    fn material(&mut self, material: &gltf::Material<'a>) -> Result<u32, String> {
        if let Some(&index) = self.materials.get(&material.index()) {
            return Ok(index);
        }
        let named = material.index().map_or("the default material".into(), |i| {
            format!("material {}", describe(i, material.name()))
        });
        let mut notes = Vec::new();
        let converted = materials::convert(material, &mut notes);
        let index = self
            .scene
            .add_material(converted)
            .map_err(|e| format!("{named}: {e}"))?;
        if matches!(converted, crate::material::Material::Pbr(_)) {
            let pbr = material.pbr_metallic_roughness();
            let mut texture = |info: Option<gltf::texture::Info<'a>>| match info {
                Some(info) => self
                    .images
                    .texture(self.scene, self.buffers, self.assets, &info, &mut notes)
                    .map_err(|e| format!("{named}: {e}")),
                None => Ok(None),
            };
            let base_color = texture(pbr.base_color_texture())?;
            let metallic_roughness = texture(pbr.metallic_roughness_texture())?;
            let emissive = texture(material.emissive_texture())?;
            let normal = match material.normal_texture() {
                Some(normal) => self
                    .images
                    .normal_map(self.scene, self.buffers, self.assets, &normal, &mut notes)
                    .map_err(|e| format!("{named}: {e}"))?,
                None => None,
            };
            let maps = crate::texture::MaterialMaps {
                base_color,
                metallic_roughness,
                normal,
                emissive,
                coverage: materials::coverage(material),
            };
            if !maps.is_empty() {
                self.scene
                    .set_material_maps(index, maps)
                    .map_err(|e| format!("{named}: {e}"))?;
            }
        }
        notes.into_iter().for_each(|n| self.note(n));
        self.materials.insert(material.index(), index);
        Ok(index)
    }
}

/// Triangles of a primitive drawn in `mode` over `vertices` (glTF 2.0, 3.7.2.1: strips
/// alternate their winding so that every triangle faces the same way).
fn assemble(mode: Mode, v: &[u32]) -> Vec<[u32; 3]> {
    match mode {
        Mode::TriangleStrip => (0..v.len().saturating_sub(2))
            .map(|i| match i % 2 {
                0 => [v[i], v[i + 1], v[i + 2]],
                _ => [v[i], v[i + 2], v[i + 1]],
            })
            .collect(),
        Mode::TriangleFan => (1..v.len().saturating_sub(1))
            .map(|i| [v[i], v[i + 1], v[0]])
            .collect(),
        _ => v.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_and_fans_keep_one_winding() {
        let v = [0, 1, 2, 3, 4];
        assert_eq!(
            assemble(Mode::TriangleStrip, &v),
            vec![[0, 1, 2], [1, 3, 2], [2, 3, 4]]
        );
        assert_eq!(
            assemble(Mode::TriangleFan, &v),
            vec![[1, 2, 0], [2, 3, 0], [3, 4, 0]]
        );
        assert_eq!(assemble(Mode::Triangles, &v), vec![[0, 1, 2]]);
        assert!(assemble(Mode::TriangleStrip, &[0, 1]).is_empty());
    }
}
