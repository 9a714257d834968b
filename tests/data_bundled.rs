//! The bundled real scans (`data/`, provenance in `data/README.md`): each reads with the
//! dimensions, type and spacing its README row states, the in-memory readers give
//! exactly what the file readers give, and the demo's embedded copies are those files.
//! (Checksums and statistics against pydicom, nibabel and tifffile are in
//! `tests/io_dicom.rs`, `tests/io_nifti.rs`, `tests/io_tiff.rs` and `tests/io_pvm_den.rs`.)

use std::path::Path;
use voxlab::io::{read_volume, read_volume_bytes, Format};
use voxlab::volume::VoxelKind;

fn data(p: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data").join(p)
}

#[test]
fn each_dataset_reads_as_its_readme_says() {
    let cases: [(&str, [usize; 3], VoxelKind); 4] = [
        (
            "microct-bone/bone_128x128x128.tif",
            [128, 128, 128],
            VoxelKind::U8,
        ),
        ("mr-brain-dicom", [256, 256, 20], VoxelKind::I16),
        (
            "mr-brain-volpack/brainsmall.den",
            [128, 128, 84],
            VoxelKind::U8,
        ),
        ("mr-colin27/ch2.nii.gz", [181, 217, 181], VoxelKind::U8),
    ];
    for (p, dims, kind) in cases {
        let v = read_volume(&data(p)).unwrap_or_else(|e| panic!("{p}: {e}"));
        assert_eq!(v.dims(), dims, "{p}");
        assert_eq!(v.kind(), kind, "{p}");
        assert_eq!(v.non_finite().total(), 0, "{p}");
    }
    // Spacing: 1 mm where the format has none; the DICOM series' slice step comes from
    // its positions (7 mm nominal), its pixels are 0.859375 mm.
    let dicom = read_volume(&data("mr-brain-dicom")).unwrap();
    let s = dicom.spacing();
    // (The y step is a tilted unit vector times 0.859375: its length is exact to 1 ulp.)
    assert!(
        (s[0] - 0.859375).abs() < 1e-12 && (s[1] - 0.859375).abs() < 1e-12,
        "{s:?}"
    );
    assert!((s[2] - 7.0).abs() < 0.01, "{s:?}");
    assert_eq!(
        read_volume(&data("mr-colin27/ch2.nii.gz"))
            .unwrap()
            .spacing(),
        [1.0; 3]
    );
}

#[test]
fn in_memory_readers_match_the_file_readers() {
    for (p, format) in [
        ("microct-bone/bone_128x128x128.tif", Format::Tiff),
        ("mr-brain-volpack/brainsmall.den", Format::Den),
        ("mr-colin27/ch2.nii.gz", Format::Nifti),
    ] {
        let path = data(p);
        let bytes = std::fs::read(&path).unwrap();
        let a = read_volume(&path).unwrap();
        let b = read_volume_bytes(&bytes, format, &path).unwrap();
        assert!(a == b, "{p}: the in-memory reader differs");
    }
}

#[test]
fn the_demo_embeds_the_bundled_files() {
    assert_eq!(
        voxlab::jobs::embedded::MICROCT_BONE_TIFF,
        &std::fs::read(data("microct-bone/bone_128x128x128.tif")).unwrap()[..]
    );
    assert_eq!(
        voxlab::jobs::embedded::MR_BRAIN_DEN,
        &std::fs::read(data("mr-brain-volpack/brainsmall.den")).unwrap()[..]
    );
    let bone = voxlab::jobs::embedded::microct_bone().unwrap();
    assert!(bone == read_volume(&data("microct-bone/bone_128x128x128.tif")).unwrap());
    // The brain keeps its values; only its affine is set upright (a rotation).
    let brain = voxlab::jobs::embedded::mr_brain().unwrap();
    let file = read_volume(&data("mr-brain-volpack/brainsmall.den")).unwrap();
    assert_eq!(brain.values_f64(), file.values_f64());
    let m = glam::DMat3::from_mat4(brain.affine());
    assert!((m.determinant() - 1.0).abs() < 1e-12);
    assert_eq!(brain.spacing(), [1.0; 3]);
}
