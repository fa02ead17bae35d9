"""sdypy-EMA's LSCF and LSFD on FRFs written by process/tests/modal_layouts.rs (independent check).

Usage: modal_sdypy_shapes.py IN OUT N_LOC LOWER UPPER POL_ORDER FRF_TYPE APPROX_HZ...
IN: float64 little-endian: NF frequencies, then N_LOC FRFs of NF lines as (re, im) pairs.
OUT: natural frequencies (Hz) and damping ratios of the poles sdypy selects closest to APPROX_HZ,
then the residues over the locations (N_LOC × N_MODES, row-major, (re, im) pairs) from sdypy's
LSFD with its own poles.
"""
import sys

import numpy as np
from sdypy import EMA

inp, out, nloc, lower, upper, order, frf_type = sys.argv[1:8]
approx = [float(a) for a in sys.argv[8:]]
nloc = int(nloc)
raw = np.fromfile(inp, dtype="<f8")
nf = raw.size // (1 + 2 * nloc)
freq = raw[:nf]
frf = raw[nf:].reshape(nloc, nf, 2)
frf = frf[:, :, 0] + 1j * frf[:, :, 1]
m = EMA.Model(frf=frf, freq=freq, lower=float(lower), upper=float(upper),
              pol_order_high=int(order), frf_type=frf_type)
m.get_poles(method="lscf", show_progress=False)
m.select_closest_poles(approx, f_window=max(4.0, 0.05 * max(approx)))
m.get_constants(method="lsfd", whose_poles="own", FRF_ind="all")
a = np.asarray(m.A, complex)
res = np.concatenate([np.asarray(m.nat_freq, float), np.asarray(m.nat_xi, float),
                      np.stack([a.real, a.imag], axis=-1).ravel()])
res.astype("<f8").tofile(out)
