//! BVH builders. Each is a pure function from primitive boxes to a [`Bvh2`].

mod aac;
mod agglomerative;
mod binned_sah;
mod box4;
mod clip;
mod lbvh;
mod median;
mod merge_tree;
pub(crate) mod morton;
mod ploc;
mod presets;
mod sbvh;
mod sweep_sah;
mod top_down;

pub use clip::{split_box, split_triangle, Clipper, SplitBoxes};
pub use presets::Preset;

use crate::{Aabb, Bvh2};
use std::fmt;
use std::str::FromStr;
use thiserror::Error;

/// Which algorithm builds the tree. Every one yields the same [`Bvh2`] format and honours
/// [`BuildParams::max_leaf_size`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Builder {
    /// The report's first method: sort centroids along one axis (0 = x, 1 = y, 2 = z),
    /// split at the median, recursively.
    SortAxis(u8),
    /// The report's second method: sort by the Morton code of the centroids, split at
    /// the median.
    MortonMedian,
    /// Karras 2012 radix tree over 63-bit Morton codes, built in parallel.
    Lbvh,
    /// Top-down surface area heuristic with binned split candidates on all three axes
    /// (Wald, "On fast construction of SAH-based BVHs", 2007), subtrees in parallel.
    #[default]
    BinnedSah,
    /// Top-down SAH sweeping every split position of all three sorted axes.
    SweepSah,
    /// Binned SAH with spatial splits (Stich et al. 2009): primitives that straddle a
    /// plane may be cut and referenced from both sides, within a duplication budget.
    Sbvh,
    /// The report's bottom-up greedy clustering (Walter et al. 2008), exact, by the
    /// nearest-neighbour chain.
    Agglomerative,
    /// Approximate agglomerative clustering (Gu et al. 2013).
    Aac,
    /// Parallel locally-ordered clustering (Meister and Bittner 2018).
    Ploc,
}

impl Builder {
    pub const ALL: &'static [Builder] = &[
        Builder::SortAxis(0),
        Builder::SortAxis(1),
        Builder::SortAxis(2),
        Builder::MortonMedian,
        Builder::Lbvh,
        Builder::BinnedSah,
        Builder::SweepSah,
        Builder::Sbvh,
        Builder::Agglomerative,
        Builder::Aac,
        Builder::Ploc,
    ];

    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Builder::SortAxis(0) => "sort-x",
            Builder::SortAxis(1) => "sort-y",
            Builder::SortAxis(_) => "sort-z",
            Builder::MortonMedian => "morton-median",
            Builder::Lbvh => "lbvh",
            Builder::BinnedSah => "binned-sah",
            Builder::SweepSah => "sweep-sah",
            Builder::Sbvh => "sbvh",
            Builder::Agglomerative => "agglomerative",
            Builder::Aac => "aac",
            Builder::Ploc => "ploc",
        }
    }

    /// One line for `--help` texts.
    pub fn description(self) -> &'static str {
        match self {
            Builder::SortAxis(0) => "report's top-down: sort centroids by x, split at the median",
            Builder::SortAxis(1) => "report's top-down: sort centroids by y, split at the median",
            Builder::SortAxis(_) => "report's top-down: sort centroids by z, split at the median",
            Builder::MortonMedian => "report's top-down: sort by Morton code, split at the median",
            Builder::Lbvh => "Karras 2012 radix tree on 63-bit Morton codes (parallel)",
            Builder::BinnedSah => "top-down SAH, binned split candidates on all axes (parallel)",
            Builder::SweepSah => "top-down SAH, full sweep over all three sorted axes",
            Builder::Sbvh => "binned SAH with spatial splits, triangles clipped (Stich 2009)",
            Builder::Agglomerative => {
                "report's bottom-up: exact greedy SAH clustering (Walter 2008)"
            }
            Builder::Aac => "approximate agglomerative clustering (Gu 2013)",
            Builder::Ploc => "parallel locally-ordered clustering (Meister & Bittner 2018)",
        }
    }
}

impl fmt::Display for Builder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A builder name that no builder answers to.
#[derive(Debug, Error, PartialEq)]
#[error("unknown BVH builder `{name}` (known: {known})")]
pub struct UnknownBuilder {
    pub name: String,
    pub known: String,
}

impl FromStr for Builder {
    type Err = UnknownBuilder;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Builder::ALL
            .iter()
            .copied()
            .find(|b| b.name() == s)
            .ok_or_else(|| UnknownBuilder {
                name: s.to_owned(),
                known: Builder::ALL
                    .iter()
                    .map(|b| b.name())
                    .collect::<Vec<_>>()
                    .join(", "),
            })
    }
}

/// Relative costs of the surface area heuristic: visiting a node vs testing a primitive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SahCosts {
    pub traversal: f32,
    pub intersection: f32,
}

impl Default for SahCosts {
    fn default() -> Self {
        Self {
            traversal: 1.0,
            intersection: 1.0,
        }
    }
}

