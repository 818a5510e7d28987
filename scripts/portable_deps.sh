#!/usr/bin/env bash
# Collects the header-only libraries the portable build needs (Eigen, CLI11, nlohmann-json,
# stb_image, nanoflann; headers and CMake package files) from this Debian machine into one prefix
# folder, so that `scripts/build_portable.sh` can build `umvs` on a machine without apt, e.g. a
# GPU machine that only has a CUDA PyTorch. The folder is git-ignored; copy it along with the
# working tree (the device tool's `carry`).
#
# Usage: scripts/portable_deps.sh [--textures] [DIR]      (default DIR: .portable_deps in the repository)
#   --textures  also the photographic texture collections of scripts/install_textures.sh (installed
#               here first), as DIR/textures/{gimp-patterns,mate-nature,scikit-image}: render with
#               TEXTURES=DIR/textures/gimp-patterns,DIR/textures/mate-nature,DIR/textures/scikit-image,
#               the same images in the same order as `--textures installed`
set -euo pipefail
cd "$(dirname "$0")/.."
WITH_TEXTURES=0
if [ "${1:-}" = --textures ]; then WITH_TEXTURES=1; shift; fi
DIR="${1:-.portable_deps}"
MARK=.umvs_portable_deps  # only a folder this script made is ever replaced
if [ -e "$DIR" ] && [ ! -f "$DIR/$MARK" ]; then
  echo "portable_deps: $DIR exists and is not a bundle of this script: name a new folder" >&2
  exit 1
fi
bash scripts/install_deps.sh >/dev/null
if ((WITH_TEXTURES)); then bash scripts/install_textures.sh >/dev/null; fi

need() { [ -e "$1" ] || { echo "portable_deps: $1 is missing (a Debian package of scripts/install_deps.sh)" >&2; exit 1; }; }
for p in /usr/include/eigen3 /usr/share/eigen3/cmake /usr/include/CLI /usr/share/cmake/CLI11 \
         /usr/include/nlohmann /usr/share/cmake/nlohmann_json /usr/include/stb/stb_image.h \
         /usr/include/stb/stb_image_write.h /usr/include/nanoflann.hpp; do
  need "$p"
done

# Into a fresh folder beside DIR, then swapped in: a failed copy leaves the old bundle as it was.
tmp="$(mktemp -d "${DIR%/}.tmp-XXXXXX")"
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp/include/stb" "$tmp/share/eigen3" "$tmp/share/cmake"
cp -r /usr/include/eigen3 /usr/include/CLI /usr/include/nlohmann /usr/include/nanoflann.hpp "$tmp/include/"
cp /usr/include/stb/stb_image.h /usr/include/stb/stb_image_write.h "$tmp/include/stb/"
cp -r /usr/share/eigen3/cmake "$tmp/share/eigen3/"
cp -r /usr/share/cmake/CLI11 /usr/share/cmake/nlohmann_json "$tmp/share/cmake/"
if ((WITH_TEXTURES)); then
  # Keep in step with installed_texture_folders() (src/io/texture_bank.cpp).
  mkdir -p "$tmp/textures"
  cp -rL /usr/share/gimp/2.0/patterns "$tmp/textures/gimp-patterns"
  cp -rL /usr/share/backgrounds/mate/nature "$tmp/textures/mate-nature"
  cp -rL /usr/local/share/unsup_mvs/textures/scikit-image "$tmp/textures/scikit-image"
fi
touch "$tmp/$MARK"
rm -rf "$DIR"
mv "$tmp" "$DIR"
trap - EXIT
echo "portable_deps: $(du -sh "$DIR" | cut -f1) in $DIR (Eigen, CLI11, nlohmann-json, stb_image, nanoflann$( ((WITH_TEXTURES)) && echo ", textures"))"
