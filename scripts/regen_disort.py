#!/usr/bin/env python3
"""Regenerate tests/reference/disort.json and tests/atmospheres/data/slab_rayleigh_cross_section.csv.

Reference sky radiances from DISORT (PythonicDISORT, pure Python) for the two plane-parallel test
atmospheres tests/atmospheres/disort_rayleigh.toml and tests/atmospheres/disort_rayleigh_hg.toml,
so that the Monte Carlo renderer can be compared against them without Python.

    python3 -m venv .venv-disort
    .venv-disort/bin/pip install -r scripts/requirements-disort.txt
    .venv-disort/bin/python scripts/regen_disort.py

The cloud-slab references (tests/reference/disort_clouds.json, multi-layer) come from the sibling
scripts/regen_disort_clouds.py, which imports this module's constants and helpers.

Both test atmospheres have the same composition at every height (one exponential profile shared
by the air and the aerosol), so optically each is a single homogeneous layer of total optical depth
tau = tau_R + tau_A, single-scattering albedo omega = (tau_R + ssa_A tau_A) / tau and phase-function
Legendre moments chi_l = (tau_R chi_l^R + ssa_A tau_A g^l) / (tau_R + ssa_A tau_A), where Rayleigh
with zero depolarisation has chi_0 = 1, chi_2 = 1/10 and all others 0 (normalisation: p(cos) =
sum_l (2l+1) chi_l P_l(cos), integrating to 4 pi over the sphere; Henyey-Greenstein has chi_l = g^l).

Method. PythonicDISORT solves the discrete-ordinate equations and gives the intensity only at its
Gauss quadrature nodes (its `subroutines.interpolate` interpolates polynomially in mu, which is
poor for optically thin layers). The radiances at the requested view angles are therefore obtained
as Stamnes' Fortran DISORT does at user angles: by integrating the source function along the line
of sight,
    I(tau*, -mu, phi) = int_0^tau* J(t, -mu, phi) exp(-(tau* - t)/mu) dt/mu,
with J = omega/(4 pi) [F0 p(cos Theta0) exp(-t/mu0) + int p I_DO dOmega'], where I_DO is
PythonicDISORT's diffuse solution at its nodes (the angular integral is its own Gauss quadrature
in mu' and an exact trapezoid rule in phi'; the depth integral is Gauss-Legendre). The single-
scattering (beam) term is integrated analytically with the exact phase function. At the
quadrature nodes this reproduces PythonicDISORT's own intensities (checked below, printed as
`node_consistency`).

Conventions (PythonicDISORT 1.8, checked here): mu > 0 is UPWARD propagation; tau = 0 at the top;
the beam propagates in the direction (mu, phi) = (-mu0, phi0) and carries the flux I0 through a
surface normal to it (direct flux on a horizontal plane = I0 mu0 exp(-tau/mu0)); the scattering
angle is between directions of propagation; a scalar Lambertian BDRF mode equals the albedo.
A viewer on the ground looking up at view zenith theta_v and relative azimuth phi_r (0 = toward the
sun's azimuth) receives the photons propagating in the direction (mu, phi) = (-cos theta_v,
phi0 + phi_r): looking toward the sun (theta_v = theta0, phi_r = 0) is forward scattering.

Output is deterministic: keys sorted, floats rounded to 9 significant digits; BLAS threads are
fixed to 1. Running the script twice gives identical bytes.
"""

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import json
import math
import sys
import warnings
from importlib import metadata
from pathlib import Path

import numpy as np
from numpy.polynomial.legendre import legval

from PythonicDISORT import pydisort, subroutines

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = "scripts/regen_disort.py"
CSV_REL = "tests/atmospheres/data/slab_rayleigh_cross_section.csv"
JSON_REL = "tests/reference/disort.json"

# The test atmospheres (must match the TOML files).
N0_M3 = 2.5e25          # air.number_density_m3
SCALE_HEIGHT_M = 8000.0  # profile scale_height_km = 8
TOP_KM = 100.0
N_COLUMN_M2 = N0_M3 * SCALE_HEIGHT_M * (1.0 - math.exp(-TOP_KM / 8.0))
GROUND_ALBEDO = 0.3
HG_G = 0.7
HG_SSA = 0.9
HG_TAU550 = 0.2
HG_ANGSTROM = 1.3
# PythonicDISORT refuses omega = 1. At omega = 1 - 1e-8 its conservative-limit solution is ill-
# conditioned (intensities at its own grazing nodes miss the transfer equation by 1.6e-3 relative at
# 64 streams, 1.4e-2 at 128); at 1 - 1e-6 by < 2e-5, while the radiances differ from omega = 1 by
# ~1e-6 relative (estimated below from omega = 1 - 1e-5).
RAYLEIGH_OMEGA = 1.0 - 1e-6

