#!/usr/bin/env python3
"""Python baseline of ident's identification: numpy FRF + scipy.optimize.least_squares.

Reads the fit problem that `ident identify MODEL --data DATA --vars VARS --export-problem P.json`
writes (docs/identification.md, "Problem export"): the resolved model at the initial values
(docs/model-json.md), the observations (characteristic, line, measured amplitude, sigma), and the
decision variables (initial value, bounds, internal scale, and per SDE the change of its six k and
six psi per unit of the variable; per body the change of its [m, m, m, J1, J2, J3]; per point mass
the change of its mass; per sensor gain the ratio). Then it solves the same problem as ident, like
for like:

- the same criterion J = 1/2 sum((|z| - |q(x)|) / sigma)^2 on the same observations;
- the same scaled variables u = x / scale, the same start, the same bounds;
- the FRF by numpy: M, K, D assembled as rfe/src/system.rs does (independently written from
  docs/model-json.md; a point mass adds its 6x6 block with the parallel-axis terms to its body's),
  one batched dense complex solve over all lines; a gain multiplies its characteristics' outputs;
- `--jac analytic` (default): the adjoint Jacobian that ident uses, dq_o/dp = -(T w_o)^T dK_c (T q)
  with w_o = A^-1 e_o (A is complex symmetric), obtained from the same batched solve with the output
  unit vectors as extra right-hand sides (a mass: dq_o/dp = omega^2 w_o^T dM q; a gain g:
  d|g q|/dg = |q|); `--jac 2-point`: scipy's forward differences.

Prints one JSON line: the fit's wall time (median over --repeat runs; reading the file and
assembling the fixed matrices excluded), function/Jacobian evaluations, final cost, status, the
estimates (SI), and the largest relative difference between this FRF and ident's at the initial
values (an independent check of the model; the problem file carries ident's amplitudes), and of
the analytic Jacobian against central differences.

bench/python/identify_vs_scipy.py runs it against the `ident identify` binary in the same run.

usage: ident_baseline.py PROBLEM.json [--repeat N] [--jac analytic|2-point] [--max-nfev N]
"""
import json
import os
import sys
import time

# Single-threaded BLAS, like ident: on 42x42 systems threads only add synchronisation, and on a
# loaded machine OpenBLAS's spinning threads make the fit 10-30x slower.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

TWO_PI = 2.0 * np.pi


def skew(a):
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def sde_from_body(pos, rot_b, point, rot_s):
    """6x6 map from a body's coordinates (principal axes at its centre of mass) to the motion of
    `point` in the SDE frame."""
    a = rot_b.T @ (point - pos)
    r_sb = rot_s.T @ rot_b
    g = np.zeros((6, 6))
    g[:3, :3] = r_sb
    g[:3, 3:] = -r_sb @ skew(a)
    g[3:, 3:] = r_sb
    return g


QUANTITY_POWER = {"displacement": 0, "velocity": 1, "acceleration": 2}
DOF_NAMES = ["u1", "u2", "u3", "r1", "r2", "r3"]


def point_mass_block(body, point, mass, inertia):
    """6x6 mass block of a point mass on a body, in the body's coordinates: m at the arm
    a = R^T (p - c), its own inertia (about global x, y, z) rotated into the body's axes."""
    rot = np.array(body["rotation"])
    a = rot.T @ (np.array(point) - np.array(body["position"]))
    s = skew(a)
    block = np.zeros((6, 6))
    block[:3, :3] = mass * np.eye(3)
    block[:3, 3:] = -mass * s
    block[3:, :3] = mass * s
    block[3:, 3:] = mass * s.T @ s + rot.T @ np.diag(inertia) @ rot
    return block


