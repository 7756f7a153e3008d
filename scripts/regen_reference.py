#!/usr/bin/env python3
"""Regenerate the reference data in tests/reference/*.json.

Every number written here comes from an implementation that is independent of
sky (miepython, PyMieScatt, pyatmos, colour-science, the ASTM G173 table shipped
in pvlib), so the Rust tests can compare against them without Python.

    python3 -m venv .venv-ref
    .venv-ref/bin/pip install -r scripts/requirements-reference.txt
    .venv-ref/bin/python scripts/regen_reference.py

Output is deterministic: keys are sorted, floats are written with Python's
shortest round-trip repr (full double precision), -0.0 is written as 0.0.
Running the script twice gives identical bytes.
"""

import os

# Both must be set before the packages are imported.
# pyatmos downloads IERS Earth-orientation data at import time unless told not to.
os.environ["ENABLE_IERS_LOAD"] = "false"
# miepython 3.3 picks its numba backend from this variable. Fixed here so that the
# output does not depend on the caller's environment (the pure-Python backend
# agrees to ~1e-13 relative but is ~60x slower and not bit-identical).
os.environ["MIEPYTHON_USE_JIT"] = "1"

import hashlib
import io
import json
import math
import subprocess
import sys
import time
import warnings
import zipfile
from importlib import metadata
from pathlib import Path

import numpy as np

import miepython as mp

ROOT = Path(__file__).resolve().parent.parent
OUT_DIR = ROOT / "tests" / "reference"
CACHE_DIR = ROOT / ".cache" / "reference"
SCRIPT = "scripts/regen_reference.py"

ANGLES_DEG = [0, 0.05, 0.1, 0.5, 1, 2, 5, 10, 20, 30, 45, 60, 90, 120, 135, 150, 170, 179, 180]

K_B = 1.380649e-23  # J/K, exact (SI 2019)


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def versions(*dists):
    out = {"python": "%d.%d" % sys.version_info[:2]}
    for d in dists:
        out[d] = metadata.version(d)
    return out


def generated_by(*dists, extra=None):
    g = {"script": SCRIPT, "packages": versions(*dists)}
    if extra:
        g.update(extra)
    return g