/// Options shared by all builders.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildParams {
    /// No leaf holds more primitives than this (at least 1).
    pub max_leaf_size: u32,
    pub sah: SahCosts,
    /// Split candidates per axis for binned builders (2 to 32).
    pub bins: u32,
    /// How many neighbours on each side PLOC searches.
    pub ploc_radius: u32,
    /// Primitives a leaf tests together (at least 1): the SAH builders (`binned-sah`,
    /// `sweep-sah`) price a leaf of `n` primitives as `ceil(n / leaf_block)` tests.
    /// 1 prices each primitive; [`crate::PACK_LANES`] suits a wide tree whose triangles
    /// are packed (a pack of 4 costs about one triangle test), and gives fuller leaves.
    pub leaf_block: u32,
    /// `sbvh`: the most references spatial splits may add, as a fraction of the
    /// primitives (0.3: up to 30% more); 0 turns spatial splits off.
    pub max_duplication: f32,
}

/// Why build parameters cannot be used as given.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum ParamsError {
    #[error("max_leaf_size must be at least 1")]
    LeafSize,
    #[error("leaf_block must be at least 1")]
    LeafBlock,
    #[error("bins must be in 2..={max}, not {bins}", max = binned_sah::MAX_BINS)]
    Bins { bins: u32 },
    #[error("the SAH cost `{name}` must be a positive finite number, not {value}")]
    SahCost { name: &'static str, value: f32 },
    #[error("ploc_radius must be at least 1")]
    PlocRadius,
    #[error("max_duplication must be a finite number from 0 to 16, not {value}")]
    Duplication { value: f32 },
}

impl BuildParams {
    /// Checks every parameter; [`build`] would clamp what this refuses.
    pub fn check(&self) -> Result<(), ParamsError> {
        if self.max_leaf_size == 0 {
            return Err(ParamsError::LeafSize);
        }
        if self.leaf_block == 0 {
            return Err(ParamsError::LeafBlock);
        }
        if !(2..=binned_sah::MAX_BINS as u32).contains(&self.bins) {
            return Err(ParamsError::Bins { bins: self.bins });
        }
        for (name, value) in [
            ("traversal", self.sah.traversal),
            ("intersection", self.sah.intersection),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(ParamsError::SahCost { name, value });
            }
        }
        if self.ploc_radius == 0 {
            return Err(ParamsError::PlocRadius);
        }
        if !(0.0..=MAX_DUPLICATION).contains(&self.max_duplication) {
            return Err(ParamsError::Duplication {
                value: self.max_duplication,
            });
        }
        Ok(())
    }

    /// The SAH price of a leaf of `n` primitives: their tests, in blocks.
    pub(crate) fn leaf_cost(&self, n: usize) -> f32 {
        self.leaf_tests(n) * self.sah.intersection
    }

    /// Whether a leaf of `n` primitives costs no more than one traversal, which every
    /// split pays before its children: then no split can win, and a builder may make the
    /// leaf without pricing any.
    pub(crate) fn leaf_beats_any_split(&self, n: usize) -> bool {
        self.sah.traversal >= self.leaf_cost(n)
    }

    /// The SAH price of testing `n` primitives in a leaf, in units of one test.
    #[inline]
    pub(crate) fn leaf_tests(&self, n: usize) -> f32 {
        let block = self.leaf_block.max(1) as usize;
        // The builders ask this for every split candidate; blocks are usually a power of
        // two, for which a shift replaces the division.
        if block.is_power_of_two() {
            ((n + block - 1) >> block.trailing_zeros()) as f32
        } else {
            n.div_ceil(block) as f32
        }
    }
}

impl Default for BuildParams {
    fn default() -> Self {
        Self {
            max_leaf_size: 4,
            sah: SahCosts::default(),
            bins: 16,
            ploc_radius: 16,
            leaf_block: 1,
            max_duplication: 0.3,
        }
    }
}

/// The largest [`BuildParams::max_duplication`]: 16 extra references per primitive.
const MAX_DUPLICATION: f32 = 16.0;

/// [`build`], refusing parameters that [`BuildParams::check`] refuses instead of
/// clamping them.
pub fn try_build(
    builder: Builder,
    boxes: &[Aabb],
    params: &BuildParams,
) -> Result<Bvh2, ParamsError> {
    params.check()?;
    Ok(build(builder, boxes, params))
}

/// Builds a BVH over primitives given by their bounding boxes.
///
/// Boxes must not contain NaN; an empty box is allowed and is never hit. Parameters out
/// of range are clamped (a leaf size or block of 0 to 1, bins to 2..=32, duplication to
/// 0..=16); use [`try_build`] or [`BuildParams::check`] to refuse them instead.
///
/// `sbvh` cuts primitives as boxes here ([`SplitBoxes`]); give it the geometry with
/// [`build_with_clipper`] to clip triangles.
pub fn build(builder: Builder, boxes: &[Aabb], params: &BuildParams) -> Bvh2 {
    build_with_clipper(builder, boxes, params, &SplitBoxes)
}

