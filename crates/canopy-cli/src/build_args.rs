//! Options shared by every command that builds a BVH.

use crate::limits;
use canopy_bvh::{BuildParams, Builder, SahCosts};
use clap::Args;

#[derive(Args, Clone, Debug)]
pub struct BuildArgs {
    /// Most primitives in a BVH leaf (1 to 256). Left at 4, a 4- or 8-wide tree over
    /// mostly triangles (90% or more) takes leaves of up to two packs of four (8).
    #[arg(long, default_value_t = BuildParams::default().max_leaf_size, value_parser = limits::leaf_size())]
    pub max_leaf_size: u32,
    /// SAH cost of visiting a node, relative to testing a primitive (0 < cost <= 1e6).
    #[arg(long, default_value_t = SahCosts::default().traversal, value_parser = limits::sah_cost)]
    pub sah_traversal: f32,
    /// SAH cost of testing a primitive (0 < cost <= 1e6).
    #[arg(long, default_value_t = SahCosts::default().intersection, value_parser = limits::sah_cost)]
    pub sah_intersection: f32,
    /// Neighbours searched on each side by `ploc` (1 to 1024).
    #[arg(long, default_value_t = BuildParams::default().ploc_radius, value_parser = limits::ploc_radius())]
    pub ploc_radius: u32,
    /// Most references `sbvh`'s spatial splits may add, as a fraction of the primitives
    /// (0 to 16; 0.3 = up to 30% more, 0 = no spatial splits).
    #[arg(long, default_value_t = BuildParams::default().max_duplication, value_parser = limits::max_duplication)]
    pub max_duplication: f32,
}

impl BuildArgs {
    /// The build parameters; every value was range-checked by the parser.
    pub fn params(&self) -> BuildParams {
        BuildParams {
            max_leaf_size: self.max_leaf_size,
            sah: SahCosts {
                traversal: self.sah_traversal,
                intersection: self.sah_intersection,
            },
            ploc_radius: self.ploc_radius,
            max_duplication: self.max_duplication,
            ..BuildParams::default()
        }
    }
}

impl BuildArgs {
    /// Refuses a build whose scratch memory would exceed what is available, before it
    /// starts: `builder` over `primitives` boxes. PLOC keeps `radius` distances per
    /// cluster; the other builders need a few dozen bytes per primitive.
    pub fn check_memory(&self, builder: Builder, primitives: usize) -> anyhow::Result<()> {
        let n = primitives as u64;
        let mut bytes = n * 256;
        if builder == Builder::Ploc {
            bytes += n * (self.ploc_radius as u64).min(n) * 4;
        }
        crate::safety::check_memory(bytes, &format!("building {builder} over {n} primitives"))
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
