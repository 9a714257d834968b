//! Analytic phantoms: exact point values and exact line integrals.
//!
//! A phantom lives in *phantom coordinates*, the cube `[-1, 1]³`, scaled to the world by
//! `half_extent_mm` (world = phantom × `half_extent_mm`, centred on the origin). Sampling
//! it onto an `nx × ny × nz` grid puts voxel centres at the cell centres of the cube:
//! `x_i = (i + 0.5) · 2 / nx − 1`, so the grid's box is exactly the phantom's cube and
//! the volume's affine is `world = spacing · (i − (n − 1)/2)` with
//! `spacing = 2 · half_extent_mm / n`.
//!
//! Ellipsoid and box phantoms are sums of constant-density primitives, so
//! - the value at a point is the sum of the densities of the primitives containing it;
//! - the line integral along a ray is the sum of density × chord length, computed in
//!   closed form (ray–quadric and ray–slab intersection). This is the X-ray truth.
//!
//! The Marschner–Lobb function (Marschner & Lobb 1994, α = 0.25, f_M = 6) is smooth and
//! has an exact value and gradient; its line integral is computed by composite
//! Gauss–Legendre quadrature to about 1e-12 relative (it has no closed form in general).
//!
//! The 3D Shepp–Logan phantom uses the ellipsoid table of Kak & Slaney as published in
//! Schabel's `phantom3d` (intensities 1, −0.98, −0.02, …), and the high-contrast
//! "modified" variant of Toft (1, −0.8, −0.2, …). The Euler-angle convention is
//! `phantom3d`'s: a point `p` lies inside ellipsoid *e* when
//! `Σ ((A p − c)_k / r_k)² ≤ 1` with `A` the (φ, θ, ψ) rotation matrix below.

use crate::error::{Error, Result};
use crate::real::slab_interval;
use crate::volume::Volume;
use glam::{DMat3, DVec3};

/// Default world size of a phantom: a 256 mm cube (half extent 128 mm), head-sized.
pub const DEFAULT_HALF_EXTENT_MM: f64 = 128.0;

/// A region of phantom space.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// Points `p` with `|D⁻¹ · rot · (p − center)| ≤ 1`, `D = diag(semi_axes)`.
    /// `rot` maps phantom axes to the ellipsoid's own axes.
    Ellipsoid {
        center: DVec3,
        semi_axes: DVec3,
        rot: DMat3,
    },
    /// The axis-aligned box `min ≤ p ≤ max`.
    Box { min: DVec3, max: DVec3 },
}

/// A shape with a constant density added to whatever lies beneath it.
#[derive(Clone, Debug, PartialEq)]
pub struct Primitive {
    pub shape: Shape,
    pub density: f64,
}

/// The function a phantom evaluates.
#[derive(Clone, Debug, PartialEq)]
pub enum PhantomKind {
    /// A sum of constant-density primitives.
    Primitives(Vec<Primitive>),
    /// `ρ(x, y, z) = (1 − sin(πz/2) + α(1 + cos(2π f_M cos(π r/2)))) / (2(1 + α))`,
    /// `r = √(x² + y²)`.
    MarschnerLobb { alpha: f64, f_m: f64 },
}

/// An analytic phantom, its function and its size in the world.
#[derive(Clone, Debug, PartialEq)]
pub struct Phantom {
    pub name: String,
    pub kind: PhantomKind,
    /// World size: phantom coordinates × this = world millimetres.
    pub half_extent_mm: f64,
}

/// The named phantoms `phantom:NAME:SIZE` understands.
pub const PHANTOM_NAMES: &[&str] = &[
    "shepp-logan",
    "shepp-logan-modified",
    "marschner-lobb",
    "sphere",
    "spheres",
    "ellipsoid",
    "slab",
];

/// `phantom3d`'s rotation matrix for Euler angles φ, θ, ψ in degrees (z-x-z).
pub fn euler_zxz(phi_deg: f64, theta_deg: f64, psi_deg: f64) -> DMat3 {
    let (sp, cp) = phi_deg.to_radians().sin_cos();
    let (st, ct) = theta_deg.to_radians().sin_cos();
    let (ss, cs) = psi_deg.to_radians().sin_cos();
    // Rows as printed in phantom3d; glam takes columns, so build from rows and transpose.
    DMat3::from_cols_array_2d(&[
        [cs * cp - ct * sp * ss, cs * sp + ct * cp * ss, ss * st],
        [-ss * cp - ct * sp * cs, -ss * sp + ct * cp * cs, cs * st],
        [st * sp, -st * cp, ct],
    ])
    .transpose()
}

