#!/bin/sh
# Builds `sky` with a diagnostic patch of src/render/kernel.rs applied and
# copies the binary to OUT; the patch is taken out again at once (so the
# next plain build recompiles the kernel). Used by scripts/scattering_orders.sh
# and scripts/cloud_contributions.sh, whose diagnostics are not in the
# shipped kernel (each is a branch or a lock in its hottest loop).
#
#   scripts/patched_build.sh PATCH OUT
set -eu
patch=$1
out=$2
root=$(git rev-parse --show-toplevel)
cd "$root"
git diff --quiet -- src/render/kernel.rs || {
    echo "src/render/kernel.rs has changes of its own: commit or stash them first" >&2
    exit 1
}
git apply "$patch" || {
    echo "$patch no longer applies to src/render/kernel.rs: update it" >&2
    exit 1
}
trap 'git checkout -- src/render/kernel.rs' EXIT
cargo build --release --bin sky
mkdir -p "$(dirname "$out")"
cp target/release/sky "$out"
