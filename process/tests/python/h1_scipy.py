"""Independent H1/coherence with scipy.signal.csd, for process/tests/scipy.rs.

usage: h1_scipy.py welch IN OUT FS NPERSEG NOVERLAP WINDOW DETREND NREF NRESP
       h1_scipy.py impact OUT FORCE_WIDTH EXP_END FILE...
IN: raw float64 little-endian, channels (refs then responses) concatenated.
OUT: raw float64 little-endian: per response j, per ref i: Re H, Im H (nf each);
     then per response multiple coherence (nf), then per ref Pxx (nf), per response Pyy (nf).
"""
import sys
import numpy as np
from scipy import signal


def welch_mode(args):
    inp, out, fs, nperseg, noverlap, window, detrend, nref, nresp = args
    fs, nperseg, noverlap, nref, nresp = float(fs), int(nperseg), int(noverlap), int(nref), int(nresp)
    detrend = False if detrend == "none" else detrend
    x = np.fromfile(inp, dtype="<f8").reshape(nref + nresp, -1)
    refs, resps = x[:nref], x[nref:]
    kw = dict(fs=fs, window=window, nperseg=nperseg, noverlap=noverlap, detrend=detrend)
    gxx = np.empty((nref, nref, nperseg // 2 + 1), complex)
    for i in range(nref):
        for l in range(nref):
            _, gxx[i, l] = signal.csd(refs[i], refs[l], **kw)
    gxy = np.empty((nref, nresp, nperseg // 2 + 1), complex)
    for i in range(nref):
        for j in range(nresp):
            _, gxy[i, j] = signal.csd(refs[i], resps[j], **kw)
    gyy = np.array([signal.welch(resps[j], **kw)[1] for j in range(nresp)])
    write(out, gxx, gxy, gyy)


def write(out, gxx, gxy, gyy):
    nref, nresp, nf = gxy.shape
    H = np.empty((nresp, nref, nf), complex)
    mc = np.empty((nresp, nf))
    for k in range(nf):
        # G_xx h_j = g_xy,j for every response j.
        h = np.linalg.solve(gxx[:, :, k], gxy[:, :, k])  # (nref, nresp)
        H[:, :, k] = h.T
        for j in range(nresp):
            mc[j, k] = np.real(np.vdot(gxy[:, j, k], h[:, j])) / gyy[j, k]
    parts = []
    for j in range(nresp):
        for i in range(nref):
            parts += [H[j, i].real, H[j, i].imag]
    parts += list(mc)
    parts += [gxx[i, i].real for i in range(nref)]
    parts += list(gyy)
    np.concatenate(parts).astype("<f8").tofile(out)


def impact_mode(args):
    out, width, end, files = args[0], float(args[1]), float(args[2]), args[3:]
    sxx = sxy = syy = 0
    fs = None
    for f in files:
        d = np.load(f)
        # One sample rate for all records (the time rows differ in the last bits from file to
        # file; a per-file rate would weight the averages unequally by ~1e-10).
        fs = fs or 1.0 / (d[0, 1] - d[0, 0])
        n = d.shape[1]
        force_w = (np.arange(n) < int(round(width * n))).astype(float)
        exp_w = np.exp(np.log(end) * np.arange(n) / (n - 1))
        x = d[1] * force_w * exp_w
        y = d[2] * exp_w
        kw = dict(fs=fs, window="boxcar", nperseg=n, noverlap=0, detrend=False)
        sxx = sxx + signal.csd(x, x, **kw)[1]
        sxy = sxy + signal.csd(x, y, **kw)[1]
        syy = syy + signal.csd(y, y, **kw)[1]
    h1 = sxy / sxx
    coh = np.abs(sxy) ** 2 / (sxx.real * syy.real)
    np.concatenate([h1.real, h1.imag, coh]).astype("<f8").tofile(out)


if __name__ == "__main__":
    {"welch": welch_mode, "impact": impact_mode}[sys.argv[1]](sys.argv[2:])
