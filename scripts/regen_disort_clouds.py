#!/usr/bin/env python3
"""Regenerate tests/reference/disort_clouds.json: DISORT sky radiances under plane-parallel cloud slabs.

Regenerate (from the repository root; about 15 minutes on 2 cores, the cases in 2 worker processes,
DISORT_JOBS=n to change that; the output does not depend on it):

    python3 -m venv .venv-disort
    .venv-disort/bin/pip install -r scripts/requirements-disort.txt
    .venv-disort/bin/python scripts/regen_disort_clouds.py

Reference radiances for tests/atmospheres/disort_cloud_tau{1,9,60}.toml: the air of
tests/atmospheres/disort_rayleigh.toml (exponential profile, 8 km scale height, N0 = 2.5e25 m^-3,
the Rayleigh cross-section table tests/atmospheres/data/slab_rayleigh_cross_section.csv, no
depolarisation, top 100 km) plus a Henyey-Greenstein cloud (g 0.85, single-scattering albedo
0.99999, optical depth tau_c = 1, 9 or 60 at every wavelength) between 3 and 5 km, over a
Lambertian ground of albedo 0.1, sun at zenith angle 60 deg (point source), 450/550/650 nm.
Shared constants and helpers come from scripts/regen_disort.py (which writes disort.json and the
cross-section CSV; this script only reads the CSV and writes disort_clouds.json).

Optical depths. The renderer (src/render/medium.rs) rasterises every profile on a 10 m altitude
grid and interpolates linearly between the nodes, and scales an aerosol so that its PROFILE's
column (Profile::column_km, a 5 m trapezoid rule) carries the stated optical depth
(src/atmosphere/optics.rs, aerosol_scale). A cloud profile with a sharp edge at 3 and 5 km would
gain a linear ramp over the 10 m raster cell outside each edge, i.e. carry 2.01/2 = 1.005 times its
nominal optical depth in the path tracer. The cloud profile is therefore a table whose rows are
raster nodes, 0 at 3.00 km, 1 at 3.01 km, 1 at 4.99 km, 0 at 5.00 km (linear): the raster
reproduces it exactly and the path tracer integrates exactly tau_c. This script re-implements the
raster and the column rule (in Python, node for node) and gives DISORT the optical depths the path
tracer integrates: per layer, Rayleigh = sigma * N0 * (integral of the raster of exp(-z/8 km))
and cloud = (tau_c / column_km) * (integral of the cloud raster); both are written per case.

Layers (top down): Rayleigh 5-100 km; ramp 4.99-5.00 km; NSUB equal sublayers of Rayleigh + cloud
in 3.01-4.99 km (the Rayleigh share varies with height inside the cloud, so the cloud is split);
ramp 3.00-3.01 km; Rayleigh 0-3 km. Each layer is homogeneous in DISORT (ramps included: their
Rayleigh optical depth is ~2e-4); refining the split (NSUB doubled, each ramp halved) is one of the
convergence checks.

Method. PythonicDISORT (NQuad streams, NLeg = NQuad Legendre moments, no delta-M: the truncated HG
tail is 0.85^128 ~ 1e-9) solves the multi-layer discrete-ordinate problem. The radiances at the view
angles come, as in Stamnes' Fortran DISORT at user angles, from integrating the source function
along the line of sight,
    I(tau*, -mu, phi) = sum_layers int J(t, -mu, phi) exp(-(tau* - t)/mu) dt/mu,
J = omega/(4 pi) [F0 p(cos Theta0) exp(-t/mu0) + int p I_DO dOmega'].
- The single-scattering (beam) term is integrated analytically per layer with the EXACT phase
  function (this is what the Nakajima-Tanaka TMS correction achieves for delta-M runs).
- The multiple-scattering term is integrated ANALYTICALLY in depth too: inside each layer
  PythonicDISORT's Fourier modes are I_m(t, mu_i) = sum_j GC[m,l,i,j] exp(K[m,l,j] (t - t_edge))
  + B[m,l,i] exp(-t/mu0) (its own coefficient arrays, read from the closure of its intensity
  function), so each exponential integrates in closed form; the angular integral uses the Fourier
  components of the (truncated) phase function between the view cosine and the quadrature nodes,
  D^m(mu, mu_i) = (1/2 pi) int p(cos Theta) cos(m dphi) d dphi, taken exactly by an FFT. There is no
  depth quadrature. Two independent checks: at DISORT's own downward nodes this reproduces its
  intensities (node_consistency), and a numerical line-of-sight integration of J computed from
  PythonicDISORT's public intensity function u(tau, phi) on graded Gauss-Legendre depth panels
  agrees (depth_quadrature, at 550 nm; 16 and 8 nodes per panel).

Conventions as in scripts/regen_disort.py (PythonicDISORT 1.8): mu > 0 is upward propagation, tau = 0
at the top, the beam propagates toward (-mu0, phi0 = 0) with flux F0 = 1 through a surface normal to
it; a viewer on the ground at view zenith theta_v and relative azimuth phi_r (0 = toward the sun)
receives the photons propagating in (-cos theta_v, phi_r).

Output is deterministic: keys sorted, floats rounded to 9 significant digits, BLAS threads fixed
to 1. Running the script twice gives identical bytes.
"""

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import json
import math
import sys
import time
import warnings
from bisect import bisect_right
from pathlib import Path

