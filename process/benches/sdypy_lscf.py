"""Baseline for benches/modal.rs: sdypy-EMA's LSCF (get_poles) on the same FRFs.

Usage: sdypy_lscf.py IN N_LOC POL_ORDER_HIGH. IN holds float64 little-endian: NF frequencies from
0 Hz, then N_LOC FRFs of NF lines as (re, im) pairs. Prints `sdypy_seconds <t>`, best of 2.
"""
import sys
import time

import numpy as np
from sdypy import EMA

inp, nloc, order = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
raw = np.fromfile(inp, dtype="<f8")
nf = raw.size // (1 + 2 * nloc)
freq = raw[:nf]
frf = raw[nf:].reshape(nloc, nf, 2)
frf = frf[:, :, 0] + 1j * frf[:, :, 1]
best = float("inf")
for _ in range(2):
    # lower at the first measured line (the 0 Hz line is padding); upper above the last line:
    # sdypy cuts the line nearest `upper` and everything above.
    m = EMA.Model(frf=frf, freq=freq, lower=freq[1], upper=freq[-1] + 1.0,
                  pol_order_high=order, frf_type="receptance")
    t0 = time.perf_counter()
    m.get_poles(method="lscf", show_progress=False)
    best = min(best, time.perf_counter() - t0)
print(f"sdypy: {len(m.all_poles[-1])} poles at the top order, {nloc} FRFs x {nf} lines")
print(f"sdypy_seconds {best:.6f}")
