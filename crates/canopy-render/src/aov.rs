//! Arbitrary output variables (AOVs): images of the surfaces a render sees, beside its
//! radiance, for a denoiser and for tools.
//!
//! - **albedo** and **normal** are what Open Image Denoise asks for: the reflectance and
//!   world-space shading normal (turned towards the ray) of the first surface that is not
//!   a mirror or glass, following those bounces to it; the background's colour (and a
//!   zero normal) where the ray escapes. They are means over all of a pixel's samples, the
//!   same camera rays as its radiance, so they are antialiased (and blurred by depth of
//!   field) exactly as the image is.
//! - **depth** (distance from the camera along the ray), **position** (world space) and
//!   the **instance and primitive ids** of the camera ray's first hit are those of each
//!   pixel's first sample: exact values a tool can select by, never a blend of two
//!   objects. Where the ray escapes: infinite depth and position, ids [`NO_ID`].
//!
//! Every layer is deterministic per pixel, like the radiance: the same in any region, any
//! number of threads and across a checkpoint.

use glam::Vec3;
use std::fmt;
use std::str::FromStr;

/// The id layers' value where the camera ray hits nothing.
pub const NO_ID: u32 = u32::MAX;

/// One output variable.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Aov {
    Albedo,
    Normal,
    Depth,
    Position,
    /// Two layers: the instance and the primitive hit.
    Id,
}

impl Aov {
    pub const ALL: [Aov; 5] = [Aov::Albedo, Aov::Normal, Aov::Depth, Aov::Position, Aov::Id];

    pub fn name(self) -> &'static str {
        match self {
            Aov::Albedo => "albedo",
            Aov::Normal => "normal",
            Aov::Depth => "depth",
            Aov::Position => "position",
            Aov::Id => "id",
        }
    }

    fn bit(self) -> u32 {
        1 << Aov::ALL.iter().position(|&a| a == self).expect("listed")
    }
}

impl fmt::Display for Aov {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Aov {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Aov::ALL.into_iter().find(|a| a.name() == s).ok_or_else(|| {
            let names: Vec<_> = Aov::ALL.iter().map(|a| a.name()).collect();
            format!("unknown AOV `{s}`, expected one of: {}", names.join(", "))
        })
    }
}

/// A set of AOVs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct AovSet(u32);

impl AovSet {
    pub const NONE: AovSet = AovSet(0);
    /// What a denoiser takes.
    pub const DENOISING: AovSet = AovSet(1 | 2);

    pub fn of(aovs: &[Aov]) -> Self {
        AovSet(aovs.iter().fold(0, |bits, a| bits | a.bit()))
    }

    pub fn contains(self, aov: Aov) -> bool {
        self.0 & aov.bit() != 0
    }

    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    pub fn union(self, other: AovSet) -> AovSet {
        AovSet(self.0 | other.0)
    }

    /// Whether every AOV of `other` is in this set.
    pub fn includes(self, other: AovSet) -> bool {
        other.0 & !self.0 == 0
    }

    pub fn iter(self) -> impl Iterator<Item = Aov> {
        Aov::ALL.into_iter().filter(move |&a| self.contains(a))
    }

    /// The set as stored in a checkpoint.
    pub fn bits(self) -> u32 {
        self.0
    }

    pub fn from_bits(bits: u32) -> Result<Self, String> {
        let known = (1 << Aov::ALL.len()) - 1;
        match bits & !known {
            0 => Ok(AovSet(bits)),
            _ => Err(format!("unknown AOVs in the set {bits:#x}")),
        }
    }
}

impl FromStr for AovSet {
    type Err = String;

    /// A comma-separated list of names (`albedo,normal`); empty is the empty set.
    fn from_str(s: &str) -> Result<Self, String> {
        let aovs = s
            .split(',')
            .map(str::trim)
            .filter(|n| !n.is_empty())
            .map(Aov::from_str)
            .collect::<Result<Vec<_>, _>>()?;
        Ok(AovSet::of(&aovs))
    }
}

impl fmt::Display for AovSet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names: Vec<_> = self.iter().map(|a| a.name()).collect();
        f.write_str(&names.join(","))
    }
}

