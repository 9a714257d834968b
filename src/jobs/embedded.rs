//! The volumes embedded in the binary, so that `voxlab demo`, `--input microct-bone`
//! and `--input mr-brain` need no file.

use crate::error::Result;
use std::path::Path;

/// The X-ray micro-CT of trabecular bone from `data/microct-bone/` (qim3d, MIT), a
/// 128³ u8 TIFF stack, embedded so that the demo needs no file.
pub const MICROCT_BONE_TIFF: &[u8] = include_bytes!("../../data/microct-bone/bone_128x128x128.tif");

/// The UNC MR brain as shipped with VolPack (`data/mr-brain-volpack/`, 128×128×84 u8).
pub const MR_BRAIN_DEN: &[u8] = include_bytes!("../../data/mr-brain-volpack/brainsmall.den");

/// Reads the embedded micro-CT of bone.
pub fn microct_bone() -> Result<crate::AnyVolume> {
    crate::io::read_volume_bytes(
        MICROCT_BONE_TIFF,
        crate::io::Format::Tiff,
        Path::new("data/microct-bone/bone_128x128x128.tif"),
    )
}

/// Reads the embedded VolPack MR brain, placed upright in a head frame.
///
/// `.den` files carry no orientation; this scan's slices along z are sagittal, with
/// index x running from the face to the back of the head and index y from the top of
/// the head down. The demo gives it the affine that maps index x to posterior (−y),
/// index y to inferior (−z) and index z to +x (a rotation, 1 mm voxels), so that the
/// orbit camera, whose up is world +z, sees the head upright.
pub fn mr_brain() -> Result<crate::AnyVolume> {
    let mut vol = crate::io::read_volume_bytes(
        MR_BRAIN_DEN,
        crate::io::Format::Den,
        Path::new("data/mr-brain-volpack/brainsmall.den"),
    )?;
    let upright = glam::DMat4::from_cols(
        glam::DVec4::new(0.0, -1.0, 0.0, 0.0),
        glam::DVec4::new(0.0, 0.0, -1.0, 0.0),
        glam::DVec4::new(1.0, 0.0, 0.0, 0.0),
        glam::DVec4::W,
    );
    crate::with_volume!(&mut vol, v => v.set_affine(upright))?;
    Ok(vol)
}