CASES = [
    ("tests/atmospheres/disort_rayleigh.toml", False),
    ("tests/atmospheres/disort_rayleigh_hg.toml", True),
]
WAVELENGTHS_NM = [450.0, 550.0, 650.0]
CSV_WAVELENGTHS_NM = [400 + 10 * i for i in range(31)]

SUN_ZENITH_DEG = 60.0
MU0 = 0.5
F0 = 1.0
VIEW_ZENITH_DEG = [0, 10, 20, 30, 40, 50, 60, 70, 80, 85]
REL_AZIMUTH_DEG = [0, 30, 60, 90, 120, 150, 180]

NQUAD = 64              # final stream count
NQUAD_CHECK = (32, 128)  # convergence: half and double
NFOURIER_MAX = 64       # PythonicDISORT warns above 64 Fourier modes
NT = 64                 # Gauss-Legendre nodes in depth for the source-function integral
NT_CHECK = 128
SIG = 9                 # significant digits written


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def rnd(x, sig=SIG):
    x = float(x)
    if x == 0.0:
        return 0.0
    return float(f"{x:.{sig - 1}e}")


def bodhaine_tau(l_nm):
    """Bodhaine et al. (1999) eq. 30: sea-level Rayleigh optical depth, l in um."""
    l = l_nm / 1000.0
    return 0.0021520 * (1.0455996 - 341.29061 * l**-2 - 0.90230850 * l**2) / (
        1.0 + 0.0027059889 * l**-2 - 85.968563 * l**2
    )


def write_cross_section_csv():
    lines = [
        "# Rayleigh cross-section for the DISORT test slabs (tests/atmospheres/disort_rayleigh*.toml)",
        "# source: chosen so that sigma * N equals the Bodhaine et al. (1999) eq. 30 sea-level Rayleigh optical depth,",
        "#   tau(l) = 0.0021520 (1.0455996 - 341.29061 l^-2 - 0.90230850 l^2) / (1 + 0.0027059889 l^-2 - 85.968563 l^2), l in um",
        "# column: N = 2.5e25 m^-3 * 8000 m * (1 - exp(-100/8)) = %.10e m^-2 (exponential profile, 8 km scale height, top 100 km)"
        % N_COLUMN_M2,
        "# units: wavelength_nm in nm; cross_section_cm2 in cm^2 per molecule",
        "# regenerate: .venv-disort/bin/python scripts/regen_disort.py",
        "wavelength_nm,cross_section_cm2",
    ]
    sigma = {}
    for l in CSV_WAVELENGTHS_NM:
        s = bodhaine_tau(float(l)) / N_COLUMN_M2 * 1e4  # m^2 -> cm^2
        txt = f"{s:.10e}"
        sigma[float(l)] = float(txt)
        lines.append(f"{l},{txt}")
    path = ROOT / CSV_REL
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return sigma


def hg_phase(g, cos):
    return (1 - g * g) / (1 + g * g - 2 * g * cos) ** 1.5  # normalised to 4 pi


def rayleigh_phase(cos):
    return 0.75 * (1 + cos * cos)  # normalised to 4 pi


def make_optics(tau_r, tau_a, ssa_a=HG_SSA, omega=None):
    """Homogeneous mixture of Rayleigh (scattering tau_r) and HG aerosol (extinction tau_a)."""
    sca_r = tau_r
    sca_a = ssa_a * tau_a
    tau = tau_r + tau_a
    fr = sca_r / (sca_r + sca_a)
    fa = sca_a / (sca_r + sca_a)
    if omega is None:
        omega = (sca_r + sca_a) / tau

    def chi(nleg):
        c = np.zeros(nleg)
        c[2] += 0.1 * fr
        if fa > 0:
            c[1:] += fa * HG_G ** np.arange(1, nleg)
        c[0] = 1.0
        return c

    def phase(cos):
        p = fr * rayleigh_phase(cos)
        if fa > 0:
            p = p + fa * hg_phase(HG_G, cos)
        return p

    return dict(tau_r=tau_r, tau_a=tau_a, tau=tau, omega=omega, chi=chi, phase=phase)


