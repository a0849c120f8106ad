//! [`RenderOptions`]: what a user may set about a render, in one serde type. The command
//! line's flags, Python's keywords, the Ray driver's options and the viewer's settings
//! command are all made into it (or checked against its names), so every front end
//! offers the same settings under the same names and refuses the same values.

use crate::{Device, RenderJob, Structure, MAX_THREADS};
use canopy_bvh::TriangleTest;
use canopy_render::{AccelKind, BvhWidth, Integrator, RenderSettings, Sampler, Schedule};
use serde::{Deserialize, Serialize};

/// Most primitives a BVH leaf may hold.
pub const MAX_LEAF_SIZE: u32 = 256;

/// Settings of one render, each `None` where the scene's (for its settings) or canopy's
/// default (for the rest) holds. Unknown names are refused, so a misspelt option is an
/// error rather than a silent default; enumerations are spelt as their names
/// (`"path"`, `"sobol"`, `"binned-sah"`, `"cpu"`, `"wavefront"`), the width as the
/// number of children per node.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderOptions {
    /// Image size, width and height in pixels.
    pub size: Option<[u32; 2]>,
    /// Samples per pixel.
    pub spp: Option<u32>,
    /// Most ray segments per path, the camera ray included.
    pub max_depth: Option<u32>,
    pub seed: Option<u64>,
    #[serde(with = "by_name")]
    pub integrator: Option<Integrator>,
    pub russian_roulette: Option<bool>,
    #[serde(with = "by_name")]
    pub sampler: Option<Sampler>,
    /// `none` (test every primitive) or a BVH builder.
    #[serde(with = "by_name")]
    pub bvh: Option<AccelKind>,
    /// Children per node: 2, 4 or 8.
    #[serde(with = "children")]
    pub width: Option<BvhWidth>,
    /// Most primitives in a BVH leaf.
    pub max_leaf_size: Option<u32>,
    /// Test triangles without the watertight test's double-precision step (the CPU only).
    pub fast_triangles: Option<bool>,
    #[serde(with = "by_name")]
    pub device: Option<Device>,
    /// The order the CPU traces paths in; the image is the same in each.
    #[serde(with = "by_name")]
    pub schedule: Option<Schedule>,
    /// Worker threads on the CPU (all cores when `None`).
    pub threads: Option<usize>,
}

/// The options that change the scene's own settings (the rest choose how it is rendered).
const SCENE_SETTINGS: [&str; 7] = [
    "size",
    "spp",
    "max_depth",
    "seed",
    "integrator",
    "russian_roulette",
    "sampler",
];