/// The ten ellipsoids (a, b, c, x0, y0, z0, φ, θ, ψ) shared by both Shepp–Logan variants.
const SHEPP_LOGAN_GEOMETRY: [[f64; 9]; 10] = [
    [0.6900, 0.920, 0.810, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.6624, 0.874, 0.780, 0.0, -0.0184, 0.0, 0.0, 0.0, 0.0],
    [0.1100, 0.310, 0.220, 0.22, 0.0, 0.0, -18.0, 0.0, 10.0],
    [0.1600, 0.410, 0.280, -0.22, 0.0, 0.0, 18.0, 0.0, 10.0],
    [0.2100, 0.250, 0.410, 0.0, 0.35, -0.15, 0.0, 0.0, 0.0],
    [0.0460, 0.046, 0.050, 0.0, 0.1, 0.25, 0.0, 0.0, 0.0],
    [0.0460, 0.046, 0.050, 0.0, -0.1, 0.25, 0.0, 0.0, 0.0],
    [0.0460, 0.023, 0.050, -0.08, -0.605, 0.0, 0.0, 0.0, 0.0],
    [0.0230, 0.023, 0.020, 0.0, -0.606, 0.0, 0.0, 0.0, 0.0],
    [0.0230, 0.046, 0.020, 0.06, -0.605, 0.0, 0.0, 0.0, 0.0],
];
/// Kak & Slaney's original intensities.
const SHEPP_LOGAN_DENSITY: [f64; 10] =
    [1.0, -0.98, -0.02, -0.02, 0.01, 0.01, 0.01, 0.01, 0.01, 0.01];
/// Toft's high-contrast intensities.
const MODIFIED_DENSITY: [f64; 10] = [1.0, -0.8, -0.2, -0.2, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1];

impl Primitive {
    /// An ellipsoid in `phantom3d`'s convention: inside when `|D⁻¹(A p − c)| ≤ 1`.
    /// That is an ellipsoid centred at `Aᵀ c` whose own axes are the rows of `A`.
    pub fn ellipsoid_phantom3d(density: f64, semi_axes: DVec3, c: DVec3, a: DMat3) -> Self {
        Primitive {
            shape: Shape::Ellipsoid {
                center: a.transpose() * c,
                semi_axes,
                rot: a,
            },
            density,
        }
    }
    /// An axis-aligned ellipsoid.
    pub fn ellipsoid(density: f64, center: DVec3, semi_axes: DVec3) -> Self {
        Primitive {
            shape: Shape::Ellipsoid {
                center,
                semi_axes,
                rot: DMat3::IDENTITY,
            },
            density,
        }
    }
    /// A sphere.
    pub fn sphere(density: f64, center: DVec3, radius: f64) -> Self {
        Self::ellipsoid(density, center, DVec3::splat(radius))
    }
    /// An axis-aligned box.
    pub fn cuboid(density: f64, min: DVec3, max: DVec3) -> Self {
        Primitive {
            shape: Shape::Box { min, max },
            density,
        }
    }

    /// Whether phantom-space point `p` is inside (boundary included).
    pub fn contains(&self, p: DVec3) -> bool {
        match &self.shape {
            Shape::Ellipsoid {
                center,
                semi_axes,
                rot,
            } => {
                let q = (*rot * (p - *center)) / *semi_axes;
                q.length_squared() <= 1.0
            }
            Shape::Box { min, max } => p.cmpge(*min).all() && p.cmple(*max).all(),
        }
    }

    /// The parameter interval `[t_in, t_out]` (possibly empty) where `o + t d` is
    /// inside, in phantom coordinates.
    pub fn chord(&self, o: DVec3, d: DVec3) -> Option<(f64, f64)> {
        match &self.shape {
            Shape::Ellipsoid {
                center,
                semi_axes,
                rot,
            } => {
                // Into the unit sphere's frame: |o' + t d'|² = 1.
                let o2 = (*rot * (o - *center)) / *semi_axes;
                let d2 = (*rot * d) / *semi_axes;
                let a = d2.length_squared();
                if a == 0.0 {
                    return None;
                }
                let b = o2.dot(d2);
                let c = o2.length_squared() - 1.0;
                let disc = b * b - a * c;
                if disc <= 0.0 {
                    return None;
                }
                let s = disc.sqrt();
                // Numerically stable roots.
                let q = -(b + b.signum() * s);
                let (t1, t2) = if q != 0.0 {
                    let r1 = q / a;
                    let r2 = c / q;
                    (r1.min(r2), r1.max(r2))
                } else {
                    (-s / a, s / a)
                };
                Some((t1, t2))
            }
            Shape::Box { min, max } => slab_interval(o, d, *min, *max),
        }
    }
}

