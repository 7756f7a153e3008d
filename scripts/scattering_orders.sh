#!/bin/sh
# Splits the twilight sky's radiance and its Monte Carlo noise by scattering
# order (README, "What a final bake costs": which orders carry the noise).
#
#   scripts/scattering_orders.sh [SKY...]      (default: clear hazed)
#
# The kernel has no order filter of its own: scripts/patched_build.sh builds
# one with scripts/scattering-orders.patch, whose kernel keeps only the
# estimates of the orders in SKY_ORDERS=MIN-MAX (the sun estimate at a
# path's n-th vertex is order n; the skylight estimates there, toward the
# lit air, order n + 1). Single scattering stays the quadrature's in every
# run. It then renders ten directions at sun zenith 91, 93, 96 and 99
# degrees, 4096 samples each, four times: every order, order 2 only,
# orders 3 and up, and none (the quadrature alone), and prints each
# direction's shares of Y and the per-sample relative variance of each part
# against the whole's Y. About 3 minutes on 2 cores after the build.
set -eu
root=$(git rev-parse --show-toplevel)
cd "$root"
work=target/scattering-orders
scripts/patched_build.sh scripts/scattering-orders.patch "$work/sky"
sky="$root/$work/sky"
out="$work/runs"
mkdir -p "$out"
printf 'zenith_deg,azimuth_deg\n0,0\n60,0\n80,0\n87,0\n89.5,0\n80,90\n87,90\n80,180\n87,180\n89.5,180\n' > "$out/dirs.csv"
skies=${*:-clear hazed}
for sky_name in $skies; do
    for sun in 91 93 96 99; do
        for orders in 0-99 2-2 3-99 99-99; do
            SKY_ORDERS=$orders "$sky" render "atmospheres/$sky_name.toml" --camera directions \
                --directions "$out/dirs.csv" --sun-zenith-deg $sun --spp 4096 --json \
                --hide-sun-disk > "$out/$sky_name-$sun-$orders.json"
        done
    done
done
python3 scripts/scattering_orders.py "$out" 4096 $skies
