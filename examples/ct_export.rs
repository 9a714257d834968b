//! Exports exact CT inputs and truths for the peer comparison in
//! `scripts/peers/ct_peers.py` (scikit-image `iradon`, RTK FDK).
//!
//! ```sh
//! cargo build --release --example ct_export
//! target/release/examples/ct_export /tmp/ct-peers
//! ```
//!
//! The phantom is `Phantom::shepp_logan()` (Kak & Slaney intensities, 256 mm cube), put in
//! the CT frame by [`voxlab::ct::phantom_to_ct`]; projections are its exact line
//! integrals ([`voxlab::cpu::project::project_phantom`]), density × mm. Files written
//! (little-endian C-order `.npy`):
//!
//! - `sino2d.npy` — `(256, 402)` float64: the scikit-image sinogram `(detector, angle)` of
//!   `Geometry::parallel_skimage(256, Geometry::even_angles(402, 180))` (1 mm bins,
//!   centre bin 128); `theta2d.txt`: the 402 angles in degrees.
//! - `truth2d.npy` — `(256, 256)` float64 in scikit-image orientation: pixel `(row, col)` is
//!   the phantom's value at CT world `X = col − 128`, `Y = 0`, `Z = row − 128` mm.
//! - `brain2d.npy` — `(256, 256)` `|u1`: 1 where that pixel centre lies inside the
//!   phantom's primitive 1 (the brain ellipsoid inside the skull).
//! - `cone_proj.npy` — `(180, 160, 160)` float64, `(angle, row, col)`: the projections of
//!   `Geometry::cone_rtk(1000, 1500, 160, 160, 3, 3, even_angles(180, 360))`.
//! - `truth3d.npy` — `(128, 128, 128)` float64, NumPy order `(z, y, x)` = CT `(Z, Y, X)`,
//!   voxel `i` at `(i − 63.5)·2` mm on each axis (RTK's centring); value at the centre.
//! - `brain3d.npy` — same shape, `|u1`: 1 where the voxel centre lies inside the
//!   phantom's primitive 1 (the brain ellipsoid inside the skull).
//! - `export.json` — the numbers above.

use glam::DVec3;
use std::io::Write;
use std::path::{Path, PathBuf};
use voxlab::cpu::project::project_phantom;
use voxlab::ct::{ct_to_phantom, Geometry};
use voxlab::phantom::{Phantom, PhantomKind};

/// Writes a C-order `.npy` (format 1.0) of `descr` (`<f8` or `|u1`) from raw bytes.
fn write_npy(path: &Path, descr: &str, shape: &[usize], bytes: &[u8]) -> std::io::Result<()> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_txt = if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let mut header =
        format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape_txt}, }}");
    // Magic (6) + version (2) + length (2) + header + '\n' is a multiple of 64.
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    f.write_all(b"\x93NUMPY\x01\x00")?;
    f.write_all(&(header.len() as u16).to_le_bytes())?;
    f.write_all(header.as_bytes())?;
    f.write_all(bytes)?;
    f.flush()
}