import numpy as np
from numpy.polynomial.legendre import legval

from PythonicDISORT import pydisort, subroutines

sys.path.insert(0, str(Path(__file__).resolve().parent))
import regen_disort as rd  # noqa: E402  (shared constants and helpers)

ROOT = rd.ROOT
SCRIPT = "scripts/regen_disort_clouds.py"
JSON_REL = "tests/reference/disort_clouds.json"

# Must match tests/atmospheres/disort_cloud_tau*.toml.
CLOUD_TAUS = [1.0, 9.0, 60.0]
CLOUD_G = 0.85
CLOUD_SSA = 0.99999
CLOUD_ALT_KM = [3.0, 3.01, 4.99, 5.0]   # table rows (raster nodes), linear interpolation
CLOUD_DEN = [0.0, 1.0, 1.0, 0.0]
GROUND_ALBEDO = 0.1
TOP_KM = rd.TOP_KM
N0_M3 = rd.N0_M3
H_KM = rd.SCALE_HEIGHT_M / 1000.0
RAYLEIGH_OMEGA = rd.RAYLEIGH_OMEGA    # albedo given to the Rayleigh COMPONENT (DISORT refuses omega = 1)

WAVELENGTHS_NM = rd.WAVELENGTHS_NM
SUN_ZENITH_DEG = rd.SUN_ZENITH_DEG
MU0 = rd.MU0
F0 = rd.F0
VIEW_ZENITH_DEG = rd.VIEW_ZENITH_DEG
REL_AZIMUTH_DEG = rd.REL_AZIMUTH_DEG

NQUAD = 128
NQUAD_CHECK = (64, 256)
NFOURIER = 64            # PythonicDISORT warns above 64 Fourier modes
NFOURIER_CHECK = 48
NSUB = 16                # cloud-interior sublayers (the error falls as 1/NSUB^2: 2e-4 at 4, 1.3e-5 at 16)
NSUB_CHECK = 32          # ... and each ramp split in two
NRAMP_CHECK = 2
DEPTH_CHECK_NM = 550.0   # the numerical depth-quadrature cross-check runs at this wavelength only

# The renderer's numerics (src/render/medium.rs, src/atmosphere/profile.rs).
GRID_STEP_KM = 0.01
COLUMN_STEP_KM = 0.005

rnd = rd.rnd
log = rd.log


# ----------------------------------------------------------------------------- renderer emulation

def table_density(z):
    """Profile::density for the cloud table (linear), 0 outside."""
    alt, den = CLOUD_ALT_KM, CLOUD_DEN
    n = len(alt)
    if z < alt[0] or z > alt[-1]:
        return 0.0
    i = min(max(bisect_right(alt, z), 1) - 1, n - 2)
    t = (z - alt[i]) / (alt[i + 1] - alt[i])
    return den[i] + t * (den[i + 1] - den[i])


def cloud_column_km(top=TOP_KM):
    """Profile::column_km for the cloud table: trapezoid on 5 m steps + the rows + both sides of the ends."""
    steps = math.ceil(top / COLUMN_STEP_KM)
    nodes = [min(i * COLUMN_STEP_KM, top) for i in range(steps + 1)]
    nodes += [a for a in CLOUD_ALT_KM if 0.0 < a < top]
    for a in (CLOUD_ALT_KM[0], CLOUD_ALT_KM[-1]):
        if 0.0 < a < top:
            nodes += [a - 1e-9, a + 1e-9]
    nodes = sorted(set(nodes))
    s = 0.0
    zp, dp = nodes[0], table_density(nodes[0])
    for z in nodes[1:]:
        d = table_density(z)
        s += 0.5 * (dp + d) * (z - zp)
        zp, dp = z, d
    return s


def raster_nodes(top=TOP_KM):
    n = math.ceil(top / GRID_STEP_KM) + 1
    return [min(k * GRID_STEP_KM, top) for k in range(n)]


ZS = raster_nodes()
AIR_RASTER = np.array([math.exp(-z / H_KM) for z in ZS])  # relative; times N0 (air.scale) below
CLOUD_RASTER = np.array([table_density(z) for z in ZS])


def raster_integral_km(d, a, b):
    """Integral over [a, b] km of Medium::density (linear between the raster nodes k * 10 m)."""
    ua, ub = a / GRID_STEP_KM, b / GRID_STEP_KM
    n = len(d)
    s = 0.0
    k0 = min(int(math.floor(ua)), n - 2)
    k1 = min(int(math.floor(ub)), n - 2)
    for k in range(k0, k1 + 1):
        lo, hi = max(ua, k), min(ub, k + 1)
        if hi <= lo:
            continue
        # d_k + (u - k)(d_{k+1} - d_k), integrated over [lo, hi]
        t0, t1 = lo - k, hi - k
        s += d[k] * (t1 - t0) + 0.5 * (d[k + 1] - d[k]) * (t1 * t1 - t0 * t0)
    return s * GRID_STEP_KM


