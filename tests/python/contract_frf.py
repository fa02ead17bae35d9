"""Independent frequency response of a resolved-model JSON (docs/model-json.md), with numpy.

Written from the contract's text alone, in the global-frame form: a point x of body b moves by
R_b u + (R_b r) x (x - c_b); an SDE's deformation is the motion of body r relative to body p at its
point, in its frame R_s. K = sum T^T K_k T, D = sum T^T diag(psi/2pi) K_k T, P from virtual work.
Usage: contract_frf.py MODEL.json F1,F2,...   -> prints the FRF JSON of `ident frf --json`.
"""
import json
import sys

import numpy as np


def skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def point_map(body, x):
    """3x6 map from body coordinates [u, r] to the global displacement of point x."""
    R = np.array(body["rotation"], dtype=float)
    c = np.array(body["position"], dtype=float)
    # (R r) x (x - c) = -skew(x - c) R r
    return np.hstack([R, -skew(np.asarray(x) - c) @ R])


def main():
    model = json.load(open(sys.argv[1]))
    freqs = [float(f) for f in sys.argv[2].split(",")]
    bodies = model["bodies"]
    n = 6 * len(bodies)
    M = np.zeros(n)
    for i, b in enumerate(bodies):
        M[6 * i:6 * i + 6] = [b["mass"]] * 3 + list(b["inertia"])
    K = np.zeros((n, n))
    D = np.zeros((n, n))
    for s in model["sdes"]:
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
    P = np.zeros(n)
    for f in model["excitation"]["forces"]:
        b = f["body"]
        body = bodies[b]
        x = f.get("point", body["position"])
        P[6 * b:6 * b + 6] += point_map(body, x).T @ np.array(f["force"], dtype=float)
        if "moment" in f:
            Rb = np.array(body["rotation"], dtype=float)
            P[6 * b + 3:6 * b + 6] += Rb.T @ np.array(f["moment"], dtype=float)
    out = {"freqs_hz": freqs, "outputs": []}
    qs = []
    for fr in freqs:
        w = 2 * np.pi * fr
        qs.append(np.linalg.solve(K + 1j * D - w * w * np.diag(M), P))
    for o in model["outputs"]:
        idx = 6 * o["body"] + o["dof"]
        vals = []
        for fr, q in zip(freqs, qs):
            w = 2 * np.pi * fr
            factor = {"displacement": 1.0, "velocity": 1j * w, "acceleration": -w * w}[o["quantity"]]
            vals.append(q[idx] * factor)
        out["outputs"].append({"body": o["body"], "dof": o["dof"], "quantity": o["quantity"],
                               "re": [v.real for v in vals], "im": [v.imag for v in vals]})
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
