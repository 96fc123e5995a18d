"""Every family on the measured records of docs/identification.md, against a straight line
through a first-order lag: the table in that document.

    python measure.py RECORDS_DIR        (the OUT_DIR of convert.py)

Each record is split as a user would: the piezo record's first 70 % fits (its first 3.28 s,
the actuator at rest and the jump to the first voltage, simulated but left out) and its last
30 % validates, continuing the fit part's state; the MR damper likewise; the tendon's first run
fits and its second run (reversals down to zero) validates, from rest.
"""

import sys
import time
from pathlib import Path

from hystmpc.experiments.reference import load_record
from hystmpc.models.identify_auto import identify_auto

RECORDS = {  # name: (fit record, validation record or None (the last 30 %), identify settings)
    "piezo (SmartHysteresis)": ("piezo/record.csv", None, {"warm_up": 16400}),
    "piezo (SmartHysteresis), first-order": ("piezo/record.csv", None, {"warm_up": 16400, "dynamics": "first-order"}),
    "MR damper (labcontrol)": ("mr-damper/record.csv", None, {}),
    "tendon catheter (hysteresis-fnn-lstm)": ("tendon/record.csv", "tendon/validation.csv", {}),
}


def main(folder: Path) -> None:
    print("| record | family | fit RMSE | validation RMSE | × linear + lag | time [s] |")
    print("|---|---|---|---|---|---|")
    for name, (data, validate, settings) in RECORDS.items():
        u, y, period = load_record(folder / data)
        validation = None if validate is None else load_record(folder / validate)[:2]
        start = time.perf_counter()
        ranking = identify_auto(u, y, period, validation, **settings)
        wall = time.perf_counter() - start
        naive = ranking.naive.validation_rmse
        for c in [*ranking.candidates, ranking.naive]:
            if c.error:
                print(f"| {name} | {c.family} | failed: {c.error} | | | {c.seconds:.1f} |")
                continue
            print(f"| {name} | {c.family} | {c.fit_rmse:.4g} | {c.validation_rmse:.4g} | "
                  f"{c.validation_rmse / naive:.3f} | {c.seconds:.1f} |")
        print(f"| {name} | *identify auto, wall clock* | | | | {wall:.1f} |")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
