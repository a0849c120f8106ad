//! The acceleration structure a render uses: none (a loop over all primitives, the
//! report's baseline) or a BVH from any builder.

use crate::scene::Primitive;
use canopy_bvh::{build, BuildParams, Builder, Bvh2, Hit, Ray};
use std::fmt;
use std::str::FromStr;
use std::time::{Duration, Instant};

/// Which acceleration structure to build.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AccelKind {
    /// Test every primitive for every ray.
    None,
    Bvh(Builder),
    #[default]
    DefaultBvh,
}

impl AccelKind {
    /// Every choice by name, `none` first.
    pub fn names() -> Vec<&'static str> {
        std::iter::once("none")
            .chain(Builder::ALL.iter().map(|b| b.name()))
            .collect()
    }

    fn resolved(self) -> Option<Builder> {
        match self {
            AccelKind::None => None,
            AccelKind::Bvh(b) => Some(b),
            AccelKind::DefaultBvh => Some(Builder::default()),
        }
    }
}

impl fmt::Display for AccelKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.resolved() {
            None => f.write_str("none"),
            Some(b) => f.write_str(b.name()),
        }
    }
}

impl FromStr for AccelKind {
    type Err = canopy_bvh::UnknownBuilder;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s == "none" {
            return Ok(AccelKind::None);
        }
        s.parse::<Builder>().map(AccelKind::Bvh).map_err(|mut e| {
            e.known = format!("none, {}", e.known);
            e
        })
    }
}

/// A built acceleration structure over a scene's primitives.
#[derive(Clone, Debug)]
pub struct Accel {
    bvh: Option<Bvh2>,
    /// Wall-clock time the build took.
    pub build_time: Duration,
}

impl Accel {
    pub fn build(kind: AccelKind, primitives: &[Primitive], params: &BuildParams) -> Self {
        let start = Instant::now();
        let bvh = kind.resolved().map(|builder| {
            let boxes: Vec<_> = primitives.iter().map(|p| p.shape.bounds()).collect();
            build(builder, &boxes, params)
        });
        Self {
            bvh,
            build_time: start.elapsed(),
        }
    }

    pub fn bvh(&self) -> Option<&Bvh2> {
        self.bvh.as_ref()
    }

    /// Closest hit; ties go to the lower primitive index whatever the structure.
    #[inline]
    pub fn intersect(&self, primitives: &[Primitive], ray: &Ray) -> Option<Hit> {
        let test = |prim: u32, ray: &Ray| primitives[prim as usize].shape.intersect(ray);
        match &self.bvh {
            Some(bvh) => bvh.intersect(ray, test),
            None => {
                let mut best: Option<Hit> = None;
                let mut ray = *ray;
                for prim in 0..primitives.len() as u32 {
                    if let Some(t) = test(prim, &ray) {
                        let hit = Hit { t, prim };
                        if best.is_none_or(|b| hit.is_before(&b)) {
                            ray.t_max = t;
                            best = Some(hit);
                        }
                    }
                }
                best
            }
        }
    }
}