def read_sigma_cm2():
    """The cross-section table as the renderer reads it (450/550/650 nm are rows)."""
    out = {}
    for line in (ROOT / rd.CSV_REL).read_text().splitlines():
        if not line or line.startswith("#") or line.startswith("wavelength"):
            continue
        l, s = line.split(",")
        out[float(l)] = float(s)
    return out


# ----------------------------------------------------------------------------- layers and optics

def layer_edges_km(nsub, nramp):
    """Layer boundaries from the top down."""
    z = [TOP_KM, 5.0]
    z += [5.0 - 0.01 * i / nramp for i in range(1, nramp)] + [4.99]            # upper ramp
    z += [4.99 - (4.99 - 3.01) * i / nsub for i in range(1, nsub)] + [3.01]    # cloud interior
    z += [3.01 - 0.01 * i / nramp for i in range(1, nramp)] + [3.0, 0.0]       # lower ramp, then air
    return z


def make_layers(sigma_cm2, tau_c, nsub=NSUB, nramp=1, ray_omega=RAYLEIGH_OMEGA):
    """Per layer (top down): z range, tau_R, tau_C (what the path tracer integrates), omega, mixing."""
    ext_r_per_km = sigma_cm2 * 1e-4 * N0_M3 * 1000.0       # per km, per unit relative air density
    col = cloud_column_km()
    ext_c_per_km = tau_c / col                             # per km, per unit cloud density
    edges = layer_edges_km(nsub, nramp)
    layers = []
    for zt, zb in zip(edges[:-1], edges[1:]):
        tr = ext_r_per_km * raster_integral_km(AIR_RASTER, zb, zt)
        tc = ext_c_per_km * raster_integral_km(CLOUD_RASTER, zb, zt)
        sca_r, sca_c = ray_omega * tr, CLOUD_SSA * tc
        layers.append(dict(z_top_km=zt, z_bottom_km=zb, tau_r=tr, tau_c=tc, tau=tr + tc,
                           omega=(sca_r + sca_c) / (tr + tc),
                           fr=sca_r / (sca_r + sca_c), fc=sca_c / (sca_r + sca_c)))
    return layers, col


def chi_rayleigh(nleg):
    c = np.zeros(nleg)
    c[0] = 1.0
    c[2] = 0.1
    return c


def chi_hg(nleg):
    return CLOUD_G ** np.arange(nleg)


def E(alpha, beta, delta):
    """int_0^delta exp(-alpha s) exp(-beta (delta - s)) ds, alpha, beta >= 0, stable when alpha ~ beta."""
    alpha, beta = np.broadcast_arrays(np.asarray(alpha, float), np.asarray(beta, float))
    x = (beta - alpha) * delta
    small = np.abs(x) < 1.0
    xs = np.where(small & (x != 0.0), x, 1.0)
    near = delta * np.exp(-beta * delta) * np.where(x == 0.0, 1.0, np.expm1(xs) / xs)
    den = np.where(small, 1.0, beta - alpha)
    far = (np.exp(-alpha * delta) - np.exp(-beta * delta)) / den
    return np.where(small, near, far)


