//! Point, spot and directional lights in a scene file ([`crate::lights::PunctualLight`]),
//! beside the emissive surfaces. Angles are in degrees; directions need not be unit.
//!
//! ```toml
//! [[lights]]
//! type = "point"
//! position = [0, 4, 0]
//! intensity = [20, 20, 20]
//!
//! [[lights]]
//! type = "spot"
//! position = [2, 3, 0]
//! direction = [-1, -1, 0]
//! intensity = [40, 35, 30]
//! inner_angle = 15   # full strength within (default 0)
//! outer_angle = 30   # nothing beyond (default 45)
//!
//! [[lights]]
//! type = "directional"
//! direction = [-1, -2, -1]   # the way the light travels
//! irradiance = [2, 2, 2]
//! ```

use super::SceneBuilder;
use crate::error::SceneError;
use crate::lights::PunctualLight;
use glam::Vec3;
use serde::Deserialize;
use toml::Spanned;

#[derive(Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub(super) enum LightDoc {
    Point {
        position: [f32; 3],
        intensity: [f32; 3],
    },
    Spot {
        position: [f32; 3],
        direction: [f32; 3],
        intensity: [f32; 3],
        #[serde(default)]
        inner_angle: f32,
        #[serde(default = "default_outer_angle")]
        outer_angle: f32,
    },
    Directional {
        direction: [f32; 3],
        irradiance: [f32; 3],
    },
}

/// glTF's default outer cone: a quarter of π.
fn default_outer_angle() -> f32 {
    45.0
}

impl SceneBuilder<'_> {
    pub(super) fn light(&mut self, doc: &Spanned<LightDoc>) -> Result<(), SceneError> {
        let unit = |d: [f32; 3]| Vec3::from(d).try_normalize();
        let light = match *doc.get_ref() {
            LightDoc::Point {
                position,
                intensity,
            } => Some(PunctualLight::Point {
                position: position.into(),
                intensity: intensity.into(),
            }),
            LightDoc::Spot {
                position,
                direction,
                intensity,
                inner_angle,
                outer_angle,
            } => unit(direction).map(|direction| PunctualLight::Spot {
                position: position.into(),
                direction,
                intensity: intensity.into(),
                cos_inner: inner_angle.to_radians().cos(),
                cos_outer: outer_angle.to_radians().cos(),
            }),
            LightDoc::Directional {
                direction,
                irradiance,
            } => unit(direction).map(|direction| PunctualLight::Directional {
                direction,
                irradiance: irradiance.into(),
            }),
        };
        let Some(light) = light else {
            return self
                .cx
                .invalid(doc.span(), "light: `direction` must be finite and not zero");
        };
        match self.scene.add_light(light) {
            Ok(()) => Ok(()),
            Err(e) => self.cx.invalid(doc.span(), format!("light: {e}")),
        }
    }
}