/// What one camera sample saw, for the AOVs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AovSample {
    pub albedo: Vec3,
    pub normal: Vec3,
    /// Of the camera ray's first hit (infinite where it escapes).
    pub depth: f32,
    pub position: Vec3,
    pub instance: u32,
    pub primitive: u32,
}

impl AovSample {
    /// A camera ray that escapes into a background of colour `background`.
    pub fn escaped(background: Vec3) -> Self {
        Self {
            albedo: background,
            normal: Vec3::ZERO,
            depth: f32::INFINITY,
            position: Vec3::splat(f32::INFINITY),
            instance: NO_ID,
            primitive: NO_ID,
        }
    }
}

/// The AOV layers of a render in progress, over the pixels of its region (row by row
/// from the top). Layers not in `set` are empty. Albedo and normal hold sums of samples
/// (divide by the sample count, as [`crate::Accumulator::film`] does); the others hold
/// the first sample's values once a pixel has one.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AovBuffers {
    pub set: AovSet,
    pub albedo: Vec<Vec3>,
    pub normal: Vec<Vec3>,
    pub depth: Vec<f32>,
    pub position: Vec<Vec3>,
    pub instance: Vec<u32>,
    pub primitive: Vec<u32>,
}

impl AovBuffers {
    /// Empty layers of `set` for `pixels` pixels.
    pub fn new(set: AovSet, pixels: usize) -> Self {
        fn layer<T: Clone>(set: AovSet, aov: Aov, value: T, pixels: usize) -> Vec<T> {
            match set.contains(aov) {
                true => vec![value; pixels],
                false => Vec::new(),
            }
        }
        Self {
            set,
            albedo: layer(set, Aov::Albedo, Vec3::ZERO, pixels),
            normal: layer(set, Aov::Normal, Vec3::ZERO, pixels),
            depth: layer(set, Aov::Depth, 0.0, pixels),
            position: layer(set, Aov::Position, Vec3::ZERO, pixels),
            instance: layer(set, Aov::Id, NO_ID, pixels),
            primitive: layer(set, Aov::Id, NO_ID, pixels),
        }
    }

    /// Adds one sample of pixel `pixel` (its first sample where `first`).
    pub fn add(&mut self, pixel: usize, sample: &AovSample, first: bool) {
        let pixels = self.pixels();
        self.rows_mut(pixels)[0].add(pixel, sample, first);
    }

    /// Pixels the layers hold (0 without any).
    fn pixels(&self) -> usize {
        [
            self.albedo.len(),
            self.normal.len(),
            self.depth.len(),
            self.position.len(),
        ]
        .into_iter()
        .chain([self.instance.len()])
        .max()
        .unwrap_or(0)
    }

    /// The layers cut into rows of `width` pixels, to fill in parallel.
    pub fn rows_mut(&mut self, width: usize) -> Vec<AovRow<'_>> {
        fn rows<T>(layer: &mut [T], width: usize, count: usize) -> Vec<&mut [T]> {
            match layer.is_empty() {
                true => (0..count).map(|_| <&mut [T]>::default()).collect(),
                false => layer.chunks_mut(width).collect(),
            }
        }
        let count = self.pixels().div_ceil(width.max(1));
        let mut albedo = rows(&mut self.albedo, width, count).into_iter();
        let mut normal = rows(&mut self.normal, width, count).into_iter();
        let mut depth = rows(&mut self.depth, width, count).into_iter();
        let mut position = rows(&mut self.position, width, count).into_iter();
        let mut instance = rows(&mut self.instance, width, count).into_iter();
        let mut primitive = rows(&mut self.primitive, width, count).into_iter();
        (0..count)
            .map(|_| AovRow {
                albedo: albedo.next().expect("a row each"),
                normal: normal.next().expect("a row each"),
                depth: depth.next().expect("a row each"),
                position: position.next().expect("a row each"),
                instance: instance.next().expect("a row each"),
                primitive: primitive.next().expect("a row each"),
            })
            .collect()
    }

    /// Only the layers of `set` (those of them this holds).
    pub fn only(&self, set: AovSet) -> AovBuffers {
        let keep = |aov| set.contains(aov);
        let pick = |aov, layer: &Vec<Vec3>| if keep(aov) { layer.clone() } else { Vec::new() };
        AovBuffers {
            set: AovSet(self.set.0 & set.0),
            albedo: pick(Aov::Albedo, &self.albedo),
            normal: pick(Aov::Normal, &self.normal),
            depth: if keep(Aov::Depth) {
                self.depth.clone()
            } else {
                Vec::new()
            },
            position: pick(Aov::Position, &self.position),
            instance: if keep(Aov::Id) {
                self.instance.clone()
            } else {
                Vec::new()
            },
            primitive: if keep(Aov::Id) {
                self.primitive.clone()
            } else {
                Vec::new()
            },
        }
    }

    /// The layers as images of `samples` samples: albedo and normal averaged (the normal
    /// not renormalised: its length tells how much the samples agree).
    pub fn resolved(&self, samples: u32) -> AovBuffers {
        let n = samples.max(1) as f32;
        AovBuffers {
            albedo: self.albedo.iter().map(|s| *s / n).collect(),
            normal: self.normal.iter().map(|s| *s / n).collect(),
            ..self.clone()
        }
    }
}