def slab_optics(sigma_cm2, l_nm, with_hg):
    tau_r = sigma_cm2 * 1e-4 * N_COLUMN_M2
    if with_hg:
        return make_optics(tau_r, HG_TAU550 * (l_nm / 550.0) ** (-HG_ANGSTROM))
    return make_optics(tau_r, 0.0, omega=RAYLEIGH_OMEGA)


class Slab:
    """PythonicDISORT solution of one homogeneous layer plus source-function integration."""

    def __init__(self, opt, nquad, albedo, mu0=MU0):
        self.opt = opt
        self.nquad = nquad
        self.mu0 = mu0
        self.tau = opt["tau"]
        self.omega = opt["omega"]
        self.chi = opt["chi"](nquad)  # NLeg = NQuad, no delta-M (f = 0)
        self.nfourier = min(nquad, NFOURIER_MAX)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "albedo very close to 1" for the Rayleigh slab
            self.mu, self.Fp, self.Fm, self.u0, self.u = pydisort(
                self.tau, self.omega, nquad, self.chi[None, :], mu0, F0, 0.0,
                NLeg=nquad, NFourier=self.nfourier,
                BDRF_Fourier_modes=[albedo] if albedo > 0 else [],
            )
        self.mu_pos, self.W = subroutines.Gauss_Legendre_quad(nquad // 2)
        self.Wfull = np.concatenate([self.W, self.W])
        self.wleg = (2 * np.arange(nquad) + 1) * self.chi

    def ptrunc(self, cos):
        return legval(cos, self.wleg)

    def beam_factor(self, mu):
        """int_0^tau exp(-t/mu0) exp(-(tau-t)/mu) dt/mu, stable at mu = mu0."""
        tau, mu0 = self.tau, self.mu0
        mu = np.asarray(mu, float)
        x = tau * (mu0 - mu) / (mu * mu0)
        small = np.abs(x) < 1.0
        xs = np.where(small & (x != 0.0), x, 1.0)
        near = tau / mu * np.exp(-tau / mu) * np.where(x == 0.0, 1.0, np.expm1(xs) / xs)
        far = mu0 / np.where(small, 1.0, mu0 - mu) * (np.exp(-tau / mu0) - np.exp(-tau / mu))
        return np.where(small, near, far)

    def down_radiance(self, mu, phi, nt=NT, exact_phase=True, chunk=256):
        """Diffuse radiance at the bottom for photons propagating in (-mu, phi), mu > 0.
        mu, phi: 1-D arrays of equal length (directions). Returns (total, single-scatter)."""
        mu = np.asarray(mu, float)
        phi = np.asarray(phi, float)
        tau, omega, mu0 = self.tau, self.omega, self.mu0
        # Beam (single-scattering) term, analytic in depth.
        cos0 = -mu * -mu0 + np.sqrt(1 - mu**2) * np.sqrt(1 - mu0**2) * np.cos(phi - 0.0)
        p0 = self.opt["phase"](cos0) if exact_phase else self.ptrunc(cos0)
        ss = omega * F0 * p0 / (4 * math.pi) * self.beam_factor(mu)
        # Multiple-scattering term: source from the DO diffuse field at the nodes.
        x, w = np.polynomial.legendre.leggauss(nt)
        t = 0.5 * tau * (x + 1)
        wt = 0.5 * tau * w
        nphi = 2 * self.nfourier + 2 * self.nquad + 2
        phik = 2 * math.pi * np.arange(nphi) / nphi
        I = np.asarray(self.u(t, phik)).reshape(self.nquad, nt, nphi)  # (j, t, k)
        wq = (self.Wfull[:, None] * (2 * math.pi / nphi)) * np.ones((1, nphi))  # (j, k)
        A = (I * wq[:, None, :]).transpose(0, 2, 1).reshape(self.nquad * nphi, nt)
        muj = self.mu[:, None]
        sj = np.sqrt(1 - self.mu**2)[:, None]
        ms = np.empty(len(mu))
        for s in range(0, len(mu), chunk):
            m = mu[s:s + chunk, None, None]
            ph = phi[s:s + chunk, None, None]
            cos = -m * muj[None] + np.sqrt(1 - m**2) * sj[None] * np.cos(ph - phik[None, None, :])
            P = self.ptrunc(cos).reshape(len(m), -1)
            J = omega / (4 * math.pi) * (P @ A)  # (d, t)
            att = np.exp(-(tau - t)[None, :] / mu[s:s + chunk, None]) / mu[s:s + chunk, None]
            ms[s:s + chunk] = (J * att) @ wt
        return ss + ms, ss

    def fluxes_at_ground(self):
        up = float(self.Fp(self.tau))
        diff, direct = self.Fm(self.tau)
        return float(diff), float(direct), up


def view_grid():
    th = np.radians(np.array(VIEW_ZENITH_DEG, float))
    ph = np.radians(np.array(REL_AZIMUTH_DEG, float))
    TH, PH = np.meshgrid(th, ph, indexing="ij")
    return np.cos(TH).ravel(), PH.ravel()


def sky(slab, nt=NT):
    mu, ph = view_grid()
    tot, _ = slab.down_radiance(mu, ph, nt=nt)
    return tot.reshape(len(VIEW_ZENITH_DEG), len(REL_AZIMUTH_DEG))


def check_single_scattering():
    """(a) Optically thin slab, albedo 0: I = omega F0 p(Theta)/(4 pi) * mu0/(mu0-mu) (e^-tau/mu0 - e^-tau/mu)."""
    out = {}
    for tau, name, with_hg in ((1e-4, "rayleigh_tau1e-4", False), (1e-5, "rayleigh_tau1e-5", False),
                               (1e-4, "henyey_greenstein_g0.7_tau1e-4", True),
                               (1e-5, "henyey_greenstein_g0.7_tau1e-5", True)):
        if with_hg:  # pure HG (g = 0.7), omega ~ 1
            opt = make_optics(0.0, tau, ssa_a=1.0, omega=RAYLEIGH_OMEGA)
        else:
            opt = make_optics(tau, 0.0, omega=RAYLEIGH_OMEGA)
        slab = Slab(opt, NQUAD, 0.0)
        # At PythonicDISORT's own nodes (its native output, no interpolation), all azimuths.
        N = NQUAD // 2
        phis = np.radians(np.array(REL_AZIMUTH_DEG, float))
        u = np.asarray(slab.u(tau, phis))[N:, :]  # downward nodes (mu < 0), (j, phi)
        mun = slab.mu_pos[:, None]
        cos = -mun * -MU0 + np.sqrt(1 - mun**2) * math.sqrt(1 - MU0**2) * np.cos(phis[None, :])
        ss = slab.omega * F0 * slab.ptrunc(cos) / (4 * math.pi) * slab.beam_factor(mun)
        sel = mun[:, 0] > 0.08  # view zenith < 85 deg
        rel_nodes = np.max(np.abs(u[sel] / ss[sel] - 1))
        # At the user view angles, through the source-function integration.
        mu, ph = view_grid()
        tot, s1 = slab.down_radiance(mu, ph)
        rel_user = np.max(np.abs(tot / s1 - 1))
        i60 = VIEW_ZENITH_DEG.index(60) * len(REL_AZIMUTH_DEG)
        out[name] = dict(
            tau=tau, omega=slab.omega, ground_albedo=0.0,
            max_rel_diff_disort_nodes_vs_single_scattering=rnd(rel_nodes, 3),
            max_rel_diff_user_angles_vs_single_scattering=rnd(rel_user, 3),
            radiance_view60_az0=rnd(tot[i60]), single_scattering_view60_az0=rnd(s1[i60]),
            radiance_view60_az180=rnd(tot[i60 + 6]), single_scattering_view60_az180=rnd(s1[i60 + 6]),
        )
        log(f"  single scattering {name}: DISORT nodes vs SS max rel {rel_nodes:.2e}; user angles {rel_user:.2e}; "
            f"view 60 az 0: {tot[i60]:.6e} vs {s1[i60]:.6e}; az 180: {tot[i60 + 6]:.6e} vs {s1[i60 + 6]:.6e}")
    return out


def check_nodes(slab):
    """The source-function integration reproduces DISORT's intensities at its own nodes."""
    N = slab.nquad // 2
    phis = np.radians(np.array(REL_AZIMUTH_DEG, float))
    M, PH = np.meshgrid(slab.mu_pos, phis, indexing="ij")
    mine, _ = slab.down_radiance(M.ravel(), PH.ravel(), exact_phase=False)
    ref = np.asarray(slab.u(slab.tau, phis))[N:, :].ravel()
    return float(np.max(np.abs(mine / ref - 1)))


def check_fluxes(slab):
    """(b) Hemispheric integrals of the radiance against DISORT's flux outputs."""
    diff, direct, up = slab.fluxes_at_ground()
    N = slab.nquad // 2
    u0 = np.asarray(slab.u0(slab.tau)).ravel()
    f_nodes = 2 * math.pi * float(np.sum(slab.W * slab.mu_pos * u0[N:]))
    # Fine user-angle grid (Gauss in mu, trapezoid in phi).
    # The field is even in phi: trapezoid over [0, pi] with 64 intervals of the full circle.
    nmu, nphi = 32, 64
    mg, wg = subroutines.Gauss_Legendre_quad(nmu)
    pg = 2 * math.pi * np.arange(nphi // 2 + 1) / nphi
    wp = np.full(len(pg), 2 * (2 * math.pi / nphi))
    wp[0] = wp[-1] = 2 * math.pi / nphi
    M, PH = np.meshgrid(mg, pg, indexing="ij")
    tot, _ = slab.down_radiance(M.ravel(), PH.ravel())
    f_user = float(np.sum(tot.reshape(nmu, len(pg)) * (wg * mg)[:, None] * wp[None, :]))
    up_expected = GROUND_ALBEDO * (diff + direct)
    up_top = float(slab.Fp(0.0))
    balance = MU0 * F0 - up_top - (diff + direct - up)
    return dict(
        flux_down_direct_vs_mu0_exp=rnd(direct / (MU0 * F0 * math.exp(-slab.tau / MU0)) - 1, 3),
        flux_down_diffuse_nodes_vs_disort=rnd(f_nodes / diff - 1, 3),
        flux_down_diffuse_user_angles_vs_disort=rnd(f_user / diff - 1, 3),
        flux_up_vs_albedo_times_down=rnd(up / up_expected - 1, 3),
        absorbed_in_slab_per_mu0F0=rnd(balance / (MU0 * F0), 6),
    )


def versions():
    return {
        "python": "%d.%d" % sys.version_info[:2],
        "PythonicDISORT": metadata.version("PythonicDISORT"),
        "numpy": metadata.version("numpy"),
        "scipy": metadata.version("scipy"),
    }


def main():
    sigma = write_cross_section_csv()
    log(f"wrote {CSV_REL}")
    log("check (a): optically thin single scattering (tau 1e-4 and 1e-5, albedo 0)")
    ss_checks = check_single_scattering()

    cases = []
    conv = {}
    flux_checks = {}
    interp_diffs = {}
    zen_spreads = {}
    omega_effect = {}
    nodes = {}
    worst_nt = 0.0
    for rel, with_hg in CASES:
        key = Path(rel).stem
        for l in WAVELENGTHS_NM:
            opt = slab_optics(sigma[l], l, with_hg)
            slab = Slab(opt, NQUAD, GROUND_ALBEDO)
            rad = sky(slab)
            lo = sky(Slab(opt, NQUAD_CHECK[0], GROUND_ALBEDO))
            hi_slab = Slab(opt, NQUAD_CHECK[1], GROUND_ALBEDO)
            hi = sky(hi_slab)
            fine_t = sky(slab, nt=NT_CHECK)
            d_lo = float(np.max(np.abs(lo / rad - 1)))
            d_hi = float(np.max(np.abs(hi / rad - 1)))
            d_t = float(np.max(np.abs(fine_t / rad - 1)))
            worst_nt = max(worst_nt, d_t)
            node = check_nodes(slab)
            nodes[f"{key}@{int(l)}"] = rnd(node, 3)
            # PythonicDISORT's own polynomial interpolation in mu, at the doubled stream count.
            ui = subroutines.interpolate(hi_slab.u)
            mu, ph = view_grid()
            pint = np.array([ui(-m, hi_slab.tau, p) for m, p in zip(mu, ph)]).reshape(rad.shape)
            d_int = float(np.max(np.abs(pint[1:] / rad[1:] - 1)))  # zenith row: see notes
            d_int_zen = float(np.max(np.abs(pint[0] / rad[0] - 1)))
            zen_spread = float(np.ptp(rad[0]) / np.mean(rad[0]))
            fl = check_fluxes(slab)
            if not with_hg:
                # Effect of omega < 1: the radiances are linear in (1 - omega) near 1, so the deviation
                # from omega = 1 is (I(1 - 1e-6) - I(1 - 1e-5)) / 9.
                o5 = sky(Slab(make_optics(opt["tau_r"], 0.0, omega=1.0 - 1e-5), NQUAD, GROUND_ALBEDO))
                omega_effect[f"{key}@{int(l)}"] = rnd(float(np.max(np.abs(rad / o5 - 1))) / 9.0, 3)
            diff, direct, up = slab.fluxes_at_ground()
            tag = f"{key}@{int(l)}"
            conv[tag] = {f"nquad_{NQUAD_CHECK[0]}_vs_{NQUAD}": rnd(d_lo, 3),
                         f"nquad_{NQUAD_CHECK[1]}_vs_{NQUAD}": rnd(d_hi, 3),
                         f"depth_nodes_{NT_CHECK}_vs_{NT}": rnd(d_t, 3)}
            flux_checks[tag] = fl
            interp_diffs[tag] = {"view_zenith_10_to_85": rnd(d_int, 3), "view_zenith_0": rnd(d_int_zen, 3)}
            zen_spreads[tag] = rnd(zen_spread, 3)
            log(f"{tag}: tau_R {opt['tau_r']:.6f} tau_A {opt['tau_a']:.6f} omega {opt['omega']:.9f}; "
                f"max rel change NQuad {NQUAD}->{NQUAD_CHECK[1]} {d_hi:.2e}, {NQUAD_CHECK[0]}->{NQUAD} {d_lo:.2e}, "
                f"Nt {d_t:.2e}; nodes {node:.2e}; interp(NQuad {NQUAD_CHECK[1]}) {d_int:.2e} (zenith {d_int_zen:.2e}); "
                f"zenith azimuth spread {zen_spread:.1e}; fluxes {fl}")
            cases.append({
                "atmosphere": rel,
                "wavelength_nm": l,
                "sun_zenith_deg": SUN_ZENITH_DEG,
                "tau_rayleigh": rnd(opt["tau_r"]),
                "tau_aerosol": rnd(opt["tau_a"]),
                "tau_total": rnd(opt["tau"]),
                "omega": rnd(opt["omega"], 12),
                "legendre_moments": [rnd(c) for c in (slab.chi[:3] if not with_hg else slab.chi)],
                "ground_albedo": GROUND_ALBEDO,
                "view_zenith_deg": [float(v) for v in VIEW_ZENITH_DEG],
                "relative_azimuth_deg": [float(a) for a in REL_AZIMUTH_DEG],
                "radiance_sr_inv": [[rnd(v) for v in row] for row in rad],
                "flux_down_diffuse": rnd(diff),
                "flux_down_direct": rnd(direct),
                "flux_up": rnd(up),
            })

    worst_lo = max(v[f"nquad_{NQUAD_CHECK[0]}_vs_{NQUAD}"] for v in conv.values())
    worst_hi = max(v[f"nquad_{NQUAD_CHECK[1]}_vs_{NQUAD}"] for v in conv.values())
    notes = [
        "Radiances are DIFFUSE downwelling radiances at the ground (bottom of the slab), per unit solar irradiance "
        "F0 measured on a surface NORMAL to the beam, in sr^-1 (the direct flux on the horizontal ground is "
        "F0 mu0 exp(-tau/mu0)). The direct solar beam itself is not included.",
        "Sun at zenith angle 60 deg (mu0 = 0.5), treated as a point source (the TOML's 0.533 deg disc is not modelled).",
        "view_zenith_deg: angle of the viewing direction from the UPWARD vertical, for a viewer on the ground looking up. "
        "relative_azimuth_deg: azimuth of the viewing direction from the sun's azimuth, 0 = looking toward the sun; "
        "the field is symmetric about the solar principal plane. radiance_sr_inv[i][j] is at view_zenith_deg[i], "
        "relative_azimuth_deg[j]; view zenith 60, azimuth 0 is the sun's own direction (forward scattering).",
        "Ground: Lambertian, albedo 0.3. flux_down_diffuse, flux_down_direct, flux_up: DISORT's own energetic fluxes at "
        "the ground per unit F0 (flux_up = albedo * (diffuse + direct)).",
        "Each atmosphere is one homogeneous layer (air and aerosol share one exponential profile): tau_rayleigh = "
        "sigma(CSV) * N with N = 2.5e25 m^-3 * 8000 m * (1 - exp(-100/8)); tau_aerosol = 0.2 (l/550)^-1.3; "
        "omega = (tau_R + 0.9 tau_A)/tau; legendre_moments chi_l with p(cos) = sum_l (2l+1) chi_l P_l(cos) "
        "(4 pi normalisation), chi = scattering-weighted mix of Rayleigh (1, 0, 0.1) and HG (g^l, g = 0.7). For the "
        "Rayleigh slab only chi_0..chi_2 are listed (the rest are 0); for the HG slab the first NQuad moments used.",
        "The Rayleigh-only slab uses omega = 1 - 1e-6 (not 1) because PythonicDISORT refuses omega = 1 exactly; "
        "1 - 1e-6 rather than 1 - 1e-8 because nearer 1 its conservative-limit solution is ill-conditioned (at "
        "1 - 1e-8 its intensities at grazing quadrature nodes miss the transfer equation by 1.6e-3 relative at 64 "
        "streams and 1.4e-2 at 128). The resulting deviation from omega = 1 is estimated from omega = 1 - 1e-5 as "
        "checks.rayleigh_omega_minus_1e-6_vs_1_max_rel_effect (~1e-6).",
        f"Solver: PythonicDISORT discrete ordinates, NQuad = {NQUAD} streams, NLeg = NQuad, NFourier = {min(NQUAD, NFOURIER_MAX)}, "
        "no delta-M (the truncated HG tail is 0.7^64 ~ 1e-10) so no Nakajima-Tanaka corrections are needed. Radiances at "
        "the view angles are by integrating DISORT's source function along the line of sight (as Fortran DISORT does at "
        "user angles), with the exact phase function in the single-scattering term; not PythonicDISORT's polynomial "
        "interpolation in mu.",
        f"Convergence: max relative change of any radiance when the streams are doubled ({NQUAD} -> {NQUAD_CHECK[1]}): "
        f"{worst_hi:.1e}; halved ({NQUAD} -> {NQUAD_CHECK[0]}): {worst_lo:.1e}; doubling the depth quadrature: "
        f"{worst_nt:.1e}. See checks.",
        "Checks (in checks): single_scattering_thin_limit: optically thin slabs (albedo 0) against "
        "omega F0 p(Theta)/(4 pi) mu0/(mu0 - mu)(exp(-tau/mu0) - exp(-tau/mu)) with mu = cos(view zenith) and "
        "cos(Theta) = mu mu0 + sin sin0 cos(relative azimuth), both at DISORT's own nodes and at the view angles; "
        "the remaining difference is multiple scattering, O(tau/mu), and falls tenfold with tau. "
        "node_consistency: the line-of-sight integration at DISORT's downward nodes against DISORT's own "
        "intensities there. fluxes: DISORT's direct flux against mu0 exp(-tau/mu0); its diffuse downward flux against "
        "the hemispheric integral of its node intensities and of the line-of-sight radiances on a 32 x 64 grid; its "
        "upward flux against albedo * total downward; the absorbed fraction from the flux balance (0 for Rayleigh). "
        "zenith_azimuth_spread: the zenith radiance is the same at every azimuth. "
        "pythonicdisort_mu_interpolation: PythonicDISORT's own polynomial interpolation in mu at 128 streams, which "
        "agrees away from the zenith but at the zenith (an extrapolation beyond the last node) wrongly varies with "
        "azimuth.",
    ]
    out = {
        "generated_by": {"script": SCRIPT, "versions": versions(),
                         "regenerate": ".venv-disort/bin/pip install -r scripts/requirements-disort.txt && "
                                       ".venv-disort/bin/python scripts/regen_disort.py"},
        "notes": notes,
        "checks": {
            "single_scattering_thin_limit": ss_checks,
            "node_consistency_max_rel_diff": nodes,
            "zenith_azimuth_spread_rel": zen_spreads,
            "rayleigh_omega_minus_1e-6_vs_1_max_rel_effect": omega_effect,
            "stream_convergence_max_rel_change": conv,
            "fluxes": flux_checks,
            f"pythonicdisort_mu_interpolation_nquad{NQUAD_CHECK[1]}_vs_final_max_rel_diff": interp_diffs,
        },
        "cases": cases,
    }
    path = ROOT / JSON_REL
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")
    log(f"wrote {JSON_REL}")


if __name__ == "__main__":
    main()
