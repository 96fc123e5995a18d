"""Held-out truths: simulated actuators of kinds hystmpc has no family for, to measure
identification (and control) as a user with an unfamiliar actuator would see it.

Written apart from hystmpc's models and fitting code, with NumPy only, and never used to
tune them: a fit is measured on them, not adjusted to them. Each truth is a class with
``respond(u) -> y`` (noise-free; ``y_k`` measured before ``u_k`` acts, a sampled rig), a
sample period, a noise level and an input range:

* ``PreisachCreep``: a piezo-like Preisach operator with a smooth two-bump density on a fine
  200 × 200 relay grid (not piecewise constant, not on any play ladder), followed by creep from
  three parallel Kelvin–Voigt elements (not a Grünwald–Letnikov memory);
* ``BoucWenResonance``: Bouc–Wen with exponent n = 1.5 (hystmpc's has n = 1), integrated in
  continuous time, driving a lightly damped 35 Hz mode (damping 0.08) after a 2-sample dead time;
* ``RateDependentPlay``: a Prandtl–Ishlinskii-type operator whose play widths grow with the
  input's speed (a loop that widens at higher frequency), then a 4 ms first-order lag;
* ``DuhemSaturation``: a Coleman–Hodgdon (Duhem) loop with a tanh anhysteretic curve: smooth,
  saturating and asymmetric. Its ``g`` is below half the curve's largest slope, so after a
  reversal the output first moves *against* the input (by 0.32 mm as the input falls 5 V from
  20 V after a rise), and a small dither drifts it toward the curve whichever way the input
  goes: no monotone hysteresis model, and no actuator we know of, does that;
* ``DuhemMonotone``: the same loop with ``g`` raised to half the curve's largest slope, the
  smallest ``g`` for which the output never moves against the input (the reversal slope from
  the steepest ascending branch is ``2g − max f′``).
"""

from __future__ import annotations

import numpy as np


def _second_order(x, sample_period: float, frequency_hz: float, damping: float, substeps: int = 20):
    """A unity-gain mass-spring-damper driven by ``x`` held over each sample (RK4), read at each
    sample before the new input acts; starts at rest at ``x[0]``."""
    wn = 2 * np.pi * frequency_hz
    h = sample_period / substeps
    pos, vel = float(x[0]), 0.0
    out = np.empty(len(x))
    for k, drive in enumerate(x):
        out[k] = pos
        for _ in range(substeps):
            def f(p, v, drive=drive):
                return v, wn * wn * (drive - p) - 2 * damping * wn * v
            k1 = f(pos, vel)
            k2 = f(pos + 0.5 * h * k1[0], vel + 0.5 * h * k1[1])
            k3 = f(pos + 0.5 * h * k2[0], vel + 0.5 * h * k2[1])
            k4 = f(pos + h * k3[0], vel + h * k3[1])
            pos += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            vel += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    return out


def _lag(x, sample_period: float, time_constant: float):
    """A first-order lag, exact under a hold, read before the new input acts; from rest at x[0]."""
    a = np.exp(-sample_period / time_constant)
    out = np.empty(len(x))
    state = float(x[0])
    for k, drive in enumerate(x):
        out[k] = state
        state = a * state + (1 - a) * drive
    return out


class PreisachCreep:
    """Relays on a fine grid over [0, 100] V with a smooth density; µm out; Kelvin–Voigt creep."""

    sample_period = 1e-3
    noise = 0.01
    input_range = (0.0, 100.0)

    def __init__(self):
        edges = np.linspace(0.0, 100.0, 201)
        centres = 0.5 * (edges[1:] + edges[:-1])
        alpha, beta = np.meshgrid(centres, centres, indexing="ij")
        keep = alpha >= beta
        self.alpha, self.beta = alpha[keep], beta[keep]

        def bump(a0, b0, width):
            return np.exp(-((self.alpha - a0) ** 2 + (self.beta - b0) ** 2) / (2 * width**2))
        density = bump(55.0, 45.0, 12.0) + 0.6 * bump(80.0, 30.0, 18.0) + 0.25  # µm per relay area, scaled below
        self.weights = density / density.sum() * 6.0  # a 12 µm output span (relays at ±1)
        self.reversible = 0.03  # µm/V
        self.creep = ((0.05, 0.3), (0.04, 3.0), (0.03, 30.0))  # (share of the static output, time constant s)

    def respond(self, u) -> np.ndarray:
        """Output before each input acts, from the demagnetised state at u[0]."""
        u = np.asarray(u, float)
        relays = np.where(self.alpha + self.beta < 2 * u[0], 1.0, -1.0)  # demagnetised at u[0]
        static = np.empty(len(u))
        last = u[0]
        for k, v in enumerate(u):
            if v > last:
                relays[self.alpha <= v] = 1.0
            elif v < last:
                relays[self.beta >= v] = -1.0
            last = v
            static[k] = self.weights @ relays + self.reversible * v
        creep = sum(share * (_lag(static, self.sample_period, tau) - static[0]) for share, tau in self.creep)
        measured = static + creep
        return np.concatenate(([measured[0]], measured[:-1]))


