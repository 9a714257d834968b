//! (being written)

use crate::error::{Error, Result};
use crate::volume::AnyVolume;
use std::path::Path;

/// Reads a volume (not written yet).
pub fn read_tiff(path: &Path) -> Result<AnyVolume> {
    Err(Error::invalid(
        "volume file",
        format!("{}: reader not written yet", path.display()),
    ))
}
