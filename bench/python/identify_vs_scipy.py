#!/usr/bin/env python3
"""Same-run comparison: `ident identify` (release binary) vs the Python baseline (numpy FRF +
scipy.optimize.least_squares, ident_baseline.py) on the same files: the FWD-32J problem of the
IDENT paper (20 variables, 3 characteristics x 38 lines = 114 points, 1 % noise, started from the
Table 1 initial values).

1. Writes the data file: `ident frf configs/models/fwd32j.toml` (truth: Table 1 identified values)
   at 38 log-spaced lines over 20-400 Hz, times (1 + 0.01 n), n ~ N(0, 1) seeded; variances stated.
2. `ident identify configs/models/fwd32j-initial.toml --data DATA --vars
   configs/identification/fwd32j.toml --export-problem P.json`: the problem scipy gets.
3. Interleaved repetitions: the whole `ident identify ... --format json --timing` process
   (start-up, file parsing, fit, Cramer-Rao, report) against scipy's fit alone (least_squares,
   trust-region reflective, the same scaled variables, start and bounds; module import, file
   reading and the fixed-matrix assembly excluded). Two ratios: whole process against scipy's fit
   (what a user waits for against the least Python would take), and fit against fit (ident's
   minimisation alone, as `--timing` reports it: the Levenberg-Marquardt iterations with their
   model solves, without start-up, parsing, the solves at the start and the estimate,
   Cramer-Rao and the report). Both single-threaded (ident is; OpenBLAS is limited to one thread,
   as multi-threaded BLAS on 42x42 systems only loses, badly so on a loaded machine).
   --baseline-ident times a second ident binary in the same interleaved loop (before/after).
4. Checks that scipy reached ident's optimum: criterion within --cost-rtol (relative) and every
   estimate within --x-tol standard errors (ident's Cramer-Rao standard errors); exits 1 if not.
5. The same fit with scipy's 2-point finite-difference Jacobian (one run; --fd-repeat), and its
   agreement, for reference.

usage: identify_vs_scipy.py [--ident target/release/ident] [--repeat 5] [--fd-repeat 1]
                            [--seed 32] [--cost-rtol 1e-6] [--x-tol 0.01] [--keep DIR]
                            [--baseline-ident OTHER_IDENT]
Build first: cargo build --release --bin ident
"""
import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import ident_baseline  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
TRUTH = os.path.join(ROOT, "configs/models/fwd32j.toml")
INITIAL = os.path.join(ROOT, "configs/models/fwd32j-initial.toml")
VARS = os.path.join(ROOT, "configs/identification/fwd32j.toml")
UNIT_FACTOR = {"MPa/um": 1e12, "N/um": 1e6, "N*m/rad": 1.0, "-": 1.0}


def run(cmd, **kw):
    out = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if out.returncode not in (0, 1):
        raise SystemExit("%s failed (exit %d):\n%s" % (" ".join(cmd), out.returncode, out.stderr))
    return out


def write_data(ident, path, seed, rel=0.01):
    lines = 20.0 * 20.0 ** (np.arange(38) / 37.0)
    frf = json.loads(run([ident, "frf", TRUTH, "--hz", ",".join(repr(float(f)) for f in lines), "--json"]).stdout)
    model = json.loads(run([ident, "model", "export", TRUTH, "--json"]).stdout)
    rng = np.random.default_rng(seed)
    chars = []
    for o in frf["outputs"]:
        q = np.hypot(o["re"], o["im"])
        chars.append({
            "body": model["bodies"][o["body"]]["name"], "dof": o["dof"], "quantity": o["quantity"],
            "freqs_hz": frf["freqs_hz"],
            "amplitude": (q * (1.0 + rel * rng.standard_normal(len(q)))).tolist(),
            "variance": (2.0 * (rel * q) ** 2).tolist(),
        })
    with open(path, "w") as f:
        json.dump({"source": "identify_vs_scipy.py: fwd32j.toml, 1 %% noise, seed %d" % seed, "characteristics": chars}, f)


def has_timing(ident):
    """True when this ident binary knows `identify --timing` (older ones do not)."""
    return "--timing" in run([ident, "identify", "--help"]).stdout


