//! Mean BVH work per camera ray for a built-in scene:
//! `cargo run --release -p canopy-render --example traversal_stats -- paper-1`
use canopy_bvh::{BuildParams, Builder, Ray, ShearedRay, TraversalStats};
use canopy_render::camera::Camera;
use canopy_render::rng::Rng;
use canopy_render::BuiltinScene;

fn main() {
    let name = std::env::args().nth(1).unwrap_or_else(|| "paper-1".into());
    let scene = BuiltinScene::find(&name)
        .expect("built-in scene")
        .load()
        .unwrap();
    let boxes = scene.primitive_bounds();
    let params = BuildParams::default();
    let bvh = canopy_bvh::build(Builder::BinnedSah, &boxes, &params);
    let st = bvh.stats(&params.sah);
    println!(
        "{name}: {} prims, {} nodes, {} leaves, depth {}, SAH {:.2}",
        boxes.len(),
        st.nodes,
        st.leaves,
        st.max_depth,
        st.sah_cost
    );
    let (w, h) = (200, 200);
    let camera = Camera::new(&scene.camera, w, h);
    let mut stats = TraversalStats::default();
    let mut bounce_stats = TraversalStats::default();
    let mut bounces = 0;
    for i in 0..w * h {
        let mut rng = Rng::for_sample(0, i as u64, 0);
        let ray: Ray = camera.ray(
            (i % w) as f32 / w as f32,
            (i / w) as f32 / h as f32,
            &mut rng,
        );
        let test = |p: u32, r: &Ray| {
            scene.primitives[p as usize]
                .shape
                .intersect_sheared(r, &ShearedRay::new(r))
        };
        if let Some(hit) = bvh.intersect_counted(&ray, test, &mut stats) {
            // One diffuse-like bounce from the hit point.
            let s = scene.primitives[hit.prim as usize].shape.surface(
                &ray,
                &hit,
                &scene.vertex_normals,
            );
            let dir = (s.geometric_normal
                * if ray.dir.dot(s.geometric_normal) < 0.0 {
                    1.0
                } else {
                    -1.0
                }
                + rng.unit_vector())
            .normalize();
            let origin = s.p
                + dir.signum() * 0.0
                + s.geometric_normal * 1e-3 * ray.dir.dot(s.geometric_normal).signum() * -1.0;
            bvh.intersect_counted(
                &Ray::new(origin, dir, 0.0, f32::INFINITY),
                test,
                &mut bounce_stats,
            );
            bounces += 1;
        }
    }
    let n = (w * h) as f64;
    println!(
        "per camera ray: {:.1} nodes visited, {:.1} primitives tested",
        stats.nodes_visited as f64 / n,
        stats.primitives_tested as f64 / n
    );
    let b = bounces.max(1) as f64;
    println!(
        "per bounce ray: {:.1} nodes visited, {:.1} primitives tested",
        bounce_stats.nodes_visited as f64 / b,
        bounce_stats.primitives_tested as f64 / b
    );
}
