"""Bench ``reluctance``: current-driven reluctance actuator linearisation (katalenic2013).

Force is not measured in operation: all three controllers are feed-forward and use the
model identified from simulated, noisy major-loop measurements (Section 3.5), never the
plant's true parameters.

* ``poly-inverse``: one single-valued 4th-order polynomial i(√F, g) over all air gaps,
  fitted to both branches of the identification data (√F since F ∝ i²; ref. [2] of the paper);
* ``hyst-inverse``: i = IH[Lut(F_ref, g)] (eq. (12a), Fig. 10), its command rate-limited to
  the amplifier's slew limit;

Both inverses command the force wanted at the next sample, when their current takes effect.
* ``nmpc``: currents over a horizon within the current bounds and slew limit, predicting
  F = Lut⁻¹(H[i], g) (eq. (12b)) with the smooth H.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np

from experiments.bench import Bench, ControllerSpec, NmpcAdapter, Scenario
from models.parametric import ParametricHysteresis, identify_major_loop
from models.smooth import smooth_max
from mpc import Nmpc, NmpcController, NmpcSettings, OpenLoopEstimator, PredictionModel
from plants.base import Measurement
from plants.reluctance import C_CORE, ReluctanceActuator, ReluctanceParams, major_loop_measurement

CORES = ("E", "C")
FORCE_MAX = {"E": 400.0, "C": 240.0}
"""Identification and ramp force ranges (N), Section 3.5."""


@dataclass(frozen=True)
class RigSettings:
    """Which actuator and air gap (fixed by each named scenario)."""

    core: str = "E"
    """``E`` or ``C`` (Table 1)."""
    gap_mm: float = 1.5
    """Air gap (mm)."""

    def __post_init__(self):
        if self.core not in CORES:
            raise ValueError(f"core {self.core!r} is unknown; allowed: {', '.join(CORES)}")
        if not 1.0 <= self.gap_mm <= 2.0:
            raise ValueError(f"gap_mm must be in [1.0, 2.0], got {self.gap_mm}")


@dataclass(frozen=True)
class IdentificationSettings:
    """The simulated identification experiment (Fig. 9) and its fit."""

    gaps_mm: tuple[float, float, float, float, float] = (1.2, 1.3, 1.5, 1.7, 1.75)
    """Air gaps of the major-loop measurements (mm)."""
    duration: float = 2.0
    """Length of each 0 → max → 0 current run (s)."""
    seed: int = 0
    """Seed of the force-measurement noise."""
    window: int = 10
    """Samples averaged per look-up-table point (1: the paper's plain table). Noise in the
    table goes 1:1 into the linearisation error; 10 samples of the decimated 2.5 kHz record
    (4 ms) cut σ = 0.05 N to about 0.016 N."""
    force_margin: float = 0.03
    """Identify up to this fraction beyond the operating force, so the table covers the peak."""

    def __post_init__(self):
        if sorted(self.gaps_mm) != list(self.gaps_mm) or len(set(self.gaps_mm)) != len(self.gaps_mm):
            raise ValueError(f"gaps_mm must increase strictly, got {self.gaps_mm}")
        if not self.duration > 0 or self.window < 1:
            raise ValueError("duration must be > 0 and window >= 1")


@dataclass(frozen=True)
class IdentifiedModel:
    """What identification gives the controllers: p1, p2 and per-gap tables (eq. (12))."""

    p1: float
    p2: float
    gaps: tuple[float, ...]
    """Identified air gaps (m), increasing."""
    tables: tuple[tuple[np.ndarray, np.ndarray], ...]
    """Per gap: (F, X) of the ascending look-up table, F increasing."""
    poly: np.ndarray
    """Coefficients of i = Σ c_ab (√F)^a (g/1 mm)^b, a + b <= 4, over all gaps (poly-inverse)."""

    def _neighbours(self, gap: float):
        gaps = np.asarray(self.gaps)
        if gap <= gaps[0]:
            return 0, 0, 0.0
        if gap >= gaps[-1]:
            return len(gaps) - 1, len(gaps) - 1, 0.0
        j = int(np.searchsorted(gaps, gap))
        return j - 1, j, (gap - gaps[j - 1]) / (gaps[j] - gaps[j - 1])

    def x_of_force(self, force, gap: float):
        """Lut(F, g): linear in F within a gap's table, linear between gaps (eq. (15))."""
        a, b, w = self._neighbours(gap)
        xa = np.interp(force, *self.tables[a])
        xb = np.interp(force, *self.tables[b])
        return (1 - w) * xa + w * xb

    def force_of_x(self, x, gap: float):
        """Lut⁻¹(X, g)."""
        a, b, w = self._neighbours(gap)
        fa = np.interp(x, self.tables[a][1], self.tables[a][0])
        fb = np.interp(x, self.tables[b][1], self.tables[b][0])
        return (1 - w) * fa + w * fb

    def poly_current(self, force, gap: float):
        """Single-valued 4th-order polynomial inverse i(F, g)."""
        return _poly_features(np.atleast_1d(force), gap) @ self.poly


    def operator(self, gap: float) -> ParametricHysteresis:
        """H with the air-gap law p2(g) = p2/g."""
        return ParametricHysteresis(self.p1, self.p2 / gap)


def _poly_features(force, gap):
    root = np.sqrt(np.maximum(np.asarray(force, float), 0.0))
    g = np.broadcast_to(np.asarray(gap, float) / 1e-3, root.shape)
    return np.stack([root**a * g**b for a in range(5) for b in range(5 - a)], axis=-1)


@functools.lru_cache(maxsize=8)
def identify(plant: ReluctanceParams, settings: IdentificationSettings, force_max: float) -> IdentifiedModel:
    """Run the simulated identification experiment on ``plant`` and fit the model (cached)."""
    gaps = tuple(g * 1e-3 for g in settings.gaps_mm)
    loops = {g: major_loop_measurement(plant, g, force_max * (1 + settings.force_margin), settings.duration,
                                       seed=settings.seed + k)
             for k, g in enumerate(gaps)}
    p1, p2, luts = identify_major_loop(loops, window=settings.window)
    tables = []
    for g in gaps:
        f_tab, x_tab = luts[g]
        f_tab, keep = np.unique(f_tab, return_index=True)
        tables.append((f_tab, np.maximum.accumulate(x_tab[keep])))
    # one polynomial in force and air gap over both branches of every loop, as in [2]
    features = np.concatenate([_poly_features(loops[g][1], g) for g in gaps])
    currents = np.concatenate([loops[g][0] for g in gaps])
    poly = np.linalg.lstsq(features, currents, rcond=None)[0]
    return IdentifiedModel(p1, p2, gaps, tuple(tables), poly)


def identified_document(config) -> dict:
    """The identified model of the configured core as a JSON-ready dict (``hystmpc identify``)."""
    model = identified_model(config)
    plant, _, force_max = _rig(config)
    return {
        "schema": "hystmpc.identified/1", "bench": "reluctance", "core": config["rig"].core,
        "p1_A": model.p1, "p2_per_A_m": model.p2,
        "true_p1_A": plant.p1, "true_p2_per_A_m": plant.p2,
        "gaps_m": list(model.gaps),
        "tables": [{"gap_m": g, "force_N": f.tolist(), "x_A": x.tolist()}
                   for g, (f, x) in zip(model.gaps, model.tables, strict=True)],
        "poly_inverse": {"features": "sqrt(F)^a * (g/1mm)^b, a+b<=4, a outer", "coefficients": model.poly.tolist()},
        "force_max_N": force_max,
    }


def _rig(config) -> tuple[ReluctanceParams, float, float]:
    rig: RigSettings = config["rig"]
    plant = config["ecore"] if rig.core == "E" else config["ccore"]
    return plant, rig.gap_mm * 1e-3, FORCE_MAX[rig.core]


def identified_model(config) -> IdentifiedModel:
    """The controllers' model for the configured core."""
    plant, _, force_max = _rig(config)
    return identify(plant, config["identification"], force_max)


class PolyInverse:
    """Feed-forward through the single-valued polynomial (the paper's baseline, Fig. 5b).

    Like every feed-forward here it commands the force wanted when the current takes
    effect, one sample ahead (``horizon = 1``); otherwise it would lag by one sample."""

    horizon = 1

    def __init__(self, model: IdentifiedModel, gap: float, current_limit: float):
        self.model, self.gap, self.limit = model, gap, current_limit
        self.predicted_output = float("nan")

    def reset(self) -> None:
        """Stateless."""

    def step(self, measurement: Measurement, ref_window) -> float:
        """Current for the reference force."""
        return float(np.clip(self.model.poly_current(float(ref_window[1]), self.gap)[0], 0.0, self.limit))

    def stats(self) -> None:
        return None


class HystInverse:
    """i = IH[Lut(F_ref, g)] (eq. (12a)); the command is rate-limited to the slew limit and the
    operator's memory follows the current actually commanded. Targets the next sample's
    reference (``horizon = 1``), as :class:`PolyInverse`."""

    horizon = 1

    def __init__(self, model: IdentifiedModel, gap: float, current_limit: float, slew_per_sample: float):
        self.model, self.gap, self.limit, self.slew = model, gap, current_limit, slew_per_sample
        self.op = model.operator(gap)
        self.reset()

    def reset(self) -> None:
        """Demagnetised at zero current."""
        self._state = self.op.initial_state(0.0)
        self.predicted_output = float("nan")

    def step(self, measurement: Measurement, ref_window) -> float:
        """Current for the reference force."""
        x_target = float(self.model.x_of_force(max(float(ref_window[1]), 0.0), self.gap))
        last = float(self._state[0])
        _, wanted = self.op.inverse_step(self._state, x_target)
        current = float(np.clip(wanted, max(0.0, last - self.slew), min(self.limit, last + self.slew)))
        self._state, x = self.op.step(self._state, current)
        self.predicted_output = float(self.model.force_of_x(x, self.gap))
        return current

    def stats(self) -> None:
        return None


def _build(kind: str):
    def build(config):
        plant, gap, _ = _rig(config)
        model = identified_model(config)
        if kind == "poly":
            return PolyInverse(model, gap, plant.current_limit)
        return HystInverse(model, gap, plant.current_limit, plant.slew_limit * plant.sample_period)
    return build


def force_table(model: IdentifiedModel, gap: float) -> tuple[np.ndarray, np.ndarray]:
    """(X, F) points of Lut⁻¹ at ``gap``, anchored at the origin.

    The identified table between the neighbouring gaps (a gap's own table when it was
    identified), with the points where the slope does not change dropped, and (0, 0)
    put in front: no current, no force. Without that anchor the table's lowest point
    (noise-level force) would be extended flat to zero current, where a model with no
    slope gives a Gauss–Newton step nothing to follow.
    """
    a, b, w = model._neighbours(gap)
    if w in (0.0, 1.0):
        x_pts = np.asarray(model.tables[b if w == 1.0 else a][1], float)
    else:
        x_pts = np.unique(np.concatenate((model.tables[a][1], model.tables[b][1])))
    f_pts = model.force_of_x(x_pts, gap)
    keep = np.concatenate(([True], (np.diff(x_pts) > 1e-6) & (np.diff(f_pts) > 0)))
    x_pts, f_pts = x_pts[keep], f_pts[keep]
    if x_pts[0] > 0 and f_pts[0] > 0:
        x_pts, f_pts = np.concatenate(([0.0], x_pts)), np.concatenate(([0.0], f_pts))
    slopes = np.diff(f_pts) / np.diff(x_pts)
    bends = np.abs(np.diff(slopes)) > 1e-9 * np.abs(slopes).max()
    keep = np.concatenate(([True], bends, [True]))
    return x_pts[keep], f_pts[keep]


def smooth_force_of_x(model: IdentifiedModel, gap: float, kink_eps: float = 1e-4):
    """Lut⁻¹(X, g) as the polyline of :func:`force_table` with its kinks rounded over
    ``kink_eps`` (for CasADi)."""
    xs, fs = force_table(model, gap)
    slopes = np.diff(fs) / np.diff(xs)

    def force(v):
        value = fs[0] + slopes[0] * (v - xs[0])
        for k in range(1, len(slopes)):
            value = value + (slopes[k] - slopes[k - 1]) * smooth_max(v - xs[k], 0.0, kink_eps)
        return value
    return force


def prediction_model(model: IdentifiedModel, gap: float, eps: float, kink_eps: float = 1e-4) -> PredictionModel:
    """F = Lut⁻¹(H[i], g), eq. (12b), with the smooth H and the table as a smooth polyline."""
    op = model.operator(gap)
    smooth = op.smooth_step(eps)
    x = ca.SX.sym("x", 5)
    u = ca.SX.sym("u")
    d = ca.SX.sym("d")
    x_next, _ = smooth(x, u)

    force = smooth_force_of_x(model, gap, kink_eps)(x[4])
    names = ("current_last", "direction", "current_at_extremum", "x_at_extremum", "x")
    return PredictionModel(
        step=ca.Function("reluctance_step", [x, u, d], [x_next], ["x", "u", "d"], ["x_next"]),
        output=ca.Function("reluctance_output", [x, d], [force], ["x", "d"], ["y"]),
        measure=ca.Function("reluctance_measure", [x, d], [force], ["x", "d"], ["z"]),
        sample_period=ReluctanceParams().sample_period,
        state_names=names,
    )


def build_nmpc(config) -> NmpcAdapter:
    """Feed-forward NMPC: the exact H re-anchors the smooth prediction every sample."""
    plant, gap, _ = _rig(config)
    model = identified_model(config)
    settings: NmpcSettings = config["nmpc"]
    op = model.operator(gap)
    pm = prediction_model(model, gap, settings.eps)
    nmpc = Nmpc(pm, settings, 0.0, plant.current_limit, plant.slew_limit * plant.sample_period)
    estimator = OpenLoopEstimator(lambda x, u: op.step(x, u)[0])

    def inverse(x, d, refs):
        state, out = np.asarray(x, float), np.empty(len(refs))
        for j, r in enumerate(refs):
            state, out[j] = op.inverse_step(state, float(model.x_of_force(max(float(r), 0.0), gap)))
        return out

    controller = NmpcController(nmpc, estimator, lambda z: op.initial_state(0.0), inverse, [0.0] * 6,
                                jump_threshold=20.0)
    return NmpcAdapter(controller, lambda m: np.zeros(0))


def offline_optimum(config, reference: np.ndarray) -> np.ndarray:
    """Best slew-limited currents for a whole reference, known in advance (a lower bound).

    Minimises Σ_k (F_{k+1} − r_{k+1})² over the full run under the current bounds and slew
    limit, with the identified model: F = Lut⁻¹(X, g) and X = H[i]. The NLP is posed in X
    (the hysteresis-free static part, solved by IPOPT), then the exact inverse IH turns X
    into currents; H moves X from i by less than p1, so the slew limit holds to within p1
    (the plant's amplifier enforces it exactly). No causal controller, with any horizon, can
    do better on this model than this sequence.

    Parameters
    ----------
    config : dict
        Bench configuration with the scenario's conditions applied.
    reference : ndarray, shape (n,)
        Force reference at each sample (N).

    Returns
    -------
    ndarray, shape (n,)
        Current commanded at each sample (A).
    """
    plant, gap, _ = _rig(config)
    model = identified_model(config)
    slew = plant.slew_limit * plant.sample_period
    ref = np.asarray(reference, float)
    n = len(ref)
    force = smooth_force_of_x(model, gap)
    opti = ca.Opti()
    x = opti.variable(n)
    opti.subject_to(opti.bounded(-slew, x - ca.vertcat(0.0, x[:-1]), slew))
    opti.subject_to(opti.bounded(0.0, x, plant.current_limit))
    target = np.append(ref[1:], ref[-1])  # the current of sample k shows in the force at k+1
    opti.minimize(ca.sumsqr(force(x) - target))
    greedy = np.empty(n)
    last = 0.0
    for k in range(n):
        last = float(np.clip(model.x_of_force(max(target[k], 0.0), gap), last - slew, last + slew))
        greedy[k] = last
    opti.set_initial(x, greedy)
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "sb": "yes", "max_iter": 500})
    try:
        x_opt = np.asarray(opti.solve().value(x), float)
    except RuntimeError as exc:
        raise RuntimeError(f"offline optimum did not converge: {exc}") from exc
    op = model.operator(gap)
    state, currents = op.initial_state(0.0), np.empty(n)
    for k in range(n):
        state, currents[k] = op.inverse_step(state, float(x_opt[k]))
    return np.clip(currents, 0.0, plant.current_limit)