class Problem:
    """The fit problem in scaled variables u = x / scale."""

    def __init__(self, p):
        if p["fit"] != "amplitude":
            raise SystemExit("ident_baseline.py fits amplitudes only (the problem says fit = %r)" % p["fit"])
        m = p["model"]
        bodies = m["bodies"]
        self.n = 6 * len(bodies)
        n = self.n
        for o in m["outputs"]:
            if o.get("at") or o.get("reference") or o.get("relative"):
                raise SystemExit("ident_baseline.py takes principal-axis outputs of the model's excitation only (an output has at/reference/relative)")
        if m.get("references"):
            raise SystemExit("ident_baseline.py takes the model's own excitation only (the model has references)")
        # M as a dense matrix: the bodies' diagonals plus their point masses' blocks.
        self.mass0 = np.diag(np.concatenate([[b["mass"]] * 3 + list(b["inertia"]) for b in bodies]))
        for pm in m.get("point_masses", []):
            b = pm["body"]
            self.mass0[6 * b:6 * b + 6, 6 * b:6 * b + 6] += point_mass_block(
                bodies[b], pm["point"], pm["mass"], pm.get("inertia", [0.0, 0.0, 0.0]))
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
        self.Tc = self.T.astype(complex)  # complex copies: no casts inside the Jacobian
        self.Tc_t = np.ascontiguousarray(self.Tc.T)
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
        self.names = [v["name"] for v in self.vars]
        self.x0 = np.array([v["initial"] for v in self.vars])
        self.scale = np.array([v["scale"] for v in self.vars])
        self.lower = np.array([v["lower"] for v in self.vars])
        self.upper = np.array([np.inf if v["upper"] is None else v["upper"] for v in self.vars])
        nv = len(self.vars)
        self.dk = np.zeros((nv, len(self.k0)))
        self.dpsi = np.zeros((nv, len(self.k0)))
        # dM per unit of each variable (bodies' masses and inertias, point masses), and the
        # gain of each output: (variable, ratio) or None.
        self.dmass = np.zeros((nv, n, n))
        body_index = {b["name"]: i for i, b in enumerate(bodies)}
        gains = {}
        for i, v in enumerate(self.vars):
            for t in v["terms"]:
                if "sde" in t:
                    self.dk[i, 6 * t["sde"]:6 * t["sde"] + 6] += t["dk"]
                    self.dpsi[i, 6 * t["sde"]:6 * t["sde"] + 6] += t["dpsi"]
                elif "point_mass" in t:
                    pm = m["point_masses"][t["point_mass"]]
                    b = pm["body"]
                    self.dmass[i, 6 * b:6 * b + 6, 6 * b:6 * b + 6] += t["dmass"] * point_mass_block(
                        bodies[b], pm["point"], 1.0, [0.0, 0.0, 0.0])
                elif "gain" in t:
                    key = (body_index[t["gain"]["body"]], DOF_NAMES.index(t["gain"]["dof"]))
                    gains[key] = (i, t["ratio"])
                elif "body" in t:
                    b = t["body"]
                    self.dmass[i, 6 * b:6 * b + 6, 6 * b:6 * b + 6] += np.diag(t["dm"])
                else:
                    raise SystemExit("unknown term %r of variable %r" % (sorted(t), v["name"]))
        self.mass_vars = [i for i in range(nv) if np.any(self.dmass[i])]
        self.freqs = np.array(p["lines_hz"])
        omega = TWO_PI * self.freqs
        self.omega2 = omega ** 2
        outs = m["outputs"]
        self.out_dof = np.array([6 * o["body"] + o["dof"] for o in outs])
        # (j omega)^k per output and line: displacement, velocity, acceleration.
        self.out_factor = np.array([(1j * omega) ** QUANTITY_POWER[o["quantity"]] for o in outs])
        self.out_gain = [gains.get((o["body"], o["dof"])) for o in outs]
        obs = p["observations"]
        self.obs_out = np.array([o["characteristic"] for o in obs])
        self.obs_line = np.array([o["line"] for o in obs])
        self.z = np.array([o["amplitude"] for o in obs])
        self.sigma = np.array([o["sigma"] for o in obs])
        self.ident_q0 = np.array([o["model_amplitude"] for o in obs])
        # Right-hand sides: the load, then the output unit vectors (adjoint solves).
        no = len(outs)
        rhs = np.zeros((n, 1 + no), dtype=complex)
        rhs[:, 0] = self.load
        for o, d in enumerate(self.out_dof):
            rhs[d, 1 + o] = 1.0
        self.rhs_all = np.broadcast_to(rhs, (len(self.freqs), n, 1 + no))
        self.rhs_load = np.broadcast_to(rhs[:, :1], (len(self.freqs), n, 1))
        self.nfev = 0
        self.njev = 0
        self._cache_u = None
        self._cache = None

    def complex_stiffness(self, x):
        dx = x - self.x0
        k = self.k0 + dx @ self.dk
        psi = self.psi0 + dx @ self.dpsi
        return k, psi, k * (1.0 + 1j * psi / TWO_PI)

    def mass(self, x):
        dx = x - self.x0
        return self.mass0 + np.tensordot(dx, self.dmass, axes=1)

    def gains(self, x):
        """Each output's gain at x (1 where no variable sets it), shape (outputs, 1)."""
        return np.array([[1.0 if g is None else g[1] * x[g[0]]] for g in self.out_gain])

    def system(self, kc, mass):
        """A(f) = T^T diag(kc) T - omega^2 M for every line, shape (lines, n, n)."""
        a0 = self.T.T @ (kc[:, None] * self.T)
        return a0[None, :, :] - self.omega2[:, None, None] * mass[None, :, :]

    def solve(self, x, adjoint):
        k, psi, kc = self.complex_stiffness(x)
        sol = np.linalg.solve(self.system(kc, self.mass(x)), self.rhs_all if adjoint else self.rhs_load)
        return k, psi, sol

    def amplitudes(self, x):
        _, _, sol = self.solve(x, False)
        q = sol[:, :, 0][:, self.out_dof].T * self.out_factor * self.gains(x)  # (outputs, lines)
        return np.abs(q[self.obs_out, self.obs_line])

    # --- least_squares callbacks (u = x / scale) ---

    def residuals(self, u):
        self.nfev += 1
        x = u * self.scale
        if self.analytic:
            # One solve gives q and the adjoint vectors; the Jacobian at this point reuses it.
            k, psi, sol = self.solve(x, True)
            self._cache_u = u.copy()
            self._cache = (k, psi, sol)
            q = sol[:, :, 0][:, self.out_dof].T * self.out_factor * self.gains(x)
            qa = np.abs(q[self.obs_out, self.obs_line])
        else:
            qa = self.amplitudes(x)
        return (self.z - qa) / self.sigma

    def jacobian(self, u):
        self.njev += 1
        if self._cache_u is None or not np.array_equal(self._cache_u, u):
            self.residuals(u)
            self.nfev -= 1
        k, psi, sol = self._cache
        q_full = sol[:, :, 0]  # (lines, n)
        w = sol[:, :, 1:]  # (lines, n, outputs): w_o = A^-1 e_o
        tq = q_full @ self.Tc_t  # (lines, 6S)
        tw = np.matmul(self.Tc, w).transpose(0, 2, 1)  # (lines, outputs, 6S)
        # d kc / d x_v = dk (1 + j psi / 2 pi) + k j dpsi / 2 pi, shape (vars, 6S)
        dkc = self.dk * (1.0 + 1j * psi / TWO_PI)[None, :] + 1j * (k / TWO_PI)[None, :] * self.dpsi
        # dq_o/dx_v = -(T w_o)^T diag(dkc_v) (T q), times (j omega)^k
        dq = -np.matmul(tw * tq[:, None, :], dkc.T).transpose(1, 0, 2) * self.out_factor[:, :, None]
        # A mass: dA/dp = -omega^2 dM, so dq_o/dp = omega^2 w_o^T dM q.
        for v in self.mass_vars:
            dmq = q_full @ self.dmass[v].T  # (lines, n): dM q per line
            dq[:, :, v] += (self.omega2[:, None] * np.einsum("lno,ln->lo", w, dmq)).T * self.out_factor
        x = u * self.scale
        g = self.gains(x)
        q = q_full[:, self.out_dof].T * self.out_factor  # (outputs, lines), before the gains
        qo = (q * g)[self.obs_out, self.obs_line]
        dqo = (dq * g[:, :, None])[self.obs_out, self.obs_line, :]  # (points, vars)
        qa = np.abs(qo)
        da = np.where(qa[:, None] > 0.0, (np.conj(qo)[:, None] * dqo).real / np.where(qa > 0, qa, 1.0)[:, None], 0.0)
        # A gain g = ratio x_v of an output: d|g q|/dx_v = ratio |q|.
        for o, gv in enumerate(self.out_gain):
            if gv is not None:
                at = self.obs_out == o
                da[at, gv[0]] += gv[1] * np.abs(q[o, self.obs_line[at]])
        return -da / self.sigma[:, None] * self.scale[None, :]