fn write_f64(path: &Path, shape: &[usize], data: &[f64]) -> std::io::Result<()> {
    assert_eq!(shape.iter().product::<usize>(), data.len());
    let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
    write_npy(path, "<f8", shape, &bytes)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "/tmp/ct-peers".into()),
    );
    std::fs::create_dir_all(&out)?;
    let phantom = Phantom::shepp_logan();
    let t0 = std::time::Instant::now();

    // 2-D parallel beam, scikit-image's geometry.
    let n2 = 256usize;
    let theta = Geometry::even_angles(402, 180.0);
    let g2 = Geometry::parallel_skimage(n2, theta.clone())?;
    let p2 = project_phantom(&phantom, &g2)?;
    let na = g2.n_angles();
    // (angle, 1, col) → scikit-image's (detector, angle).
    let mut sino = vec![0.0; n2 * na];
    for k in 0..na {
        for c in 0..n2 {
            sino[c * na + k] = p2.view(k)[c];
        }
    }
    write_f64(&out.join("sino2d.npy"), &[n2, na], &sino)?;
    let theta_txt: String = theta.iter().map(|t| format!("{t:?}\n")).collect();
    std::fs::write(out.join("theta2d.txt"), theta_txt)?;
    let brain = match &phantom.kind {
        PhantomKind::Primitives(prims) => prims[1].clone(),
        _ => unreachable!("Shepp–Logan is made of primitives"),
    };
    let in_brain = |p: DVec3| brain.contains(ct_to_phantom(p) / phantom.half_extent_mm);
    let h = (n2 / 2) as f64;
    let mut truth2 = vec![0.0; n2 * n2];
    let mut mask2 = vec![0u8; n2 * n2];
    for row in 0..n2 {
        for col in 0..n2 {
            let p = DVec3::new(col as f64 - h, 0.0, row as f64 - h);
            truth2[row * n2 + col] = phantom.value_world(ct_to_phantom(p));
            mask2[row * n2 + col] = in_brain(p) as u8;
        }
    }
    write_f64(&out.join("truth2d.npy"), &[n2, n2], &truth2)?;
    write_npy(&out.join("brain2d.npy"), "|u1", &[n2, n2], &mask2)?;
    eprintln!("2-D: {:.1} s", t0.elapsed().as_secs_f64());

    // 3-D circular cone beam, RTK's geometry.
    let (sid, sdd, det, pitch, n_proj) = (1000.0, 1500.0, 160usize, 3.0, 180usize);
    let g3 = Geometry::cone_rtk(
        sid,
        sdd,
        det,
        det,
        pitch,
        pitch,
        Geometry::even_angles(n_proj, 360.0),
    )?;
    let p3 = project_phantom(&phantom, &g3)?;
    write_f64(&out.join("cone_proj.npy"), &[n_proj, det, det], &p3.data)?;
    eprintln!("cone projections: {:.1} s", t0.elapsed().as_secs_f64());

    let (n3, sp) = (128usize, 2.0);
    let axis = |i: usize| (i as f64 - (n3 as f64 - 1.0) / 2.0) * sp;
    let mut truth3 = vec![0.0; n3 * n3 * n3];
    let mut mask = vec![0u8; n3 * n3 * n3];
    let mut brain_voxels = 0usize;
    for z in 0..n3 {
        for y in 0..n3 {
            for x in 0..n3 {
                let p = DVec3::new(axis(x), axis(y), axis(z));
                let i = (z * n3 + y) * n3 + x;
                truth3[i] = phantom.value_world(ct_to_phantom(p));
                if in_brain(p) {
                    mask[i] = 1;
                    brain_voxels += 1;
                }
            }
        }
    }
    write_f64(&out.join("truth3d.npy"), &[n3, n3, n3], &truth3)?;
    write_npy(&out.join("brain3d.npy"), "|u1", &[n3, n3, n3], &mask)?;

    let meta = serde_json::json!({
        "phantom": phantom.name,
        "half_extent_mm": phantom.half_extent_mm,
        "parallel": {
            "detector": n2, "du": 1.0, "cu": g2.cu, "angles": na, "range_deg": 180.0,
            "truth": "pixel (row, col) at X = col - 128, Y = 0, Z = row - 128 mm",
        },
        "cone": {
            "sid": sid, "sdd": sdd, "cols": det, "rows": det, "du": pitch, "dv": pitch,
            "cu": g3.cu, "cv": g3.cv, "angles": n_proj, "range_deg": 360.0,
        },
        "volume": {
            "shape_zyx": [n3, n3, n3], "spacing_mm": sp,
            "origin_mm": -(n3 as f64 - 1.0) / 2.0 * sp,
            "brain_voxels": brain_voxels,
        },
    });
    std::fs::write(
        out.join("export.json"),
        serde_json::to_string_pretty(&meta)? + "\n",
    )?;
    eprintln!(
        "wrote {} in {:.1} s ({brain_voxels} brain voxels)",
        out.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}
