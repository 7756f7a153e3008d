#!/bin/bash
# Times a draft bake through two single-thread `sky worker` daemons on this
# machine, for two builds of sky, alternating, and compares their files.
#
#   scripts/farm-bake-compare.sh OLD_SKY NEW_SKY [BAKE.toml] [ROUNDS]
#
# Each build's bake runs on workers of the same build (a coordinator and
# its workers must agree on the build). The cache is off, so every round
# renders everything. Prints each round's wall seconds, then whether the
# two builds' files are byte-identical.
set -euo pipefail
[ $# -ge 2 ] || { echo "usage: $0 OLD_SKY NEW_SKY [BAKE.toml] [ROUNDS]" >&2; exit 2; }
declare -A BIN=([old]="$1" [new]="$2")
BAKE=${3:-tests/bakes/tiny.toml}
ROUNDS=${4:-3}
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
export SKY_CACHE_DIR=off SKY_FARM_TOKEN=farm-bake-compare
for r in $(seq 1 "$ROUNDS"); do
    for b in old new; do
        pids=()
        addrs=()
        for i in 1 2; do
            f="$OUT/worker-$b-$i.out"
            : >"$f"
            # Owner-load pausing off: the coordinator shares these cores.
            "${BIN[$b]}" worker --listen 127.0.0.1:0 --threads 1 --owner-load-limit 1 --nice 0 --name "w$i" >"$f" 2>"$OUT/worker-$b-$i.err" &
            pids+=($!)
            for _ in $(seq 100); do grep -q "listening on" "$f" && break; sleep 0.1; done
            addrs+=("$(sed -n 's/.*listening on \(.*\)/\1/p' "$f" | head -1)")
        done
        rm -rf "$OUT/$b"
        t0=$(date +%s.%N)
        "${BIN[$b]}" bake-luts "$BAKE" --out "$OUT/$b" --quality draft --method monte-carlo --workers "${addrs[0]},${addrs[1]}" >/dev/null 2>"$OUT/$b.err" || {
            echo "the $b build's bake failed:" >&2
            tail -5 "$OUT/$b.err" >&2
            kill "${pids[@]}"
            exit 1
        }
        t1=$(date +%s.%N)
        kill "${pids[@]}"
        wait "${pids[@]}" 2>/dev/null || true
        echo "round $r: $b $(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.2f", b - a }') s"
    done
done
for f in "$OUT"/old/*.ktx2 "$OUT"/old/manifest.json; do
    if cmp -s "$f" "$OUT/new/$(basename "$f")"; then echo "identical: $(basename "$f")"; else echo "differs: $(basename "$f")"; fi
done