class Column:
    """PythonicDISORT solution of the layered column and the line-of-sight integration."""

    def __init__(self, layers, nquad, nfourier=NFOURIER, albedo=GROUND_ALBEDO):
        self.layers = layers
        self.nquad = nquad
        self.nleg = nquad
        self.nfourier = nfourier
        self.dtau = np.array([L["tau"] for L in layers])
        self.tau_cum = np.cumsum(self.dtau)
        self.t_top = np.concatenate([[0.0], self.tau_cum[:-1]])
        self.T = float(self.tau_cum[-1])
        self.omega = np.array([L["omega"] for L in layers])
        self.fr = np.array([L["fr"] for L in layers])
        self.fc = np.array([L["fc"] for L in layers])
        self.chi = self.fr[:, None] * chi_rayleigh(self.nleg)[None] + self.fc[:, None] * chi_hg(self.nleg)[None]
        self.chi[:, 0] = 1.0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "albedos very close to 1"
            self.mu, self.Fp, self.Fm, self.u0, self.u = pydisort(
                self.tau_cum, self.omega, nquad, self.chi, MU0, F0, 0.0,
                NLeg=self.nleg, NFourier=nfourier, BDRF_Fourier_modes=[albedo] if albedo > 0 else [],
            )
        cl = dict(zip(self.u.__code__.co_freevars, (c.cell_contents for c in self.u.__closure__)))
        self.GC = cl["GC_collect"]      # (NFourier, NLayers, NQuad, NQuad)
        self.K = cl["K_collect"]        # (NFourier, NLayers, NQuad)
        self.B = cl["B_collect"]        # (NFourier, NLayers, NQuad)
        self.rescale = float(cl["rescale_factor"])
        assert np.allclose(cl["tau_arr"], self.tau_cum) and np.all(cl["scale_tau"] == 1.0)
        N = nquad // 2
        assert np.all(self.K[:, :, :N] < 0) and np.all(self.K[:, :, N:] > 0)
        self.mu_pos, self.W = subroutines.Gauss_Legendre_quad(N)
        self.Wfull = np.concatenate([self.W, self.W])
        self.wl_r = (2 * np.arange(self.nleg) + 1) * chi_rayleigh(self.nleg)
        self.wl_hg = (2 * np.arange(self.nleg) + 1) * chi_hg(self.nleg)

    # --- phase functions
    def phase_exact(self, l, cos):
        return self.fr[l] * rd.rayleigh_phase(cos) + self.fc[l] * rd.hg_phase(CLOUD_G, cos)

    def dm(self, mu_prop, nf, mu_other=None):
        """D^m(mu, mu') of the Rayleigh and HG components, (2, Nv, nf, len(mu')), for propagation cosines mu and
        mu' (default: the quadrature nodes)."""
        mo = self.mu if mu_other is None else np.asarray(mu_other, float)
        if nf == 1:
            # m = 0 only: D^0 = sum_l (2l+1) chi_l P_l(mu) P_l(mu'), directly.
            V = np.polynomial.legendre.legvander(np.asarray(mu_prop, float), self.nleg - 1)
            Vi = np.polynomial.legendre.legvander(mo, self.nleg - 1)
            return np.stack([((V * wl) @ Vi.T)[:, None, :] for wl in (self.wl_r, self.wl_hg)])
        M = 2 * self.nleg + 2 * nf
        dphi = 2 * math.pi * np.arange(M) / M
        mu = np.asarray(mu_prop, float)[:, None, None]
        cos = (mu * mo[None, :, None]
               + np.sqrt(1 - mu**2) * np.sqrt(1 - mo**2)[None, :, None] * np.cos(dphi)[None, None, :])
        out = []
        for wl in (self.wl_r, self.wl_hg):
            p = legval(cos, wl)
            out.append((np.fft.rfft(p, axis=-1).real / M)[:, :, :nf].transpose(0, 2, 1))
        return np.stack(out)

    # --- single scattering
    def single_scatter(self, muv, phv, exact=True):
        """Beam term at the ground for photons propagating in (-muv, phv), analytic per layer. exact=False:
        with the phase function as DISORT has it, Legendre series truncated at NLeg and Fourier series at
        NFourier (for comparisons at its nodes)."""
        muv = np.asarray(muv, float)
        phv = np.asarray(phv, float)
        beta = 1.0 / muv
        cos0 = muv * MU0 + np.sqrt(1 - muv**2) * math.sqrt(1 - MU0**2) * np.cos(phv)
        if not exact:
            D = self.dm(-muv, self.nfourier, [-MU0])[:, :, :, 0]          # (2, Nv, nf)
            cm = (2.0 - (np.arange(self.nfourier) == 0)) * np.cos(np.arange(self.nfourier)[None, :] * phv[:, None])
            pf = (D * cm[None]).sum(axis=-1)                                # (2, Nv)
        ss = np.zeros_like(muv)
        for l in range(len(self.layers)):
            a, b, d = self.t_top[l], self.tau_cum[l], self.dtau[l]
            p = self.phase_exact(l, cos0) if exact else self.fr[l] * pf[0] + self.fc[l] * pf[1]
            ss += (self.omega[l] * F0 * p / (4 * math.pi) * math.exp(-a / MU0)
                   * np.exp(-(self.T - b) * beta) * beta * E(1.0 / MU0, beta, d))
        return ss

    # --- multiple scattering, Fourier modes
    def ms_modes(self, muv, nf=None):
        """I_ms,m at the ground for photons propagating in (-muv, .), (Nv, nf): analytic in depth."""
        nf = self.nfourier if nf is None else nf
        muv = np.asarray(muv, float)
        beta = 1.0 / muv                                   # (Nv,)
        N = self.nquad // 2
        D = self.dm(-muv, nf)                              # (2, Nv, nf, NQuad)
        out = np.zeros((len(muv), nf))
        for l in range(len(self.layers)):
            a, b, d = self.t_top[l], self.tau_cum[l], self.dtau[l]
            K = self.K[:nf, l, :]                           # (nf, NQuad)
            Fm = np.empty((len(muv), nf, self.nquad))
            kneg = -K[:, :N]                                # > 0, decays from the layer top
            Fm[:, :, :N] = beta[:, None, None] * E(kneg[None], beta[:, None, None], d)
            kpos = K[:, N:]                                 # > 0, decays from the layer bottom
            s = kpos[None] + beta[:, None, None]
            Fm[:, :, N:] = beta[:, None, None] * -np.expm1(-s * d) / s
            Fb = beta * math.exp(-a / MU0) * E(1.0 / MU0, beta, d)            # (Nv,)
            # Q[v, m, i] = sum_j GC[m, l, i, j] F[v, m, j] + B[m, l, i] Fb[v]
            Q = np.einsum("mij,vmj->vmi", self.GC[:nf, l], Fm, optimize=True)
            Q += self.B[:nf, l, :][None] * Fb[:, None, None]
            Dl = self.fr[l] * D[0] + self.fc[l] * D[1]        # (Nv, nf, NQuad)
            att = np.exp(-(self.T - b) * beta)               # (Nv,)
            out += (0.5 * self.omega[l]) * att[:, None] * np.einsum("vmi,vmi->vm", Dl * self.Wfull, Q)
        return self.rescale * out

    def radiance(self, muv, phis, exact=True):
        """Diffuse radiance at the ground, (len(muv), len(phis)), for photons propagating in (-muv, phi)."""
        muv = np.asarray(muv, float)
        phis = np.asarray(phis, float)
        I_m = self.ms_modes(muv)
        cosm = np.cos(np.arange(self.nfourier)[:, None] * phis[None, :])
        ms = I_m @ cosm
        MU, PH = np.meshgrid(muv, phis, indexing="ij")
        ss = self.single_scatter(MU.ravel(), PH.ravel(), exact=exact).reshape(MU.shape)
        return ms + ss

    def fluxes_at_ground(self):
        up = float(self.Fp(self.T))
        diff, direct = self.Fm(self.T)
        return float(diff), float(direct), up


