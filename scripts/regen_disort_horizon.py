#!/usr/bin/env python3
"""Regenerate tests/reference/disort_horizon.json: DISORT sky radiances near the horizon.

The same two plane-parallel slabs, sun and method as scripts/regen_disort.py (whose constants and
Slab class this imports: PythonicDISORT's discrete-ordinate solution, the radiance at each view by
integrating its source function along the line of sight, the single scattering analytic with the
exact phase function), at views 85, 88 and 89 deg from the zenith, where tests/reference/disort.json
stops at 85. It judges the deterministic solver's source integration along long, nearly horizontal
paths (tests/transport.rs). A separate file, so that `sky bench disort` and the path tracer's tests
keep the directions they were measured on.

    python3 -m venv .venv-disort
    .venv-disort/bin/pip install -r scripts/requirements-disort.txt
    .venv-disort/bin/python scripts/regen_disort_horizon.py

Settings: NQuad = 128 streams (the stated convergence is against 64), 256 Gauss-Legendre nodes in
depth for the source integral (against 128). About a minute on 2 cores.
"""

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import regen_disort as base  # noqa: E402

JSON_REL = "tests/reference/disort_horizon.json"
VIEW_ZENITH_DEG = [85, 88, 89]
REL_AZIMUTH_DEG = [0, 30, 60, 90, 120, 150, 180]
NQUAD, NQUAD_CHECK = 128, 64
NT, NT_CHECK = 256, 128


def read_sigma_cm2():
    """The cross-section table regen_disort.py writes (wavelength_nm, cross_section_cm2)."""
    sigma = {}
    for line in open(base.ROOT / base.CSV_REL):
        parts = line.replace(",", " ").split()
        try:
            sigma[float(parts[0])] = float(parts[1])
        except (ValueError, IndexError):
            pass
    return sigma


def main():
    base.VIEW_ZENITH_DEG = VIEW_ZENITH_DEG
    base.REL_AZIMUTH_DEG = REL_AZIMUTH_DEG
    sigma = read_sigma_cm2()
    cases, worst_streams, worst_depth = [], 0.0, 0.0
    for rel, with_hg in base.CASES:
        for l in base.WAVELENGTHS_NM:
            opt = base.slab_optics(sigma[l], l, with_hg)
            slab = base.Slab(opt, NQUAD, base.GROUND_ALBEDO)
            rad = base.sky(slab, nt=NT)
            fewer = base.sky(base.Slab(opt, NQUAD_CHECK, base.GROUND_ALBEDO), nt=NT)
            coarser = base.sky(slab, nt=NT_CHECK)
            worst_streams = max(worst_streams, float(np.max(np.abs(fewer / rad - 1))))
            worst_depth = max(worst_depth, float(np.max(np.abs(coarser / rad - 1))))
            base.log(f"{rel} {l} nm: done")
            cases.append({
                "atmosphere": rel,
                "wavelength_nm": l,
                "sun_zenith_deg": base.SUN_ZENITH_DEG,
                "ground_albedo": base.GROUND_ALBEDO,
                "view_zenith_deg": [float(z) for z in VIEW_ZENITH_DEG],
                "relative_azimuth_deg": [float(a) for a in REL_AZIMUTH_DEG],
                "radiance_sr_inv": [[base.rnd(v) for v in row] for row in rad],
            })
    out = {
        "generated_by": {
            "script": "scripts/regen_disort_horizon.py",
            "regenerate": ".venv-disort/bin/pip install -r scripts/requirements-disort.txt && "
            ".venv-disort/bin/python scripts/regen_disort_horizon.py",
            "versions": base.versions(),
        },
        "notes": (
            f"Diffuse radiance at the ground per unit solar irradiance normal to the beam, sr^-1, as in "
            f"disort.json. PythonicDISORT, NQuad = {NQUAD}, NLeg = NQuad, no delta-M; source integrated "
            f"along the line of sight on {NT} Gauss-Legendre depth nodes. Largest relative change with "
            f"NQuad {NQUAD_CHECK}: {worst_streams:.1e}; with {NT_CHECK} depth nodes: {worst_depth:.1e}."
        ),
        "cases": cases,
    }
    path = base.ROOT / JSON_REL
    path.write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")
    base.log(f"wrote {JSON_REL}; streams {worst_streams:.1e}, depth nodes {worst_depth:.1e}")


if __name__ == "__main__":
    main()
