"""Independent reference fit of the DTOP three-storey example (examples/real-three-storey).

usage: python3 reference_fit.py [--json OUT.json]      (numpy, scipy, pyuff: .ci/requirements.txt)

Fits the same model form as model.toml to the same lines with the same criterion as
`ident identify model.toml --data ../../data/dtop-three-storey/three-storey-hammer.uff
--map map.toml --vars variables.toml --band 3:40`, without calling ident:

- model: three rigid floors (6 DOFs each: u = translation of the centre of mass, θ = rotation,
  global axes = principal axes), three general spring-damping elements (one per storey, at
  mid-height, axes = global axes) with hysteretic damping. Written here from the equations:
  the element's deformation at its point p is d = (u_r + θ_r × (p − c_r)) − (u_p + θ_p × (p − c_p))
  for translations and θ_r − θ_p for rotations, its dynamic stiffness diag(k_i (1 + j ψ_i / 2π)),
  so the system's is Σ Tᵀ diag(k (1 + jψ/2π)) T and (K + jD − ω² M) q = P, P = 1 N along x on
  floor 1. Outputs: the floors' x accelerations −ω² q_x.
- data: the UFF58 file's reference-1 FRFs (hammer on floor 1) of floors 1-3, lines in 3-40 Hz
  (inclusive).
- variables: each storey's x stiffness k1 and one ψ1 shared by the three storeys; start = the
  model's values (52.5 kN/m, 0.025); bounds ≥ 0; scaled by the start.
- criterion: log-amplitude, r = ln|z| − ln|q| (ident's `--fit auto` for data without variances:
  σ = 0.01 in ln, the same on every line, so the optimum is the plain least-squares one).

Prints the estimates and the RMS amplitude error in dB over all fitted lines,
sqrt(mean((20 log10(|q|/|z|))²)), per characteristic and overall.
"""
import json
import os
import sys

import numpy as np
import pyuff
from scipy.optimize import least_squares

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.join(HERE, "..", "..", "data", "dtop-three-storey", "three-storey-hammer.uff")
BAND = (3.0, 40.0)

MASS = 5.201
INERTIA = (0.0392, 0.0392, 0.0780)
FLOOR_Z = (0.2018, 0.3801, 0.5584)
STOREY_Z = (0.11265, 0.29095, 0.46925)
K_STOREY = np.array([52.5e3, 3.65e6, 137e6, 3.08e6, 3.08e6, 8.3e4])
PSI0 = 0.025


def skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def body_transform(point, centre):
    """6x6: the motion at `point` (translation, rotation) from a body's (u, θ) at `centre`."""
    t = np.eye(6)
    t[0:3, 3:6] = -skew(np.asarray(point) - np.asarray(centre))  # θ × r = −r × θ
    return t


def assemble(params):
    """Complex dynamic stiffness K + jD (18x18) and the mass matrix for (k1, k2, k3, ψ)."""
    k1, k2, k3, psi = params
    n = 18
    stiff = np.zeros((n, n), complex)
    for s, (ks, zs) in enumerate(zip((k1, k2, k3), STOREY_Z)):
        k = K_STOREY.copy()
        k[0] = ks
        psis = np.full(6, PSI0)
        psis[0] = psi
        c = np.diag(k * (1 + 1j * psis / (2 * np.pi)))
        p = np.array([0.0, 0.0, zs])
        # storey s joins body s-1 (ground for s = 0) and body s
        t = np.zeros((6, n))
        t[:, 6 * s:6 * s + 6] = body_transform(p, (0.0, 0.0, FLOOR_Z[s]))
        if s > 0:
            t[:, 6 * (s - 1):6 * s] -= body_transform(p, (0.0, 0.0, FLOOR_Z[s - 1]))
        stiff += t.T @ c @ t
    mass = np.diag(np.tile([MASS, MASS, MASS, *INERTIA], 3))
    return stiff, mass


def accelerance(params, freqs):
    """x accelerations of floors 1-3 per 1 N along x on floor 1, shape (3, lines)."""
    stiff, mass = assemble(params)
    force = np.zeros(18)
    force[0] = 1.0
    w = 2 * np.pi * freqs
    out = np.empty((3, len(freqs)), complex)
    for i, wi in enumerate(w):
        q = np.linalg.solve(stiff - wi ** 2 * mass, force)
        out[:, i] = -wi ** 2 * q[[0, 6, 12]]
    return out


def measured():
    u = pyuff.UFF(DATA)
    rows = {}
    for i, t in enumerate(u.get_set_types()):
        if int(t) != 58:
            continue
        d = u.read_sets(i)
        if int(d["ref_node"]) == 1 and int(d["func_type"]) == 4:
            rows[int(d["rsp_node"])] = (np.asarray(d["x"], float), np.asarray(d["data"], complex))
    f = rows[1][0]
    keep = (f >= BAND[0]) & (f <= BAND[1])
    z = np.array([rows[n][1][keep] for n in (1, 2, 3)])
    return f[keep], z


def main():
    freqs, z = measured()
    x0 = np.array([K_STOREY[0]] * 3 + [PSI0])
    ln_z = np.log(np.abs(z)).ravel()

    def residual(u):
        q = accelerance(u * x0, freqs)
        return ln_z - np.log(np.abs(q)).ravel()

    fit = least_squares(residual, np.ones(4), bounds=(0.0, np.inf), method="trf",
                        x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=2000)
    est = fit.x * x0
    q = accelerance(est, freqs)
    db = 20 * np.log10(np.abs(q) / np.abs(z))
    per = np.sqrt(np.mean(db ** 2, axis=1))
    overall = float(np.sqrt(np.mean(db ** 2)))
    result = {
        "estimates": {"k storey 1": est[0], "k storey 2": est[1], "k storey 3": est[2],
                      "psi sway": est[3]},
        "rms_db": {"floor 1": per[0], "floor 2": per[1], "floor 3": per[2]},
        "rms_db_overall": overall,
        "lines": int(len(freqs)),
        "criterion": float(0.5 * np.sum((fit.fun / 0.01) ** 2)),
        "evaluations": int(fit.nfev),
    }
    for k, v in result["estimates"].items():
        print(f"{k:12s} {v:.6g}")
    for k, v in result["rms_db"].items():
        print(f"{k}: {v:.3f} dB")
    print(f"RMS dB over all {3 * len(freqs)} observations: {overall:.4f}")
    if "--json" in sys.argv:
        with open(sys.argv[sys.argv.index("--json") + 1], "w") as out:
            json.dump(result, out, indent=1)


if __name__ == "__main__":
    main()