class BoucWenResonance:
    """Bouc–Wen (n = 1.5) in the piezo form ``y = k·u − h``, V → µm, a 2-sample dead time and a
    35 Hz mode with damping 0.08."""

    sample_period = 1e-3
    noise = 0.005
    input_range = (-60.0, 60.0)

    def __init__(self):
        self.k, self.a, self.beta, self.gamma, self.n = 0.11, 0.05, 0.004, 0.001, 1.5
        self.delay, self.frequency, self.damping = 2, 35.0, 0.08

    def _hysteresis(self, u):
        h, out, last = 0.0, np.empty(len(u)), u[0]
        for k, v in enumerate(u):
            steps = 40
            du = (v - last) / steps
            for _ in range(steps):  # dh = A du − β|du||h|^(n−1) h − γ du |h|^n, fine steps of the move
                h += self.a * du - self.beta * abs(du) * abs(h) ** (self.n - 1) * h - self.gamma * du * abs(h) ** self.n
            last = v
            out[k] = self.k * v - h
        return out

    def respond(self, u) -> np.ndarray:
        u = np.asarray(u, float)
        h = self._hysteresis(np.concatenate((np.full(self.delay, u[0]), u))[: len(u)])
        return _second_order(h, self.sample_period, self.frequency, self.damping)


class RateDependentPlay:
    """Plays whose half-widths grow with the input's speed: ``r_i (1 + 0.004 s/V · |du/dt|)``."""

    sample_period = 1e-3
    noise = 0.01
    input_range = (0.0, 80.0)

    def __init__(self):
        self.radii = np.array([2.5, 7.0, 13.0, 21.0])
        self.weights = np.array([0.05, 0.04, 0.03, 0.02])
        self.linear, self.speed, self.time_constant = 0.04, 0.004, 0.004

    def respond(self, u) -> np.ndarray:
        u = np.asarray(u, float)
        z = np.full(len(self.radii), u[0])
        static = np.empty(len(u))
        last = u[0]
        for k, v in enumerate(u):
            speed = abs(v - last) / self.sample_period
            r = self.radii * (1 + self.speed * speed)
            z = np.clip(z, v - r, v + r)
            last = v
            static[k] = self.linear * v + self.weights @ z
        return _lag(static, self.sample_period, self.time_constant)


class DuhemSaturation:
    """Coleman–Hodgdon: ``dy = α|du| (f(u) − y) + g du``, ``f = 3 tanh((u − 8)/15) + 0.02 u``."""

    sample_period = 1e-3
    noise = 0.005
    input_range = (-30.0, 40.0)

    def __init__(self):
        self.alpha, self.g = 0.12, 0.02

    def _anhysteretic(self, u):
        return 3.0 * np.tanh((u - 8.0) / 15.0) + 0.02 * u

    def respond(self, u) -> np.ndarray:
        u = np.asarray(u, float)
        y, last = self._anhysteretic(u[0]), u[0]
        out = np.empty(len(u))
        for k, v in enumerate(u):
            out[k] = y  # measured before the move
            steps = 20
            du = (v - last) / steps
            for j in range(steps):
                x = last + (j + 0.5) * du
                y += self.alpha * abs(du) * (self._anhysteretic(x) - y) + self.g * du
            last = v
        return out


class DuhemMonotone(DuhemSaturation):
    """``DuhemSaturation`` with ``g = max f′ / 2``: the output never moves against the input."""

    def __init__(self):
        super().__init__()
        u = np.linspace(*self.input_range, 20001)
        self.g = 0.5 * float(np.max(np.gradient(self._anhysteretic(u), u)))


TRUTHS = {"preisach-creep": PreisachCreep, "bouc-wen-resonance": BoucWenResonance,
          "rate-dependent-play": RateDependentPlay, "duhem-saturation": DuhemSaturation,
          "duhem-monotone": DuhemMonotone}


def excitation(lo: float, hi: float, sample_period: float, seconds: float, seed: int) -> np.ndarray:
    """A record a careful user would take: from rest at ``lo``, moves at several speeds between
    random levels, held a while at some (creep), and a decaying sine (nested minor loops)."""
    rng = np.random.default_rng(seed)
    n = int(round(seconds / sample_period))
    parts, level = [np.full(50, lo)], lo
    while sum(len(p) for p in parts) < 0.6 * n:
        target = lo + (hi - lo) * rng.uniform(0, 1)
        move = int(rng.integers(5, 400))
        parts.append(np.linspace(level, target, move))
        if rng.uniform() < 0.2:
            parts.append(np.full(int(rng.integers(100, 800)), target))
        level = target
    rest = n - sum(len(p) for p in parts)
    t = np.arange(rest) * sample_period
    parts.append(0.5 * (lo + hi) + (level - 0.5 * (lo + hi)) * np.cos(2 * np.pi * 3.0 * t) * np.exp(-t / (0.3 * t[-1])))
    return np.concatenate(parts)[:n]


def record(truth, seconds: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``(u, y)``: :func:`excitation` through ``truth`` with its sensor noise (seeded)."""
    u = excitation(*truth.input_range, truth.sample_period, seconds, seed)
    y = truth.respond(u) + truth.noise * np.random.default_rng(seed + 1000).standard_normal(len(u))
    return u, y
