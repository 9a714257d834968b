//! `voxlab phantom`: an analytic phantom sampled on a grid ([`crate::phantom`]).

use crate::error::Result;
use crate::phantom::Phantom;
use crate::volume::{AnyVolume, VoxelKind};

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

/// The sampled phantom as a volume of `kind`: each value times `scale`, rounded and
/// saturated into an integer type (`round(v · scale)`), as a scanner stores intensities;
/// for f32 the product itself.
///
/// # Errors
/// A `scale` that is not finite and positive.
pub fn quantised(p: &Sampled, kind: VoxelKind, scale: f64) -> Result<AnyVolume> {
    super::convert::quantise(&p.volume, kind, scale)
}