impl Primitive {
    /// The fraction of the axis-aligned cell `[c0, c0 + h]` (phantom coordinates) inside
    /// this primitive; `unit` is a quadrature rule on `[0, 1]` (nodes, weights). See
    /// [`Phantom::sample_cell_average`].
    pub fn cell_fraction(&self, c0: DVec3, h: DVec3, unit: &[(f64, f64)]) -> f64 {
        match &self.shape {
            Shape::Box { min, max } => (0..3)
                .map(|a| ((max[a].min(c0[a] + h[a]) - min[a].max(c0[a])) / h[a]).max(0.0))
                .product(),
            Shape::Ellipsoid {
                center,
                semi_axes,
                rot,
            } => {
                // The smallest radius of curvature of the surface: cells are split until
                // they are small against it, so that the normal hardly turns inside one.
                let curv = semi_axes.min_element().powi(2) / semi_axes.max_element();
                self.ellipsoid_fraction(c0, h, unit, (*center, *semi_axes, *rot), curv, 0)
            }
        }
    }

    /// [`Primitive::cell_fraction`] of an ellipsoid, by recursive subdivision.
    fn ellipsoid_fraction(
        &self,
        c0: DVec3,
        h: DVec3,
        unit: &[(f64, f64)],
        (center, semi_axes, rot): (DVec3, DVec3, DMat3),
        curv: f64,
        depth: usize,
    ) -> f64 {
        // The cell's bounding sphere, mapped into the unit sphere's frame, lies within
        // r' = ρ / min(semi-axes) of the mapped centre.
        let mid = c0 + 0.5 * h;
        let o = (rot * (mid - center)) / semi_axes;
        let rho = 0.5 * h.length();
        let r = rho / semi_axes.min_element();
        let d = o.length();
        if d >= 1.0 + r {
            return 0.0;
        }
        if d + r <= 1.0 {
            return 1.0;
        }
        if rho > 0.1 * curv && depth < 4 {
            let hh = 0.5 * h;
            let mut acc = 0.0;
            for k in 0..8 {
                let off = DVec3::new((k & 1) as f64, ((k >> 1) & 1) as f64, (k >> 2) as f64);
                acc += self.ellipsoid_fraction(
                    c0 + off * hh,
                    hh,
                    unit,
                    (center, semi_axes, rot),
                    curv,
                    depth + 1,
                );
            }
            return 0.125 * acc;
        }
        // Integrate the exact chord along the axis `a` closest to the surface normal at
        // the cell centre: no ray along it is tangent to the surface inside the cell, so
        // the clipped chord is continuous over the face (with kinks where the surface
        // crosses the cell's faces) and the face rule converges.
        let n = rot.transpose() * (o / semi_axes);
        let n = n.abs();
        let a = if n.x >= n.y && n.x >= n.z {
            0
        } else if n.y >= n.z {
            1
        } else {
            2
        };
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        let mut dir = DVec3::ZERO;
        dir[a] = 1.0;
        let mut acc = 0.0;
        for &(v, wv) in unit {
            for &(u, wu) in unit {
                let mut p = c0;
                p[b] += u * h[b];
                p[c] += v * h[c];
                if let Some((t0, t1)) = self.chord(p, dir) {
                    let len = t1.min(h[a]) - t0.max(0.0);
                    if len > 0.0 {
                        acc += wu * wv * len;
                    }
                }
            }
        }
        acc / h[a]
    }
}

/// The `n`-point Gauss–Legendre rule on `[−1, 1]`: nodes (ascending) and weights,
/// exact for polynomials of degree `2n − 1`. Newton's iteration on the three-term
/// recurrence `k P_k = (2k − 1) x P_{k−1} − (k − 1) P_{k−2}`.
pub fn gauss_legendre_rule(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut nodes = vec![0.0; n];
    let mut weights = vec![0.0; n];
    for i in 0..n {
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 0.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            if n == 1 {
                p0 = 1.0;
            }
            dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            let dx = p1 / dp;
            x -= dx;
            if dx.abs() < 1e-16 {
                break;
            }
        }
        nodes[n - 1 - i] = x;
        weights[n - 1 - i] = 2.0 / ((1.0 - x * x) * dp * dp);
    }
    (nodes, weights)
}

