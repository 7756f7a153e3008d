#!/usr/bin/env python3
"""Regenerate tests/reference/colour_spaces.json: colour-science's XYZ -> linear
RGB matrices and conversions of test colours for the LUT colour spaces of
`sky bake-luts` (src/lut/colour.rs), so the Rust tests can compare without
Python.

Uses only colour-science and numpy, pinned in scripts/requirements-reference.txt
(the venv of scripts/regen_reference.py; `make regen-reference` runs both):

    python3 -m venv .venv-ref
    .venv-ref/bin/pip install -r scripts/requirements-reference.txt
    .venv-ref/bin/python scripts/regen_colour_spaces.py

(colour-science==0.4.7 numpy==2.0.2 scipy==1.13.1 alone are enough for this
script.) Output is deterministic: keys sorted, floats in Python's shortest
round-trip repr, -0.0 written as 0.0. Running it twice gives identical bytes.
"""

import json
import math
import sys
import warnings
from importlib import metadata
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "tests" / "reference" / "colour_spaces.json"
SCRIPT = "scripts/regen_colour_spaces.py"


def clean(obj):
    if isinstance(obj, dict):
        return {str(k): clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [clean(v) for v in obj.tolist()]
    if isinstance(obj, (int, np.integer)) and not isinstance(obj, bool):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        if not math.isfinite(v):
            raise ValueError("non-finite value in reference output")
        return 0.0 if v == 0.0 else v
    return obj


def main():
    warnings.filterwarnings("ignore")
    import colour

    d65 = np.asarray(colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"], dtype=float)
    xyz_d65 = colour.xy_to_XYZ(d65)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]

    # Test colours, absolute XYZ (any scale: the conversion is linear).
    colours = {
        "d65_white_y1": xyz_d65,
        "equal_energy_xyz_1": np.array([1.0, 1.0, 1.0]),
        "aces_white_y1": colour.xy_to_XYZ(np.asarray(colour.RGB_COLOURSPACES["ACEScg"].whitepoint, dtype=float)),
        # Spectral colours (CIE 1931 CMF values): outside every RGB gamut
        # here, so some channels go negative.
        "monochromatic_520nm": np.asarray(cmfs[520], dtype=float),
        "monochromatic_450nm": np.asarray(cmfs[450], dtype=float),
        "monochromatic_610nm": np.asarray(cmfs[610], dtype=float),
        # Sky-like values in cd/m^2-scaled XYZ.
        "zenith_blue": np.array([4200.0, 4500.0, 7800.0]),
        "sunset_orange": np.array([2.1e4, 1.8e4, 6.0e3]),
        "twilight_dim": np.array([1.2e-3, 1.0e-3, 2.5e-3]),
    }

    spaces = {}
    for key, name in [("rec709", "ITU-R BT.709"), ("rec2020", "ITU-R BT.2020"), ("acescg", "ACEScg")]:
        cs = colour.RGB_COLOURSPACES[name]
        white = np.asarray(cs.whitepoint, dtype=float)
        cat_bradford = colour.adaptation.matrix_chromatic_adaptation_VonKries(
            xyz_d65, colour.xy_to_XYZ(white), transform="Bradford")
        cat_cat02 = colour.adaptation.matrix_chromatic_adaptation_VonKries(
            xyz_d65, colour.xy_to_XYZ(white), transform="CAT02")
        npm = colour.normalised_primary_matrix(cs.primaries, white)
        converted = {}
        for cname, xyz in colours.items():
            converted[cname] = {
                "XYZ": xyz,
                "RGB_bradford_from_d65": colour.XYZ_to_RGB(
                    xyz, cs, illuminant=d65, chromatic_adaptation_transform="Bradford"),
            }
        spaces[key] = {
            "colour_name": name,
            "primaries_xy": np.asarray(cs.primaries, dtype=float),
            "whitepoint_xy": white,
            "whitepoint_name": cs.whitepoint_name,
            "matrix_XYZ_to_RGB_no_adaptation": np.asarray(cs.matrix_XYZ_to_RGB, dtype=float),
            "matrix_RGB_to_XYZ_no_adaptation": np.asarray(cs.matrix_RGB_to_XYZ, dtype=float),
            "normalised_primary_matrix": np.asarray(npm, dtype=float),
            "cat_bradford_d65_to_white": np.asarray(cat_bradford, dtype=float),
            "cat_cat02_d65_to_white": np.asarray(cat_cat02, dtype=float),
            "matrix_XYZ_to_RGB_bradford_from_d65": np.asarray(cs.matrix_XYZ_to_RGB @ cat_bradford, dtype=float),
            "colours": converted,
        }

    out = {
        "generated_by": {
            "script": SCRIPT,
            "packages": {"python": "%d.%d" % sys.version_info[:2],
                         "colour-science": metadata.version("colour-science"),
                         "numpy": metadata.version("numpy")},
        },
        "notes": [
            "Row-major 3x3 matrices, rgb = M @ XYZ. XYZ is CIE 1931 2 degree, any absolute scale (the maps are linear).",
            "colour_name: the key into colour.RGB_COLOURSPACES. matrix_XYZ_to_RGB_no_adaptation is that colourspace's "
            "matrix_XYZ_to_RGB (for BT.709 and BT.2020 derived from the primaries and D65 (0.3127, 0.3290); for ACEScg "
            "the AP1 primaries and the ACES white (0.32168, 0.33767)). normalised_primary_matrix is "
            "colour.normalised_primary_matrix(primaries, whitepoint), RGB -> XYZ.",
            "cat_bradford_d65_to_white = colour.adaptation.matrix_chromatic_adaptation_VonKries(XYZ(D65), "
            "XYZ(whitepoint), transform='Bradford'), XYZ from xy with Y = 1, D65 = "
            "colour.CCS_ILLUMINANTS['CIE 1931 2 Degree Standard Observer']['D65']; identity for BT.709 and BT.2020. "
            "cat_cat02_d65_to_white: the same with CAT02 (colour's default), for comparison only.",
            "matrix_XYZ_to_RGB_bradford_from_d65 = matrix_XYZ_to_RGB_no_adaptation @ cat_bradford_d65_to_white: what "
            "sky uses (the data's adapted white is taken to be D65, so D65 maps to R = G = B).",
            "colours[*].RGB_bradford_from_d65 = colour.XYZ_to_RGB(XYZ, colourspace, illuminant=D65 xy, "
            "chromatic_adaptation_transform='Bradford'), no clamping, no transfer function (linear).",
        ],
        "spaces": spaces,
    }
    text = json.dumps(clean(out), sort_keys=True, indent=1, allow_nan=False) + "\n"
    OUT.write_text(text)
    print("wrote %s (%d bytes)" % (OUT.relative_to(ROOT), len(text)), file=sys.stderr)


if __name__ == "__main__":
    main()
