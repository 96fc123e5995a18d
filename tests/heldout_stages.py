"""Held-out stages: simulated actuators with the Plant protocol, to run hystmpc's controllers
on actuators it has no exact family for, as a user would with a rig (``--plant``).

Written apart from hystmpc's models, fitting code and controllers, with NumPy only, and never
used to tune them: results are measured on them, not adjusted to them. Each stage has
``reset(seed) -> Measurement`` (at rest, read before any input acts), ``step(u) ->
Measurement`` (``u`` held for one sample, read at its end), a sample period, a sensor noise
level and an input range:

* ``PreisachCreepStage``: a piezo-like Preisach operator on a fine 120 × 120 relay grid with a
  smooth skewed density, two Kelvin–Voigt creep elements (0.5 s and 8 s) and a 2 ms lag;
* ``BoucWenResonanceStage``: Bouc–Wen with exponent n = 1.5 and a 2-sample dead time driving a
  lightly damped 60 Hz mode (damping 0.06);
* ``FastBoucWenStage``: a 2 kHz stage, Bouc–Wen (n = 1.2) with a 1-sample dead time driving
  a 180 Hz mode (damping 0.08), for timing the controllers at a 0.5 ms period;
* ``DuhemLagStage``: a saturating, asymmetric Coleman–Hodgdon (Duhem) loop, a 1-sample dead
  time and a 3 ms lag, on a bipolar input. Its ``g`` is below half the curve's largest slope:
  after a reversal the output first moves against the input (0.31 mm as the input falls 6 V
  from 20 V after a rise), and a dither drifts it whichever way the input goes;
* ``DuhemMonotoneStage``: the same with ``g`` raised to half the curve's largest slope, the
  smallest for which the output never moves against the input.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from hystmpc.plants.base import Measurement


class _Stage:
    """Sensor noise, time and the dead time around a stage's noise-free ``_advance(u) -> y``."""

    sample_period = 1e-3
    delay = 0

    def reset(self, seed: int) -> Measurement:
        """At rest at the input range's lower end; the first measurement."""
        self.rng = np.random.default_rng(seed)
        self.k = 0
        self._rest()
        self.queue = deque([self.input_range[0]] * self.delay)
        return self._measure(self._output())

    def step(self, u: float) -> Measurement:
        """Apply ``u`` for one sample; the measurement at its end."""
        self.k += 1
        self.queue.append(float(u))
        return self._measure(self._advance(self.queue.popleft()))

    def _measure(self, y: float) -> Measurement:
        return Measurement(self.k * self.sample_period, y + self.noise * self.rng.standard_normal(),
                           truth={"y": y})

    def respond(self, u, seed: int = 0) -> np.ndarray:
        """Open loop: the measurement before each input acts (a record's rows)."""
        y = [self.reset(seed).y]
        for v in u[:-1]:
            y.append(self.step(v).y)
        return np.array(y)


def _lag_gain(time_constant: float, sample_period: float) -> float:
    return 1.0 - np.exp(-sample_period / time_constant)


class PreisachCreepStage(_Stage):
    """Relays on a fine grid over [0, 100] V, µm out, creep and a lag."""

    description = "held-out Preisach stage with creep"
    noise = 0.01
    input_range = (0.0, 100.0)

    def __init__(self):
        edges = np.linspace(0.0, 100.0, 121)
        centres = 0.5 * (edges[1:] + edges[:-1])
        alpha, beta = np.meshgrid(centres, centres, indexing="ij")
        keep = alpha >= beta
        self.alpha, self.beta = alpha[keep], beta[keep]
        width = self.alpha - self.beta
        density = np.exp(-width / 35.0) * (1.0 + 0.8 * np.exp(-((self.alpha + self.beta - 90.0) / 60.0) ** 2))
        self.weights = density / density.sum() * 5.0  # relays at ±1: a 10 µm hysteretic span
        self.reversible = 0.035  # µm/V
        self.creep = np.array([[0.06, 0.5], [0.05, 8.0]])  # share of the static move, time constant (s)
        self.lag = _lag_gain(0.002, self.sample_period)
        self.reset(0)

    def _rest(self):
        self.relays = -np.ones(len(self.alpha))
        self.last = self.input_range[0]
        self.static0 = self._static()
        self.creep_state = np.zeros(len(self.creep))
        self.y = self.static0

    def _static(self) -> float:
        return float(self.weights @ (self.relays + 1.0) + self.reversible * self.last)  # 0 at rest

    def _output(self) -> float:
        return self.y

    def _advance(self, u: float) -> float:
        if u > self.last:
            self.relays[self.alpha <= u] = 1.0
        elif u < self.last:
            self.relays[self.beta >= u] = -1.0
        self.last = u
        static = self._static()
        gains = np.array([_lag_gain(tau, self.sample_period) for tau in self.creep[:, 1]])
        self.creep_state += gains * (self.creep[:, 0] * (static - self.static0) - self.creep_state)
        self.y += self.lag * (static + self.creep_state.sum() - self.y)
        return self.y