/// Phantom coordinates (the cube `[−1, 1]³`) of index-space point `p` in the grid of
/// `dims` voxels that [`Phantom::sample`] uses: `(p + ½)·2/n − 1` on each axis, so that
/// voxel `i` sits at the centre of the `i`-th of `n` equal cells of the cube.
#[inline]
pub fn index_to_phantom(p: [f64; 3], dims: [usize; 3]) -> DVec3 {
    let c = |x: f64, n: usize| (x + 0.5) * 2.0 / n as f64 - 1.0;
    DVec3::new(c(p[0], dims[0]), c(p[1], dims[1]), c(p[2], dims[2]))
}

impl Phantom {
    /// The 3D Shepp–Logan head phantom (Kak & Slaney intensities).
    pub fn shepp_logan() -> Self {
        Self::shepp_logan_with("shepp-logan", &SHEPP_LOGAN_DENSITY)
    }
    /// The high-contrast ("modified", Toft) 3D Shepp–Logan phantom.
    pub fn shepp_logan_modified() -> Self {
        Self::shepp_logan_with("shepp-logan-modified", &MODIFIED_DENSITY)
    }
    fn shepp_logan_with(name: &str, density: &[f64; 10]) -> Self {
        let prims = SHEPP_LOGAN_GEOMETRY
            .iter()
            .zip(density)
            .map(|(g, &rho)| {
                Primitive::ellipsoid_phantom3d(
                    rho,
                    DVec3::new(g[0], g[1], g[2]),
                    DVec3::new(g[3], g[4], g[5]),
                    euler_zxz(g[6], g[7], g[8]),
                )
            })
            .collect();
        Self::from_primitives(name, prims)
    }
    /// Marschner–Lobb with the customary α = 0.25, f_M = 6.
    pub fn marschner_lobb() -> Self {
        Phantom {
            name: "marschner-lobb".into(),
            kind: PhantomKind::MarschnerLobb {
                alpha: 0.25,
                f_m: 6.0,
            },
            half_extent_mm: DEFAULT_HALF_EXTENT_MM,
        }
    }
    /// A phantom made of the given primitives.
    pub fn from_primitives(name: &str, prims: Vec<Primitive>) -> Self {
        Phantom {
            name: name.into(),
            kind: PhantomKind::Primitives(prims),
            half_extent_mm: DEFAULT_HALF_EXTENT_MM,
        }
    }
    /// Looks a phantom up by name (see [`PHANTOM_NAMES`]).
    pub fn by_name(name: &str) -> Result<Self> {
        let z = DVec3::ZERO;
        Ok(match name {
            "shepp-logan" => Self::shepp_logan(),
            "shepp-logan-modified" | "modified-shepp-logan" => Self::shepp_logan_modified(),
            "marschner-lobb" | "ml" => Self::marschner_lobb(),
            "sphere" => Self::from_primitives("sphere", vec![Primitive::sphere(1.0, z, 0.6)]),
            // Nested and separate spheres with distinct values: MIP sees 1.5 through the
            // nested pair, MinIP sees the low-density hole.
            "spheres" => Self::from_primitives(
                "spheres",
                vec![
                    Primitive::sphere(1.0, DVec3::new(-0.4, 0.0, 0.0), 0.35),
                    Primitive::sphere(0.5, DVec3::new(-0.4, 0.0, 0.0), 0.15),
                    Primitive::sphere(0.75, DVec3::new(0.45, 0.3, 0.0), 0.3),
                    Primitive::sphere(-0.5, DVec3::new(0.45, 0.3, 0.0), 0.12),
                    Primitive::sphere(0.25, DVec3::new(0.4, -0.5, 0.1), 0.25),
                ],
            ),
            "ellipsoid" => Self::from_primitives(
                "ellipsoid",
                vec![Primitive::ellipsoid_phantom3d(
                    1.0,
                    DVec3::new(0.7, 0.4, 0.3),
                    DVec3::new(0.05, -0.1, 0.1),
                    euler_zxz(30.0, 20.0, 10.0),
                )],
            ),
            "slab" => Self::from_primitives(
                "slab",
                vec![Primitive::cuboid(
                    1.0,
                    DVec3::new(-1.0, -1.0, -0.25),
                    DVec3::new(1.0, 1.0, 0.25),
                )],
            ),
            _ => {
                return Err(Error::invalid(
                    "phantom name",
                    format!("'{name}' is not one of {}", PHANTOM_NAMES.join(", ")),
                ))
            }
        })
    }

