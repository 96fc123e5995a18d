"""Generate the piezo stage's measured-style records (run once; hystmpc never reads this file).

The truth is written here with NumPy and SciPy alone, not with hystmpc's models:

* hysteresis: 0.06 um/V linear term plus 24 play operators with thresholds evenly spaced
  up to 48 V and weights decaying as 0.006·exp(−r/15 V) um/V, and a slight stiffening,
  −2e-5·u² um (which no Prandtl–Ishlinskii model has);
* dynamics: a 180 Hz, ζ = 0.25 mass-spring stage after the hysteresis (exact
  zero-order-hold discretisation), one sample of dead time;
* sensor: 0.01 um of white noise (seeded), sampled at 1 kHz; input 0–100 V.

Each CSV has ``t`` (s), ``u`` (V: the input applied from that sample on) and ``y`` (um: the
output measured at that sample, before ``u`` acts).
"""

from pathlib import Path

import numpy as np
from scipy.linalg import expm

DT = 1e-3
THRESHOLDS = np.linspace(2.0, 48.0, 24)
WEIGHTS = 0.006 * np.exp(-THRESHOLDS / 15.0)
LINEAR, STIFFENING = 0.06, -2e-5
WN, ZETA, DELAY, NOISE = 2 * np.pi * 180.0, 0.25, 1, 0.01


def truth(u, seed):
    """Measured output for the input sequence ``u`` from rest at 0 V."""
    a = np.array([[0.0, 1.0], [-WN**2, -2 * ZETA * WN]])
    block = np.zeros((3, 3))
    block[:2, :2], block[:2, 2] = a * DT, np.array([0.0, WN**2]) * DT
    phi = expm(block)
    ad, bd = phi[:2, :2], phi[:2, 2]
    z = np.zeros_like(THRESHOLDS)  # play outputs, centred at 0 V
    x = np.zeros(2)
    queue = [0.0] * DELAY
    y = np.empty(len(u))
    for k, uk in enumerate(u):
        y[k] = x[0]
        queue.append(uk)
        v = queue.pop(0)
        z = np.clip(z, v - THRESHOLDS, v + THRESHOLDS)
        h = LINEAR * v + WEIGHTS @ z + STIFFENING * v**2
        x = ad @ x + bd * h
    return y + NOISE * np.random.default_rng(seed).standard_normal(len(u))


def write(name, u, seed):
    t = np.arange(len(u)) * DT
    y = truth(u, seed)
    rows = "\n".join(f"{a:.3f},{b:.4f},{c:.5f}" for a, b, c in zip(t, u, y, strict=True))
    (Path(__file__).parent / name).write_text("t,u,y\n" + rows + "\n")


if __name__ == "__main__":
    t = np.arange(4000) * DT  # 4 s at 1 Hz: a decaying sine, nested minor loops
    write("slow.csv", 50.0 - 50.0 * np.cos(2 * np.pi * t) * (1 - 0.2 * t), seed=1)
    t = np.arange(3000) * DT  # 3 s: two sines, loops the fit did not see
    write("validate.csv", 50.0 - 30.0 * np.cos(2 * np.pi * 0.7 * t) - 20.0 * np.cos(2 * np.pi * 2.3 * t), seed=2)
    t = np.arange(1500) * DT  # 1.5 s: steps every 0.1 s for the stage dynamics
    levels = np.random.default_rng(3).uniform(20.0, 80.0, 15)
    write("fast.csv", np.where(t < 0.05, 0.0, levels[(t // 0.1).astype(int)]), seed=3)
