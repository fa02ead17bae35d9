"""Independent milling/turning stability lobes of a resolved-model JSON, with numpy and scipy.

Written for the cross-check of `ident stability` (tests/cli_stability.rs) from the method's
textbook statement, not from the Rust code:
- the model's dynamic stiffness K + jD - w^2 M from docs/model-json.md (global-frame form, as
  contract_frf.py), solved directly per frequency line (numpy.linalg.solve, batched);
- the relative tool-workpiece receptance Phi_ij: row i reads d_i.(x_tool - x_workpiece), load j
  is +d_j on the tool point and -d_j on the workpiece point;
- milling: Altintas & Budak's zeroth-order approximation with the average directional matrix
  integrated numerically (scipy.integrate.quad) from the instantaneous one; turning: Tlusty's
  G = Kr Phi_00 + Kt Phi_01;
- lobes: a = -1/(2 Re G), eps = 2 arg G - pi, n = 60 f / (N (eps/2pi + k)), the boundary the lowest
  lobe at each speed (linear interpolation along each lobe between lines).

Usage: stability_zoa.py MODEL.json CUT.toml  -> JSON {speeds_rpm, depth_m, chatter_hz, seconds}
(`seconds`: the FRF and lobes, after reading the files, for the benchmark).
"""
import json
import re
import sys
import time
import tomllib

import numpy as np
from scipy.integrate import quad

UNITS = {"": 1.0, "m": 1.0, "mm": 1e-3, "Pa": 1.0, "kPa": 1e3, "MPa": 1e6, "GPa": 1e9,
         "N/mm^2": 1e6, "N/m^2": 1.0, "Hz": 1.0, "N/um": 1e6, "N/m": 1.0}


def value(v):
    if isinstance(v, (int, float)):
        return float(v)
    m = re.fullmatch(r"\s*([-+0-9.eE]+)\s*(\S*)\s*", v)
    return float(m.group(1)) * UNITS[m.group(2)]


def skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def point_map(body, x):
    R = np.array(body["rotation"], dtype=float)
    c = np.array(body["position"], dtype=float)
    return np.hstack([R, -skew(np.asarray(x, dtype=float) - c) @ R])


def assemble(model):
    bodies = model["bodies"]
    assert not model.get("point_masses"), "point masses are not handled by this check"
    n = 6 * len(bodies)
    M = np.zeros(n)
    for i, b in enumerate(bodies):
        M[6 * i:6 * i + 6] = [b["mass"]] * 3 + list(b["inertia"])
    K = np.zeros((n, n))
    D = np.zeros((n, n))
    for s in model["sdes"]:
        if not s.get("enabled", True):
            continue
        Rs = np.array(s["rotation"], dtype=float)
        T = np.zeros((6, n))
        for side, sign in ((0, -1.0), (1, 1.0)):
            b = s["bodies"][side]
            if b is None:
                continue
            body = bodies[b]
            T[0:3, 6 * b:6 * b + 6] += sign * Rs.T @ point_map(body, s["point"])
            Rb = np.array(body["rotation"], dtype=float)
            T[3:6, 6 * b + 3:6 * b + 6] += sign * Rs.T @ Rb
        k = np.array(s["k"], dtype=float)
        psi = np.array(s["psi"], dtype=float)
        K += T.T @ np.diag(k) @ T
        D += T.T @ np.diag(psi / (2 * np.pi) * k) @ T
    return M, K, D


def unit(v):
    v = np.array(v, dtype=float)
    return v / np.linalg.norm(v)