    /// The phantom's value at phantom-space point `p`.
    pub fn value_at(&self, p: DVec3) -> f64 {
        match &self.kind {
            PhantomKind::Primitives(prims) => prims
                .iter()
                .filter(|pr| pr.contains(p))
                .map(|pr| pr.density)
                .sum(),
            PhantomKind::MarschnerLobb { alpha, f_m } => marschner_lobb(p, *alpha, *f_m),
        }
    }

    /// The phantom's value at world point `w` (mm).
    pub fn value_world(&self, w: DVec3) -> f64 {
        self.value_at(w / self.half_extent_mm)
    }

    /// The exact gradient of Marschner–Lobb in phantom coordinates; zero almost
    /// everywhere for the piecewise-constant phantoms.
    pub fn gradient_at(&self, p: DVec3) -> DVec3 {
        match &self.kind {
            PhantomKind::Primitives(_) => DVec3::ZERO,
            PhantomKind::MarschnerLobb { alpha, f_m } => marschner_lobb_gradient(p, *alpha, *f_m),
        }
    }

    /// The line integral `∫ f(o + t d) |d| dt` over `t ∈ [t0, t1]`, in world units
    /// (density × mm). `o`, `d` are in world mm; `d` need not be unit length. Infinite
    /// bounds integrate the whole line.
    pub fn line_integral_world(&self, o: DVec3, d: DVec3, t0: f64, t1: f64) -> f64 {
        let h = self.half_extent_mm;
        // In phantom coordinates the same t parameterises o/h + t d/h, and a length in
        // phantom units is h times smaller than in mm.
        let (op, dp) = (o / h, d / h);
        let speed = d.length();
        match &self.kind {
            PhantomKind::Primitives(prims) => prims
                .iter()
                .filter_map(|pr| {
                    let (a, b) = pr.chord(op, dp)?;
                    let (a, b) = (a.max(t0), b.min(t1));
                    (b > a).then_some(pr.density * (b - a) * speed)
                })
                .sum(),
            PhantomKind::MarschnerLobb { .. } => {
                // The function is defined on the cube only; integrate the part inside.
                let Some((a, b)) = slab_interval(op, dp, DVec3::splat(-1.0), DVec3::ONE) else {
                    return 0.0;
                };
                let (a, b) = (a.max(t0), b.min(t1));
                if b <= a {
                    return 0.0;
                }
                gauss_legendre(|t| self.value_at(op + dp * t), a, b, 256) * speed
            }
        }
    }

    /// Point-samples the phantom at the voxel centres of an `nx × ny × nz` grid that
    /// exactly covers its cube (see the module docs), as an f32 volume centred on the
    /// world origin.
    pub fn sample(&self, dims: [usize; 3]) -> Result<Volume<f32>> {
        let mut v = Volume::from_fn(dims, [1.0; 3], |i, j, k| {
            let p = [i as f64, j as f64, k as f64];
            self.value_at(index_to_phantom(p, dims)) as f32
        })?;
        v.set_affine(self.grid_affine(dims))?;
        Ok(v)
    }

