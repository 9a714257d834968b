//! Forward projection: the line integrals a CT scanner measures, `p = ∫ μ(ℓ) dℓ` along
//! every detector pixel's ray (Xu & Mueller 2006, eq. 1), in the geometry of
//! [`crate::ct`].
//!
//! [`project_phantom`] is the oracle: the exact line integrals of an analytic phantom
//! (ellipsoids have closed-form chords), placed in the CT frame by
//! [`crate::ct::phantom_to_ct`]. Values are density × mm.

use crate::ct::{ct_to_phantom, Geometry, Projections};
use crate::error::Result;
use crate::phantom::Phantom;
use rayon::prelude::*;

/// Exact projections of `phantom` (f64): one line integral per detector pixel centre.
pub fn project_phantom(phantom: &Phantom, g: &Geometry) -> Result<Projections<f64>> {
    g.validate()?;
    let mut out = Projections::<f64>::zeros(g)?;
    let per_view = g.rows * g.cols;
    out.data
        .par_chunks_mut(g.cols)
        .enumerate()
        .for_each(|(line, dst)| {
            let (k, row) = (line / g.rows, line % g.rows);
            debug_assert!(line < g.n_angles() * per_view);
            for (col, v) in dst.iter_mut().enumerate() {
                let (o, d, t0) = g.ray(k, col as f64, row as f64);
                *v = phantom.line_integral_world(
                    ct_to_phantom(o),
                    ct_to_phantom(d),
                    t0,
                    f64::INFINITY,
                );
            }
        });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::phantom::Primitive;
    use glam::DVec3;

    #[test]
    fn a_centred_sphere_projects_to_its_chords() {
        // Radius 0.5 in phantom units = 64 mm; density 2.
        let ph = Phantom::from_primitives("ball", vec![Primitive::sphere(2.0, DVec3::ZERO, 0.5)]);
        for g in [
            Geometry::parallel_skimage(201, vec![0.0, 45.0, 123.0]).unwrap(),
            Geometry::cone_rtk(1000.0, 1500.0, 201, 5, 1.0, 1.0, vec![0.0, 200.0]).unwrap(),
        ] {
            let p = project_phantom(&ph, &g).unwrap();
            for k in 0..g.n_angles() {
                for row in 0..g.rows {
                    for col in 0..g.cols {
                        let (o, d, _) = g.ray(k, col as f64, row as f64);
                        // Distance of the ray from the centre, then the chord length.
                        let dist = (o - d * o.dot(d)).length();
                        let chord = 2.0 * (64.0f64 * 64.0 - dist * dist).max(0.0).sqrt();
                        let got = p.view(k)[row * g.cols + col];
                        // Compare squares: near a tangent the chord is the square root of
                        // a difference, and its rounding error grows without bound there.
                        let (got2, want2) = (got * got, 4.0 * chord * chord);
                        assert!(
                            (got2 - want2).abs() < 1e-9 * 256.0 * 256.0,
                            "{k} {row} {col}: {got}"
                        );
                    }
                }
            }
        }
    }
}
