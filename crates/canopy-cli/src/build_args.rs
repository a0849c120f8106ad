//! Options shared by every command that builds a BVH.

use canopy_bvh::{BuildParams, Builder, SahCosts};
use clap::Args;

#[derive(Args, Clone, Debug)]
pub struct BuildArgs {
    /// Most primitives in a BVH leaf.
    #[arg(long, default_value_t = BuildParams::default().max_leaf_size)]
    pub max_leaf_size: u32,
    /// SAH cost of visiting a node, relative to testing a primitive.
    #[arg(long, default_value_t = SahCosts::default().traversal)]
    pub sah_traversal: f32,
    /// SAH cost of testing a primitive.
    #[arg(long, default_value_t = SahCosts::default().intersection)]
    pub sah_intersection: f32,
    /// Neighbours searched on each side by `ploc`.
    #[arg(long, default_value_t = BuildParams::default().ploc_radius)]
    pub ploc_radius: u32,
}

impl BuildArgs {
    pub fn params(&self) -> anyhow::Result<BuildParams> {
        let costs_ok = |c: f32| c.is_finite() && c > 0.0;
        if !costs_ok(self.sah_traversal) || !costs_ok(self.sah_intersection) {
            anyhow::bail!("SAH costs must be positive numbers");
        }
        Ok(BuildParams {
            max_leaf_size: self.max_leaf_size,
            sah: SahCosts {
                traversal: self.sah_traversal,
                intersection: self.sah_intersection,
            },
            ploc_radius: self.ploc_radius,
            ..BuildParams::default()
        })
    }
}

/// `intro`, then the builders one per line, for `--help`.
pub fn builders_help(intro: &str) -> String {
    let mut help = format!("{intro}\n");
    for b in Builder::ALL {
        help.push_str(&format!("  {:<14} {}\n", b.name(), b.description()));
    }
    help
}