impl RenderOptions {
    /// Every option's name, in the order declared: the names each front end offers.
    pub fn names() -> &'static [&'static str] {
        field_names::of::<RenderOptions>()
    }

    /// The names of the options given (not `None`), in the order declared.
    pub fn given(&self) -> Vec<&'static str> {
        let Ok(serde_json::Value::Object(fields)) = serde_json::to_value(self) else {
            unreachable!("a struct serializes to an object")
        };
        Self::names()
            .iter()
            .copied()
            .filter(|name| fields.get(*name).is_some_and(|value| !value.is_null()))
            .collect()
    }

    /// The names of the given options that change the scene's settings (a resumed
    /// render keeps its checkpoint's, so these must not be given with it).
    pub fn given_scene_settings(&self) -> Vec<&'static str> {
        self.given()
            .into_iter()
            .filter(|name| SCENE_SETTINGS.contains(name))
            .collect()
    }

    /// The options parsed from JSON, or why not (naming the option at fault).
    pub fn from_json(text: &str) -> Result<RenderOptions, String> {
        Self::deserialize_named(&mut serde_json::Deserializer::from_str(text))
    }

    /// The options `deserializer` holds (JSON, a Python dict, ...), or why not, naming
    /// the option at fault: `spp: invalid value: integer `-1`, expected u32`.
    pub fn deserialize_named<'de, D: serde::Deserializer<'de>>(
        deserializer: D,
    ) -> Result<RenderOptions, String> {
        serde_path_to_error::deserialize(deserializer).map_err(|e| {
            let path = e.path().to_string();
            match path.as_str() {
                "." => e.into_inner().to_string(),
                _ => format!("{path}: {}", e.into_inner()),
            }
        })
    }

    /// Why these options cannot be rendered with, where they cannot: a leaf size or
    /// thread count out of range, or a GPU render asked for what only the CPU does.
    pub fn check(&self) -> Result<(), String> {
        if let Some(n) = self.max_leaf_size {
            if !(1..=MAX_LEAF_SIZE).contains(&n) {
                return Err(format!(
                    "max_leaf_size must be in 1..={MAX_LEAF_SIZE}, not {n}"
                ));
            }
        }
        if let Some(n) = self.threads {
            if !(1..=MAX_THREADS).contains(&n) {
                return Err(format!("threads must be in 1..={MAX_THREADS}, not {n}"));
            }
        }
        if self.device == Some(Device::Gpu) {
            if self.fast_triangles == Some(true) {
                return Err(
                    "fast_triangles chooses the CPU's triangle test (the GPU's is watertight): drop it or render on the CPU"
                        .into(),
                );
            }
            if self.bvh == Some(AccelKind::None) {
                return Err(
                    "a GPU render traces through a BVH: choose a builder, not `none`".into(),
                );
            }
        }
        Ok(())
    }

    /// `settings` with the given scene settings put in, checked whole.
    pub fn apply_to_settings(&self, settings: &mut RenderSettings) -> Result<(), String> {
        let s = settings;
        if let Some([width, height]) = self.size {
            (s.width, s.height) = (width, height);
        }
        s.spp = self.spp.unwrap_or(s.spp);
        s.max_depth = self.max_depth.unwrap_or(s.max_depth);
        s.seed = self.seed.unwrap_or(s.seed);
        s.integrator = self.integrator.unwrap_or(s.integrator);
        s.russian_roulette = self.russian_roulette.unwrap_or(s.russian_roulette);
        s.sampler = self.sampler.unwrap_or(s.sampler);
        s.check()
    }

    /// `structure` with the given tree options put in.
    pub fn apply_to_structure(&self, structure: &mut Structure) {
        structure.kind = self.bvh.unwrap_or(structure.kind);
        structure.width = self.width.unwrap_or(structure.width);
        if let Some(n) = self.max_leaf_size {
            structure.params.max_leaf_size = n;
        }
        if let Some(fast) = self.fast_triangles {
            structure.triangle_test = match fast {
                true => TriangleTest::Fast,
                false => TriangleTest::Watertight,
            };
        }
    }

    /// `job` with the given structure, device, schedule and threads put in, after
    /// [`check`](Self::check). The scene's settings are the caller's to apply (with
    /// [`apply_to_settings`](Self::apply_to_settings)) before the job borrows it.
    pub fn apply_to_job(&self, job: &mut RenderJob<'_>) -> Result<(), String> {
        self.check()?;
        self.apply_to_structure(&mut job.structure);
        job.device = self.device.unwrap_or(job.device);
        job.schedule = self.schedule.unwrap_or(job.schedule);
        job.threads = self.threads.or(job.threads);
        Ok(())
    }
}

/// A struct's field names, as its derived `Deserialize` declares them (in order).
mod field_names {
    use serde::de::{value::Error, Deserialize, Deserializer, Error as _, Visitor};

    pub fn of<T: for<'de> Deserialize<'de>>() -> &'static [&'static str] {
        let mut names: &'static [&'static str] = &[];
        let _ = T::deserialize(Names(&mut names));
        names
    }

    /// A deserializer that only takes note of the fields a struct asks for.
    struct Names<'a>(&'a mut &'static [&'static str]);

    impl<'de> Deserializer<'de> for Names<'_> {
        type Error = Error;

        fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, Error> {
            Err(Error::custom("not a struct"))
        }

        fn deserialize_struct<V: Visitor<'de>>(
            self,
            _: &'static str,
            fields: &'static [&'static str],
            _: V,
        ) -> Result<V::Value, Error> {
            *self.0 = fields;
            Err(Error::custom("names taken"))
        }

        serde::forward_to_deserialize_any! {
            bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes
            byte_buf option unit unit_struct newtype_struct seq tuple tuple_struct map
            enum identifier ignored_any
        }
    }
}

/// An option spelt as its name: written with `Display`, read with `FromStr`, whose
/// error (the names it takes) becomes serde's.
mod by_name {
    use serde::{de::Error, Deserialize, Deserializer, Serializer};
    use std::fmt::Display;
    use std::str::FromStr;

    pub fn serialize<T: Display, S: Serializer>(
        value: &Option<T>,
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        match value {
            Some(value) => serializer.serialize_some(&value.to_string()),
            None => serializer.serialize_none(),
        }
    }

    pub fn deserialize<'de, T, D>(deserializer: D) -> Result<Option<T>, D::Error>
    where
        T: FromStr<Err: Display>,
        D: Deserializer<'de>,
    {
        Option::<String>::deserialize(deserializer)?
            .map(|name| name.parse().map_err(D::Error::custom))
            .transpose()
    }
}

