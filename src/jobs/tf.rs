//! `voxlab tf`: the built-in transfer-function presets ([`crate::transfer`]).

use crate::error::Result;
use crate::transfer::TransferFunction;

/// Every 1D preset, by name.
///
/// # Errors
/// A preset that does not parse (a defect of the build).
pub fn list() -> Result<Vec<(&'static str, TransferFunction)>> {
    crate::transfer::PRESETS
        .iter()
        .map(|(n, _)| Ok((*n, TransferFunction::preset(n)?)))
        .collect()
}

/// The preset `name`.
///
/// # Errors
/// An unknown name (the error lists the presets).
pub fn get(name: &str) -> Result<TransferFunction> {
    TransferFunction::preset(name)
}