def clean(obj):
    """Convert numpy scalars/arrays to plain Python, normalise -0.0, reject NaN/inf."""
    if isinstance(obj, dict):
        return {str(k): clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [clean(v) for v in obj.tolist()]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        if not math.isfinite(v):
            raise ValueError("non-finite value in reference output")
        return 0.0 if v == 0.0 else v
    return obj


def write_json(name, obj):
    text = json.dumps(clean(obj), sort_keys=True, indent=1, allow_nan=False) + "\n"
    path = OUT_DIR / name
    path.write_text(text)
    log("wrote %s (%d bytes)" % (path.relative_to(ROOT), len(text)))


def rel(a, b):
    """|a-b|/|b| (b is the reference)."""
    return abs(a - b) / abs(b) if b != 0 else abs(a - b)


# --------------------------------------------------------------------------
# 1. single-particle Mie (miepython)
# --------------------------------------------------------------------------

SINGLE_CASES = (
    [(1.33, -1e-7, x) for x in (0.01, 0.1, 1, 5, 10, 50, 100, 1000, 5000, 10000)]
    + [(1.5, 0.0, x) for x in (0.2, 3, 30)]
    + [(1.53, -0.006, x) for x in (0.5, 5, 50)]
    + [(1.75, -0.44, x) for x in (0.05, 0.5, 5, 50, 500, 2000)]
    + [(2.0, -1.0, x) for x in (1, 20)]
    + [(1.33, -0.01, 1000)]
)


def mie_amplitudes_bh(m, x, mu):
    """Unnormalised Bohren & Huffman S1, S2 (exp(-i w t) convention).

    miepython 3.3.0 S1_S2(norm='wiscombe') applies no scaling and returns the
    complex conjugate of the BH amplitudes (verified below against BH's a_n, b_n
    from miepython.coefficients and against PyMieScatt.MieS1S2), so conjugate.
    """
    s1, s2 = mp.S1_S2(m, x, mu, norm="wiscombe")
    return np.conj(s1), np.conj(s2)


def series_efficiencies(m, x):
    """qext, qsca from the full a_n, b_n series (bypasses the small-sphere branch)."""
    a, b = mp.coefficients(m, x)
    n = np.arange(1, len(a) + 1)
    qext = 2.0 / x**2 * np.sum((2 * n + 1) * (a.real + b.real))
    qsca = 2.0 / x**2 * np.sum((2 * n + 1) * (np.abs(a) ** 2 + np.abs(b) ** 2))
    return float(qext), float(qsca)


def mie_single():
    import PyMieScatt as ps

    mu = np.cos(np.radians(np.array(ANGLES_DEG, dtype=float)))
    cases = []
    worst_ot = 0.0
    worst_qb = 0.0
    worst_ps = 0.0
    for m_re, m_im, x in SINGLE_CASES:
        x = float(x)
        m = complex(m_re, -abs(m_im))
        qext, qsca, qback, g = (float(v) for v in mp.efficiencies_mx(m, x))
        s1, s2 = mie_amplitudes_bh(m, x, mu)
        small_branch = bool(m.real > 0 and abs(m) * x < 0.1)
        qext_ser, qsca_ser = series_efficiencies(m, x)
        # optical theorem (BH 4.76): qext = 4/x^2 Re S(0); S1(0) == S2(0)
        ot = rel(4.0 / x**2 * s1[0].real, qext)
        # BH 4.82 radar backscatter efficiency: qback = 4 |S1(180)|^2 / x^2
        qb = rel(4.0 / x**2 * abs(s1[-1]) ** 2, qback)
        worst_ot = max(worst_ot, ot)
        worst_qb = max(worst_qb, qb)
        case = {
            "m_re": m_re,
            "m_im": -abs(m_im),
            "x": x,
            "qext": qext,
            "qsca": qsca,
            "qback": qback,
            "g": g,
            "angles_deg": ANGLES_DEG,
            "s1_re": s1.real,
            "s1_im": s1.imag,
            "s2_re": s2.real,
            "s2_im": s2.imag,
            "efficiencies_from": "small_sphere_expansion" if small_branch else "full_series",
            "checks": {
                "optical_theorem_rel_err": ot,
                "qback_vs_s1_180_rel_err": qb,
                "qext_full_series": qext_ser,
                "qsca_full_series": qsca_ser,
            },
        }
        # independent sign/normalisation check of S against PyMieScatt (BH formulae)
        if x <= 1000:
            err = 0.0
            for i, mui in enumerate(mu):
                p1, p2 = ps.MieS1S2(complex(m_re, abs(m_im)), x, float(mui))
                scale = abs(s1[0])
                err = max(err, abs(p1 - s1[i]) / scale, abs(p2 - s2[i]) / scale)
            case["checks"]["pymiescatt_MieS1S2_max_abs_diff_over_abs_S0"] = err
            worst_ps = max(worst_ps, err)
        cases.append(case)
        log("mie_single m=%s x=%g qext=%.6g ot=%.1e qb=%.1e" % (m, x, qext, ot, qb))

    notes = [
        "Single homogeneous sphere in vacuum/air (medium index 1), from miepython 3.3.0 with its numba backend (MIEPYTHON_USE_JIT=1).",
        "Refractive index m = m_re + i*m_im with m_im <= 0, i.e. m = m_re - i*|m_im| (miepython convention: negative imaginary part = absorbing). "
        "The physical absorption index is k = |m_im|; in Bohren & Huffman (BH) notation the same material is m = m_re + i*k. "
        "x = 2*pi*r/wavelength (size parameter).",
        "qext, qsca, qback, g are miepython.efficiencies_mx(m, x). For m_im == 0 exactly miepython sets qsca = qext.",
        "qback is BH's radar backscattering efficiency (BH eq. 4.82 / 5.9 convention): qback = |sum_n (2n+1)(-1)^n (a_n - b_n)|^2 / x^2 "
        "= 4*|S1(180 deg)|^2 / x^2 = sigma_back/(pi r^2), sigma_back = 4*pi*dC_sca/dOmega(180). It is 4*pi times the per-steradian "
        "value, i.e. NOT |S1(180)|^2/x^2. Verified numerically for every case (checks.qback_vs_s1_180_rel_err; worst %.2e)." % worst_qb,
        "s1_*, s2_* are the UNNORMALISED BH amplitudes S1(theta), S2(theta) (BH eqs. 4.74, exp(-i*omega*t) time convention), "
        "S1 = sum_n (2n+1)/(n(n+1)) (a_n pi_n + b_n tau_n), S2 = sum_n (2n+1)/(n(n+1)) (a_n tau_n + b_n pi_n), "
        "so that C_sca = (1/k^2) * integral over 4pi of (|S1|^2+|S2|^2)/2 dOmega and the optical theorem qext = 4/x^2 * Re S(0) holds "
        "(checks.optical_theorem_rel_err; worst %.2e)." % worst_ot,
        "miepython 3.3.0 normalisation options (miepython.core.normalization_factor): the raw series is divided by a factor; "
        "norm='wiscombe' -> factor 1 (unnormalised BH magnitudes, used here); norm='bohren' -> factor 1/2, i.e. it returns 2*S_BH "
        "(NOT the BH amplitudes despite the name: with it Re S(0) = x^2 qext/2); the default norm='albedo' -> factor x*sqrt(pi*qext).",
        "SIGN: miepython.S1_S2 returns the COMPLEX CONJUGATE of the BH amplitudes (its a_n, b_n from miepython.coefficients equal BH's, "
        "but S1_S2 conjugates the sum). The arrays here are conj(miepython) = BH convention, e.g. for small dielectric spheres "
        "S(0) ~ -i x^3 (m^2-1)/(m^2+2): Im S(0) < 0, Re S(0) > 0. |S|^2, Re S and every efficiency are unaffected by the conjugation. "
        "Cross-checked against PyMieScatt 1.8.1.1 MieS1S2 (plain BH formulae, m = m_re + i|m_im|) for x <= 1000: "
        "max |S_pymiescatt - S_here| / |S(0)| = %.2e (checks.pymiescatt_MieS1S2_max_abs_diff_over_abs_S0), i.e. the same sign "
        "convention. The larger per-case differences are PyMieScatt's, not miepython's: for x < 0.5 PyMieScatt uses a two-term "
        "low-frequency expansion of a_n, b_n (up to ~1e-4 at x=0.2), and for weakly absorbing large spheres its downward D_n "
        "recurrence starts only at max(n_max, |m x|)+16, too low (water x=1000: a_n off by up to 0.09 at high orders, while a "
        "converged recurrence started 100+ orders higher agrees with miepython's a_n to 4e-11)." % worst_ps,
        "At theta = 0 and 180 deg, S1 = S2 and S1 = -S2 respectively.",
        "efficiencies_from: miepython uses Wiscombe's small-sphere expansion (not the series) for qext/qsca/qback/g when |m|*x < 0.1 "
        "(here water x=0.01 and soot x=0.05); S1/S2 always come from the full series. checks.qext_full_series / qsca_full_series "
        "give the series values (2/x^2 sum (2n+1) Re(a_n+b_n), 2/x^2 sum (2n+1)(|a_n|^2+|b_n|^2)) for comparison.",
        "Series length is miepython's (Wiscombe) n_max ~ x + 4.05 x^(1/3) + 2.",
    ]
    return {
        "generated_by": generated_by("miepython", "numba", "numpy", "PyMieScatt",
                                     extra={"miepython_backend": "numba (MIEPYTHON_USE_JIT=1)"}),
        "notes": notes,
        "angles_deg": ANGLES_DEG,
        "cases": cases,
    }


# --------------------------------------------------------------------------
# 2. log-normal bulk optics (own trapezoid integration of miepython)
# --------------------------------------------------------------------------

LOGNORMAL_CASES = [
    # name, wavelength nm, m_re, m_im, r_med um, sigma (=ln GSD)
    ("water_fine", 550.0, 1.33, -1e-7, 0.12, 0.45),
    ("water_coarse_450", 450.0, 1.33, -1e-7, 4.0, 0.55),
    ("water_coarse_650", 650.0, 1.33, -1e-7, 4.0, 0.55),
    ("opac_water_soluble", 550.0, 1.53, -0.006, 0.0212, math.log(2.24)),
    ("opac_soot", 550.0, 1.75, -0.44, 0.0118, math.log(2.0)),
    ("mineral_coarse", 550.0, 1.53, -0.0055, 1.90, math.log(2.15)),
    ("cloud_droplets", 550.0, 1.33, -1e-7, 6.0, 0.35),
]

N0_INTERVALS = 1024
MIN_LEVELS = 3  # at least 1024 -> 2048 -> 4096 -> 8192 intervals
MAX_INTERVALS = 1 << 20
CONV_TARGET = 1e-4  # last doubling must change every output by < 0.01% ...
CONV_PREV = 5e-4  # ... and the doubling before it by < 0.05%
CONV_REQUIRED = 5e-4  # hard failure if the last doubling changed anything by more


def lognormal_integrate(wl_nm, m, r_med, sigma):
    lam = wl_nm * 1e-3
    k = 2.0 * math.pi / lam
    u0 = math.log(r_med)
    ua = u0 - 6.0 * sigma
    ub = u0 + 4.0 * sigma**2 + 6.0 * sigma
    mu = np.cos(np.radians(np.array(ANGLES_DEG, dtype=float)))
    n_out = 3 + len(ANGLES_DEG)
    cache = np.full((MAX_INTERVALS + 1, n_out), np.nan)
    have = np.zeros(MAX_INTERVALS + 1, dtype=bool)

    def point(u):
        r = math.exp(u)
        x = k * r
        qext, qsca, _qb, g = mp.efficiencies_mx(m, x)
        s1, s2 = mp.S1_S2(m, x, mu, norm="wiscombe")
        iavg = 0.5 * (np.abs(s1) ** 2 + np.abs(s2) ** 2)
        w = math.exp(-((u - u0) ** 2) / (2 * sigma**2)) / (math.sqrt(2 * math.pi) * sigma)
        area = math.pi * r * r
        return np.concatenate(([qext * area * w, qsca * area * w, g * qsca * area * w], iavg * w))

    def integrate(n_int):
        step = MAX_INTERVALS // n_int
        h = (ub - ua) / n_int
        keys = np.arange(n_int + 1) * step
        for key in keys[~have[keys]]:
            cache[key] = point(ua + (ub - ua) * key / MAX_INTERVALS)
            have[key] = True
        f = cache[keys]
        tot = h * (f.sum(axis=0) - 0.5 * (f[0] + f[-1]))
        cext, csca, gcsca = tot[0], tot[1], tot[2]
        phase = tot[3:] / (k * k * csca)
        return {
            "c_ext_um2": float(cext),
            "c_sca_um2": float(csca),
            "ssa": float(csca / cext),
            "g": float(gcsca / csca),
            "phase_sr_inv": phase,
        }

    def flat(res):
        return np.concatenate(([res["c_ext_um2"], res["c_sca_um2"], res["ssa"], res["g"]], res["phase_sr_inv"]))

    n_int = N0_INTERVALS
    prev = integrate(n_int)
    history = []
    level = 0
    while True:
        n_int *= 2
        level += 1
        cur = integrate(n_int)
        a, b = flat(cur), flat(prev)
        d = np.abs(a - b) / np.abs(a)
        history.append(float(d.max()))
        prev = cur
        done = level >= MIN_LEVELS and history[-1] < CONV_TARGET and history[-2] < CONV_PREV
        if done or n_int >= MAX_INTERVALS:
            break
    if history[-1] >= CONV_REQUIRED:
        raise RuntimeError("log-normal integration did not converge: %r" % history)
    names = ["c_ext_um2", "c_sca_um2", "ssa", "g"] + ["phase_sr_inv[%g deg]" % a for a in ANGLES_DEG]
    conv = {
        "ln_r_min": ua,
        "ln_r_max": ub,
        "n_points": n_int + 1,
        "max_rel_change_last_doubling": history[-1],
        "worst_output_last_doubling": names[int(np.argmax(d))],
        "max_rel_change_per_doubling": history,
        "x_min": k * math.exp(ua),
        "x_max": k * math.exp(ub),
        "reached_target": bool(history[-1] < CONV_TARGET and history[-2] < CONV_PREV),
        "rel_change_last_doubling": {
            "c_ext_um2": float(d[0]),
            "c_sca_um2": float(d[1]),
            "ssa": float(d[2]),
            "g": float(d[3]),
            "phase_sr_inv": d[4:],
        },
    }
    return cur, conv


def pymiescatt_lognormal(wl_nm, m_re, m_im, r_med, sigma, lower_nm=None, upper_nm=None):
    import PyMieScatt as ps

    kw = {}
    if lower_nm is not None:
        kw = {"lower": lower_nm, "upper": upper_nm}
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        res = ps.Mie_Lognormal(complex(m_re, abs(m_im)), float(wl_nm), float(math.exp(sigma)),
                               float(2000.0 * r_med), 1.0, asDict=True, **kw)
    msgs = sorted({str(x.message) for x in w if "distribution may not be compact" in str(x.message)})
    return res, msgs


def mie_lognormal():
    cases = []
    worst_conv = 0.0
    for name, wl, m_re, m_im, r_med, sigma in LOGNORMAL_CASES:
        m = complex(m_re, -abs(m_im))
        t = time.time()
        res, conv = lognormal_integrate(wl, m, r_med, sigma)
        worst_conv = max(worst_conv, conv["max_rel_change_last_doubling"])
        log("lognormal %s: %d points, last doubling %.2e, %.1fs" % (
            name, conv["n_points"], conv["max_rel_change_last_doubling"], time.time() - t))
        case = {
            "name": name,
            "wavelength_nm": wl,
            "m_re": m_re,
            "m_im": -abs(m_im),
            "median_radius_um": r_med,
            "sigma": sigma,
            "angles_deg": ANGLES_DEG,
            "integration": conv,
        }
        case.update(res)

        sub = {
            "call": "PyMieScatt.Mie_Lognormal(m=%r, wavelength=%r, geoStdDev=exp(sigma)=%r, geoMean=2000*r_med=%r nm, "
                    "numberOfParticles=1, asDict=True, ...)" % (complex(m_re, abs(m_im)), wl, math.exp(sigma), 2000.0 * r_med),
        }
        grids = [("default_grid", None, None)]
        lo_nm = 2000.0 * math.exp(conv["ln_r_min"])
        hi_nm = 2000.0 * math.exp(conv["ln_r_max"])
        grids.append(("matched_range", lo_nm, hi_nm))
        for label, lo, hi in grids:
            t = time.time()
            pr, msgs = pymiescatt_lognormal(wl, m_re, m_im, r_med, sigma, lo, hi)
            p_cext, p_csca, p_g = float(pr["Bext"]), float(pr["Bsca"]), float(pr["bigG"])
            p_ssa = p_csca / p_cext
            sub[label] = {
                "lower_nm": 1.0 if lo is None else lo,
                "upper_nm": 1000.0 if hi is None else hi,
                "number_of_bins": 10000,
                "c_ext_um2": p_cext,
                "c_sca_um2": p_csca,
                "ssa": p_ssa,
                "g": p_g,
                "rel_diff": {
                    "c_ext_um2": (p_cext - res["c_ext_um2"]) / res["c_ext_um2"],
                    "c_sca_um2": (p_csca - res["c_sca_um2"]) / res["c_sca_um2"],
                    "ssa": (p_ssa - res["ssa"]) / res["ssa"],
                    "g": (p_g - res["g"]) / res["g"],
                },
                "warnings": msgs,
            }
            log("  pymiescatt %s: cext %.4g (%.2e) csca %.4g g %.4g (%.2e) %.1fs" % (
                label, p_cext, sub[label]["rel_diff"]["c_ext_um2"], p_csca, p_g,
                sub[label]["rel_diff"]["g"], time.time() - t))
        sub["assessment"] = pymiescatt_assessment(sub)
        case["pymiescatt"] = sub
        cases.append(case)

    # phase-function normalisation check on single particles (Gauss-Legendre in mu)
    gl_mu, gl_w = np.polynomial.legendre.leggauss(4000)
    norm_err = 0.0
    for m, x in [(1.33 - 1e-7j, 5.0), (1.53 - 0.006j, 50.0), (1.75 - 0.44j, 0.5)]:
        s1, s2 = mp.S1_S2(m, x, gl_mu, norm="wiscombe")
        _qe, qs, _qb, _g = mp.efficiencies_mx(m, x)
        integral = 2 * math.pi * np.sum(gl_w * 0.5 * (np.abs(s1) ** 2 + np.abs(s2) ** 2))
        norm_err = max(norm_err, rel(integral, math.pi * x * x * qs))

    notes = [
        "Bulk optics of a log-normal NUMBER size distribution n(r) = N/(sqrt(2 pi) sigma r) exp(-(ln r - ln r_med)^2/(2 sigma^2)), "
        "sigma = ln(GSD) (the field 'sigma' is already the natural log), r = sphere radius, medium index 1.",
        "Single-particle values from miepython 3.3.0 (numba backend): qext, qsca, g from efficiencies_mx, unnormalised amplitudes "
        "from S1_S2(norm='wiscombe'); m passed as m_re - i|m_im| (miepython convention, see mie_single.json). Integrated here with numpy.",
        "Integration: trapezoid rule in u = ln r on a uniform grid over [ln r_med - 6 sigma, ln r_med + 4 sigma^2 + 6 sigma] "
        "(integration.ln_r_min/ln_r_max, r in um). Not renormalised for the truncated tails (missing number fraction ~1e-9).",
        "c_ext_um2, c_sca_um2 = mean cross-section per particle in um^2 = int C(r) n(r) dr / N. ssa = c_sca/c_ext. "
        "g = int g(r) C_sca(r) n dr / int C_sca n dr.",
        "phase_sr_inv(theta) = int (|S1|^2+|S2|^2)/2 n dr / (k^2 int C_sca n dr), k = 2 pi / wavelength: the bulk phase function "
        "normalised to integral over the sphere = 1 (units 1/sr; isotropic = 1/(4 pi)). Single-particle check of that normalisation "
        "(Gauss-Legendre 4000 nodes, int (|S1|^2+|S2|^2)/2 dOmega = pi x^2 qsca): worst rel err %.1e." % norm_err,
        "Convergence: the grid starts at %d intervals and is doubled (nested, reusing points) at least %d times, until one doubling "
        "changes EVERY output (c_ext, c_sca, ssa, g and the phase function at every listed angle) by < %.0e relative and the "
        "doubling before it by < %.0e, or %d intervals are reached (integration.reached_target false); the script fails if the "
        "last doubling changed anything by >= %.0e. integration.max_rel_change_per_doubling lists every doubling and "
        "integration.rel_change_last_doubling the last doubling's change per output (use it for per-output tolerances); reported "
        "values are from the finest grid. Worst last-doubling change over all cases: %.2e. The slowly converging outputs are the "
        "near-backscatter phase values of the weakly absorbing (k=1e-7) water cases, whose integrands carry very narrow "
        "morphology-dependent resonances." % (N0_INTERVALS, MIN_LEVELS, CONV_TARGET, CONV_PREV, MAX_INTERVALS,
                                             CONV_REQUIRED, worst_conv),
        "pymiescatt: cross-check with PyMieScatt 1.8.1.1 Mie_Lognormal (its own Mie code; m = m_re + i|m_im|; geoMean = median "
        "DIAMETER in nm = 2000*r_med; geoStdDev = GSD = exp(sigma); wavelength in nm; numberOfParticles = 1 cm^-3 so that its "
        "Bext/Bsca in Mm^-1 equal the mean cross-section in um^2). It integrates with trapz over numberOfBins=10000 diameters "
        "log-spaced in [lower, upper] nm. 'default_grid' uses its defaults lower=1 nm, upper=1000 nm, which truncates every "
        "distribution with appreciable cross-section above 1 um diameter; 'matched_range' passes lower/upper equal to the range "
        "used here. rel_diff = (pymiescatt - here)/here. See each case's pymiescatt.assessment.",
        "PyMieScatt uses the Rayleigh approximation for x < 0.01 (qsca = 8/3 x^4 |LL|^2, qabs = 4x Im LL, g = 0) instead of the series.",
    ]
    return {
        "generated_by": generated_by("miepython", "numba", "numpy", "PyMieScatt", "scipy",
                                     extra={"miepython_backend": "numba (MIEPYTHON_USE_JIT=1)"}),
        "notes": notes,
        "angles_deg": ANGLES_DEG,
        "cases": cases,
    }


def pymiescatt_assessment(sub):
    d = sub["default_grid"]["rel_diff"]
    mt = sub["matched_range"]["rel_diff"]
    dmax = max(abs(v) for v in d.values())
    mmax = max(abs(v) for v in mt.values())
    if dmax > 1e-4 and mmax < 0.1 * dmax:
        s = ("default grid differs by up to %.2e; with the integration range matched the difference drops to %.2e: "
             "the default-grid difference is caused by PyMieScatt's fixed default integration grid (10000 log-spaced "
             "diameters over 1..1000 nm)" % (dmax, mmax))
    else:
        s = "default grid max |rel diff| %.2e, matched range %.2e" % (dmax, mmax)
    if mmax > 1e-3:
        s += "; matched-range difference above 1e-3 remains (PyMieScatt's 10000-bin trapz over a wide range / its own Mie numerics)"
    return s


# --------------------------------------------------------------------------
# 3. U.S. Standard Atmosphere 1976 (pyatmos)
# --------------------------------------------------------------------------

def us76_strict(z_km):
    """Own minimal US76 (r0 = 6356.766 km), molecular-scale temperature; only used to quantify pyatmos deviations in notes."""
    r0 = 6356.766
    g0, rstar, m0 = 9.80665, 8314.32, 28.9644
    hb = [0.0, 11.0, 20.0, 32.0, 47.0, 51.0, 71.0, 84.8520]
    lb = [-6.5, 0.0, 1.0, 2.8, 0.0, -2.8, -2.0]
    h = r0 * z_km / (r0 + z_km)
    t, p = 288.15, 101325.0
    for i in range(7):
        top = hb[i + 1]
        hh = min(h, top) if i < 6 else h
        dh = hh - hb[i]
        if lb[i] == 0:
            p2 = p * math.exp(-g0 * m0 * dh * 1e3 / (rstar * t))
            t2 = t
        else:
            t2 = t + lb[i] * dh
            p2 = p * (t2 / t) ** (-g0 * m0 / (rstar * lb[i] * 1e-3))
        t, p = t2, p2
        if h <= top:
            break
    return t, p


def us1976():
    from pyatmos import coesa76

    alts = sorted([float(z) for z in range(0, 87)] + [0.5, 10.5, 47.3, 79.9])
    r = coesa76(alts)
    T = np.asarray(r.T, dtype=float)
    P = np.asarray(r.P, dtype=float)
    rho = np.asarray(r.rho, dtype=float)
    n = P / (K_B * T)

    dt = dp = 0.0
    for z, t, p in zip(alts, T, P):
        ts, pstrict = us76_strict(z)
        dt = max(dt, rel(t, ts))
        dp = max(dp, rel(p, pstrict))
    notes = [
        "pyatmos 1.2.7 coesa76(altitude_km, alt_type='geometric'); imported with ENABLE_IERS_LOAD=false. Altitudes are GEOMETRIC km, "
        "0..86 every 1 km plus 0.5, 10.5, 47.3, 79.9, sorted ascending.",
        "temperature_k is the MOLECULAR-SCALE temperature T_M of US76 (pyatmos ussa76 applies the 7 lapse-rate layers below 86 km "
        "with no M/M0 correction). Below 80 km T_M equals the kinetic temperature; between 80 and 86 km the kinetic temperature is "
        "T = T_M * M/M0 with M/M0 falling from 1 to 0.999579 at 86 km (US76 at 86 km: T_M = 186.946 K, kinetic T = 186.8673 K, "
        "the constant pyatmos itself uses just above 86 km; pyatmos gives T_M(86 km) = 186.941 K because of its Earth radius, "
        "see CAVEAT). So temperature_k is up to 0.042% above the kinetic temperature between 80 and 86 km.",
        "pressure_pa from the hydrostatic layer formulas with g0 = 9.80665, R* = 8314.32 J/(kmol K), M0 = 28.9644 kg/kmol; "
        "density_kg_m3 = P * M0 / (R* T_M) (exact US76 relation, correct also above 80 km).",
        "number_density_m3 = pressure_pa / (k_B * temperature_k) with k_B = 1.380649e-23 J/K and the pyatmos temperature (T_M). "
        "Above 80 km this is the 'molecular-scale' number density; the true US76 total number density P/(k_B T_kinetic) is larger "
        "by M0/M (up to +0.042% at 86 km). Note also US76 itself uses N_A = 6.022169e26 /kmol, i.e. k = R*/N_A = 1.380619e-23, "
        "so the US76-consistent rho*N_A/M0 = P/(k T_M) is 2.2e-5 relative larger than number_density_m3.",
        "CAVEAT: pyatmos converts geometric to geopotential altitude with Earth radius R0 = 6371.0008 km, not the US76 value "
        "r0 = 6356.766 km. Against a strict US76 evaluation (r0 = 6356.766 km) this changes temperature by at most %.2e relative "
        "and pressure by at most %.2e relative over 0..86 km (largest at the top). Allow for that in tolerances." % (dt, dp),
    ]
    return {
        "generated_by": generated_by("pyatmos", "numpy", "setuptools"),
        "notes": notes,
        "altitude_km": alts,
        "temperature_k": T,
        "pressure_pa": P,
        "density_kg_m3": rho,
        "number_density_m3": n,
        "k_b_j_per_k": K_B,
    }


# --------------------------------------------------------------------------
# 4. colour-science
# --------------------------------------------------------------------------

PVLIB_VERSION = "0.16.1"


def astm_g173_csv():
    CACHE_DIR.mkdir(parents=True, exist_ok=True)
    wheels = sorted(CACHE_DIR.glob("pvlib-%s-*.whl" % PVLIB_VERSION))
    if not wheels:
        log("downloading pvlib==%s wheel (no deps) to %s" % (PVLIB_VERSION, CACHE_DIR))
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
                        "pvlib==%s" % PVLIB_VERSION, "-d", str(CACHE_DIR)], check=True,
                       stdout=subprocess.DEVNULL)
        wheels = sorted(CACHE_DIR.glob("pvlib-%s-*.whl" % PVLIB_VERSION))
    whl = wheels[0]
    with zipfile.ZipFile(whl) as z:
        raw = z.read("pvlib/data/ASTMG173.csv")
    return whl.name, raw


