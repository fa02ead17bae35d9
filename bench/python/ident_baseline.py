#!/usr/bin/env python3
"""Python baseline of ident's identification benchmark (identify/benches/identification.rs).

Reads the problem JSON the benchmark writes: the resolved model (docs/model-json.md: bodies, SDEs
with six stiffnesses k and dissipations psi each, forces, outputs), the measured amplitudes with
their standard deviations, and the decision variables (initial value, bounds, scale, and per SDE
the change of its k and psi per unit of the variable). Assembles M, K, D with numpy exactly as
identify/src/system.rs does, computes the frequency response by one dense complex solve per line
(batched), and fits the amplitudes with scipy.optimize.least_squares (trust-region reflective,
2-point finite-difference Jacobian) on x / scale within the bounds.

Prints one JSON line: median wall time of the fit over --repeat runs (assembly of the fixed
matrices excluded, as in ident), function evaluations, final cost (J = 1/2 sum r^2), the
estimates, and the largest relative difference between this FRF and ident's at the initial
values (an independent check of the model).

usage: ident_baseline.py PROBLEM.json [--repeat N]
"""
import json
import sys
import time

import numpy as np
from scipy.optimize import least_squares


def skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def sde_from_body(pos, rot_b, point, rot_s):
    a = rot_b.T @ (point - pos)
    r_sb = rot_s.T @ rot_b
    g = np.zeros((6, 6))
    g[:3, :3] = r_sb
    g[:3, 3:] = -r_sb @ skew(a)
    g[3:, 3:] = r_sb
    return g


class Problem:
    def __init__(self, p):
        m = p["model"]
        bodies = m["bodies"]
        self.n = 6 * len(bodies)
        n = self.n
        self.mass = np.concatenate([[b["mass"]] * 3 + list(b["inertia"]) for b in bodies])
        sdes = m["sdes"]
        # T: stacked deformation maps, 6 rows per SDE: delta = G_r q_r - G_p q_p.
        self.T = np.zeros((6 * len(sdes), n))
        for s, e in enumerate(sdes):
            rot_s = np.array(e["rotation"])
            point = np.array(e["point"])
            for side, sign in ((0, -1.0), (1, 1.0)):
                b = e["bodies"][side]
                if b is None:
                    continue
                body = bodies[b]
                g = sde_from_body(np.array(body["position"]), np.array(body["rotation"]), point, rot_s)
                self.T[6 * s:6 * s + 6, 6 * b:6 * b + 6] += sign * g
        self.k0 = np.concatenate([e["k"] for e in sdes])
        self.psi0 = np.concatenate([e["psi"] for e in sdes])
        self.load = np.zeros(n)
        for f in m["excitation"]["forces"]:
            body = bodies[f["body"]]
            rot = np.array(body["rotation"])
            pos = np.array(body["position"])
            point = np.array(f.get("point") or body["position"])
            fl = rot.T @ np.array(f["force"])
            a = rot.T @ (point - pos)
            mom = np.cross(a, fl) + rot.T @ np.array(f.get("moment") or [0.0, 0.0, 0.0])
            self.load[6 * f["body"]:6 * f["body"] + 6] += np.concatenate([fl, mom])
        self.vars = p["variables"]
        self.x0 = np.array([v["x0"] for v in self.vars])
        self.scale = np.array([v["scale"] for v in self.vars])
        self.lower = np.array([v["lower"] for v in self.vars])
        self.upper = np.array([np.inf if v["upper"] is None else v["upper"] for v in self.vars])
        nv = len(self.vars)
        self.dk = np.zeros((nv, len(self.k0)))
        self.dpsi = np.zeros((nv, len(self.k0)))
        for i, v in enumerate(self.vars):
            for t in v["terms"]:
                self.dk[i, 6 * t["sde"]:6 * t["sde"] + 6] += t["dk"]
                self.dpsi[i, 6 * t["sde"]:6 * t["sde"] + 6] += t["dpsi"]
        chars = p["characteristics"]
        self.freqs = np.unique(np.concatenate([c["freqs_hz"] for c in chars]))
        self.rows = []
        for c in chars:
            dof = 6 * c["body"] + c["dof"]
            lines = np.searchsorted(self.freqs, c["freqs_hz"])
            self.rows.append((dof, lines))
        self.z = np.concatenate([c["amplitude"] for c in chars])
        self.sigma = np.concatenate([c["sigma"] for c in chars])
        self.check = np.concatenate([c["check_amplitude"] for c in chars])
        self.omega2 = (2.0 * np.pi * self.freqs) ** 2
        self.nfev = 0

    def amplitudes(self, x):
        dx = x - self.x0
        k = self.k0 + dx @ self.dk
        psi = self.psi0 + dx @ self.dpsi
        kc = k * (1.0 + 1j * psi / (2.0 * np.pi))
        a0 = self.T.T @ (kc[:, None] * self.T)
        a = a0[None, :, :] - self.omega2[:, None, None] * np.diag(self.mass)[None, :, :]
        q = np.linalg.solve(a, np.broadcast_to(self.load.astype(complex), (len(self.freqs), self.n))[..., None])[..., 0]
        return np.concatenate([np.abs(q[lines, dof]) for dof, lines in self.rows])

    def residuals(self, u):
        self.nfev += 1
        return (self.z - self.amplitudes(u * self.scale)) / self.sigma


def main():
    path = sys.argv[1]
    repeat = int(sys.argv[sys.argv.index("--repeat") + 1]) if "--repeat" in sys.argv else 3
    with open(path) as f:
        p = json.load(f)
    prob = Problem(p)
    q0 = prob.amplitudes(prob.x0)
    check = float(np.max(np.abs(q0 - prob.check) / np.abs(prob.check)))
    times = []
    res = None
    for _ in range(repeat):
        prob.nfev = 0
        t = time.perf_counter()
        res = least_squares(
            prob.residuals,
            prob.x0 / prob.scale,
            bounds=(prob.lower / prob.scale, prob.upper / prob.scale),
            method="trf",
            jac="2-point",
            xtol=1e-9,
            ftol=1e-12,
            gtol=1e-8,
            max_nfev=20000,
        )
        times.append(time.perf_counter() - t)
    print(json.dumps({
        "median_s": float(np.median(times)),
        "nfev": prob.nfev,
        "cost": float(res.cost),
        "status": int(res.status),
        "x": (res.x * prob.scale).tolist(),
        "frf_check_max_rel": check,
    }))


if __name__ == "__main__":
    main()