class BoucWenResonanceStage(_Stage):
    """Bouc–Wen (n = 1.5), piezo form ``k·u − h`` in µm, a 2-sample dead time, a 60 Hz mode."""

    description = "held-out Bouc-Wen stage with a 60 Hz mode"
    noise = 0.005
    input_range = (0.0, 120.0)
    delay = 2

    def __init__(self):
        self.stiffness, self.a, self.beta, self.gamma, self.n = 0.1, 0.045, 0.005, 0.0015, 1.5
        self.frequency, self.damping = 60.0, 0.06
        self.reset(0)

    def _rest(self):
        self.h, self.last = 0.0, self.input_range[0]
        self.pos = self.stiffness * self.last
        self.vel = 0.0

    def _output(self) -> float:
        return self.pos

    def _advance(self, u: float) -> float:
        substeps = 40
        du = (u - self.last) / substeps
        for _ in range(substeps):
            self.h += (self.a * du - self.beta * abs(du) * abs(self.h) ** (self.n - 1) * self.h
                       - self.gamma * du * abs(self.h) ** self.n)
        self.last = u
        drive = self.stiffness * u - self.h
        wn = 2 * np.pi * self.frequency
        dt = self.sample_period / substeps
        for _ in range(substeps):  # semi-implicit Euler, fine steps
            self.vel += dt * (wn * wn * (drive - self.pos) - 2 * self.damping * wn * self.vel)
            self.pos += dt * self.vel
        return self.pos


class FastBoucWenStage(BoucWenResonanceStage):
    """A 2 kHz stage: Bouc–Wen (n = 1.2), a 1-sample dead time, a 180 Hz mode."""

    description = "held-out 2 kHz Bouc-Wen stage with a 180 Hz mode"
    sample_period = 5e-4
    noise = 0.004
    input_range = (0.0, 100.0)
    delay = 1

    def __init__(self):
        self.stiffness, self.a, self.beta, self.gamma, self.n = 0.12, 0.05, 0.012, 0.004, 1.2
        self.frequency, self.damping = 180.0, 0.08
        self.reset(0)


class DuhemLagStage(_Stage):
    """Coleman–Hodgdon ``dy = α|du| (f(u) − y) + g du`` with ``f = 2.5 tanh((u − 5)/12) + 0.03 u``,
    a 1-sample dead time and a 3 ms lag; bipolar input in V, output in mm."""

    description = "held-out Duhem stage"
    noise = 0.004
    input_range = (-30.0, 30.0)
    delay = 1

    def __init__(self):
        self.alpha, self.g = 0.1, 0.025
        self.lag = _lag_gain(0.003, self.sample_period)
        self.reset(0)

    def _anhysteretic(self, u):
        return 2.5 * np.tanh((u - 5.0) / 12.0) + 0.03 * u

    def _rest(self):
        self.last = self.input_range[0]
        self.z = self._anhysteretic(self.last)
        self.y = self.z

    def _output(self) -> float:
        return self.y

    def _advance(self, u: float) -> float:
        substeps = 20
        du = (u - self.last) / substeps
        for j in range(substeps):
            x = self.last + (j + 0.5) * du
            self.z += self.alpha * abs(du) * (self._anhysteretic(x) - self.z) + self.g * du
        self.last = u
        self.y += self.lag * (self.z - self.y)
        return self.y


class DuhemMonotoneStage(DuhemLagStage):
    """``DuhemLagStage`` with ``g = max f′ / 2``: the output never moves against the input."""

    description = "held-out monotone Duhem stage"

    def __init__(self):
        super().__init__()
        u = np.linspace(*self.input_range, 20001)
        self.g = 0.5 * float(np.max(np.gradient(self._anhysteretic(u), u)))
        self.reset(0)


STAGES = {"preisach-creep": PreisachCreepStage, "bouc-wen-resonance": BoucWenResonanceStage,
          "fast-bouc-wen": FastBoucWenStage,
          "duhem-lag": DuhemLagStage, "duhem-monotone-lag": DuhemMonotoneStage}


def make_preisach_creep():
    """``--plant heldout_stages:make_preisach_creep``."""
    return PreisachCreepStage()


def make_bouc_wen_resonance():
    """``--plant heldout_stages:make_bouc_wen_resonance``."""
    return BoucWenResonanceStage()


def make_fast_bouc_wen():
    """``--plant heldout_stages:make_fast_bouc_wen``."""
    return FastBoucWenStage()


def make_duhem_lag():
    """``--plant heldout_stages:make_duhem_lag``."""
    return DuhemLagStage()


def make_duhem_monotone_lag():
    """``--plant heldout_stages:make_duhem_monotone_lag``."""
    return DuhemMonotoneStage()
