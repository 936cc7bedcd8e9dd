//! Command-line flags shared by the commands that look at a model: screen size, tile grid,
//! and the camera.

use anyhow::{bail, Context, Result};
use clap::Args;
use codec::view::{Camera, TileGrid};
use glam::Vec3;

/// Parses `WxH` (or `CxR`).
pub fn parse_pair(s: &str) -> Result<(u32, u32), String> {
    let (a, b) = s.split_once(['x', 'X']).ok_or_else(|| format!("expected WIDTHxHEIGHT, got '{s}'"))?;
    let n = |v: &str| v.trim().parse::<u32>().map_err(|_| format!("'{v}' is not a whole number in '{s}'"));
    Ok((n(a)?, n(b)?))
}

/// Parses `x,y,z`.
pub fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|c| c.trim().parse::<f32>().map_err(|_| format!("'{c}' is not a number in '{s}'")))
        .collect::<Result<_, _>>()?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(Vec3::new(x, y, z)),
        [_, _, _] => Err(format!("'{s}' has a non-finite coordinate")),
        _ => Err(format!("expected x,y,z, got '{s}'")),
    }
}

/// Screen size and tile grid.
#[derive(Args, Clone, Debug)]
pub struct GridArgs {
    /// Frame size in pixels, WIDTHxHEIGHT.
    #[arg(long, value_parser = parse_pair, default_value = "1920x1080")]
    pub size: (u32, u32),
    /// Tile grid, COLSxROWS.
    #[arg(long, value_parser = parse_pair, default_value = "8x8")]
    pub tiles: (u32, u32),
}

impl GridArgs {
    pub fn grid(&self) -> Result<TileGrid> {
        Ok(TileGrid::new(self.size.0, self.size.1, self.tiles.0, self.tiles.1)?)
    }
}

/// The camera; every flag left out comes from the default camera, which frames the model.
#[derive(Args, Clone, Debug, Default)]
pub struct CameraArgs {
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<Vec3>,
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub target: Option<Vec3>,
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub up: Option<Vec3>,
    /// Vertical field of view in degrees.
    #[arg(long)]
    pub fovy: Option<f32>,
    #[arg(long)]
    pub near: Option<f32>,
    #[arg(long)]
    pub far: Option<f32>,
}

impl CameraArgs {
    /// The camera for a model with this bounding box, at this aspect ratio. When the eye or
    /// target moves and no clip planes are given, near and far follow the model's bounding
    /// sphere from the new eye.
    pub fn camera(&self, bbox_min: [f32; 3], bbox_max: [f32; 3], aspect: f32) -> Result<Camera> {
        let mut cam = Camera::framing(bbox_min, bbox_max, aspect);
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parsers() {
        assert_eq!(parse_pair("1920x1080"), Ok((1920, 1080)));
        assert!(parse_pair("1920").is_err());
        assert!(parse_pair("-1x3").is_err());
        assert_eq!(parse_vec3("1,-2.5,3"), Ok(Vec3::new(1.0, -2.5, 3.0)));
        assert!(parse_vec3("1,2").is_err());
        assert!(parse_vec3("1,nan,2").is_err());
    }

    #[test]
    fn eye_equal_to_target_is_an_error() {
        let args = CameraArgs { eye: Some(Vec3::ONE), target: Some(Vec3::ONE), ..Default::default() };
        let e = args.camera([0.0; 3], [1.0; 3], 1.0).unwrap_err();
        assert!(format!("{e:#}").contains("eye and target"), "{e:#}");
    }
}

/// `--tile-coding`: how tile streams are entropy-coded ([`codec::bft::Coding`]).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileCoding {
    Prefix,
    Range,
}

impl From<TileCoding> for codec::bft::Coding {
    fn from(c: TileCoding) -> Self {
        match c {
            TileCoding::Prefix => codec::bft::Coding::Prefix,
            TileCoding::Range => codec::bft::Coding::Range,
        }
    }
}