/// A tree width spelt as its number of children per node.
mod children {
    use canopy_render::BvhWidth;
    use serde::{de::Error, Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(
        value: &Option<BvhWidth>,
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        match value {
            Some(width) => serializer.serialize_some(&width.children()),
            None => serializer.serialize_none(),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(
        deserializer: D,
    ) -> Result<Option<BvhWidth>, D::Error> {
        Option::<u32>::deserialize(deserializer)?
            .map(|n| n.to_string().parse().map_err(D::Error::custom))
            .transpose()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_the_fields_in_order() {
        let names = RenderOptions::names();
        assert_eq!(names.first(), Some(&"size"));
        assert_eq!(names.last(), Some(&"threads"));
        assert_eq!(names.len(), 14);
        assert_eq!(names[..SCENE_SETTINGS.len()], SCENE_SETTINGS);
    }

    #[test]
    fn options_read_back_as_written() {
        let options = RenderOptions {
            size: Some([64, 48]),
            spp: Some(3),
            max_depth: Some(5),
            seed: Some(u64::MAX),
            integrator: Some(Integrator::Bsdf),
            russian_roulette: Some(false),
            sampler: Some(Sampler::Independent),
            bvh: Some("sweep-sah".parse().unwrap()),
            width: Some("4".parse().unwrap()),
            max_leaf_size: Some(2),
            fast_triangles: Some(true),
            device: Some(Device::Gpu),
            schedule: Some(Schedule::Depth),
            threads: Some(3),
        };
        let text = serde_json::to_string(&options).unwrap();
        assert!(text.contains(r#""bvh":"sweep-sah""#), "{text}");
        assert!(text.contains(r#""width":4"#), "{text}");
        assert_eq!(RenderOptions::from_json(&text).unwrap(), options);
        assert_eq!(options.given(), RenderOptions::names());
        assert_eq!(options.given_scene_settings().len(), SCENE_SETTINGS.len());
        assert_eq!(
            RenderOptions::from_json("{}").unwrap(),
            RenderOptions::default()
        );
        assert!(RenderOptions::default().given().is_empty());
    }

    #[test]
    fn a_misspelt_option_or_a_bad_value_is_named() {
        let e = RenderOptions::from_json(r#"{"spp": 4, "max_dept": 3}"#).unwrap_err();
        assert!(e.contains("unknown field `max_dept`"), "{e}");
        let e = RenderOptions::from_json(r#"{"integrator": "whitted"}"#).unwrap_err();
        assert!(e.contains("whitted"), "{e}");
        let e = RenderOptions::from_json(r#"{"width": 3}"#).unwrap_err();
        assert!(e.starts_with("width: ") && e.contains('3'), "{e}");
        let e = RenderOptions::from_json(r#"{"spp": -1}"#).unwrap_err();
        assert!(e.starts_with("spp: ") && e.contains("-1"), "{e}");
        let e = RenderOptions::from_json(r#"{"size": [4, -5]}"#).unwrap_err();
        assert!(e.starts_with("size") && e.contains("-5"), "{e}");
        let e = RenderOptions::from_json(r#"{"bvh": "octree"}"#).unwrap_err();
        assert!(e.contains("octree"), "{e}");
    }

    #[test]
    fn settings_take_what_is_given_and_are_checked() {
        let mut settings = RenderSettings::default();
        let options = RenderOptions {
            spp: Some(7),
            size: Some([10, 20]),
            ..RenderOptions::default()
        };
        options.apply_to_settings(&mut settings).unwrap();
        assert_eq!((settings.spp, settings.width, settings.height), (7, 10, 20));
        assert_eq!(settings.max_depth, RenderSettings::default().max_depth);
        let empty = RenderOptions {
            size: Some([0, 20]),
            ..RenderOptions::default()
        };
        assert!(empty.apply_to_settings(&mut settings).is_err());
    }

    #[test]
    fn what_only_the_cpu_does_is_refused_on_the_gpu() {
        let gpu = RenderOptions {
            device: Some(Device::Gpu),
            ..RenderOptions::default()
        };
        assert!(gpu.check().is_ok());
        for refused in [
            RenderOptions {
                fast_triangles: Some(true),
                ..gpu.clone()
            },
            RenderOptions {
                bvh: Some(AccelKind::None),
                ..gpu.clone()
            },
            RenderOptions {
                max_leaf_size: Some(0),
                ..RenderOptions::default()
            },
            RenderOptions {
                threads: Some(0),
                ..RenderOptions::default()
            },
        ] {
            assert!(refused.check().is_err(), "{refused:?}");
        }
    }

    #[test]
    fn the_structure_takes_the_tree_options() {
        let mut structure = Structure::default();
        RenderOptions {
            bvh: Some(AccelKind::None),
            width: Some("2".parse().unwrap()),
            max_leaf_size: Some(9),
            fast_triangles: Some(true),
            ..RenderOptions::default()
        }
        .apply_to_structure(&mut structure);
        assert_eq!(structure.kind, AccelKind::None);
        assert_eq!(structure.width.children(), 2);
        assert_eq!(structure.params.max_leaf_size, 9);
        assert_eq!(structure.triangle_test, TriangleTest::Fast);
    }
}
