"""pyuff side of the UFF58 round trips in process/tests/uff.rs.

usage: uff_pyuff.py dump IN.uff OUT.bin   -> for each dataset: n, x (n), re (n), im (n) as float64
       uff_pyuff.py write OUT.uff BINARY  -> writes the reference datasets (see reference())
"""
import sys
import numpy as np
import pyuff


def reference():
    f = np.arange(1, 201) * 0.5
    h = 1.0 / (1.0e4 - (2 * np.pi * f) ** 2 + 1j * 2 * np.pi * f * 3.0)
    t = np.arange(300) / 2000.0
    x = np.sin(2 * np.pi * 50 * t) * np.exp(-t * 3) + 0.1
    fu = np.array([1.0, 2.5, 7.25, 100.0])
    hu = np.array([1 + 2j, -3e-7 + 1j, 4.5e10 - 0.0j, -1e-300 + 1e300j])
    return [(4, f, h, 1), (1, t, x, 1), (4, fu, hu, 0)]


def dump(inp, out):
    u = pyuff.UFF(inp)
    parts = []
    for i in range(len(u.get_set_types())):
        d = u.read_sets(i)
        data = np.asarray(d["data"])
        n = len(data)
        parts += [np.array([n], float), np.asarray(d["x"], float), data.real.astype(float), np.imag(data).astype(float)]
    np.concatenate(parts).astype("<f8").tofile(out)


def write(out, binary):
    u = pyuff.UFF(out)
    sets = []
    for func_type, x, y, even in reference():
        sets.append(pyuff.prepare_58(
            binary=binary, func_type=func_type, rsp_node=1, rsp_dir=3, ref_node=2, ref_dir=3,
            data=y, x=x, id1="pyuff", rsp_ent_name="NODE", ref_ent_name="NODE",
            abscissa_spacing=even, abscissa_spec_data_type=18 if func_type == 4 else 17,
            ordinate_spec_data_type=12, orddenom_spec_data_type=13, z_axis_spec_data_type=0))
    # pyuff 2.5.8 reopens binary files with 'wb' in overwrite mode, truncating earlier sets:
    # write each set in 'add' mode to a fresh file instead.
    import os
    if os.path.exists(out):
        os.remove(out)
    for s in sets:
        u.write_sets(s, mode="add")


if __name__ == "__main__":
    if sys.argv[1] == "dump":
        dump(sys.argv[2], sys.argv[3])
    else:
        write(sys.argv[2], int(sys.argv[3]))
