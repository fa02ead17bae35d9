"""sdypy-EMA's LSCF on FRFs written by process/tests/modal_sdypy.rs (independent check).

Usage: modal_sdypy.py IN OUT N_LOC LOWER UPPER POL_ORDER APPROX_HZ...
IN: float64 little-endian: NF frequencies (uniform, from 0 Hz), then N_LOC FRFs of NF lines as
(re, im) pairs. OUT: natural frequencies (Hz), damping ratios of the poles sdypy selects closest
to APPROX_HZ, then the seconds sdypy's get_poles took.
"""
import sys
import time

import numpy as np
from sdypy import EMA

inp, out, nloc, lower, upper, order = sys.argv[1:7]
approx = [float(a) for a in sys.argv[7:]]
nloc = int(nloc)
raw = np.fromfile(inp, dtype="<f8")
nf = raw.size // (1 + 2 * nloc)
freq = raw[:nf]
frf = raw[nf:].reshape(nloc, nf, 2)
frf = frf[:, :, 0] + 1j * frf[:, :, 1]
m = EMA.Model(frf=frf, freq=freq, lower=float(lower), upper=float(upper),
              pol_order_high=int(order), frf_type="receptance")
t0 = time.perf_counter()
m.get_poles(method="lscf", show_progress=False)
elapsed = time.perf_counter() - t0
m.select_closest_poles(approx, f_window=max(4.0, 0.05 * max(approx)))
res = np.concatenate([np.asarray(m.nat_freq, float), np.asarray(m.nat_xi, float), [elapsed]])
res.astype("<f8").tofile(out)
