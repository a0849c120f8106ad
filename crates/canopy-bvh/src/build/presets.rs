//! Named choices of builder and parameters, from the fastest build to the best tree, for
//! users who would rather not choose among eight builders (as obvhs offers
//! `fast_build`/`medium_build`/`slow_build`). On the 202k-triangle dragon, 2 cores:
//! `fast-build` about 50 ms, `balanced` about 90 ms, `best-trees` about 230 ms; SAH cost
//! falls in that order (`tests/tree_quality.rs` in canopy-render holds it on the bunny).

use super::{BuildParams, Builder};
use std::fmt;
use std::str::FromStr;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Preset {
    /// LBVH (Karras 2012): Morton codes and a radix tree, in parallel. For trees rebuilt
    /// every frame, or scenes traced with few rays.
    FastBuild,
    /// Binned SAH, 16 bins on all axes, subtrees in parallel: near the best trees at a
    /// fraction of their build time. canopy's default.
    #[default]
    Balanced,
    /// Full-sweep SAH over every split position: the best trees canopy builds, for scenes
    /// traced with many rays.
    BestTrees,
}

impl Preset {
    pub const ALL: [Preset; 3] = [Preset::FastBuild, Preset::Balanced, Preset::BestTrees];

    pub fn name(self) -> &'static str {
        match self {
            Preset::FastBuild => "fast-build",
            Preset::Balanced => "balanced",
            Preset::BestTrees => "best-trees",
        }
    }

    /// The builder and the parameters this preset stands for.
    pub fn choice(self) -> (Builder, BuildParams) {
        let params = BuildParams::default();
        match self {
            Preset::FastBuild => (Builder::Lbvh, params),
            Preset::Balanced => (Builder::BinnedSah, params),
            Preset::BestTrees => (Builder::SweepSah, params),
        }
    }
}

impl fmt::Display for Preset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Preset {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Preset::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| {
                format!("unknown preset `{s}` (known: fast-build, balanced, best-trees)")
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_round_trip_and_have_valid_parameters() {
        for preset in Preset::ALL {
            assert_eq!(preset.name().parse::<Preset>(), Ok(preset));
            assert_eq!(preset.choice().1.check(), Ok(()));
        }
        assert!("fastest".parse::<Preset>().is_err());
        assert_eq!(Preset::default().choice().0, Builder::default());
    }
}
