//! Regression guard on tree quality: binned SAH must stay close to the full sweep.

use canopy_bvh::{build, BuildParams, Builder, Preset};
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

#[test]
fn presets_trade_build_time_for_tree_quality_in_order_on_the_bunny() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/meshes/bunny.ply");
    let boxes = load_scene(path).unwrap().primitive_bounds();
    let sah = |preset: Preset| {
        let (builder, params) = preset.choice();
        let bvh = canopy_bvh::try_build(builder, &boxes, &params).unwrap();
        bvh.validate(&boxes).unwrap();
        bvh.stats(&params.sah).sah_cost
    };
    let (fast, balanced, best) = (
        sah(Preset::FastBuild),
        sah(Preset::Balanced),
        sah(Preset::BestTrees),
    );
    assert!(
        best <= balanced * 1.01 && balanced < fast,
        "SAH: fast-build {fast}, balanced {balanced}, best-trees {best}"
    );
}

#[test]
fn spatial_splits_lower_the_sah_of_binned_sah_on_the_bunny() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/meshes/bunny.ply");
    let scene = load_scene(path).unwrap();
    let boxes = scene.primitive_bounds();
    let params = BuildParams::default();
    let clipper = canopy_render::clipper(&scene.primitives);
    let sbvh = canopy_bvh::build_with_clipper(Builder::Sbvh, &boxes, &params, &clipper);
    sbvh.validate(&boxes).unwrap();
    let binned = build(Builder::BinnedSah, &boxes, &params);
    let (a, b) = (sbvh.stats(&params.sah), binned.stats(&params.sah));
    // Measured: 25.09 against 25.44, with 2% more references.
    assert!(
        a.sah_cost < 0.995 * b.sah_cost && a.references <= boxes.len() * 13 / 10,
        "sbvh {a:?}, binned-sah {b:?}"
    );
}
