#!/usr/bin/env bash
# Installs the photographic texture collections that `umvs synth` maps onto synthetic scenes (its
# default `--textures installed`); docs/synthetic.md lists each source and licence. Nothing of
# them goes into the repository. Idempotent: returns at once when everything is there.
#   scripts/install_textures.sh
# About 140 MB on disk (gimp-data brings GIMP's brushes and scripts with its patterns):
#   /usr/share/gimp/2.0/patterns                       gimp-data: 60 tiling material photographs (.pat)
#   /usr/share/backgrounds/mate/nature                 mate-backgrounds: 12 nature photographs
#   /usr/local/share/unsup_mvs/textures/scikit-image   11 sample images of python3-skimage, taken
#                                                      from its .deb without installing the package
#                                                      (and its Python dependencies)
set -euo pipefail

PACKAGES=(gimp-data mate-backgrounds)
SKIMAGE_DIR=/usr/local/share/unsup_mvs/textures/scikit-image
# The photographs with a clear licence (CC0 or public domain; see docs/synthetic.md).
SKIMAGE_FILES=(brick.png grass.png gravel.png coffee.png chelsea.png camera.png rocket.jpg coins.png
               text.png hubble_deep_field.jpg retina.jpg)

SUDO=""
if [[ $(id -u) -ne 0 ]]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
skimage_missing=0
for f in "${SKIMAGE_FILES[@]}"; do [ -f "$SKIMAGE_DIR/$f" ] || skimage_missing=1; done
if ((${#missing[@]} == 0 && skimage_missing == 0)); then
  echo "[install_textures] all collections present"
  exit 0
fi

$SUDO apt-get update -q
if ((${#missing[@]} > 0)); then
  echo "[install_textures] installing ${missing[*]}"
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
fi
if ((skimage_missing)); then
  tmp="$(mktemp -d /tmp/umvs_textures.XXXXXX)"
  trap 'rm -rf "$tmp"' EXIT
  chmod 755 "$tmp"
  chown _apt "$tmp" 2>/dev/null || true  # apt-get download runs as _apt where it can
  (cd "$tmp" && apt-get download -q python3-skimage)
  dpkg-deb -x "$tmp"/python3-skimage_*.deb "$tmp/x"
  src="$tmp/x/usr/lib/python3/dist-packages/skimage/data"
  $SUDO mkdir -p "$SKIMAGE_DIR"
  for f in "${SKIMAGE_FILES[@]}"; do $SUDO install -m 644 "$src/$f" "$SKIMAGE_DIR/$f"; done
  $SUDO install -m 644 "$tmp/x/usr/share/doc/python3-skimage/copyright" "$SKIMAGE_DIR/copyright"
  echo "[install_textures] ${#SKIMAGE_FILES[@]} scikit-image sample images in $SKIMAGE_DIR"
fi
echo "[install_textures] done: umvs synth now uses these collections by default (--textures none: procedural only)"