def fit(prob, jac="analytic", max_nfev=20000):
    prob.analytic = jac == "analytic"
    prob.nfev = 0
    prob.njev = 0
    prob._cache_u = None
    return least_squares(
        prob.residuals,
        prob.x0 / prob.scale,
        jac=prob.jacobian if prob.analytic else "2-point",
        bounds=(prob.lower / prob.scale, prob.upper / prob.scale),
        method="trf",
        xtol=1e-9,
        ftol=1e-12,
        gtol=1e-8,
        max_nfev=max_nfev,
    )


def jacobian_check(prob):
    """Largest relative difference between the analytic Jacobian and central differences at the
    initial values (columns compared by their norm)."""
    prob.analytic = True
    u0 = prob.x0 / prob.scale
    ja = prob.jacobian(u0)
    worst = 0.0
    for v in range(len(u0)):
        h = 1e-6 * max(1.0, abs(u0[v]))
        up, um = u0.copy(), u0.copy()
        up[v] += h
        um[v] -= h
        col = (prob.residuals(up) - prob.residuals(um)) / (2 * h)
        worst = max(worst, np.linalg.norm(col - ja[:, v]) / max(np.linalg.norm(ja[:, v]), 1e-300))
    return float(worst)


def main():
    args = sys.argv[1:]
    if not args or args[0].startswith("-"):
        raise SystemExit(__doc__)
    path = args[0]
    repeat = int(args[args.index("--repeat") + 1]) if "--repeat" in args else 3
    jac = args[args.index("--jac") + 1] if "--jac" in args else "analytic"
    if jac not in ("analytic", "2-point"):
        raise SystemExit("--jac must be analytic or 2-point")
    max_nfev = int(args[args.index("--max-nfev") + 1]) if "--max-nfev" in args else 20000
    with open(path) as f:
        p = json.load(f)
    prob = Problem(p)
    q0 = prob.amplitudes(prob.x0)
    frf_check = float(np.max(np.abs(q0 - prob.ident_q0) / np.abs(prob.ident_q0)))
    jac_check = jacobian_check(prob)
    times = []
    res = None
    for _ in range(repeat):
        t = time.perf_counter()
        res = fit(prob, jac, max_nfev)
        times.append(time.perf_counter() - t)
    x = res.x * prob.scale
    print(json.dumps({
        "jac": jac,
        "median_s": float(np.median(times)),
        "times_s": times,
        "nfev": prob.nfev,
        "njev": prob.njev if jac == "analytic" else int(res.njev or 0),
        "cost": float(res.cost),
        "status": int(res.status),
        "message": res.message,
        "optimality": float(res.optimality),
        "names": prob.names,
        "x": x.tolist(),
        "frf_check_max_rel": frf_check,
        "jacobian_check_max_rel": jac_check,
    }))


if __name__ == "__main__":
    main()
