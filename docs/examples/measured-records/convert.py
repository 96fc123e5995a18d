"""Convert the public measured records docs/identification.md uses into hystmpc's t,u,y CSVs.

Their licences do not all allow copies here, so they are not shipped: clone each repository at
the commit named in docs/identification.md, then

    python convert.py SOURCE_DIR OUT_DIR

with SOURCE_DIR holding the clones as ``SmartHysteresis/``, ``mr-damper/`` and
``hysteresis-fnn-lstm/``. Nothing is scaled, filtered or offset; only the tendon records,
sampled irregularly at about 500 Hz, are interpolated onto a uniform 100 Hz grid.
"""

import sys
from pathlib import Path

import numpy as np


def write(path: Path, t, u, y) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = "\n".join(f"{a:.6f},{float(b)!r},{float(c)!r}" for a, b, c in zip(t, u, y, strict=True))
    path.write_text("t,u,y\n" + rows + "\n")


def piezo(source: Path, out: Path) -> None:
    """SmartHysteresis Data/hysteresis_v_150_1hz.csv: columns (index, t, displacement um, voltage V)."""
    raw = np.genfromtxt(source / "SmartHysteresis/Data/hysteresis_v_150_1hz.csv", delimiter=",")
    raw = raw[np.isfinite(raw[:, 1])]
    write(out / "piezo/record.csv", np.arange(len(raw)) * 2e-4, raw[:, 3], raw[:, 2])  # the stored t: 0.2 ms steps


def mr_damper(source: Path, out: Path) -> None:
    """mr-damper data/data_simulation_4.1_MRdamper.mat: piston displacement dist (mm), force forc (N), Ts."""
    from scipy.io import loadmat
    mat = loadmat(source / "mr-damper/data/data_simulation_4.1_MRdamper.mat")
    u, y = np.ravel(mat["dist"]), np.ravel(mat["forc"])
    write(out / "mr-damper/record.csv", np.arange(len(u)) * float(np.ravel(mat["Ts"])[0]), u, y)


def tendon(source: Path, out: Path) -> None:
    """hysteresis-fnn-lstm tendon_data/20230928/all_data/data_{1,2}_1.txt: time, tendon displacement
    (column 2, mm), tip angle (column 7, deg), resampled to 100 Hz."""
    for name, target in (("data_1_1.txt", "record.csv"), ("data_2_1.txt", "validation.csv")):
        raw = np.loadtxt(source / "hysteresis-fnn-lstm/tendon_data/20230928/all_data" / name, delimiter=",",
                         skiprows=1)
        t = np.arange(0.0, raw[-1, 0] + 1e-9, 0.01)
        write(out / "tendon" / target, t, np.interp(t, raw[:, 0], raw[:, 1]), np.interp(t, raw[:, 0], raw[:, 6]))


if __name__ == "__main__":
    src, dst = Path(sys.argv[1]), Path(sys.argv[2])
    for convert in (piezo, mr_damper, tendon):
        convert(src, dst)
