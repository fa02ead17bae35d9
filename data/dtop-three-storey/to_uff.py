"""Writes three-storey-hammer.uff (UFF58, ASCII) from the three source CSV files beside it.

usage: python3 to_uff.py            (numpy and pyuff, pinned in .ci/requirements.txt)

Each CSV (`;`-separated, complex numbers as written by numpy) holds one hammer position: column 0
the frequency (Hz, 0.03125 Hz lines from 0.03125 to 128 Hz), columns 1-3 the accelerance of the
accelerometers on floors 1, 2, 3. The hammer position is the floor whose column shows the mass line
(|H| -> 1/m above the last resonance): Experimental.csv floor 1, test_2.csv floor 2, test_3.csv
floor 3. The values are (m/s^2)/N (the mass line is 0.19 (m/s^2)/N, i.e. 5.3 kg per floor; in g/N,
as a comment in the source's code says, the floors would weigh 0.54 kg).

The UFF keeps lines 0.03125-64 Hz (the first 2048 lines; the structure's three storey modes lie
below 30 Hz) so that the file stays small. Nodes 1-3 are the floors, direction +X (the storeys'
sway direction), reference node = the floor hit by the hammer.
"""
import os
import numpy as np
import pyuff

SOURCES = [("Experimental.csv", 1), ("test_2.csv", 2), ("test_3.csv", 3)]
LINES = 2048
OUT = "three-storey-hammer.uff"


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    out = os.path.join(here, OUT)
    if os.path.exists(out):
        os.remove(out)
    u = pyuff.UFF(out)
    for name, ref in SOURCES:
        d = np.genfromtxt(os.path.join(here, name), dtype=complex, delimiter=";")
        f = d[:LINES, 0].real
        for rsp in (1, 2, 3):
            h = d[:LINES, rsp]
            s = pyuff.prepare_58(
                binary=0, func_type=4, rsp_node=rsp, rsp_dir=1, ref_node=ref, ref_dir=1,
                data=h, x=f, id1=f"DTOP three-storey structure, hammer on floor {ref}",
                id2=f"source {name}, column {rsp}", rsp_ent_name="floor", ref_ent_name="floor",
                abscissa_spacing=1, abscissa_spec_data_type=18, abscissa_axis_units_lab="Hz",
                ordinate_spec_data_type=12, ordinate_axis_units_lab="m/s^2",
                orddenom_spec_data_type=13, orddenom_axis_units_lab="N",
                z_axis_spec_data_type=0)
            u.write_sets(s, mode="add")


if __name__ == "__main__":
    main()
