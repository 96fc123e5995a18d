"""The whole user path on the held-out stages of heldout_stages.py, with the command line only:
record, ``identify auto``, an actuator file, then ``compare`` twice, on the file's simulated
plant (what compare predicts) and on the stage itself (``--plant``, what the rig gives).

    python tests/measure_heldout_stages.py OUT_DIR [--only STAGE[,STAGE...]] [--set KEY=VALUE ...]

Prints, per stage and reference (the file's sine and staircase, and a band-limited random
reference), each controller's RMSE on both plants, the NMPC over the best baseline on the stage,
and whether the simulated plant ranks the controllers as the stage does. Nothing here is tuned
on the stages; ``--set`` passes settings to both compares (to measure a candidate default;
``plant.*`` only to the simulated plant's).
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
from heldout_stages import STAGES
from heldout_truths import excitation
from scipy.signal import butter, sosfiltfilt

SETTINGS = {  # stage: (identify options, output range, units): what a user would choose, knowing the kind;
    # "{steps}" stands for a record of steps written for the stage (a record that shows its resonance)
    "preisach-creep": (["--dynamics", "first-order", "--creep", "kelvin-voigt"], (0.0, 12.0), "um"),
    "bouc-wen-resonance": (["--dynamics", "second-order"], (0.0, 8.5), "um"),
    "fast-bouc-wen": (["--dynamics", "second-order", "--dynamics-data", "{steps}"], (0.0, 9.0), "um"),
    "duhem-lag": (["--dynamics", "first-order"], (-3.0, 2.5), "mm"),
    "duhem-monotone-lag": (["--dynamics", "first-order"], (-3.5, 2.5), "mm"),
}
TESTS = Path(__file__).parent


def _hystmpc(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "hystmpc.experiments", *args], check=True,
                   env={**__import__("os").environ, "PYTHONPATH": str(TESTS)})


def _write_record(path: Path, stage, seconds: float, seed: int) -> None:
    u = excitation(*stage.input_range, stage.sample_period, seconds, seed)
    y = stage.respond(u, seed)
    t = np.arange(len(u)) * stage.sample_period
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header="t,u,y", comments="", fmt="%.9g")


def _write_steps(path: Path, stage, seconds: float, seed: int) -> None:
    """Steps to random levels every 50 ms: a record that shows the stage's resonance."""
    samples, hold = round(seconds / stage.sample_period), round(0.05 / stage.sample_period)
    levels = np.random.default_rng(seed).uniform(*stage.input_range, size=samples // hold + 1)
    u = np.repeat(levels, hold)[:samples]
    y = stage.respond(u, seed)
    t = np.arange(samples) * stage.sample_period
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header="t,u,y", comments="", fmt="%.9g")


def _random_reference(path: Path, rest: float, lo: float, hi: float) -> None:
    """4 s of noise low-passed at 3 Hz over 10–90 % of the range, blended in from rest over 0.4 s."""
    dt = 1e-3
    t = np.arange(4001) * dt
    x = sosfiltfilt(butter(2, 3.0, fs=1 / dt, output="sos"), np.random.default_rng(5).standard_normal(len(t)))
    ref = lo + (hi - lo) * (0.1 + 0.8 * (x - x.min()) / (x.max() - x.min()))
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.clip(t / 0.4, 0, 1))
    start = min(max(rest, lo), hi)
    np.savetxt(path, np.column_stack([t, start + ramp * (ref - start)]), delimiter=",", header="t,ref",
               comments="", fmt="%.9g")


def _actuator_file(folder: Path, name: str, stage, output_range, units: str) -> Path:
    lo, hi = stage.input_range
    path = folder / "stage.toml"
    path.write_text(f'name = "{name}"\nsample_period = {stage.sample_period}\noutput_name = "displacement"\n'
                    f'units = "{units}"\ninput_units = "V"\ninput_bounds = [{lo}, {hi}]\n'
                    f'output_range = [{output_range[0]}, {output_range[1]}]\n\n[model]\nfile = "model.json"\n\n'
                    f'[sensor]\nnoise_std = {stage.noise}\n\n[plant]\nmismatch = 0.05\nseed = 0\n')
    return path


