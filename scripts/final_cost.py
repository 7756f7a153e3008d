#!/usr/bin/env python3
"""The projected cost of a final bake from a cost probe (`make final-cost`),
standard library only: final_cost.py PROBE.json TEXEL_FACTOR SLICES.

PROBE.json is the --json summary of `sky bake-luts bakes/cost-probe.toml
--quality final --slice ...`: per slice its core-seconds, texels and mean
samples. Each probed slice's core-seconds times TEXEL_FACTOR (the probe has
that many times fewer texels than the real slice, over the same mappings)
estimates the real slice's. A basis sky is the mean of its probed slices
above the horizon (index < 48) times 48 plus the mean of those below times
16, the time mapping's split; a part with no probed slice is left out and
the sky marked as a lower bound, as is one whose slices reached the
preset's sample cap (16384: such texels stopped short of the target)."""
import json
import sys

probe = json.load(open(sys.argv[1]))
factor, slices = float(sys.argv[2]), int(sys.argv[3])
UPPER = 48  # slices above the horizon (the talk's 48 + 16)
CAP = 16384
skies = {}
for s in probe["slices"]:
    skies.setdefault(s["slice"].split(":")[0], []).append(s)
total = 0.0
lower_bound = False
print(f"{'sky':<8} {'slice':>6} {'sun zen':>8} {'samples/texel':>13} {'core-s (probe)':>15} {'core-s per real slice':>22}")
for name, rows in skies.items():
    real = []
    for r in rows:
        c = r["core_seconds"] * factor
        real.append(c)
        print(f"{name:<8} {r['slice'].split(':')[1]:>6} {r['sun_zenith_deg']:>8.2f} {r['mean_samples']:>13.0f} {r['core_seconds']:>15.1f} {c:>22.0f}")
    upper = [c for r, c in zip(rows, real) if int(r["slice"].split(":")[1]) < UPPER]
    lower = [c for r, c in zip(rows, real) if int(r["slice"].split(":")[1]) >= UPPER]
    sky = (sum(upper) / len(upper) * UPPER if upper else 0.0) + (sum(lower) / len(lower) * (slices - UPPER) if lower else 0.0)
    capped = any(r["mean_samples"] >= 0.97 * CAP for r in rows)
    bound = (not upper or not lower or capped)
    lower_bound = lower_bound or bound
    total += sky
    why = ", ".join(w for w, c in [("no slice below the horizon probed", not lower), ("no slice above probed", not upper), ("texels at the sample cap", capped)] if c)
    print(f"{name:<8} all {slices} slices: {'at least ' if bound else ''}{sky / 3600:.2f} core-hours{' (' + why + ')' if why else ''}")
print(f"final bake, all skies: {'at least ' if lower_bound else ''}{total / 3600:.2f} core-hours")
