"""pyuff side of process/tests/uff_measured.rs: the same FRFs written as UFF58 in three units.

usage: uff_frf_units.py IN.bin OUT_PREFIX
  IN.bin (float64, little endian): n, then n frequencies (Hz), then for each of two responses
  (node 1 +Z, node 2 +Z; reference node 9 +Z) n real and n imaginary parts of the receptance (m/N).
  Writes OUT_PREFIX-receptance.uff (ASCII, m per N), OUT_PREFIX-mobility.uff (58b little endian,
  mm/s per N) and OUT_PREFIX-accelerance.uff (58b big endian, g per N, after a dataset 164 that
  ident skips with a note), each with an uneven abscissa in Hz.
"""
import sys
import types

import numpy as np
import pyuff
import pyuff.datasets.dataset_58 as d58

G = 9.80665


def write(path, binary, big_endian, unit, spec, scale, power, h, f, extra_164=False):
    # pyuff writes 58b in the machine's byte order: present a big-endian `sys` to it for that.
    fake = types.SimpleNamespace(**{k: getattr(sys, k) for k in dir(sys) if not k.startswith("__")})
    fake.byteorder = "big" if big_endian else "little"
    d58.sys = fake
    jw = 1j * 2 * np.pi * f
    with open(path, "w") as fh:
        if extra_164:
            fh.write("    -1\n   164\n         1SI - mks (Newton)  2\n"
                     "    1.00000000000000000E+00    1.00000000000000000E+00    1.00000000000000000E+00\n"
                     "    2.73149999999999977E+02\n    -1\n")
    u = pyuff.UFF(path)
    for k, node in enumerate([1, 2]):
        data = h[k] * jw ** power / scale
        s = pyuff.prepare_58(
            binary=binary, func_type=4, rsp_node=node, rsp_dir=3, ref_node=9, ref_dir=3,
            data=data, x=f, id1=f"FRF {node}", rsp_ent_name="NODE", ref_ent_name="NODE",
            abscissa_spacing=0, abscissa_spec_data_type=18, abscissa_axis_units_lab="Hz",
            ordinate_spec_data_type=spec, ordinate_axis_units_lab=unit,
            orddenom_spec_data_type=13, orddenom_axis_units_lab="N", z_axis_spec_data_type=0)
        u.write_sets(s, mode="add")


def main(inp, prefix):
    v = np.fromfile(inp, dtype="<f8")
    n = int(v[0])
    f = v[1:1 + n]
    h = []
    for k in range(2):
        base = 1 + n + 2 * n * k
        h.append(v[base:base + n] + 1j * v[base + n:base + 2 * n])
    write(prefix + "-receptance.uff", 0, False, "m", 8, 1.0, 0, h, f)
    write(prefix + "-mobility.uff", 1, False, "mm/s", 11, 1e-3, 1, h, f)
    write(prefix + "-accelerance.uff", 1, True, "g", 12, G, 2, h, f, extra_164=True)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