/// [`build`], with `clipper` cutting primitives for the builders with spatial splits
/// (the others ignore it).
pub fn build_with_clipper(
    builder: Builder,
    boxes: &[Aabb],
    params: &BuildParams,
    clipper: &dyn Clipper,
) -> Bvh2 {
    let params = BuildParams {
        max_leaf_size: params.max_leaf_size.max(1),
        bins: params.bins.clamp(2, binned_sah::MAX_BINS as u32),
        max_duplication: match params.max_duplication {
            d if d.is_nan() => 0.0,
            d => d.clamp(0.0, MAX_DUPLICATION),
        },
        ..*params
    };
    let bvh = match builder {
        Builder::SortAxis(axis) => median::build_sort_axis(boxes, &params, axis.min(2) as usize),
        Builder::MortonMedian => median::build_morton_median(boxes, &params),
        Builder::Lbvh => lbvh::build(boxes, &params),
        Builder::BinnedSah => binned_sah::build(boxes, &params),
        Builder::SweepSah => sweep_sah::build(boxes, &params),
        Builder::Sbvh => sbvh::build(boxes, &params, clipper),
        Builder::Agglomerative => agglomerative::build(boxes, &params),
        Builder::Aac => aac::build(boxes, &params),
        Builder::Ploc => ploc::build(boxes, &params),
    };
    debug_assert_eq!(bvh.validate(boxes), Ok(()));
    bvh
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builder_names_round_trip() {
        for &b in Builder::ALL {
            assert_eq!(b.name().parse::<Builder>(), Ok(b));
        }
    }

    #[test]
    fn unknown_builder_lists_the_known_ones() {
        let err = "octree".parse::<Builder>().unwrap_err();
        assert!(err.to_string().contains("binned-sah"), "{err}");
    }

    #[test]
    fn leaves_priced_in_blocks_are_fuller_and_valid() {
        let boxes: Vec<Aabb> = (0..2000)
            .map(|i| {
                let p = glam::Vec3::new((i % 17) as f32, (i / 17 % 13) as f32, (i / 221) as f32);
                Aabb::new(p, p + glam::Vec3::splat(0.6))
            })
            .collect();
        for builder in [Builder::BinnedSah, Builder::SweepSah] {
            let leaves = |block| {
                let params = BuildParams {
                    max_leaf_size: 8,
                    leaf_block: block,
                    ..BuildParams::default()
                };
                let bvh = build(builder, &boxes, &params);
                bvh.validate(&boxes).unwrap();
                bvh.stats(&params.sah).leaves
            };
            let (single, packed) = (leaves(1), leaves(4));
            assert!(
                (packed as f32) < 0.8 * single as f32,
                "{builder}: {packed} leaves priced in fours, {single} priced one by one"
            );
        }
    }

    /// Builders split their work across threads above a few hundred primitives; the tree
    /// (and so every image) must not depend on how many there are.
    #[test]
    fn every_builder_makes_the_same_tree_whatever_the_threads() {
        let mut seed = 7u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1 << 24) as f32
        };
        let boxes: Vec<Aabb> = (0..3000)
            .map(|_| {
                let p = glam::Vec3::new(next(), next(), next()) * 50.0;
                Aabb::new(p, p + glam::Vec3::new(next(), next(), next()))
            })
            .collect();
        let (boxes, params) = (&boxes, &BuildParams::default());
        let on = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            move |builder| pool.install(|| build(builder, boxes, params))
        };
        let (one, four) = (on(1), on(4));
        for &builder in Builder::ALL {
            let tree = four(builder);
            tree.validate(boxes).unwrap();
            assert!(tree == one(builder), "{builder}: another tree on 4 threads");
        }
    }

    #[test]
    fn check_names_what_is_wrong_and_try_build_refuses_it() {
        let ok = BuildParams::default();
        assert_eq!(ok.check(), Ok(()));
        let cases = [
            (
                BuildParams {
                    max_leaf_size: 0,
                    ..ok
                },
                ParamsError::LeafSize,
            ),
            (
                BuildParams {
                    leaf_block: 0,
                    ..ok
                },
                ParamsError::LeafBlock,
            ),
            (BuildParams { bins: 1, ..ok }, ParamsError::Bins { bins: 1 }),
            (
                BuildParams { bins: 33, ..ok },
                ParamsError::Bins { bins: 33 },
            ),
            (
                BuildParams {
                    ploc_radius: 0,
                    ..ok
                },
                ParamsError::PlocRadius,
            ),
        ];
        for (params, expected) in cases {
            assert_eq!(params.check(), Err(expected.clone()));
            assert_eq!(
                try_build(Builder::BinnedSah, &[Aabb::EMPTY], &params).unwrap_err(),
                expected
            );
        }
        for value in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            let params = BuildParams {
                sah: SahCosts {
                    traversal: value,
                    intersection: 1.0,
                },
                ..ok
            };
            let e = params.check().unwrap_err();
            assert!(e.to_string().contains("`traversal`"), "{e}");
        }
        assert!(try_build(Builder::Ploc, &[Aabb::EMPTY; 3], &ok).is_ok());
    }
}