def sky(col):
    mu = np.cos(np.radians(np.array(VIEW_ZENITH_DEG, float)))
    ph = np.radians(np.array(REL_AZIMUTH_DEG, float))
    return col.radiance(mu, ph)


# ----------------------------------------------------------------------------- checks

def check_nodes(col):
    """At DISORT's downward nodes (truncated phase in the beam term) against its own intensities: the max
    relative difference at the nodes with mu > 0.08 (view zenith < 85.4 deg) and at all nodes."""
    N = col.nquad // 2
    phis = np.radians(np.array(REL_AZIMUTH_DEG, float))
    mine = col.radiance(col.mu_pos, phis, exact=False)
    ref = np.asarray(col.u(col.T, phis))[N:, :]
    r = np.abs(mine / ref - 1)
    return float(np.max(r[col.mu_pos > 0.08])), float(np.max(r))


def panels(delta, ng):
    """Gauss-Legendre nodes/weights on [0, delta], panels graded geometrically toward both ends."""
    d = [0.0]
    x = 1e-6
    while x < 0.5 * delta:
        d.append(x)
        x *= 4.0
    d.append(0.5 * delta)
    edges = sorted(set(d + [delta - v for v in d]))
    g, w = np.polynomial.legendre.leggauss(ng)
    ts, ws = [], []
    for lo, hi in zip(edges[:-1], edges[1:]):
        ts.append(lo + 0.5 * (hi - lo) * (g + 1))
        ws.append(0.5 * (hi - lo) * w)
    return np.concatenate(ts), np.concatenate(ws)


def ms_numeric(col, muv, phv, ng):
    """Multiple-scattering term by numerical depth quadrature of J from PythonicDISORT's public u(tau, phi)
    (the angular integral as a Gauss x exact-trapezoid sum over its intensities, as in regen_disort.py)."""
    nphi = 2 * col.nfourier + 2 * col.nquad + 2
    phik = 2 * math.pi * np.arange(nphi) / nphi
    wq = (col.Wfull[:, None] * (2 * math.pi / nphi)) * np.ones((1, nphi))
    m = muv[:, None, None]
    cos = -m * col.mu[None, :, None] + np.sqrt(1 - m**2) * np.sqrt(1 - col.mu**2)[None, :, None] * np.cos(
        phv[:, None, None] - phik[None, None, :])
    PR = legval(cos, col.wl_r).reshape(len(muv), -1)
    PH = legval(cos, col.wl_hg).reshape(len(muv), -1)
    out = np.zeros(len(muv))
    for l in range(len(col.layers)):
        a, b = col.t_top[l], col.tau_cum[l]
        t, wt = panels(b - a, ng)
        t = np.clip(a + t, np.nextafter(a, np.inf), b)
        I = np.asarray(col.u(t, phik)).reshape(col.nquad, len(t), nphi)
        A = (I * wq[:, None, :]).transpose(0, 2, 1).reshape(col.nquad * nphi, len(t))
        J = col.omega[l] / (4 * math.pi) * ((col.fr[l] * PR + col.fc[l] * PH) @ A)    # (Nv, Nt)
        att = np.exp(-(col.T - t)[None, :] / muv[:, None]) / muv[:, None]
        out += (J * att) @ wt
    return out


def check_depth_quadrature(col):
    mu = np.cos(np.radians(np.array(VIEW_ZENITH_DEG, float)))
    ph = np.radians(np.array(REL_AZIMUTH_DEG, float))
    M, P = np.meshgrid(mu, ph, indexing="ij")
    M, P = M.ravel(), P.ravel()
    ms_an = (col.ms_modes(mu) @ np.cos(np.arange(col.nfourier)[:, None] * ph[None, :])).ravel()
    tot = ms_an + col.single_scatter(M, P)
    n16 = ms_numeric(col, M, P, 16)
    n8 = ms_numeric(col, M, P, 8)
    return float(np.max(np.abs(n16 - ms_an) / tot)), float(np.max(np.abs(n8 - ms_an) / tot))


