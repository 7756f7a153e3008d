#!/bin/sh
# Where the light and the noise under a thick cloud layer come from
# (README, "What a final bake costs"): scripts/patched_build.sh builds the
# renderer with scripts/cloud-contributions.patch, whose kernel sums each
# path's estimates by the altitude of the vertex that made them (below the
# 3 to 5 km layer of cloudy3 and cloudy5, its tenths, above it) and the sun
# estimates at collisions also by the decade of the phase function toward
# the sun, then renders single directions (the zenith, and 80 degrees from
# it toward the sun) under cloudy3 and cloudy5 with the sun at zenith 60
# and 85 degrees, 32768 paths each, and prints each one's shares of the
# mean and variances (per path, relative to the mean squared). About a
# minute on 2 cores after the build.
set -eu
root=$(git rev-parse --show-toplevel)
cd "$root"
work=target/cloud-contributions
scripts/patched_build.sh scripts/cloud-contributions.patch "$work/sky"
for sky in cloudy3 cloudy5; do
    for sun in 60 85; do
        for dir in 0,0 80,0; do
            printf 'zenith_deg,azimuth_deg\n%s\n' "$dir" > "$work/direction.csv"
            echo "$sky, sun zenith $sun deg, view (zenith, azimuth from the sun) $dir deg:"
            "$work/sky" render "atmospheres/$sky.toml" --camera directions --directions "$work/direction.csv" \
                --sun-zenith-deg $sun --spp 32768 --threads 2 --hide-sun-disk --json 2>&1 >/dev/null | tail -n 22
        done
    done
done
