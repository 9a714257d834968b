//! Sort-last compositing: the pieces of one pixel that the bricks of a distributed
//! render made (`cpu::raycast::render_owned`), joined in the order the pixel's ray
//! meets the bricks, and the whole render's pixel made from the result.
//!
//! Each brick owns a run of every ray's samples (`raycast::Owned`), so the ray's
//! samples are the bricks' runs one after another, front to back:
//! - **DVR**: a brick's piece is its premultiplied `(C, A)`, composited from zero
//!   (front to back, or back to front with `over`); the pieces are joined front to
//!   back with the same operator, `C += (1 − A) C_b`, `A += (1 − A) A_b`. It equals
//!   the single-process sum up to the reassociation of the products, and up to
//!   `1 − ert` where early ray termination ended the ray inside a brick (a brick
//!   behind cannot know its ray has ended: its piece adds at most `1 − A ≤ 1 − ert`).
//! - **MIP / MinIP**: the maximum / minimum of the pieces: exactly the
//!   single-process value, in any order, then the grey window.
//! - **X-ray**: the sum of the pieces, front to back (the single-process sum with its
//!   terms grouped by brick).
//!
//! A piece with no samples (count 0) is left out.

use super::modes::window_map;
use super::shade::over_background;
use crate::io::brick::KdTree;
use crate::real::Real;
use crate::settings::{Mode, RenderSettings};

/// Adds `piece` (a pixel value and its sample count), which lies behind everything in
/// `acc`, to `acc`.
#[inline]
pub fn join<R: Real>(mode: Mode, acc: &mut ([R; 4], u32), piece: ([R; 4], u32)) {
    let (v, n) = piece;
    if n == 0 {
        return;
    }
    let first = acc.1 == 0;
    acc.1 += n;
    let a = &mut acc.0;
    match mode {
        Mode::Mip if !first => a[0] = a[0].max(v[0]),
        Mode::Minip if !first => a[0] = a[0].min(v[0]),
        Mode::Xray if !first => a[0] = a[0] + v[0],
        Mode::Dvr => {
            let t = R::one() - a[3];
            for c in 0..3 {
                a[c] = a[c] + t * v[c];
            }
            a[3] = a[3] + t * v[3];
        }
        _ => a[0] = v[0],
    }
}

/// The whole render's pixel from the joined pieces `acc` of a ray that `hit` the
/// volume's box (or not): the background under DVR's colour (the background itself
/// for a ray that missed), the window over MIP and MinIP, the miss value for a
/// scalar ray with no samples.
#[inline]
pub fn finish<R: Real>(settings: &RenderSettings, acc: ([R; 4], u32), hit: bool) -> [R; 4] {
    let bg = settings.background.map(R::of);
    let (v, n) = acc;
    match settings.mode {
        Mode::Dvr if !hit => bg,
        Mode::Dvr => over_background([v[0], v[1], v[2]], v[3], bg),
        _ if n == 0 => [R::of(settings.miss_value), R::zero(), R::zero(), R::zero()],
        Mode::Mip | Mode::Minip => {
            let w = settings.window.map(|w| w.map(R::of));
            [
                w.map_or(v[0], |w| window_map(v[0], w)),
                R::zero(),
                R::zero(),
                R::zero(),
            ]
        }
        _ => [v[0], R::zero(), R::zero(), R::zero()],
    }
}

/// One pixel of the whole render from the pieces of the bricks of `tree`
/// (`piece(b)`: brick `b`'s value and sample count): joined in the order a ray of
/// index-space direction `d` meets the bricks, then [`finish`]ed. Returns the pixel
/// and the samples of all pieces; `order` is scratch space.
#[inline]
pub fn composite_pixel<R: Real>(
    tree: &KdTree,
    d: [f64; 3],
    settings: &RenderSettings,
    hit: bool,
    piece: impl Fn(usize) -> ([R; 4], u32),
    order: &mut Vec<usize>,
) -> ([R; 4], u32) {
    order.clear();
    tree.front_to_back(d, order);
    let mut acc = ([R::zero(); 4], 0u32);
    for &b in order.iter() {
        join(settings.mode, &mut acc, piece(b));
    }
    (finish(settings, acc, hit), acc.1)
}