def colour_data():
    import colour

    warnings.filterwarnings("ignore")
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    shape_1nm = colour.SpectralShape(360, 830, 1)
    assert cmfs.shape == shape_1nm, cmfs.shape
    wl5 = np.arange(360, 831, 5)
    xyz5 = cmfs[wl5]
    wl1 = np.arange(360, 831, 1)
    cmf1 = cmfs.values

    whl_name, raw = astm_g173_csv()
    lines = raw.decode("ascii").splitlines()
    assert lines[1].startswith("wavelength,extraterrestrial"), lines[:2]
    etr = {}
    for line in lines[2:]:
        f = line.split(",")
        w = float(f[0])
        if 360 <= w <= 830 and w == int(w):
            etr[int(w)] = float(f[1])
    assert sorted(etr) == list(range(360, 831))
    E = np.array([etr[w] for w in range(360, 831)])
    sd = colour.SpectralDistribution(E, wl1, name="ASTM G173-03 ETR")

    xyz_int = np.asarray(colour.sd_to_XYZ(sd, cmfs, method="Integration", k=1), dtype=float)
    xyz_sum = E @ cmf1  # plain sum, d_lambda = 1 nm
    xyz_e308 = np.asarray(colour.sd_to_XYZ(sd, cmfs), dtype=float)
    xyz_e308_k1 = np.asarray(colour.sd_to_XYZ(sd, cmfs, method="ASTM E308", k=1), dtype=float)

    def xy(v):
        return np.asarray(colour.XYZ_to_xy(v), dtype=float)

    def chrom(sd_in, label):
        s = sd_in.copy().align(shape_1nm)
        X = np.asarray(colour.sd_to_XYZ(s, cmfs, method="Integration", k=1), dtype=float)
        return {"XYZ_integration_k1": X, "xy": xy(X), "source": label}

    ee = colour.sd_ones(shape_1nm)
    d65 = colour.SDS_ILLUMINANTS["D65"]
    bb = colour.sd_blackbody(5778, shape_1nm)

    srgb = colour.RGB_COLOURSPACES["sRGB"]
    derived = np.linalg.inv(colour.normalised_primary_matrix(srgb.primaries, srgb.whitepoint))

    astm = {
        "source": "pvlib %s wheel %s, file pvlib/data/ASTMG173.csv (ASTM G173-03, column 'extraterrestrial', W m^-2 nm^-1), "
                  "sha256 %s" % (PVLIB_VERSION, whl_name, hashlib.sha256(raw).hexdigest()),
        "wavelength_nm": wl1,
        "etr_w_m2_nm": E,
        "XYZ_integration_k1": xyz_int,
        "xy_integration_k1": xy(xyz_int),
        "XYZ_plain_numpy_sum": xyz_sum,
        "XYZ_astm_e308_default": xyz_e308,
        "xy_astm_e308_default": xy(xyz_e308),
        "XYZ_astm_e308_k1": xyz_e308_k1,
    }
    notes = [
        "colour-science 0.4.7. CMFs: colour.MSDS_CMFS['CIE 1931 2 Degree Standard Observer'] (CIE 1931 2 deg, CVRL 1 nm table, "
        "native shape 360..830 nm step 1). cmf_* arrays are that table sampled at 360..830 every 5 nm (exact table values, "
        "no interpolation).",
        "astm_g173_etr: the ASTM G173-03 extraterrestrial spectrum restricted to its integer wavelengths 360..830 nm (the file is "
        "0.5 nm spaced below 400 nm and 1 nm above; only integer-nm rows are used, so the grid is a uniform 1 nm). etr_w_m2_nm holds "
        "the exact values used.",
        "XYZ_integration_k1 = colour.sd_to_XYZ(sd, cmfs, method='Integration', k=1). In colour 0.4.7 that is "
        "XYZ = k * sum_l R(l) S(l) cmf(l) d_l / 100 with S = illuminant E = 100.0 (default) and d_l = 1 nm, so the /100 "
        "(applied whenever k is given) cancels and it is the PLAIN SUM sum_l E(l) cmf(l) * 1 nm, in W m^-2 (CMF-weighted, "
        "no 683 lm/W). XYZ_plain_numpy_sum is the same sum done directly with numpy (agrees to rounding).",
        "XYZ_astm_e308_default = colour.sd_to_XYZ(sd, cmfs) with all defaults: method 'ASTM E308', illuminant E, k=None, "
        "use_practice_range=True. For 1 nm data this trims the CMFs to the ASTM E308 practice range 360..780 nm and then does the "
        "same summation with k = 100 / sum(ybar * S): a RELATIVE result, XYZ = 100 * sum_360^780 E cmf / sum_360^780 ybar "
        "(units of E, i.e. W m^-2 nm^-1 times 100). XYZ_astm_e308_k1 is method 'ASTM E308' with k=1: plain sum over 360..780 only.",
        "chromaticities: each spectrum aligned to 360..830 nm step 1 with colour's SpectralDistribution.align defaults, then "
        "colour.sd_to_XYZ(method='Integration', k=1) and colour.XYZ_to_xy. equal_energy = colour.sd_ones (constant 1). "
        "d65 = colour.SDS_ILLUMINANTS['D65'], which colour ships at 300..780 nm step 5: align() interpolates with the Sprague "
        "interpolator (CIE 167:2005, uniform data) and extrapolates 780..830 by holding the 780 nm value constant. "
        "blackbody_5778k = colour.sd_blackbody(5778, shape) (Planck with c1 = 3.741771e-16 W m^2, c2 = 1.4388e-2 m K, n = 1).",
        "srgb: matrix_XYZ_to_RGB = colour.RGB_COLOURSPACES['sRGB'].matrix_XYZ_to_RGB, i.e. what colour uses for XYZ -> LINEAR sRGB "
        "(XYZ scaled so that Y = 1 is white). In 0.4.7 this is the IEC 61966-2-1 published 4-decimal matrix "
        "(use_derived_matrix_XYZ_to_RGB = False), not the one derived from the primaries; the derived one (inverse of "
        "colour.normalised_primary_matrix(primaries, whitepoint), whitepoint xy = (0.3127, 0.3290)) is given as "
        "matrix_XYZ_to_RGB_derived_from_primaries. Row-major, rgb = M @ XYZ.",
    ]
    return {
        "generated_by": generated_by("colour-science", "numpy",
                                     extra={"astm_g173_source": "pvlib==%s wheel via pip download --no-deps" % PVLIB_VERSION}),
        "notes": notes,
        "cmf_wavelength_nm": wl5,
        "x_bar": xyz5[:, 0],
        "y_bar": xyz5[:, 1],
        "z_bar": xyz5[:, 2],
        "astm_g173_etr": astm,
        "chromaticity": {
            "equal_energy": chrom(ee, "colour.sd_ones(SpectralShape(360, 830, 1))"),
            "d65": chrom(d65, "colour.SDS_ILLUMINANTS['D65'] aligned to 360..830 step 1"),
            "blackbody_5778k": chrom(bb, "colour.sd_blackbody(5778, SpectralShape(360, 830, 1))"),
            "d65_colour_ccs_constant_xy": np.asarray(
                colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"], dtype=float),
        },
        "srgb": {
            "matrix_XYZ_to_RGB": np.asarray(srgb.matrix_XYZ_to_RGB, dtype=float),
            "matrix_RGB_to_XYZ": np.asarray(srgb.matrix_RGB_to_XYZ, dtype=float),
            "matrix_XYZ_to_RGB_derived_from_primaries": derived,
            "primaries_xy": np.asarray(srgb.primaries, dtype=float),
            "whitepoint_xy": np.asarray(srgb.whitepoint, dtype=float),
        },
    }


def main():
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    only = set(sys.argv[1:])
    jobs = [
        ("mie_single.json", mie_single),
        ("us1976.json", us1976),
        ("colour.json", colour_data),
        ("mie_lognormal.json", mie_lognormal),
    ]
    for name, fn in jobs:
        if only and name.split(".")[0] not in only:
            continue
        t = time.time()
        data = fn()
        write_json(name, data)
        log("%s done in %.1fs" % (name, time.time() - t))


if __name__ == "__main__":
    main()
