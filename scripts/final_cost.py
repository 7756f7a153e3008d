#!/usr/bin/env python3
"""The projected cost of a final bake from a cost probe (`make final-cost`),
standard library only: final_cost.py PROBE.json TEXEL_FACTOR SLICES.

PROBE.json is the --json summary of `sky bake-luts bakes/cost-probe.toml
--quality final --slice ...`: per slice its core-seconds, texels and mean
samples. Each probed slice's core-seconds times TEXEL_FACTOR (the probe has
that many times fewer texels than the real slice, over the same mappings)
estimates the real slice's; their mean times SLICES estimates a basis sky."""
import json
import sys

probe = json.load(open(sys.argv[1]))
factor, slices = float(sys.argv[2]), int(sys.argv[3])
skies = {}
for s in probe["slices"]:
    skies.setdefault(s["slice"].split(":")[0], []).append(s)
total = 0.0
print(f"{'sky':<8} {'slice':>6} {'sun zen':>8} {'samples/texel':>13} {'core-s (probe)':>15} {'core-s per real slice':>22}")
for name, rows in skies.items():
    real = []
    for r in rows:
        c = r["core_seconds"] * factor
        real.append(c)
        print(f"{name:<8} {r['slice'].split(':')[1]:>6} {r['sun_zenith_deg']:>8.2f} {r['mean_samples']:>13.0f} {r['core_seconds']:>15.1f} {c:>22.0f}")
    sky = sum(real) / len(real) * slices
    total += sky
    print(f"{name:<8} all {slices} slices: {sky / 3600:.2f} core-hours (mean of {len(real)} probed slices)")
print(f"final bake, all skies: {total / 3600:.2f} core-hours")
