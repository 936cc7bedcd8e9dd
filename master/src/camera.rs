//! The camera a command asks for, as plain values: where it starts (a preset framing the
//! model), what the user set over it, and the checks that refuse a camera the 32-bit depth
//! buffer and float projection cannot render. `cli::CameraArgs` parses the flags into a
//! [`CameraSpec`]; the render plan, the walls and the commands carry only the spec.

use anyhow::{bail, Context, Result};
use codec::view::Camera;
use glam::Vec3;

/// The camera; every field left `None` comes from the preset, which frames the model.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CameraSpec {
    /// The preset the camera starts from.
    pub view: ViewPreset,
    /// With [`ViewPreset::ThreeQuarter`]: degrees about +Y from the +Z side.
    pub azimuth: f32,
    pub eye: Option<Vec3>,
    pub target: Option<Vec3>,
    pub up: Option<Vec3>,
    /// Vertical field of view in degrees.
    pub fovy: Option<f32>,
    pub near: Option<f32>,
    pub far: Option<f32>,
    /// Lens shift in normalised device coordinates (an off-axis frustum).
    pub shift: Option<[f32; 2]>,
}

/// Where a [`CameraSpec`] starts before its eye, target and the rest (`--view`).
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ViewPreset {
    #[default]
    Front,
    ThreeQuarter,
}

/// Where a stereo run's two eyes go (`render --stereo-output`): a file each, or one frame
/// with the left eye on the left.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StereoOutput {
    #[default]
    Separate,
    SideBySide,
}

impl CameraSpec {
    /// The camera for a model with this bounding box, at this aspect ratio. When the eye or
    /// target moves and no clip planes are given, near and far follow the model's bounding
    /// sphere from the new eye.
    pub fn camera(&self, bbox_min: [f32; 3], bbox_max: [f32; 3], aspect: f32) -> Result<Camera> {
        self.camera_fitting(bbox_min, bbox_max, None, aspect)
    }

    /// [`CameraSpec::camera`], where the three-quarter view fits `points` (the model's
    /// vertices, when the caller holds them) rather than the box's corners.
    pub fn camera_fitting(
        &self,
        bbox_min: [f32; 3],
        bbox_max: [f32; 3],
        points: Option<&[[f32; 3]]>,
        aspect: f32,
    ) -> Result<Camera> {
        const MARGIN: f32 = 0.04;
        let mut cam = match (self.view, points) {
            (ViewPreset::Front, _) => Camera::framing(bbox_min, bbox_max, aspect),
            (ViewPreset::ThreeQuarter, Some(p)) if !p.is_empty() => {
                Camera::three_quarter_fit(bbox_min, bbox_max, p, aspect, self.azimuth, MARGIN)
            }
            (ViewPreset::ThreeQuarter, _) => Camera::three_quarter(bbox_min, bbox_max, aspect, self.azimuth, MARGIN),
        };
        if let Some(v) = self.eye {
            cam.eye = v;
        }
        if let Some(v) = self.target {
            cam.target = v;
        }
        if let Some(v) = self.up {
            cam.up = v;
        }
        if let Some(v) = self.fovy {
            cam.fovy = v;
        }
        if let Some(v) = self.shift {
            cam.shift = v;
        }
        if self.eye.is_some() || self.target.is_some() {
            let (lo, hi) = (Vec3::from(bbox_min), Vec3::from(bbox_max));
            let radius = ((hi - lo).length() * 0.5).max(1e-6);
            let dist = cam.eye.distance((lo + hi) * 0.5);
            cam.near = ((dist - radius) * 0.5).max(radius * 1e-3);
            cam.far = dist + radius * 2.0;
        }
        if let Some(v) = self.near {
            cam.near = v;
        }
        if let Some(v) = self.far {
            cam.far = v;
        }
        cam.validate().context("bad camera")?;
        if cam.near >= cam.far {
            bail!("near {} must be less than far {}", cam.near, cam.far);
        }
        Ok(cam)
    }
}

/// Far/near ratios above this are refused: a 32-bit float depth buffer under the standard
/// projection resolves about `2^-24 * far / near` of the distance at the far plane, so at
/// 1e7 two surfaces less than 60% of their distance apart cannot be told apart.
pub const MAX_DEPTH_RATIO: f64 = 1e7;
/// Far/near ratios above this get a warning (0.06% of the distance at the far plane).
pub const WARN_DEPTH_RATIO: f64 = 1e4;
/// The smallest angle one pixel may span, in radians: eye-space positions are `f32`, with a
/// relative precision of about 6e-8 of their distance, so below 1e-6 rad a pixel is a few
/// rounding steps wide and the image is noise.
pub const MIN_PIXEL_ANGLE: f64 = 1e-6;
/// Pixel angles below this get a warning.
pub const WARN_PIXEL_ANGLE: f64 = 1e-5;