    /// Cell-averages the phantom over the voxels of the grid [`Phantom::sample`] uses:
    /// voxel `(i, j, k)` holds `(1/|C|) ∫_C f`, the mean of the phantom over its cell `C`
    /// (the box-filtered phantom `f * box` sampled at the voxel centres), not the point
    /// value at the centre. For a sum of primitives the mean is `Σ density × (the
    /// fraction of C inside the primitive)`, computed per primitive:
    /// - a box: exactly, the product of the per-axis overlaps;
    /// - an ellipsoid: 0 or 1 when the cell's bounding sphere lies wholly outside or
    ///   inside it (tested in the ellipsoid's unit-sphere frame); otherwise the cell is
    ///   split in octants (at most 4 levels) until it is small against the surface's
    ///   smallest radius of curvature, and then the fraction is
    ///   `(1/(h_b h_c)) ∫∫ L(u, v) du dv / h_a`, with `L` the exact chord of the line
    ///   along axis `a` through the ellipsoid, clipped to the cell, and `a` the axis
    ///   closest to the surface normal (so that no such line touches the surface
    ///   tangentially inside the cell and `L` is continuous), integrated by an
    ///   `order × order` Gauss–Legendre rule over the cell's `b–c` face.
    ///
    /// Marschner–Lobb (smooth) is averaged by an `order³` Gauss–Legendre rule.
    ///
    /// Why: the line integral of the cell averages along a grid axis, `Σ_k v_ijk · s`, is
    /// exactly the analytic projection averaged over the detector pixel `(i, j)`'s
    /// `s × s` footprint; point samples have no such identity, and a feature thinner
    /// than a voxel (the Shepp–Logan skull) is hit or missed whole.
    pub fn sample_cell_average(&self, dims: [usize; 3], order: usize) -> Result<Volume<f32>> {
        if !(1..=64).contains(&order) {
            return Err(Error::invalid(
                "cell-average order",
                format!("{order}: the quadrature order must lie in 1 … 64"),
            ));
        }
        let (nodes, weights) = gauss_legendre_rule(order);
        // The rule on [0, 1].
        let unit: Vec<(f64, f64)> = nodes
            .iter()
            .zip(&weights)
            .map(|(&x, &w)| (0.5 * (x + 1.0), 0.5 * w))
            .collect();
        let h = DVec3::new(
            2.0 / dims[0] as f64,
            2.0 / dims[1] as f64,
            2.0 / dims[2] as f64,
        );
        let lo = |i: usize, j: usize, k: usize| {
            DVec3::new(i as f64, j as f64, k as f64) * h - DVec3::ONE
        };
        let mut v = match &self.kind {
            PhantomKind::Primitives(prims) => Volume::from_fn(dims, [1.0; 3], |i, j, k| {
                let c0 = lo(i, j, k);
                prims
                    .iter()
                    .map(|pr| pr.density * pr.cell_fraction(c0, h, &unit))
                    .sum::<f64>() as f32
            })?,
            PhantomKind::MarschnerLobb { alpha, f_m } => {
                Volume::from_fn(dims, [1.0; 3], |i, j, k| {
                    let c0 = lo(i, j, k);
                    let mut acc = 0.0;
                    for &(z, wz) in &unit {
                        for &(y, wy) in &unit {
                            for &(x, wx) in &unit {
                                let p = c0 + DVec3::new(x, y, z) * h;
                                acc += wx * wy * wz * marschner_lobb(p, *alpha, *f_m);
                            }
                        }
                    }
                    acc as f32
                })?
            }
        };
        v.set_affine(self.grid_affine(dims))?;
        Ok(v)
    }

    /// The index-to-world affine of the grid [`Phantom::sample`] produces:
    /// `world = spacing · (i − (n − 1)/2)`, `spacing = 2 · half_extent_mm / n`.
    pub fn grid_affine(&self, dims: [usize; 3]) -> glam::DMat4 {
        let s = DVec3::new(
            2.0 * self.half_extent_mm / dims[0] as f64,
            2.0 * self.half_extent_mm / dims[1] as f64,
            2.0 * self.half_extent_mm / dims[2] as f64,
        );
        let c = DVec3::new(
            (dims[0] as f64 - 1.0) * 0.5,
            (dims[1] as f64 - 1.0) * 0.5,
            (dims[2] as f64 - 1.0) * 0.5,
        );
        glam::DMat4::from_scale(s) * glam::DMat4::from_translation(-c)
    }
}

/// Marschner–Lobb's test function at phantom point `p`.
pub fn marschner_lobb(p: DVec3, alpha: f64, f_m: f64) -> f64 {
    use std::f64::consts::PI;
    let r = (p.x * p.x + p.y * p.y).sqrt();
    let rho_r = (2.0 * PI * f_m * (PI * r / 2.0).cos()).cos();
    (1.0 - (PI * p.z / 2.0).sin() + alpha * (1.0 + rho_r)) / (2.0 * (1.0 + alpha))
}

/// The exact gradient of [`marschner_lobb`].
pub fn marschner_lobb_gradient(p: DVec3, alpha: f64, f_m: f64) -> DVec3 {
    use std::f64::consts::PI;
    let r = (p.x * p.x + p.y * p.y).sqrt();
    let k = 1.0 / (2.0 * (1.0 + alpha));
    // d/dr cos(2π f cos(π r / 2)) = sin(2π f cos(πr/2)) · 2π f · sin(πr/2) · π/2
    let drho =
        (2.0 * PI * f_m * (PI * r / 2.0).cos()).sin() * 2.0 * PI * f_m * (PI * r / 2.0).sin() * PI
            / 2.0;
    let (gx, gy) = if r > 0.0 {
        (alpha * drho * p.x / r, alpha * drho * p.y / r)
    } else {
        (0.0, 0.0)
    };
    let gz = -(PI / 2.0) * (PI * p.z / 2.0).cos();
    DVec3::new(gx, gy, gz) * k
}

