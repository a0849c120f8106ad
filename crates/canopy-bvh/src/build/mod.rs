//! BVH builders. Each is a pure function from primitive boxes to a [`Bvh2`].

mod binned_sah;

use crate::{Aabb, Bvh2};
use std::fmt;
use std::str::FromStr;
use thiserror::Error;

/// Which algorithm builds the tree.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Builder {
    /// Top-down surface area heuristic with binned split candidates on all three axes
    /// (Wald, "On fast construction of SAH-based BVHs", 2007).
    #[default]
    BinnedSah,
}

impl Builder {
    pub const ALL: &'static [Builder] = &[Builder::BinnedSah];

    /// The name used on the command line and in scene files.
    pub fn name(self) -> &'static str {
        match self {
            Builder::BinnedSah => "binned-sah",
        }
    }

    /// One line for `--help` texts.
    pub fn description(self) -> &'static str {
        match self {
            Builder::BinnedSah => "top-down SAH, binned split candidates on all axes",
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
    /// Split candidates per axis for binned builders.
    pub bins: u32,
}

impl Default for BuildParams {
    fn default() -> Self {
        Self {
            max_leaf_size: 4,
            sah: SahCosts::default(),
            bins: 16,
        }
    }
}

/// Builds a BVH over primitives given by their bounding boxes.
///
/// Boxes must not contain NaN; an empty box is allowed and is never hit.
pub fn build(builder: Builder, boxes: &[Aabb], params: &BuildParams) -> Bvh2 {
    let params = BuildParams {
        max_leaf_size: params.max_leaf_size.max(1),
        bins: params.bins.clamp(2, 256),
        ..*params
    };
    let bvh = match builder {
        Builder::BinnedSah => binned_sah::build(boxes, &params),
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
}