/// Lens shifts beyond this many half-frames are refused: the image window would lie a
/// thousand frames off the view axis, and a float shift that large is rounded to about half
/// a pixel of a 16384-pixel frame (stereo eyes far apart for their focal distance, or a wall
/// seen from far off to its side).
pub const MAX_SHIFT: f64 = 1e3;

/// Refuses a camera whose depth range, field of view or lens shift the 32-bit depth buffer
/// and float projection cannot represent at `height` pixels, or that is not finite, and
/// returns warnings (with the numbers) for ones that are close. Every camera a run uses is
/// checked: each stereo eye, the first and last frames of a zoom, each eye through a wall.
pub fn check_precision(cam: &Camera, height: u32) -> Result<Vec<String>> {
    let mut warnings = Vec::new();
    let finite = cam.eye.is_finite()
        && cam.target.is_finite()
        && cam.up.is_finite()
        && [cam.fovy, cam.near, cam.far, cam.shift[0], cam.shift[1]].iter().all(|v| v.is_finite());
    if !finite {
        bail!(
            "a camera with eye {}, target {}, near {}, far {} and shift {:?} is not finite; the flags that set it are too large",
            cam.eye,
            cam.target,
            cam.near,
            cam.far,
            cam.shift
        );
    }
    let shift = cam.shift[0].abs().max(cam.shift[1].abs()) as f64;
    if shift > MAX_SHIFT {
        bail!(
            "a lens shift of {shift:.3e} half-frames (at most {MAX_SHIFT:e}) puts the image window beyond what float projection resolves; a stereo eye separation or an eye this far to the side of a wall is too large"
        );
    }
    let ratio = cam.far as f64 / cam.near as f64;
    let depth_step = ratio * 2f64.powi(-24);
    if ratio > MAX_DEPTH_RATIO {
        bail!(
            "far/near = {:.3e} / {:.3e} = {ratio:.3e} is beyond what a 32-bit depth buffer resolves (at most {MAX_DEPTH_RATIO:e}; depth steps would be {:.0}% of the distance at the far plane); raise --near or lower --far",
            cam.far,
            cam.near,
            depth_step * 100.0
        );
    }
    if ratio > WARN_DEPTH_RATIO {
        warnings.push(format!(
            "far/near = {ratio:.3e}: the depth buffer resolves only {:.2}% of the distance at the far plane; surfaces closer than that may show through each other",
            depth_step * 100.0
        ));
    }
    let pixel = (cam.fovy as f64).to_radians() / height as f64;
    if pixel < MIN_PIXEL_ANGLE {
        bail!(
            "a field of view of {}° over {height} pixels is {pixel:.3e} rad a pixel, below the {MIN_PIXEL_ANGLE:e} that float projection resolves; raise --fovy",
            cam.fovy
        );
    }
    if pixel < WARN_PIXEL_ANGLE {
        warnings.push(format!(
            "a field of view of {}° over {height} pixels is {pixel:.3e} rad a pixel; positions are rounded to a few percent of a pixel",
            cam.fovy
        ));
    }
    Ok(warnings)
}

/// [`check_precision`], printing its warnings on stderr.
pub fn check_camera(cam: &Camera, height: u32) -> Result<()> {
    for w in check_precision(cam, height)? {
        eprintln!("warning: {w}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn precision_limits() {
        let mut cam = Camera::framing([0.0; 3], [1.0; 3], 1.0);
        assert!(check_precision(&cam, 1080).unwrap().is_empty());
        cam.near = 1e-30;
        let e = check_precision(&cam, 1080).unwrap_err().to_string();
        assert!(e.contains("far/near") && e.contains("depth buffer"), "{e}");
        cam.near = cam.far / 1e5;
        assert_eq!(check_precision(&cam, 1080).unwrap().len(), 1);
        cam.near = cam.far / 10.0;
        cam.fovy = 1e-30;
        let e = check_precision(&cam, 1080).unwrap_err().to_string();
        assert!(e.contains("field of view"), "{e}");
        cam.fovy = 0.5;
        assert_eq!(check_precision(&cam, 1080).unwrap().len(), 1);
    }

    #[test]
    fn eye_equal_to_target_is_an_error() {
        let args = CameraSpec { eye: Some(Vec3::ONE), target: Some(Vec3::ONE), ..Default::default() };
        let e = args.camera([0.0; 3], [1.0; 3], 1.0).unwrap_err();
        assert!(format!("{e:#}").contains("eye and target"), "{e:#}");
    }
}