def main():
    model = json.load(open(sys.argv[1]))
    cut = tomllib.load(open(sys.argv[2], "rb"))
    names = [b["name"] for b in model["bodies"]]
    op = cut["operation"]
    if op == "milling":
        mil = cut["milling"]
        feed = unit(mil["feed"])
        axis = unit(mil.get("axis", [0.0, 0.0, 1.0]))
        dirs = [feed, np.cross(axis, feed)]
        periods = int(mil["teeth"])
    else:
        dirs = [unit(cut["turning"]["thickness"]), unit(cut["turning"]["cutting"])]
        periods = 1
    kt, kr = value(cut["cutting"]["kt"]), value(cut["cutting"]["kr"])
    speeds = np.linspace(cut["speed_rpm"][0], cut["speed_rpm"][1], int(cut.get("speeds", 200)))
    lines = int(cut.get("lines", 4000))
    t0 = time.perf_counter()

    M, K, D = assemble(model)
    n = len(M)
    # rows R (2 x n) and loads P (n x 2) of the relative receptance
    R = np.zeros((2, n))
    P = np.zeros((n, 2))
    for role, sign in (("tool", 1.0), ("workpiece", -1.0)):
        c = cut[role]
        if c["body"] == "ground":
            continue
        b = names.index(c["body"])
        Tm = point_map(model["bodies"][b], c["point"])
        for i, d in enumerate(dirs):
            R[i, 6 * b:6 * b + 6] += sign * d @ Tm
            P[6 * b:6 * b + 6, i] += sign * Tm.T @ d
    # frequency grid: log-spaced around the modes, as docs/stability.md states
    if "band_hz" in cut:
        lo, hi = cut["band_hz"]
    else:
        lam = np.linalg.eigvals((K + 1j * D) / M[:, None])
        f = np.sqrt(np.maximum(lam.real, 0.0)) / (2 * np.pi)
        tool_f = [value(m["freq"]) for m in cut["tool"].get("mode", [])]
        f = np.concatenate([f[f > 0], tool_f])
        lo, hi = 0.7 * f.min(), 1.3 * f.max()
    freqs = lo * (hi / lo) ** (np.arange(lines) / (lines - 1))
    w = 2 * np.pi * freqs
    phi = np.empty((lines, 2, 2), dtype=complex)
    A0 = K + 1j * D
    for s in range(0, lines, 500):
        ww = w[s:s + 500]
        A = A0[None, :, :] - (ww ** 2)[:, None, None] * np.diag(M)[None, :, :]
        X = np.linalg.solve(A, np.broadcast_to(P, (len(ww), n, 2)))
        phi[s:s + 500] = R[None, :, :] @ X
    for m in cut["tool"].get("mode", []):
        d = unit(m["direction"])
        r = freqs / value(m["freq"])
        h = 1.0 / (value(m["stiffness"]) * (1 - r * r + 2j * m["damping_ratio"] * r))
        e = np.array([di @ d for di in dirs])
        phi += h[:, None, None] * np.outer(e, e)[None, :, :]

    if op == "milling":
        D_ = value(mil["diameter"])
        ae = value(mil["radial_depth"])
        c = np.clip(1 - 2 * ae / D_, -1.0, 1.0)
        st, ex = (0.0, np.arccos(c)) if mil["direction"] == "up" else (np.pi - np.arccos(c), np.pi)
        rho = kr / kt

        def inst(p, i, j):
            s, co = np.sin(p), np.cos(p)
            return [[-s * (co + rho * s), -co * (co + rho * s)],
                    [s * (s - rho * co), co * (s - rho * co)]][i][j]

        # 1/2 Kt A0 = N/(2 pi) * integral of the instantaneous matrix (per unit Kt)
        H0 = np.array([[quad(inst, st, ex, args=(i, j))[0] for j in range(2)] for i in range(2)])
        H0 *= periods / (2 * np.pi)
        B = H0[None, :, :] @ phi
        lam = np.linalg.eigvals(B)
        # follow the two eigenvalues from line to line (nearest match)
        for l in range(1, lines):
            a, b = lam[l]
            if abs(a - lam[l - 1, 0]) + abs(b - lam[l - 1, 1]) > abs(b - lam[l - 1, 0]) + abs(a - lam[l - 1, 1]):
                lam[l] = [b, a]
        G = -kt * lam  # F = a Kt H0 (r - r_tau), r = Phi F: 1 + a (1 - e) G = 0
    else:
        G = (kr * phi[:, 0, 0] + kt * phi[:, 0, 1])[:, None]

    best = np.full(len(speeds), np.inf)
    chatter = np.full(len(speeds), np.nan)
    for b in range(G.shape[1]):
        g = G[:, b]
        ok = (g.real[:-1] < 0) & (g.real[1:] < 0)
        arg = np.mod(np.angle(g), 2 * np.pi)
        eps = 2 * arg - np.pi
        ok &= np.abs(np.diff(eps)) <= np.pi
        a = -0.5 / g.real
        kmax = int(np.floor(60 * freqs.max() / (periods * speeds[0])))
        for k in range(kmax + 1):
            nn = 60 * freqs / (periods * (eps / (2 * np.pi) + k))
            n0, n1 = nn[:-1][ok], nn[1:][ok]
            a0, a1 = a[:-1][ok], a[1:][ok]
            f0, f1 = freqs[:-1][ok], freqs[1:][ok]
            lo_, hi_ = np.minimum(n0, n1), np.maximum(n0, n1)
            for i, s in enumerate(speeds):
                m = (lo_ <= s) & (s <= hi_) & (hi_ > lo_)
                if not m.any():
                    continue
                t = (s - n0[m]) / (n1[m] - n0[m])
                d = a0[m] + t * (a1[m] - a0[m])
                j = np.argmin(d)
                if d[j] < best[i]:
                    best[i] = d[j]
                    chatter[i] = f0[m][j] + t[j] * (f1[m][j] - f0[m][j])
    seconds = time.perf_counter() - t0
    json.dump({"speeds_rpm": speeds.tolist(),
               "depth_m": [x if np.isfinite(x) else None for x in best],
               "chatter_hz": [x if np.isfinite(x) else None for x in chatter],
               "seconds": seconds}, sys.stdout)


if __name__ == "__main__":
    main()