/// Composite Gauss–Legendre quadrature (8 points per panel) of `f` over `[a, b]`.
pub fn gauss_legendre(f: impl Fn(f64) -> f64, a: f64, b: f64, panels: usize) -> f64 {
    // Nodes and weights of the 8-point rule on [-1, 1].
    const X: [f64; 4] = [
        0.183_434_642_495_649_8,
        0.525_532_409_916_329,
        0.796_666_477_413_626_7,
        0.960_289_856_497_536_3,
    ];
    const W: [f64; 4] = [
        0.362_683_783_378_362,
        0.313_706_645_877_887_3,
        0.222_381_034_453_374_5,
        0.101_228_536_290_376_3,
    ];
    let h = (b - a) / panels as f64;
    let mut sum = 0.0;
    for p in 0..panels {
        let mid = a + (p as f64 + 0.5) * h;
        let half = 0.5 * h;
        for q in 0..4 {
            sum += W[q] * (f(mid - half * X[q]) + f(mid + half * X[q])) * half;
        }
    }
    sum
}

/// Parses `NAME`, `NAME:N` or `NAME:NX,NY,NZ` (the part after `phantom:`), defaulting
/// the size to `default_n`³.
pub fn parse_spec(spec: &str, default_n: usize) -> Result<(Phantom, [usize; 3])> {
    let (name, size) = match spec.split_once(':') {
        Some((n, s)) => (n, Some(s)),
        None => (spec, None),
    };
    let phantom = Phantom::by_name(name)?;
    let dims = match size {
        None => [default_n; 3],
        Some(s) => {
            let parts: Vec<&str> = s.split([',', 'x']).collect();
            let nums: std::result::Result<Vec<usize>, _> =
                parts.iter().map(|p| p.trim().parse::<usize>()).collect();
            match nums.as_deref() {
                Ok([n]) => [*n; 3],
                Ok([x, y, z]) => [*x, *y, *z],
                _ => {
                    return Err(Error::invalid(
                        "phantom size",
                        format!("'{s}' should be N or NX,NY,NZ (positive integers)"),
                    ))
                }
            }
        }
    };
    crate::volume::check_dims(dims)?;
    if dims.iter().any(|&n| n > 4096) {
        return Err(Error::too_large(
            "phantom",
            format!("{dims:?}: at most 4096 voxels per axis"),
        ));
    }
    Ok((phantom, dims))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_chord_is_exact() {
        let p = Phantom::from_primitives("s", vec![Primitive::sphere(2.0, DVec3::ZERO, 0.5)]);
        let h = p.half_extent_mm;
        // A ray at distance 0.3 from the centre: chord = 2 sqrt(0.25 - 0.09) = 0.8.
        let o = DVec3::new(-5.0, 0.3, 0.0) * h;
        let li = p.line_integral_world(o, DVec3::X, f64::NEG_INFINITY, f64::INFINITY);
        assert!((li - 2.0 * 0.8 * h).abs() < 1e-12 * h);
    }

    #[test]
    fn rotated_ellipsoid_chord_matches_numeric_integration() {
        let p = Phantom::by_name("ellipsoid").unwrap();
        let o = DVec3::new(-200.0, 10.0, -5.0);
        let d = DVec3::new(1.0, 0.1, 0.05).normalize();
        let exact = p.line_integral_world(o, d, 0.0, 400.0);
        // Fine midpoint sum of the point values (error O(h) at the two boundaries).
        let n = 400_000;
        let h = 400.0 / n as f64;
        let num: f64 = (0..n)
            .map(|i| p.value_world(o + d * ((i as f64 + 0.5) * h)) * h)
            .sum();
        assert!(exact > 10.0, "the test ray must cross the ellipsoid");
        assert!((exact - num).abs() < 2.0 * h, "{exact} vs {num}");
    }

    #[test]
    fn shepp_logan_values() {
        let p = Phantom::shepp_logan_modified();
        // Centre: inside ellipsoids 1 and 2 only → 1 − 0.8.
        assert!((p.value_at(DVec3::ZERO) - 0.2).abs() < 1e-15);
        // Outside the skull.
        assert_eq!(p.value_at(DVec3::new(0.95, 0.0, 0.0)), 0.0);
        let o = Phantom::shepp_logan();
        assert!((o.value_at(DVec3::ZERO) - 0.02).abs() < 1e-15);
    }

    #[test]
    fn ml_gradient_matches_difference_quotient() {
        let p = Phantom::marschner_lobb();
        let x = DVec3::new(0.31, -0.22, 0.4);
        let g = p.gradient_at(x);
        let h = 1e-6;
        for a in 0..3 {
            let mut e = DVec3::ZERO;
            e[a] = h;
            let fd = (p.value_at(x + e) - p.value_at(x - e)) / (2.0 * h);
            assert!((fd - g[a]).abs() < 1e-7, "axis {a}: {fd} vs {}", g[a]);
        }
    }

    #[test]
    fn gauss_legendre_is_exact_on_polynomials() {
        let v = gauss_legendre(|x| x.powi(15) + 3.0 * x * x, -1.0, 2.0, 1);
        let exact = (2f64.powi(16) - 1.0) / 16.0 + (8.0 + 1.0);
        assert!((v - exact).abs() < 1e-9 * exact);
    }

    #[test]
    fn gauss_legendre_rule_is_exact_to_degree_2n_minus_1() {
        for n in [1, 2, 3, 8, 16] {
            let (x, w) = gauss_legendre_rule(n);
            for deg in 0..2 * n {
                let got: f64 = x.iter().zip(&w).map(|(x, w)| w * x.powi(deg as i32)).sum();
                let want = if deg % 2 == 0 {
                    2.0 / (deg as f64 + 1.0)
                } else {
                    0.0
                };
                assert!(
                    (got - want).abs() < 1e-13,
                    "n {n} degree {deg}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn cell_averages_integrate_to_the_primitives_volumes() {
        // Σ voxel × cell volume = Σ density × primitive volume (4π/3·abc; boxes exact).
        let prims = vec![
            Primitive::ellipsoid_phantom3d(
                1.0,
                DVec3::new(0.5, 0.3, 0.2),
                DVec3::new(0.1, -0.1, 0.05),
                euler_zxz(30.0, 20.0, 10.0),
            ),
            Primitive::sphere(-0.5, DVec3::new(-0.4, 0.3, 0.0), 0.07),
            Primitive::cuboid(
                0.25,
                DVec3::new(-0.3, -0.61, -0.2),
                DVec3::new(0.1, -0.3, 0.33),
            ),
        ];
        let want = 4.0 / 3.0 * std::f64::consts::PI * (0.5 * 0.3 * 0.2 - 0.5 * 0.07f64.powi(3))
            + 0.25 * 0.4 * 0.31 * 0.53;
        let p = Phantom::from_primitives("t", prims);
        let n = 24;
        let v = p.sample_cell_average([n; 3], 12).unwrap();
        let cell = (2.0 / n as f64).powi(3);
        let got: f64 = v.data().iter().map(|&x| x as f64).sum::<f64>() * cell;
        eprintln!(
            "cell averages: relative error {:.1e}",
            (got - want).abs() / want
        );
        // Measured 4.4e-9 (order 12; f32 voxels).
        assert!((got - want).abs() < 5e-8 * want, "{got} vs {want}");
        // Point sampling is much further off at this size.
        let pt: f64 = p
            .sample([n; 3])
            .unwrap()
            .data()
            .iter()
            .map(|&x| x as f64)
            .sum();
        assert!((pt * cell - want).abs() > 10.0 * (got - want).abs());
        // Cells wholly inside or outside hold the point value.
        let pv = p.sample([n; 3]).unwrap();
        let same = v
            .data()
            .iter()
            .zip(pv.data())
            .filter(|(a, b)| a == b)
            .count();
        assert!(same > n * n * n * 9 / 10, "{same}");
    }

    #[test]
    fn parse_spec_sizes() {
        assert_eq!(parse_spec("sphere:16", 8).unwrap().1, [16; 3]);
        assert_eq!(parse_spec("slab:4,5,6", 8).unwrap().1, [4, 5, 6]);
        assert_eq!(parse_spec("sphere", 8).unwrap().1, [8; 3]);
        assert!(parse_spec("nope:4", 8).is_err());
        assert!(parse_spec("sphere:0", 8).is_err());
        assert!(parse_spec("sphere:-3", 8).is_err());
        assert!(parse_spec("sphere:100000", 8).is_err());
    }
}