def check_fluxes(col):
    diff, direct, up = col.fluxes_at_ground()
    N = col.nquad // 2
    # Hemispheric integral of the line-of-sight radiances: Gauss in mu; in phi the multiple-scattering part
    # keeps only its m = 0 mode, the single-scattering part by a 2048-point trapezoid (periodic).
    nmu, nphi = 256, 2048
    mg, wg = subroutines.Gauss_Legendre_quad(nmu)
    ms0 = col.ms_modes(mg, nf=1)[:, 0]
    pg = 2 * math.pi * np.arange(nphi) / nphi
    MU, PH = np.meshgrid(mg, pg, indexing="ij")
    ss = col.single_scatter(MU.ravel(), PH.ravel()).reshape(MU.shape).mean(axis=1)
    f_user = float(2 * math.pi * np.sum(wg * mg * (ms0 + ss)))
    u0 = np.asarray(col.u0(col.T)).ravel()
    f_nodes = 2 * math.pi * float(np.sum(col.W * col.mu_pos * u0[N:]))
    # Energy: absorbed = 1 - reflected at the top - net flux into the ground, against
    # sum_layers (1 - omega) * int (diffuse + direct actinic flux) dtau.
    balance = MU0 * F0 - float(col.Fp(0.0)) - (diff + direct - up)
    implied = 0.0
    for l in range(len(col.layers)):
        a, b = col.t_top[l], col.tau_cum[l]
        U = np.asarray(col.u0(np.array([np.nextafter(a, np.inf), b]), is_antiderivative_wrt_tau=True))
        act = 2 * math.pi * float(np.sum(col.Wfull * (U[:, 1] - U[:, 0])))
        act += F0 * MU0 * (math.exp(-a / MU0) - math.exp(-b / MU0))
        implied += (1 - col.omega[l]) * act
    return dict(
        flux_down_direct_vs_mu0_exp=rnd(direct / (MU0 * F0 * math.exp(-col.T / MU0)) - 1, 3)
        if col.T / MU0 < 700 else 0.0,
        flux_down_diffuse_nodes_vs_disort=rnd(f_nodes / diff - 1, 3),
        flux_down_diffuse_user_angles_vs_disort=rnd(f_user / diff - 1, 3),
        flux_up_vs_albedo_times_down=rnd(up / (GROUND_ALBEDO * (diff + direct)) - 1, 3),
        absorbed_per_mu0F0_from_flux_balance=rnd(balance / (MU0 * F0), 6),
        absorbed_per_mu0F0_from_omega=rnd(implied / (MU0 * F0), 6),
        absorbed_balance_vs_omega_rel_diff=rnd(balance / implied - 1, 3),
    )


def maxrel(a, b):
    return float(np.max(np.abs(a / b - 1)))


# ----------------------------------------------------------------------------- main

def run_case(job):
    """One (cloud, wavelength) case with all its checks; returns plain data (runs in a worker process)."""
    tau_c, l = job
    sigma = read_sigma_cm2()
    rel = f"tests/atmospheres/disort_cloud_tau{int(tau_c)}.toml"
    tag = f"{Path(rel).stem}@{int(l)}"
    t0 = time.time()
    layers, _ = make_layers(sigma[l], tau_c)
    col = Column(layers, NQUAD)
    rad = sky(col)
    d_lo = maxrel(sky(Column(layers, NQUAD_CHECK[0])), rad)
    d_hi = maxrel(sky(Column(layers, NQUAD_CHECK[1])), rad)
    d_nf = maxrel(sky(Column(layers, NQUAD, nfourier=NFOURIER_CHECK)), rad)
    fine_layers, _ = make_layers(sigma[l], tau_c, nsub=NSUB_CHECK, nramp=NRAMP_CHECK)
    d_sub = maxrel(sky(Column(fine_layers, NQUAD)), rad)
    # Rayleigh component albedo 1 - 1e-6 instead of 1: radiances are linear in (1 - omega_R) near 1,
    # so the deviation from omega_R = 1 is (I(1 - 1e-6) - I(1 - 1e-5)) / 9.
    o5, _ = make_layers(sigma[l], tau_c, ray_omega=1.0 - 1e-5)
    d_om = maxrel(sky(Column(o5, NQUAD)), rad) / 9.0
    node, node_all = check_nodes(col)
    depthq = None
    if l == DEPTH_CHECK_NM:  # ~2 min each: one wavelength per cloud
        dq16, dq8 = check_depth_quadrature(col)
        depthq = {"gauss_16_per_panel_vs_analytic": rnd(dq16, 3), "gauss_8_per_panel_vs_analytic": rnd(dq8, 3)}
    fl = check_fluxes(col)
    conv = {f"nquad_{NQUAD_CHECK[0]}_vs_{NQUAD}": rnd(d_lo, 3),
            f"nquad_{NQUAD_CHECK[1]}_vs_{NQUAD}": rnd(d_hi, 3),
            f"nfourier_{NFOURIER_CHECK}_vs_{NFOURIER}": rnd(d_nf, 3),
            f"sublayers_{NSUB_CHECK}_ramps_{NRAMP_CHECK}_vs_{NSUB}_1": rnd(d_sub, 3)}
    diff, direct, up = col.fluxes_at_ground()
    iv60 = VIEW_ZENITH_DEG.index(60)
    log(f"{tag}: tau_R {sum(L['tau_r'] for L in layers):.6f} tau_C {sum(L['tau_c'] for L in layers):.9f}; "
        f"max rel change NQuad {NQUAD}->{NQUAD_CHECK[1]} {d_hi:.2e}, {NQUAD_CHECK[0]}->{NQUAD} {d_lo:.2e}, "
        f"NFourier {NFOURIER_CHECK} {d_nf:.2e}, sublayers {d_sub:.2e}, omega_R {d_om:.1e}; nodes {node:.1e} "
        f"(all {node_all:.1e}); depth quadrature {depthq}; zenith {rad[0, 0]:.6e} view60/az0 {rad[iv60, 0]:.6e} "
        f"view85/az180 {rad[-1, -1]:.6e}; fluxes {fl}; {time.time() - t0:.1f} s")
    case = {
        "atmosphere": rel,
        "wavelength_nm": l,
        "sun_zenith_deg": SUN_ZENITH_DEG,
        "cloud_optical_depth": rnd(sum(L["tau_c"] for L in layers)),
        "tau_rayleigh": rnd(sum(L["tau_r"] for L in layers)),
        "tau_total": rnd(col.T),
        "ground_albedo": GROUND_ALBEDO,
        "layers": [{
            "z_top_km": rnd(L["z_top_km"]), "z_bottom_km": rnd(L["z_bottom_km"]),
            "tau_rayleigh": rnd(L["tau_r"]), "tau_cloud": rnd(L["tau_c"]),
            "omega": rnd(L["omega"], 12),
            "rayleigh_share_of_scattering": rnd(L["fr"]),
        } for L in layers],
        "view_zenith_deg": [float(v) for v in VIEW_ZENITH_DEG],
        "relative_azimuth_deg": [float(a) for a in REL_AZIMUTH_DEG],
        "radiance_sr_inv": [[rnd(v) for v in row] for row in rad],
        "flux_down_diffuse": rnd(diff),
        "flux_down_direct": rnd(direct),
        "flux_up": rnd(up),
    }
    return dict(tag=tag, case=case, conv=conv, nodes={"mu_above_0.08": rnd(node, 3), "all_nodes": rnd(node_all, 3)},
                depthq=depthq, omega=rnd(d_om, 3), fluxes=fl)


