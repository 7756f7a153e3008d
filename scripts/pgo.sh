#!/usr/bin/env bash
# Profile-guided build of `sky` (issue 12; the talk credits profile-guided
# optimisation with "10 % reduction in computation time"): an instrumented
# build renders a training bake, LLVM merges the profile, and the release
# build is made again with it, into target/pgo/release/sky.
#
#   scripts/pgo.sh build    the instrumented build, the training run, the optimised build
#   scripts/pgo.sh compare  the plain build against the optimised one on the same bake,
#                           alternating rounds, and the two bakes' files compared byte for
#                           byte (a worker built this way must render bit-identically)
#
# Needs llvm-profdata of the LLVM major version rustc uses (`rustc -vV`);
# on Debian it is the llvm-N package, which `build` installs when it is
# missing and this runs as root.
set -euo pipefail
cd "$(dirname "$0")/.."

CARGO=${CARGO:-cargo}
# The bake's and the workers' binary: without the GPU preview unless asked
# (FEATURES=preview), so the builds skip wgpu.
FEATURES=${FEATURES:-}
FEATURE_ARGS=()
[ -n "$FEATURES" ] && FEATURE_ARGS=(--features "$FEATURES")
TRAIN_BAKE=${TRAIN_BAKE:-bakes/demo.toml}
BENCH_BAKE=${BENCH_BAKE:-bakes/demo.toml}
ROUNDS=${ROUNDS:-3}
OUT=${OUT:-out}/pgo
PROFILES=$PWD/target/pgo-profiles

llvm_major() { rustc -vV | sed -n 's/^LLVM version: \([0-9]*\).*/\1/p'; }

profdata() {
    local v
    v=$(llvm_major)
    if ! command -v "llvm-profdata-$v" >/dev/null; then
        if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
            echo "installing llvm-$v for llvm-profdata-$v (rustc's LLVM is $v)" >&2
            DEBIAN_FRONTEND=noninteractive apt-get install -y -q "llvm-$v" >/dev/null
        else
            echo "error: llvm-profdata-$v not found: rustc uses LLVM $v, whose profiles older tools cannot read (on Debian: apt-get install llvm-$v)" >&2
            exit 2
        fi
    fi
    echo "llvm-profdata-$v"
}

build() {
    local tool
    tool=$(profdata)
    rm -rf "$PROFILES"
    mkdir -p "$PROFILES/raw" "$OUT"
    echo "== instrumented build (target/pgo-gen)" >&2
    RUSTFLAGS="-Cprofile-generate=$PROFILES/raw" $CARGO build --release --locked "${FEATURE_ARGS[@]}" --target-dir target/pgo-gen
    echo "== training: a draft bake of $TRAIN_BAKE" >&2
    rm -rf "$OUT/train"
    target/pgo-gen/release/sky bake-luts "$TRAIN_BAKE" --out "$OUT/train" --quality draft --method monte-carlo >/dev/null
    "$tool" merge -o "$PROFILES/sky.profdata" "$PROFILES/raw"
    echo "== optimised build (target/pgo)" >&2
    RUSTFLAGS="-Cprofile-use=$PROFILES/sky.profdata" $CARGO build --release --locked "${FEATURE_ARGS[@]}" --target-dir target/pgo
    echo "target/pgo/release/sky" >&2
}

# Wall seconds of one draft bake of $BENCH_BAKE with binary $1 into $2.
bake_seconds() {
    rm -rf "$2"
    local t0 t1
    t0=$(date +%s.%N)
    "$1" bake-luts "$BENCH_BAKE" --out "$2" --quality draft --method monte-carlo >/dev/null
    t1=$(date +%s.%N)
    awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.2f\n", b - a }'
}

compare() {
    [ -x target/pgo/release/sky ] || {
        echo "error: no target/pgo/release/sky: run scripts/pgo.sh build first" >&2
        exit 2
    }
    mkdir -p "$OUT"
    # The plain build of the same features (in target/release, whose
    # dependencies are built already; `make build` puts the preview back).
    $CARGO build --release --locked "${FEATURE_ARGS[@]}"
    cp target/release/sky "$OUT/sky-plain"
    local plain=() pgo=()
    for r in $(seq 1 "$ROUNDS"); do
        plain+=("$(bake_seconds "$OUT/sky-plain" "$OUT/plain")")
        pgo+=("$(bake_seconds target/pgo/release/sky "$OUT/optimised")")
        echo "round $r: plain ${plain[-1]} s, profile-guided ${pgo[-1]} s" >&2
    done
    local identical=yes
    for f in "$OUT"/plain/*.ktx2 "$OUT"/plain/manifest.json; do
        if ! cmp -s "$f" "$OUT/optimised/$(basename "$f")"; then
            identical=no
            echo "differs: $(basename "$f")" >&2
        fi
    done
    local best_plain best_pgo
    best_plain=$(printf '%s\n' "${plain[@]}" | sort -g | head -1)
    best_pgo=$(printf '%s\n' "${pgo[@]}" | sort -g | head -1)
    printf 'draft bake of %s, fastest of %s alternating rounds: plain %.1f s, profile-guided %.1f s, ratio %.3f; files identical: %s\n' \
        "$BENCH_BAKE" "$ROUNDS" "$best_plain" "$best_pgo" "$(awk -v a="$best_pgo" -v b="$best_plain" 'BEGIN { print a / b }')" "$identical"
    [ "$identical" = yes ]
}

case "${1:-}" in
build) build ;;
compare) compare ;;
*)
    echo "usage: scripts/pgo.sh build|compare" >&2
    exit 2
    ;;
esac
