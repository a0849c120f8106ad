//! A thin-lens perspective camera, or an orthographic one.

use crate::rng::Rng;
use canopy_bvh::Ray;
use glam::Vec3;

/// Where the camera is and how it sees, as written in a scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraSpec {
    pub look_from: Vec3,
    pub look_at: Vec3,
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub vfov: f32,
    /// Lens diameter; 0 is a pinhole (everything in focus).
    pub aperture: f32,
    /// Distance to the plane in focus; defaults to the distance to `look_at`.
    pub focus_distance: Option<f32>,
    /// An orthographic camera: the height of the view in world units (its width follows
    /// the image's aspect); rays start on the plane through `look_from` and travel along
    /// the viewing direction (`vfov` and the lens do not apply). `None`: perspective.
    pub ortho_height: Option<f32>,
}

impl Default for CameraSpec {
    fn default() -> Self {
        Self {
            look_from: Vec3::new(0.0, 0.0, 1.0),
            look_at: Vec3::ZERO,
            up: Vec3::Y,
            vfov: 40.0,
            aperture: 0.0,
            focus_distance: None,
            ortho_height: None,
        }
    }
}

/// A camera ready to generate rays for an image of a given aspect ratio.
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    origin: Vec3,
    upper_left: Vec3,
    horizontal: Vec3,
    vertical: Vec3,
    u: Vec3,
    v: Vec3,
    w: Vec3,
    lens_radius: f32,
    orthographic: bool,
    width: u32,
    height: u32,
}

/// A camera's frame as vectors, for renderers that generate its rays themselves (the
/// GPU's): a ray through `(s, t)` in `[0, 1)²` aims at
/// `upper_left + s·horizontal − t·vertical` from `origin`, moved by up to `lens_radius`
/// along `u` and `v` for depth of field; for an orthographic camera it starts there and
/// travels along `forward`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraBasis {
    pub origin: Vec3,
    pub upper_left: Vec3,
    pub horizontal: Vec3,
    pub vertical: Vec3,
    pub u: Vec3,
    pub v: Vec3,
    pub lens_radius: f32,
    /// The viewing direction (unit).
    pub forward: Vec3,
    pub orthographic: bool,
}

impl Camera {
    pub fn basis(&self) -> CameraBasis {
        CameraBasis {
            origin: self.origin,
            upper_left: self.upper_left,
            horizontal: self.horizontal,
            vertical: self.vertical,
            u: self.u,
            v: self.v,
            lens_radius: self.lens_radius,
            forward: -self.w,
            orthographic: self.orthographic,
        }
    }

    pub fn new(spec: &CameraSpec, width: u32, height: u32) -> Self {
        let aspect = width as f32 / height as f32;
        let half_height = (spec.vfov.to_radians() / 2.0).tan();
        let half_width = aspect * half_height;
        let w = (spec.look_from - spec.look_at).normalize();
        let u = spec.up.cross(w).normalize();
        let v = w.cross(u);
        let focus = spec
            .focus_distance
            .unwrap_or_else(|| (spec.look_from - spec.look_at).length());
        if let Some(view_height) = spec.ortho_height {
            // The view's rectangle on the plane through the eye.
            let horizontal = aspect * view_height * u;
            let vertical = view_height * v;
            return Self {
                origin: spec.look_from,
                upper_left: spec.look_from - 0.5 * horizontal + 0.5 * vertical,
                horizontal,
                vertical,
                u,
                v,
                w,
                lens_radius: 0.0,
                orthographic: true,
                width,
                height,
            };
        }
        let horizontal = 2.0 * half_width * focus * u;
        let vertical = 2.0 * half_height * focus * v;
        Self {
            origin: spec.look_from,
            upper_left: spec.look_from - focus * w - 0.5 * horizontal + 0.5 * vertical,
            horizontal,
            vertical,
            u,
            v,
            w,
            lens_radius: spec.aperture / 2.0,
            orthographic: false,
            width,
            height,
        }
    }

    /// Depth of `p` in front of the camera (along the viewing direction).
    #[inline]
    pub fn depth(&self, p: Vec3) -> f32 {
        -(p - self.origin).dot(self.w)
    }

    /// Pixel coordinates (x right, y down, in pixels) where the pinhole camera sees `p`,
    /// or `None` for points not in front of it.
    pub fn project(&self, p: Vec3) -> Option<(f32, f32)> {
        let depth = self.depth(p);
        if depth <= 0.0 {
            return None;
        }
        if self.orthographic {
            let on_plane = p - self.upper_left;
            let s = on_plane.dot(self.horizontal) / self.horizontal.length_squared();
            let t = -on_plane.dot(self.vertical) / self.vertical.length_squared();
            return Some((s * self.width as f32, t * self.height as f32));
        }
        // Where the line of sight crosses the image plane (at the focus distance).
        let focus = -(self.upper_left + 0.5 * self.horizontal - 0.5 * self.vertical - self.origin)
            .dot(self.w);
        let on_plane = self.origin + (p - self.origin) * (focus / depth) - self.upper_left;
        let s = on_plane.dot(self.horizontal) / self.horizontal.length_squared();
        let t = -on_plane.dot(self.vertical) / self.vertical.length_squared();
        Some((s * self.width as f32, t * self.height as f32))
    }