def _smooth_path(waypoints, segment: float):
    """Raised-cosine moves through ``waypoints`` (N), ``segment`` seconds each."""
    waypoints = np.asarray(waypoints, float)

    def reference(t):
        t = np.asarray(t, float)
        k = np.clip((t // segment).astype(int), 0, len(waypoints) - 2)
        frac = np.clip((t - k * segment) / segment, 0.0, 1.0)
        return waypoints[k] + (waypoints[k + 1] - waypoints[k]) * 0.5 * (1 - np.cos(np.pi * frac))
    return reference


def _steps(levels, dwell: float):
    levels = np.asarray(levels, float)

    def reference(t):
        k = np.clip((np.asarray(t, float) // dwell).astype(int), 0, len(levels) - 1)
        return levels[k]
    return reference


def _scenarios() -> dict[str, Scenario]:
    out = []
    for gap in (1.2, 1.3, 1.5, 1.7):
        out.append(Scenario(f"ramp-{gap:g}mm", f"E-core, {gap:g} mm: 0 → 400 N → 0 in 8 s (Fig. 11)", 8.0,
                            _smooth_path([0.0, 400.0, 0.0], 4.0), (f"rig.gap_mm={gap}", "rig.core=E")))
    out.append(Scenario("reversals-1.75mm", "E-core, 1.75 mm: non-periodic, higher-order reversal curves (Fig. 13)",
                        8.0, _smooth_path([0, 350, 100, 300, 150, 250, 50, 400, 0], 1.0),
                        ("rig.gap_mm=1.75", "rig.core=E")))
    out.append(Scenario("ccore-ramp-1.5mm", "C-core, 1.5 mm: 0 → 240 N → 0 in 8 s (Fig. 12)", 8.0,
                        _smooth_path([0.0, 240.0, 0.0], 4.0), ("rig.gap_mm=1.5", "rig.core=C")))
    out.append(Scenario("steps-1.5mm", "E-core, 1.5 mm: force steps every 0.1 s; the slew limit binds", 0.7,
                        _steps([50, 250, 100, 350, 150, 300, 50], 0.1), ("rig.gap_mm=1.5", "rig.core=E")))
    return {s.name: s for s in out}


def _defaults() -> dict:
    return {"rig": RigSettings(), "ecore": ReluctanceParams(), "ccore": C_CORE,
            "identification": IdentificationSettings(),
            "nmpc": NmpcSettings(horizon=16, q_output=1.0, r_rate=1.0, eps=1e-5, solver="sqp", max_iter=50)}


def _plant(config):
    plant, gap, _ = _rig(config)
    return ReluctanceActuator(plant, gap)


BENCH = Bench(
    name="reluctance",
    description="Current-driven reluctance actuator, parametric (Lambert W) hysteresis (katalenic2013)",
    paper="katalenic2013_reluctance_actuator_hysteresis_linearization",
    output_name="force",
    units="N",
    input_units="A",
    sample_period=ReluctanceParams().sample_period,
    scenarios=_scenarios(),
    controllers={
        "poly-inverse": ControllerSpec("poly-inverse", "single-valued 4th-order polynomial inverse",
                                       _build("poly")),
        "hyst-inverse": ControllerSpec("hyst-inverse", "IH[Lut(F, g)], eq. (12a), Fig. 10", _build("hyst")),
        "nmpc": ControllerSpec("nmpc", "feed-forward NMPC: currents over a horizon, slew limit, F = Lut⁻¹(H[i])",
                               build_nmpc),
    },
    defaults=_defaults,
    make_plant=_plant,
    output_range=(0.0, 450.0),
    input_bounds=(0.0, ReluctanceParams().current_limit),
    loop=("current", "force", "current [A]", "force [N]"),
    default_scenario="ramp-1.5mm",
    error_vs_reference=True,
)