/// The one order of `tree`'s bricks that is the order each ray of `camera` meets them
/// (index space of `affine`): from the eye for a perspective camera, along the view
/// direction for an orthographic one.
pub fn ray_order(tree: &KdTree, camera: &crate::camera::Camera, affine: glam::DMat4) -> Vec<usize> {
    let to_index = affine.inverse();
    let mut order = Vec::new();
    match camera.projection {
        crate::camera::Projection::Perspective { .. } => {
            tree.front_to_back_from(to_index.transform_point3(camera.eye).to_array(), &mut order)
        }
        crate::camera::Projection::Orthographic { .. } => tree.front_to_back(
            to_index.transform_vector3(camera.forward).to_array(),
            &mut order,
        ),
    }
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joined_dvr_pieces_are_the_samples_composited_in_one_run() {
        // Three samples (premultiplied colour, alpha) split after the first.
        let s = [
            ([0.2, 0.1, 0.0], 0.3),
            ([0.5, 0.5, 0.5], 0.6),
            ([0.0, 0.9, 0.1], 0.4),
        ];
        let run = |samples: &[([f64; 3], f64)]| {
            let (mut c, mut a) = ([0.0; 3], 0.0);
            for &(rgb, al) in samples {
                super::super::shade::under(&mut c, &mut a, rgb, al);
            }
            ([c[0], c[1], c[2], a], samples.len() as u32)
        };
        let mut acc = ([0.0; 4], 0);
        join(Mode::Dvr, &mut acc, run(&s[..1]));
        join(Mode::Dvr, &mut acc, ([9.0; 4], 0)); // an empty piece changes nothing
        join(Mode::Dvr, &mut acc, run(&s[1..]));
        let whole = run(&s);
        assert_eq!(acc.1, 3);
        for c in 0..4 {
            assert!((acc.0[c] - whole.0[c]).abs() < 1e-15, "{acc:?} {whole:?}");
        }
    }

    #[test]
    fn scalar_pieces_take_the_extreme_or_the_sum_and_empty_rays_miss() {
        let s = RenderSettings {
            mode: Mode::Mip,
            miss_value: -7.0,
            ..RenderSettings::default()
        };
        let mut acc = ([0.0f64; 4], 0);
        join(Mode::Mip, &mut acc, ([-3.0, 0.0, 0.0, 0.0], 2));
        join(Mode::Mip, &mut acc, ([-5.0, 0.0, 0.0, 0.0], 1));
        assert_eq!(finish(&s, acc, true)[0], -3.0);
        assert_eq!(finish(&s, ([0.0; 4], 0), true)[0], -7.0);
        let mut sum = ([0.0f64; 4], 0);
        join(Mode::Xray, &mut sum, ([1.5, 0.0, 0.0, 0.0], 2));
        join(Mode::Xray, &mut sum, ([2.0, 0.0, 0.0, 0.0], 2));
        assert_eq!(sum.0[0], 3.5);
    }

    /// The one order of `ray_order` is each ray's: for eyes outside and inside a volume
    /// cut into 7 bricks (perspective) and for view directions (orthographic), the
    /// bricks a ray crosses, sorted by where it crosses them, come in that order.
    #[test]
    fn ray_order_is_the_order_every_ray_meets_the_bricks() {
        use crate::camera::{Camera, Projection};
        use glam::{DMat4, DVec3};
        let dims = [20, 17, 13];
        let (tree, bricks) = crate::io::brick::kd_tree(dims, 7).unwrap();
        // The part of a ray (t ≥ t_min) inside brick b: the middle of its interval.
        let crossing = |b: &crate::io::brick::Brick, o: DVec3, d: DVec3, t_min: f64| {
            let (mut t0, mut t1) = (t_min, f64::INFINITY);
            for a in 0..3 {
                let (lo, hi) = (b.lo[a] as f64 - 0.5, b.hi[a] as f64 - 0.5);
                if d[a] == 0.0 {
                    if o[a] < lo || o[a] >= hi {
                        return None;
                    }
                    continue;
                }
                let (ta, tb) = ((lo - o[a]) / d[a], (hi - o[a]) / d[a]);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
            (t1 > t0 + 1e-9).then_some(0.5 * (t0 + t1))
        };
        let affine = DMat4::IDENTITY;
        let centre = DVec3::new(9.5, 8.0, 6.0);
        let mut rays_checked = 0;
        // Inside, looking nearly along a cut's plane (x = 13.5 for y < 8): rays cross
        // it both ways, against the view direction's x too.
        let along = DVec3::new(14.6, 1.0, 6.0);
        for (eye, target, ortho) in [
            (DVec3::new(-30.0, 4.0, 40.0), centre, false),
            (DVec3::new(50.0, -20.0, 3.0), centre, false),
            (DVec3::new(7.3, 11.2, 2.9), centre, false),
            (along, along + DVec3::new(0.1, 1.0, 0.0), false),
            (DVec3::new(-30.0, 25.0, -10.0), centre, true),
            (DVec3::new(40.0, 30.0, 25.0), centre, true),
        ] {
            let projection = if ortho {
                Projection::Orthographic {
                    width_mm: 60.0,
                    height_mm: 50.0,
                }
            } else {
                Projection::Perspective { fov_y_deg: 150.0 }
            };
            let up = DVec3::new(0.3, 0.0, 1.0);
            let cam = Camera::look_at(eye, target, up, projection, 31, 23).unwrap();
            let order = ray_order(&tree, &cam, affine);
            assert_eq!(order.len(), bricks.len());
            let rank = |b: usize| order.iter().position(|&x| x == b).unwrap();
            for row in 0..cam.height {
                for col in 0..cam.width {
                    let r = cam.ray(col, row);
                    let t_min = if ortho { -1e9 } else { 0.0 };
                    let mut met: Vec<(f64, usize)> = (0..bricks.len())
                        .filter_map(|b| {
                            crossing(&bricks[b], r.origin, r.dir, t_min).map(|t| (t, b))
                        })
                        .collect();
                    met.sort_by(|x, y| x.0.total_cmp(&y.0));
                    if met.len() > 1 {
                        rays_checked += 1;
                    }
                    for w in met.windows(2) {
                        assert!(rank(w[0].1) < rank(w[1].1), "{eye} {order:?} {met:?}");
                    }
                }
            }
        }
        assert!(rays_checked > 1000, "{rays_checked}");
    }
}
