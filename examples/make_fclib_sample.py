"""Write ``examples/box-3-contacts.hdf5``: a small FCLib local problem to try ``fixplan fclib`` on.

The default 3-2-1 box (2 kg, ``fixplan/data/default.toml``) rests at its start pose on the three
base locators B1, B2, B3 (μ = 0.25). One Moreau–Jean step of h = 1 ms from rest under gravity
gives the local problem ``u = W r + q`` with ``W = J M⁻¹ Jᵀ`` and ``q = J M⁻¹ h w_g`` (contact
frame rows: normal, tangent 1, tangent 2 per contact). Its solution holds the box: every contact
velocity is 0 and the normal impulses add up to m g h = 0.01962 N·s (how they split depends on
the tangential impulses, which friction leaves statically indeterminate).

Run from the repository root: ``.venv/bin/python examples/make_fclib_sample.py``.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

import fixplan
from fixplan.fixture import default_fixture_path
from fixplan.locating import contact_set

H_S = 1e-3  # time step [s]
OUT = Path(__file__).resolve().parent / "box-3-contacts.hdf5"


def main() -> None:
    """Build the problem from the default fixture and write it beside this script."""
    fixture = fixplan.load(default_fixture_path())
    cs = contact_set(fixture, "start")
    J = cs.J  # (3 k) x 6, rows (n, t1, t2) per contact
    M_inv = np.linalg.inv(cs.mass_matrix)
    W = J @ M_inv @ J.T
    q = J @ M_inv @ (H_S * fixture.gravity_wrench())
    mu = np.array([c.friction for c in cs.contacts])
    W[np.abs(W) < 1e-15] = 0.0
    rows, cols = np.nonzero(W)
    with h5py.File(OUT, "w") as fh:
        root = fh.create_group("fclib_local")
        root["spacedim"] = np.array([3], np.int32)
        g = root.create_group("W")
        m = W.shape[0]
        g["m"] = np.array([m], np.int32)
        g["n"] = np.array([m], np.int32)
        g["nz"] = np.array([-2], np.int32)  # compressed rows
        g["nzmax"] = np.array([len(rows)], np.int32)
        g["p"] = np.searchsorted(rows, np.arange(m + 1)).astype(np.int32)
        g["i"] = cols.astype(np.int32)
        g["x"] = W[rows, cols]
        vec = root.create_group("vectors")
        vec["q"] = q
        vec["mu"] = mu
        info = root.create_group("info")
        info["title"] = np.bytes_(b"box-3-contacts")
        info["description"] = np.bytes_(
            f"fixplan's default 3-2-1 box at rest on {', '.join(cs.names)}: one 1 ms step under gravity".encode()
        )
        info["math_info"] = np.bytes_(b"u = W r + q, Coulomb friction")
    print(f"wrote {OUT}: {len(mu)} contacts, W {m}x{m} with {len(rows)} entries")


if __name__ == "__main__":
    main()
