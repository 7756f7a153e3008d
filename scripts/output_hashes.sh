#!/usr/bin/env bash
# Hashes what a build of `sky` writes, so that a change meant to move code
# and not physics (a refactor) can be shown to leave every output byte for
# byte as it was: run it with the build before and the build after and
# compare the two lists (`make hashes` does it for target/release/sky).
#
# usage: scripts/output_hashes.sh [SKY_BINARY] [WORK_DIR]
#
# It writes, with fixed seeds and no cache shared with anything else:
#   - a small render (clear sky, fisheye 32x32, 16 samples a pixel: EXR and PNG),
#   - a render with the adaptive stopping rule and the denoiser,
#   - a draft bake of bakes/tiny.toml (every KTX2 file; the manifest with
#     its generator line, which names the version, not the commit),
#   - a decoded sky from that bake (the CPU reference decoder),
#   - a GPU preview frame of that bake when the binary has `sky preview`
#     and a Vulkan driver is present (Mesa's lavapipe on a CPU machine).
# and prints one "sha256  name" line per file, sorted by name.
set -euo pipefail
sky="$(realpath "${1:-target/release/sky}")"
root="$(cd "$(dirname "$0")/.." && pwd)"
work="${2:-$(mktemp -d)}"
mkdir -p "$work"
cd "$root"
export SKY_CACHE_DIR="$work/cache"
"$sky" render atmospheres/clear.toml --camera fisheye --size 32x32 --sun-zenith-deg 80 --spp 16 \
    --out "$work/render.exr" --png "$work/render.png" >/dev/null 2>&1
"$sky" render atmospheres/hazed.toml --camera equirect --size 32x16 --sun-zenith-deg 60 --spp 32 \
    --max-rel-error 0.2 --denoise --out "$work/adaptive.exr" >/dev/null 2>&1
"$sky" bake-luts bakes/tiny.toml --out "$work/luts" --cache "$work/bake-cache" --quality draft --method monte-carlo >/dev/null 2>&1
# The decoded pictures record the manifest's path as given: a relative one,
# so that two work folders hash alike.
cd "$work"
"$sky" lut decode luts/manifest.json --sun-elevation-deg 10 --haziness 0 --cloudiness 0.1 \
    --camera fisheye --size 32x32 --out decoded.exr --png decoded.png >/dev/null 2>&1
if "$sky" preview --help >/dev/null 2>&1 && ls /usr/share/vulkan/icd.d/*.json >/dev/null 2>&1; then
    WGPU_BACKEND=vulkan NODEVICE_SELECT=1 "$sky" preview luts/manifest.json --sun-elevation-deg 10 \
        --camera fisheye --size 64x64 --out preview >/dev/null 2>&1
fi
find render.* adaptive.* decoded.* luts preview -maxdepth 1 -type f ! -path 'luts/cache*' 2>/dev/null \
    | LC_ALL=C sort | xargs sha256sum
