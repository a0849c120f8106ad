//! Regression guard on tree quality: binned SAH must stay close to the full sweep.

use canopy_bvh::{build, BuildParams, Builder};
use canopy_render::load_scene;

#[test]
fn binned_sah_is_within_ten_percent_of_sweep_sah_on_the_bunny() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/meshes/bunny.ply");
    let scene = load_scene(path).unwrap();
    let boxes = scene.primitive_bounds();
    assert!(boxes.len() > 3000);
    let params = BuildParams::default();
    let sah = |builder| {
        let bvh = build(builder, &boxes, &params);
        bvh.validate(&boxes).unwrap();
        bvh.stats(&params.sah).sah_cost
    };
    let (binned, sweep) = (sah(Builder::BinnedSah), sah(Builder::SweepSah));
    assert!(
        binned <= 1.10 * sweep,
        "binned SAH {binned} is more than 10% above sweep SAH {sweep}"
    );
}
