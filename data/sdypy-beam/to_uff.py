"""Writes beam-hammer.uff (UFF58b, binary, double precision) from sdypy-EMA's sample data.

usage: python3 to_uff.py PATH/TO/acc_data.npy      (numpy and pyuff, pinned in .ci/requirements.txt)

`acc_data.npy` is in the source distribution of sdypy-EMA 0.27.3 on PyPI
(`pip download --no-deps --no-binary :all: sdypy-EMA==0.27.3`, file `data/acc_data.npy`). It holds
`freq, H1_main = np.load(..., allow_pickle=True)`: the frequency lines (1.00019535 Hz apart, from
1.0002 to 10000.95 Hz) and H1 of shape (6 hammer locations, 7 accelerometers, lines), complex
accelerance of a free-free beam measured by a roving hammer with 7 fixed accelerometers.

The UFF keeps the lines up to 2000 Hz (the first 2000 lines; the beam's first four bending modes,
176, 476, 932 and 1535 Hz, lie below) so that the file stays small. Nodes 1-7 are the
accelerometers, nodes 11-16 the hammer locations (the source gives no geometry, so no point is
assumed to be both), direction +Z for all (the source does not state it; the beam is hit and
measured across its length).
"""
import os
import sys

import numpy as np
import pyuff

LINES = 2000
OUT = "beam-hammer.uff"


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    freq, h1 = np.load(sys.argv[1], allow_pickle=True)
    freq = np.asarray(freq, float)[:LINES]
    out = os.path.join(here, OUT)
    if os.path.exists(out):
        os.remove(out)
    u = pyuff.UFF(out)
    for ref in range(h1.shape[0]):
        for rsp in range(h1.shape[1]):
            s = pyuff.prepare_58(
                binary=1, func_type=4, rsp_node=rsp + 1, rsp_dir=3, ref_node=ref + 11, ref_dir=3,
                data=np.asarray(h1[ref, rsp, :LINES], complex), x=freq,
                id1=f"sdypy-EMA free-free beam, hammer at location {ref + 1}",
                id2=f"acc_data.npy H1_main[{ref}, {rsp}]", rsp_ent_name="acc",
                ref_ent_name="hammer", abscissa_spacing=1, abscissa_spec_data_type=18,
                abscissa_axis_units_lab="Hz", ordinate_spec_data_type=12,
                orddenom_spec_data_type=13, z_axis_spec_data_type=0)
            u.write_sets(s, mode="add")


if __name__ == "__main__":
    main()