def time_ident(ident, data, timing=True):
    """(whole-process wall time, fit wall time from --timing or None, the JSON report)."""
    cmd = [ident, "identify", INITIAL, "--data", data, "--vars", VARS, "--format", "json"]
    t = time.perf_counter()
    out = run(cmd + (["--timing"] if timing else []))
    dt = time.perf_counter() - t
    if out.returncode != 0:
        raise SystemExit("ident identify did not converge:\n" + out.stderr)
    fit = re.search(r"timing: .*\bfit ([0-9.]+) ms", out.stderr) if timing else None
    if timing and fit is None:
        raise SystemExit("ident identify --timing printed no fit time:\n" + out.stderr)
    return dt, (float(fit.group(1)) * 1e-3 if fit else None), json.loads(out.stdout)


def agreement(prob, res, report, cost_rtol, x_tol):
    """(ok, worst |dx|/se, relative cost difference, lines) comparing scipy's result with ident's."""
    x_py = res.x * prob.scale
    worst = 0.0
    lines = []
    for i, row in enumerate(report["table"]):
        factor = UNIT_FACTOR.get(row["unit"], 1.0)
        se = row["std_error"]
        dx = abs(x_py[i] / factor - row["identified"])
        rel = dx / se if se else (0.0 if dx == 0.0 else float("inf"))
        worst = max(worst, rel)
        lines.append("  %-20s ident %12.6g  scipy %12.6g  %-7s  |diff| = %.2e se" % (
            row["variable"], row["identified"], x_py[i] / factor, row["unit"], rel))
    dcost = abs(res.cost - report["criterion"]) / report["criterion"]
    return worst <= x_tol and dcost <= cost_rtol, worst, dcost, lines


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ident", default=os.path.join(os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target")), "release", "ident"))
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--fd-repeat", type=int, default=1)
    ap.add_argument("--seed", type=int, default=32)
    ap.add_argument("--cost-rtol", type=float, default=1e-6)
    ap.add_argument("--x-tol", type=float, default=0.01)
    ap.add_argument("--keep", help="keep the data and problem files in this directory")
    ap.add_argument("--baseline-ident", help="a second ident binary timed in the same interleaved loop")
    a = ap.parse_args()
    for b in [a.ident] + ([a.baseline_ident] if a.baseline_ident else []):
        if not os.access(b, os.X_OK):
            raise SystemExit("no ident binary at %s: run `cargo build --release --bin ident` (or pass --ident)" % b)
    if not has_timing(a.ident):
        raise SystemExit("%s has no `identify --timing`: the fit-to-fit ratio needs it" % a.ident)
    base_timing = has_timing(a.baseline_ident) if a.baseline_ident else False
    work = a.keep or tempfile.mkdtemp(prefix="ident-vs-scipy-")
    os.makedirs(work, exist_ok=True)
    data = os.path.join(work, "fwd32j-data.json")
    problem = os.path.join(work, "fwd32j-problem.json")
    write_data(a.ident, data, a.seed)
    run([a.ident, "identify", INITIAL, "--data", data, "--vars", VARS, "--export-problem", problem])
    with open(problem) as f:
        prob = ident_baseline.Problem(json.load(f))
    frf_check = float(np.max(np.abs(prob.amplitudes(prob.x0) - prob.ident_q0) / prob.ident_q0))
    jac_check = ident_baseline.jacobian_check(prob)

    t_ident, t_fit, t_py, t_base, t_base_fit = [], [], [], [], []
    report = res = base_report = None
    for _ in range(a.repeat):
        dt, fit, report = time_ident(a.ident, data)
        t_ident.append(dt)
        t_fit.append(fit)
        t = time.perf_counter()
        res = ident_baseline.fit(prob, "analytic")
        t_py.append(time.perf_counter() - t)
        if a.baseline_ident:
            dt, fit, base_report = time_ident(a.baseline_ident, data, base_timing)
            t_base.append(dt)
            t_base_fit.append(fit)
    nfev, njev = prob.nfev, prob.njev
    ok, worst, dcost, lines = agreement(prob, res, report, a.cost_rtol, a.x_tol)

    t_fd = []
    res_fd = None
    for _ in range(a.fd_repeat):
        t = time.perf_counter()
        res_fd = ident_baseline.fit(prob, "2-point")
        t_fd.append(time.perf_counter() - t)
    nfev_fd = prob.nfev
    ok_fd, worst_fd, dcost_fd, _ = agreement(prob, res_fd, report, a.cost_rtol, a.x_tol) if res_fd is not None else (None, 0, 0, [])

    mi, mp = float(np.median(t_ident)), float(np.median(t_py))
    mfit = float(np.median(t_fit))
    print("FWD-32J identification: 20 variables, 114 points; %d interleaved repetitions, medians; load average %.1f" % (
        a.repeat, os.getloadavg()[0]))
    print("model check: numpy FRF vs ident at the initial values, max rel diff %.1e; analytic vs central-difference Jacobian, max rel col diff %.1e" % (
        frf_check, jac_check))
    print("ident identify (release binary, whole process):   %8.1f ms  [%s]  %d iterations, %d model evaluations (%d with Jacobian), J %.6f -> %.9f, %s" % (
        mi * 1e3, " ".join("%.0f" % (t * 1e3) for t in t_ident), report["iterations"], report["model_evaluations"],
        report["jacobian_evaluations"], report["criterion_initial"], report["criterion"], report["stop"]))
    print("ident identify, fit alone (its --timing):          %8.1f ms  [%s]" % (
        mfit * 1e3, " ".join("%.1f" % (t * 1e3) for t in t_fit)))
    if a.baseline_ident:
        mb = float(np.median(t_base))
        same = abs(base_report["criterion"] - report["criterion"]) / report["criterion"]
        print("baseline ident (%s, whole process):  %8.1f ms  [%s]  %d iterations, %d model evaluations, J -> %.9f (rel. diff %.1e)" % (
            a.baseline_ident, mb * 1e3, " ".join("%.0f" % (t * 1e3) for t in t_base), base_report["iterations"],
            base_report["model_evaluations"], base_report["criterion"], same))
        if base_timing:
            print("baseline ident, fit alone (its --timing):          %8.1f ms" % (float(np.median(t_base_fit)) * 1e3))
    print("scipy least_squares, analytic Jacobian (fit only): %8.1f ms  [%s]  %d residual + %d Jacobian evaluations, J -> %.9f, %s" % (
        mp * 1e3, " ".join("%.0f" % (t * 1e3) for t in t_py), nfev, njev, res.cost, res.message))
    if res_fd is not None:
        mf = float(np.median(t_fd))
        print("scipy least_squares, 2-point Jacobian (fit only):  %8.1f ms  [%s]  %d residual evaluations, J -> %.9f, %s" % (
            mf * 1e3, " ".join("%.0f" % (t * 1e3) for t in t_fd), nfev_fd, res_fd.cost, res_fd.message))
    print("same optimum (analytic): %s  (criterion rel diff %.1e <= %.0e; worst estimate diff %.2e se <= %.2g se)" % (
        "yes" if ok else "NO", dcost, a.cost_rtol, worst, a.x_tol))
    if res_fd is not None:
        print("same optimum (2-point):  %s  (criterion rel diff %.1e; worst estimate diff %.2e se)" % (
            "yes" if ok_fd else "NO", dcost_fd, worst_fd))
    print("\n".join(lines))
    print("RATIO scipy(analytic) fit / ident whole process = %.1f" % (mp / mi))
    print("RATIO scipy(analytic) fit / ident fit (fit to fit) = %.1f" % (mp / mfit))
    if a.baseline_ident:
        print("RATIO scipy(analytic) fit / baseline ident whole process = %.1f" % (mp / float(np.median(t_base))))
        if base_timing:
            print("RATIO scipy(analytic) fit / baseline ident fit (fit to fit) = %.1f" % (mp / float(np.median(t_base_fit))))
    if res_fd is not None:
        print("RATIO scipy(2-point) fit / ident whole process = %.1f" % (float(np.median(t_fd)) / mi))
    if not a.keep:
        shutil.rmtree(work, ignore_errors=True)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
