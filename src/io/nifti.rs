//! (being written)

use crate::error::{Error, Result};
use crate::volume::AnyVolume;
use std::path::Path;

/// Reads a volume (not written yet).
pub fn read_nifti(path: &Path) -> Result<AnyVolume> {
    Err(Error::invalid(
        "volume file",
        format!("{}: reader not written yet", path.display()),
    ))
}

/// Writes a volume (not written yet).
pub fn write_nifti(path: &Path, _vol: &AnyVolume) -> Result<()> {
    Err(Error::invalid(
        "volume file",
        format!("{}: writer not written yet", path.display()),
    ))
}