def prepare(out: Path) -> None:
    """Records, models and actuator files (kept when already there)."""
    for name, (options, output_range, units) in SETTINGS.items():
        folder = out / name
        if (folder / "stage.toml").exists():
            continue
        folder.mkdir(parents=True, exist_ok=True)
        stage = STAGES[name]()
        _write_record(folder / "fit.csv", stage, 20.0, 1)
        _write_record(folder / "validate.csv", stage, 10.0, 2)
        if "{steps}" in options:
            _write_steps(folder / "steps.csv", stage, 2.0, 3)
            options = [str(folder / "steps.csv") if o == "{steps}" else o for o in options]
        _hystmpc("identify", "auto", str(folder / "fit.csv"), "--validate", str(folder / "validate.csv"), *options,
                 "--out", str(folder / "model.json"), "--no-plots", "--quiet")
        _random_reference(folder / "random.csv", stage.reset(0).truth["y"], *output_range)
        _actuator_file(folder, name, stage, output_range, units)


def compare(out: Path, sets: list[str], tag: str) -> dict:
    """RMSEs by (stage, scenario, controller, plant)."""
    found = {}
    for name in SETTINGS:
        folder = out / name
        factory = "make_" + name.replace("-", "_")
        for plant in ("sim", "stage"):
            own = ["--plant", f"heldout_stages:{factory}"] if plant == "stage" else []
            given = sets if plant == "sim" else _plantless(sets)
            for label, reference in (("file", ["sine", "staircase"]),
                                     ("random", ["--reference", str(folder / "random.csv")])):
                result = folder / tag / f"{plant}-{label}"
                _hystmpc("compare", str(folder / "stage.toml"), *reference, *own, *given, "--out", str(result),
                         "--overwrite", "--no-plots", "--quiet")
                for run in json.loads((result / "results.json").read_text())["runs"]:
                    found[(name, run["scenario"], run["controller"], plant)] = run["metrics"]
    return found


def _plantless(sets: list[str]) -> list[str]:
    """``sets`` without ``--set plant.*`` (the stage is the plant: compare refuses them there)."""
    kept = []
    for flag, value in zip(sets[::2], sets[1::2], strict=True):
        if not value.startswith("plant."):
            kept += [flag, value]
    return kept


def report(found: dict) -> None:
    cases = sorted({k[:2] for k in found}, key=lambda k: (list(SETTINGS).index(k[0]), k[1]))
    print("| stage | reference | NMPC / best baseline (stage) | ranking (stage) | simulated plant ranks alike | "
          "worst sim/stage RMSE ratio | oscillating on the stage |")
    print("|---|---|---|---|---|---|---|")
    for stage, scenario in cases:
        controllers = [k[2] for k in found if k[:2] == (stage, scenario) and k[3] == "stage"]
        rmse = {p: {c: found[(stage, scenario, c, p)]["rmse"] for c in controllers} for p in ("sim", "stage")}
        best = min((c for c in controllers if c != "nmpc"), key=rmse["stage"].get)
        ranks = {p: sorted(controllers, key=rmse[p].get) for p in rmse}
        ratio = max(max(rmse["sim"][c] / rmse["stage"][c], rmse["stage"][c] / rmse["sim"][c]) for c in controllers)
        oscillating = [c for c in controllers if found[(stage, scenario, c, "stage")].get("oscillating")]
        print(f"| {stage} | {scenario} | {rmse['stage']['nmpc'] / rmse['stage'][best]:.2f} ({best}) | "
              f"{' < '.join(ranks['stage'])} | {'yes' if ranks['sim'] == ranks['stage'] else 'no'} | {ratio:.2f} | "
              f"{', '.join(oscillating) or '–'} |")


if __name__ == "__main__":
    out_dir, extra = Path(sys.argv[1]), sys.argv[2:]
    if extra[:1] == ["--only"]:
        chosen = extra[1].split(",")
        unknown = [name for name in chosen if name not in SETTINGS]
        if unknown:
            sys.exit(f"--only: unknown stage {unknown[0]!r}; allowed: {', '.join(SETTINGS)}")
        SETTINGS = {name: SETTINGS[name] for name in chosen}
        extra = extra[2:]
    prepare(out_dir)
    report(compare(out_dir, extra, "results" if not extra else "results-" + "-".join(s for s in extra if s != "--set")))