def main():
    t_start = time.time()
    col_km = cloud_column_km()
    raster_km = raster_integral_km(CLOUD_RASTER, 0.0, TOP_KM)
    log(f"cloud profile: column_km (renderer's normalisation) {col_km:.15f}, raster integral {raster_km:.15f}, "
        f"ratio - 1 = {raster_km / col_km - 1:.2e}")
    jobs = [(tau_c, l) for tau_c in CLOUD_TAUS for l in WAVELENGTHS_NM]
    # Cases are independent and each is single-threaded (BLAS threads fixed to 1), so they run in worker
    # processes; the results are collected in job order, so the output does not depend on the count.
    workers = int(os.environ.get("DISORT_JOBS", min(2, os.cpu_count() or 1)))
    if workers > 1:
        from concurrent.futures import ProcessPoolExecutor
        with ProcessPoolExecutor(workers) as ex:
            results = list(ex.map(run_case, jobs))
    else:
        results = [run_case(j) for j in jobs]
    cases = [r["case"] for r in results]
    conv = {r["tag"]: r["conv"] for r in results}
    nodes = {r["tag"]: r["nodes"] for r in results}
    depthq = {r["tag"]: r["depthq"] for r in results if r["depthq"] is not None}
    omega_effect = {r["tag"]: r["omega"] for r in results}
    flux_checks = {r["tag"]: r["fluxes"] for r in results}

    worst = {k: max(v[k] for v in conv.values()) for k in next(iter(conv.values()))}
    notes = [
        "Radiances are DIFFUSE downwelling radiances at the ground, per unit solar irradiance F0 on a surface NORMAL "
        "to the beam, in sr^-1 (the direct flux on the horizontal ground is F0 mu0 exp(-tau/mu0)); the direct beam is "
        "not included. Sun at zenith angle 60 deg (mu0 = 0.5) as a point source (the TOML's 0.533 deg disc is not "
        "modelled; it matters only at view 60 / azimuth 0, the sun's own direction, where HG g = 0.85 averaged over "
        "the disc is ~6e-4 lower than at its centre in the single-scattering part).",
        "view_zenith_deg: from the UPWARD vertical, for a viewer on the ground looking up; relative_azimuth_deg: from "
        "the sun's azimuth, 0 = looking toward the sun. radiance_sr_inv[i][j] is at view_zenith_deg[i], "
        "relative_azimuth_deg[j]. Same conventions as disort.json.",
        "Atmosphere: the air of disort_rayleigh.toml (exponential, 8 km, N0 = 2.5e25 m^-3, cross-section CSV, "
        "depolarisation 0, top 100 km) plus an HG cloud (g 0.85, single-scattering albedo 0.99999, optical depth "
        "tau_c at every wavelength) between 3 and 5 km; Lambertian ground, albedo 0.1. flux_down_diffuse, "
        "flux_down_direct, flux_up: DISORT's fluxes at the ground per unit F0.",
        "Optical depths are those the path tracer integrates: the renderer rasterises densities on a 10 m grid "
        "(linear between nodes) and normalises an aerosol by its profile's 5 m trapezoid column. The cloud profile's "
        "table rows (3.00, 3.01, 4.99, 5.00 km; density 0, 1, 1, 0, linear) are raster nodes, so the raster equals "
        "the profile and carries exactly tau_c (a sharp-edged 3-5 km table would carry 1.005 tau_c). The script "
        "re-implements the raster and the column rule and uses, per layer, tau_rayleigh = sigma * 2.5e25 m^-3 * "
        "(integral of the raster of exp(-z/8 km)) (within 1.3e-7 of the exponential's integral) and tau_cloud = "
        "(tau_c / column) * (integral of the cloud raster); cases[].layers lists them.",
        f"Layers (top down): Rayleigh 5-100 km; cloud ramp 4.99-5.00 km; {NSUB} equal sublayers 3.01-4.99 km; ramp "
        "3.00-3.01 km; Rayleigh 0-3 km; each homogeneous. omega = (omega_R tau_R + 0.99999 tau_C)/(tau_R + tau_C) with "
        "the Rayleigh component's albedo omega_R = 1 - 1e-6 (DISORT refuses 1; see disort.json); the effect of that "
        "against omega_R = 1 is checks.rayleigh_omega_minus_1e-6_vs_1_max_rel_effect. Phase-function moments "
        "chi_l = (Rayleigh share) * (1, 0, 0.1, 0, ...) + (cloud share) * 0.85^l by scattering optical depth "
        "(rayleigh_share_of_scattering).",
        f"Solver: PythonicDISORT, NQuad = {NQUAD} streams, NLeg = NQuad (no delta-M; the truncated HG tail is 0.85^128 "
        f"~ 1e-9), NFourier = {NFOURIER}. Radiances at the view angles by integrating DISORT's source function along "
        "the line of sight, analytically in depth (both its beam term, with the EXACT phase function, and its "
        "multiple-scattering term, from PythonicDISORT's per-layer exponential solution), the angular integral "
        "through the Fourier components of the truncated phase function between the view cosine and the nodes.",
        f"Convergence (max relative change of any radiance, any case): streams doubled {NQUAD}->{NQUAD_CHECK[1]}: "
        f"{worst[f'nquad_{NQUAD_CHECK[1]}_vs_{NQUAD}']:.1e}; halved ->{NQUAD_CHECK[0]}: "
        f"{worst[f'nquad_{NQUAD_CHECK[0]}_vs_{NQUAD}']:.1e}; NFourier {NFOURIER}->{NFOURIER_CHECK}: "
        f"{worst[f'nfourier_{NFOURIER_CHECK}_vs_{NFOURIER}']:.1e}; cloud split refined ({NSUB_CHECK} sublayers, ramps "
        f"halved): {worst[f'sublayers_{NSUB_CHECK}_ramps_{NRAMP_CHECK}_vs_{NSUB}_1']:.1e}. Per case in "
        "checks.convergence_max_rel_change.",
        "Other checks: node_consistency: the line-of-sight integration at DISORT's downward nodes (truncated phase) "
        "against its own intensities, with the beam term's phase function as DISORT has it (Legendre series cut at "
        "NLeg, Fourier series at NFourier: near the forward peak the Fourier modes m >= 64 of the single scattering, "
        "which the radiances here keep, are worth up to 1e-4 at the nodes next to mu0 for tau_c = 1), at the nodes "
        "with mu > 0.08 (the view grid's range) and at all nodes; the grazing nodes (mu < 0.02) differ by up to "
        "~1e-4 at 128 streams (~4e-6 at 64): PythonicDISORT's near-conservative solution is ill-conditioned there "
        "(cf. disort.json's notes); they enter the source function only with their tiny quadrature weights. "
        "depth_quadrature (at "
        "550 nm): the multiple-scattering term integrated numerically instead, from PythonicDISORT's public "
        "u(tau, phi) on Gauss-Legendre panels graded toward each layer edge, relative to the radiance. "
        "In the cloud-free limit (tau_c = 1e-9, albedo 0.3, 64 streams) this script reproduces disort.json's "
        "disort_rayleigh radiances to 1e-6 (checked once by hand, not rerun here). fluxes: direct flux against mu0 exp(-tau/mu0); diffuse downward flux against the hemispheric "
        "integral of DISORT's node intensities and of the line-of-sight radiances (256 Gauss mu x 2048 phi); upward "
        "flux against albedo * total downward; the absorbed fraction from the flux balance against "
        "sum (1 - omega) * actinic flux integrated over each layer.",
    ]
    out = {
        "generated_by": {"script": SCRIPT, "versions": rd.versions(),
                         "regenerate": ".venv-disort/bin/pip install -r scripts/requirements-disort.txt && "
                                       ".venv-disort/bin/python scripts/regen_disort_clouds.py"},
        "notes": notes,
        "cloud_profile": {
            "altitude_km": CLOUD_ALT_KM, "relative_density": CLOUD_DEN, "interpolation": "linear",
            "renderer_column_km": rnd(col_km, 12), "raster_integral_km": rnd(raster_km, 12),
            "raster_vs_column_rel_diff": rnd(raster_km / col_km - 1, 3),
            "g": CLOUD_G, "single_scattering_albedo": CLOUD_SSA,
        },
        "checks": {
            "convergence_max_rel_change": conv,
            "node_consistency_max_rel_diff": nodes,
            "depth_quadrature_max_rel_diff": depthq,
            "rayleigh_omega_minus_1e-6_vs_1_max_rel_effect": omega_effect,
            "fluxes": flux_checks,
        },
        "cases": cases,
    }
    path = ROOT / JSON_REL
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")
    log(f"wrote {JSON_REL} in {time.time() - t_start:.0f} s")


if __name__ == "__main__":
    main()