/// One row of [`AovBuffers`], borrowed to be filled (layers not held are empty).
pub struct AovRow<'a> {
    albedo: &'a mut [Vec3],
    normal: &'a mut [Vec3],
    depth: &'a mut [f32],
    position: &'a mut [Vec3],
    instance: &'a mut [u32],
    primitive: &'a mut [u32],
}

impl AovRow<'_> {
    /// Adds one sample of the row's pixel `x`: albedo and normal to their sums (a
    /// non-finite value as zero), the rest set from the pixel's `first` sample.
    #[inline]
    pub fn add(&mut self, x: usize, sample: &AovSample, first: bool) {
        let finite_or_zero = |v: Vec3| if v.is_finite() { v } else { Vec3::ZERO };
        if let Some(sum) = self.albedo.get_mut(x) {
            *sum += finite_or_zero(sample.albedo);
        }
        if let Some(sum) = self.normal.get_mut(x) {
            *sum += finite_or_zero(sample.normal);
        }
        if !first {
            return;
        }
        if let Some(depth) = self.depth.get_mut(x) {
            *depth = sample.depth;
        }
        if let Some(position) = self.position.get_mut(x) {
            *position = sample.position;
        }
        if let (Some(instance), Some(primitive)) =
            (self.instance.get_mut(x), self.primitive.get_mut(x))
        {
            (*instance, *primitive) = (sample.instance, sample.primitive);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sets_parse_print_and_store_their_names() {
        let set: AovSet = "normal, albedo,id".parse().unwrap();
        assert!(set.contains(Aov::Albedo) && set.contains(Aov::Normal) && set.contains(Aov::Id));
        assert!(!set.contains(Aov::Depth));
        assert_eq!(set.to_string(), "albedo,normal,id");
        assert_eq!(AovSet::from_bits(set.bits()), Ok(set));
        assert!(AovSet::from_bits(1 << 9).is_err());
        assert_eq!("".parse::<AovSet>(), Ok(AovSet::NONE));
        let err = "albedo,colour".parse::<AovSet>().unwrap_err();
        assert!(
            err.contains("`colour`") && err.contains("albedo, normal"),
            "{err}"
        );
    }

    #[test]
    fn first_sample_layers_are_set_once_and_sums_add() {
        let set = AovSet::of(&Aov::ALL);
        let mut buffers = AovBuffers::new(set, 2);
        let hit = AovSample {
            albedo: Vec3::splat(0.5),
            normal: Vec3::Z,
            depth: 2.0,
            position: Vec3::ONE,
            instance: 3,
            primitive: 4,
        };
        buffers.add(1, &hit, true);
        buffers.add(1, &AovSample::escaped(Vec3::ONE), false);
        buffers.add(1, &AovSample::escaped(Vec3::ONE), false);
        let image = buffers.resolved(3);
        assert_eq!(image.albedo[1], Vec3::splat(2.5 / 3.0));
        assert_eq!(image.normal[1], Vec3::Z / 3.0);
        assert_eq!(
            (image.depth[1], image.instance[1], image.primitive[1]),
            (2.0, 3, 4)
        );
        assert_eq!(image.instance[0], NO_ID);
    }
}