    /// The ray through image position (`s`, `t`) in [0, 1]², `t` going down.
    #[inline]
    pub fn ray(&self, s: f32, t: f32, rng: &mut Rng) -> Ray {
        if self.orthographic {
            let origin = self.upper_left + s * self.horizontal - t * self.vertical;
            return Ray::new(origin, -self.w, 0.0, f32::INFINITY);
        }
        let origin = if self.lens_radius > 0.0 {
            let disk = self.lens_radius * rng.in_unit_disk();
            self.origin + disk.x * self.u + disk.y * self.v
        } else {
            self.origin
        };
        let target = self.upper_left + s * self.horizontal - t * self.vertical;
        Ray::new(origin, (target - origin).normalize(), 0.0, f32::INFINITY)
    }

    /// The ray through the centre of pixel (`x`, `y`): the primary ray the heat map and
    /// the viewer's explorer trace (a lens is sampled by the pixel's first stream of
    /// `seed`; a pinhole draws nothing).
    pub fn pixel_centre_ray(&self, x: u32, y: u32, seed: u64) -> Ray {
        let mut rng = Rng::for_sample(seed, y as u64 * self.width as u64 + x as u64, 0);
        self.ray(
            (x as f32 + 0.5) / self.width as f32,
            (y as f32 + 0.5) / self.height as f32,
            &mut rng,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_ray_points_at_look_at() {
        let spec = CameraSpec {
            look_from: Vec3::new(0.0, 0.0, 5.0),
            ..CameraSpec::default()
        };
        let cam = Camera::new(&spec, 200, 100);
        let r = cam.ray(0.5, 0.5, &mut Rng::for_sample(0, 0, 0));
        assert!((r.dir - -Vec3::Z).length() < 1e-6);
    }

    #[test]
    fn top_of_image_looks_up() {
        let cam = Camera::new(&CameraSpec::default(), 100, 100);
        let mut rng = Rng::for_sample(0, 0, 0);
        assert!(cam.ray(0.5, 0.0, &mut rng).dir.y > 0.0);
        assert!(cam.ray(0.0, 0.5, &mut rng).dir.x < 0.0);
    }

    #[test]
    fn projection_inverts_ray_generation() {
        let spec = CameraSpec {
            look_from: Vec3::new(1.0, 2.0, 5.0),
            vfov: 50.0,
            ..CameraSpec::default()
        };
        let cam = Camera::new(&spec, 200, 100);
        let mut rng = Rng::for_sample(0, 0, 0);
        for (s, t) in [(0.5, 0.5), (0.1, 0.9), (0.8, 0.25)] {
            let r = cam.ray(s, t, &mut rng);
            let (x, y) = cam.project(r.at(7.0)).unwrap();
            assert!(
                (x - s * 200.0).abs() < 1e-3 && (y - t * 100.0).abs() < 1e-3,
                "{x} {y}"
            );
        }
        assert_eq!(
            cam.project(Vec3::new(1.0, 2.0, 9.0)),
            None,
            "behind the camera"
        );
    }

    #[test]
    fn orthographic_rays_are_parallel_and_span_the_view() {
        let spec = CameraSpec {
            look_from: Vec3::new(0.0, 0.0, 5.0),
            ortho_height: Some(4.0),
            ..CameraSpec::default()
        };
        let cam = Camera::new(&spec, 200, 100);
        let mut rng = Rng::for_sample(0, 0, 0);
        for (s, t, x, y) in [
            (0.5, 0.5, 0.0, 0.0),
            (0.0, 0.0, -4.0, 2.0),
            (1.0, 1.0, 4.0, -2.0),
        ] {
            let r = cam.ray(s, t, &mut rng);
            assert_eq!(r.dir, -Vec3::Z);
            assert!(
                (r.origin - Vec3::new(x, y, 5.0)).length() < 1e-5,
                "{}",
                r.origin
            );
            let (px, py) = cam.project(r.at(3.0)).unwrap();
            assert!((px - s * 200.0).abs() < 1e-3 && (py - t * 100.0).abs() < 1e-3);
        }
    }

    #[test]
    fn vertical_field_of_view_is_honoured() {
        let spec = CameraSpec {
            vfov: 90.0,
            ..CameraSpec::default()
        };
        let cam = Camera::new(&spec, 100, 100);
        let top = cam.ray(0.5, 0.0, &mut Rng::for_sample(0, 0, 0)).dir;
        assert!((top.y.atan2(-top.z).to_degrees() - 45.0).abs() < 1e-3);
    }
}
