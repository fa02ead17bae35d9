"""The scipy side of `cargo bench -p identify --bench multistart`.

usage: multistart_scipy.py PROBLEM.json STARTS.json

PROBLEM.json is `identification::problem`'s export (the model, data, variables, scaling and
bounds); STARTS.json the list of start points (SI), the first the written start. Fits from every
start with ident_baseline.py's numpy FRF and adjoint Jacobian and scipy.optimize.least_squares
(trust-region reflective, same scaled variables and bounds) and prints one JSON line: total
seconds, evaluations, the best cost (= ident's J) and every start's cost.
"""
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ident_baseline import Problem, fit  # noqa: E402


def main():
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    with open(sys.argv[1]) as f:
        prob = Problem(json.load(f))
    with open(sys.argv[2]) as f:
        starts = [np.array(s, float) for s in json.load(f)]
    costs, nfev, njev = [], 0, 0
    t = time.perf_counter()
    for x0 in starts:
        prob.x0 = x0
        res = fit(prob, "analytic")
        costs.append(float(res.cost))
        nfev += prob.nfev
        njev += prob.njev
    seconds = time.perf_counter() - t
    print(json.dumps({"seconds": seconds, "nfev": nfev, "njev": njev,
                      "best_cost": min(costs), "costs": costs}))


if __name__ == "__main__":
    main()
