//! `voxlab phantom`: an analytic phantom sampled on a grid ([`crate::phantom`]).

use crate::error::Result;
use crate::phantom::Phantom;
use crate::volume::AnyVolume;

/// A sampled phantom.
#[derive(Clone, Debug)]
pub struct Sampled {
    pub phantom: Phantom,
    pub dims: [usize; 3],
    pub volume: AnyVolume,
}

/// Samples `spec` (`NAME`, `NAME:N` or `NAME:NX,NY,NZ`, with or without the `phantom:`
/// prefix; 128³ when no size is given).
///
/// # Errors
/// An unknown name or a bad size.
pub fn run(spec: &str) -> Result<Sampled> {
    let spec = spec.strip_prefix("phantom:").unwrap_or(spec);
    let (phantom, dims) = crate::phantom::parse_spec(spec, 128)?;
    let volume: AnyVolume = phantom.sample(dims)?.into();
    Ok(Sampled {
        phantom,
        dims,
        volume,
    })
}
