"""Baseline for benches/welch.rs: H1 + coherence with scipy.signal.csd/welch on the same data.

Generates the same splitmix64 signals as the Rust benchmark (force + 8 responses, 2^24 samples),
times csd (force vs all responses, broadcast) + welch (force, responses), H1 and coherence, best
of 2 runs; prints `scipy_seconds <t>` and peak memory; writes H1/coherence at lines 100, 1000,
3000 to argv[1] for the same-data check.
"""
import resource
import sys
import time

import numpy as np
from scipy import signal

LEN, RESP, SEG = 1 << 24, 8, 8192
M1, M2, M3 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB), np.uint64(0x9E3779B97F4A7C15)


def uniform(ch, n):
    z = (np.uint64(ch) << np.uint64(40)) | n
    z = z + M3
    z = (z ^ (z >> np.uint64(30))) * M1
    z = (z ^ (z >> np.uint64(27))) * M2
    z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53)) - 0.5


def main(out):
    with np.errstate(over="ignore"):
        n = np.arange(LEN, dtype=np.uint64)
        x = uniform(0, n)
        y = np.empty((RESP, LEN))
        for j in range(RESP):
            y[j] = (0.5 + 0.1 * j) * x + uniform(j + 1, n)
        del n
    kw = dict(fs=1.0, window="hann", nperseg=SEG, noverlap=SEG // 2, detrend="constant")
    best = None
    for _ in range(2):
        t0 = time.perf_counter()
        _, pxy = signal.csd(x[None, :], y, **kw)
        _, pxx = signal.welch(x, **kw)
        _, pyy = signal.welch(y, **kw)
        h1 = pxy / pxx
        coh = np.abs(pxy) ** 2 / (pxx * pyy)
        dt = time.perf_counter() - t0
        best = dt if best is None else min(best, dt)
    rows = []
    for k in (100, 1000, 3000):
        for j in range(RESP):
            rows += [h1[j, k].real, h1[j, k].imag, coh[j, k]]
    np.array(rows, "<f8").tofile(out)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"scipy: csd+welch+H1+coherence best of 2: {best:.3f} s; peak memory (ru_maxrss) {peak:.0f} MiB "
          f"(input arrays alone {9 * LEN * 8 / 2**20:.0f} MiB)")
    print(f"scipy_seconds {best:.6f}")


if __name__ == "__main__":
    main(sys.argv[1])
