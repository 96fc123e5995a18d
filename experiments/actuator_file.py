"""Actuator files (TOML, interface.md "Actuator files"): your own actuator as a bench.

From one file hystmpc builds, for every command that takes a bench:

* the **prediction model**: the identified hysteresis (a ``hystmpc.model/1`` document),
  creep if the family has one, and the linear block after it (exact zero-order-hold
  discretisation), with the dead time;
* the **controllers**: ``nmpc``, and the baselines ``pid`` and ``inverse-ff-pid``, whose
  gains are tuned automatically on the tuning ensemble (:mod:`hystmpc.experiments.actuator_tuning`,
  :meth:`ActuatorSpec.tuning_ensemble`), behind a notch on the command where the linear
  block is a lightly damped mode (:meth:`ActuatorSpec.command_notch`), and ``inverse-lmpc``,
  the inverse model in series with the input and a linear MPC on the linear block, whose
  rate weight is tuned the same way, as are both estimators' disturbance walks;
* a **simulated plant**: the exact, non-smooth model (or, with ``plant.truth = runner-up``,
  the model and the runner-up family of an ``identify auto`` ranking in parallel, blended by
  what the model missed on the validation record), every parameter perturbed by a seeded
  relative ``mismatch``, with sensor noise, so that no controller runs on its own model;
* two **scenarios** from the output range: ``sine`` and ``staircase``.

The plants are built in :mod:`hystmpc.experiments.actuator_plants`, the controllers in
:mod:`hystmpc.experiments.actuator_controllers` (both mixed into :class:`ActuatorSpec`); this
module reads the file and puts the bench together.

Groups for ``--set`` (and for optional tables of the same names in the file): ``plant``
(mismatch, seed, noise, truth), ``model`` (``model.hysteresis.*``; ``model.dynamics.*``) and
those of :data:`GROUP_TABLES`.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import re
import tomllib
from pathlib import Path

import numpy as np

from hystmpc.experiments.actuator_controllers import ActuatorControllers
from hystmpc.experiments.actuator_groups import ActuatorModel, ActuatorPlant, DisturbanceWalk, parameter_class
from hystmpc.experiments.actuator_plants import ActuatorPlants
from hystmpc.experiments.baselines import (
    FeedforwardPidGains,
    PidGains,
)
from hystmpc.experiments.bench import MULTIPLE_SHOOTING, SINGLE_SHOOTING, Bench, ControllerSpec
from hystmpc.experiments.config import apply_values
from hystmpc.experiments.runner import Scenario
from hystmpc.models.document import dynamics_from, read_model_document
from hystmpc.models.identification import build_hysteresis, hysteresis_output
from hystmpc.models.linear_dynamics import KIND_KEYS
from hystmpc.models.prediction import Smoothing
from hystmpc.mpc import NmpcSettings, RtiSettings, SolverSettings
from hystmpc.mpc.linear_mpc import LinearMpcSettings

LOG = logging.getLogger("hystmpc")
_WARNED: set[str] = set()
"""Warnings already given, once per file and process (the output range beyond the model's
reach: the path; a linear block above Nyquist: the path with "#nyquist")."""
SECOND_START_SHARE = 0.0025
"""The NMPC solves from the inverse model's inputs too where its first plan misses the reference by this
share of the output span (RMS over the horizon, and at its end): where the shifted plan tracks, the second
start hardly ever wins (docs/your-actuator.md)."""
GROUP_TABLES = ("nmpc", "smoothing", "solver", "pid", "inverse_ff_pid", "lmpc", "estimator", "lmpc_estimator")
"""Optional tables that set the groups of the same name (as ``--set`` would)."""
NMPC_GROUPS, LMPC_GROUPS = ("model", "nmpc", "smoothing", "solver", "estimator"), ("model", "lmpc", "lmpc_estimator")
TABLES = {"model": {"file"}, "sensor": {"noise_std"}, "plant": {"mismatch", "seed", "truth"},
          "dynamics": {"kind", "natural_frequency_hz", "damping", "time_constant", "delay_samples", "creep"},
          "scenarios": {"sine_hz", "step_s", "duration_s"}}
KEYS = {"name", "description", "sample_period", "output_name", "units", "input_units", "input_bounds",
        "input_rate", "output_range", *TABLES, *GROUP_TABLES}


class ActuatorSpec(ActuatorPlants, ActuatorControllers):
    """A parsed actuator file; :meth:`bench` makes the :class:`Bench`.

    Parameters
    ----------
    path : str or Path
        The actuator file (TOML); ``ValueError`` naming the bad key.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path).resolve()
        raw = self._read()
        self.raw = raw
        where = f"actuator file {path}"
        self.name = self._text(raw, "name", None)
        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._-]*", self.name):  # it names the results folder
            raise self._fail("name", f"must be letters, digits, '.', '_' or '-' (a folder name), got {self.name!r}")
        self.description = self._text(raw, "description", f"your actuator ({self.path.name})")
        self.output_name = self._text(raw, "output_name", "output")
        if self.output_name.strip() == "t":  # it names the reference CSV's column beside time's 't'
            raise self._fail("output_name", "= 't' is the reference CSV's time column; choose another name "
                             "(for example 'position')")
        self.units = self._text(raw, "units", "")
        self.input_units = self._text(raw, "input_units", "")
        self.sample_period = self._number(raw, "sample_period", None, positive=True)
        self.input_bounds = self._pair(raw, "input_bounds")
        self.output_range = self._pair(raw, "output_range")
        self.input_rate = self._number(raw, "input_rate", np.inf, positive=True)
        span = self.input_bounds[1] - self.input_bounds[0]
        if np.isfinite(self.input_rate) and self.input_rate >= span:
            raise self._fail("input_rate", f"= {self.input_rate:g} is per sample and spans the whole input range "
                             f"({span:g}), so it limits nothing; give the change per sample (per second × "
                             f"sample_period), or leave it out for no limit")
        model = raw.get("model", {})
        if "file" not in model:
            raise ValueError(f"{where}: missing key 'model.file' (the hystmpc.model/1 document)")
        if not isinstance(model["file"], str) or not model["file"].strip():
            raise self._fail("model.file", f"must be the model document's path as text, got {model['file']!r}")
        model_file = (self.path.parent / model["file"]).resolve()
        try:
            self.identified = read_model_document(model_file, self.sample_period)
            document = json.loads(model_file.read_text())
        except ValueError as exc:
            raise ValueError(f"{where}: model.file: {exc}") from None
        fitted_at = document.get("sample_period_s")
        fitted_units = document.get("units") if isinstance(document.get("units"), dict) else {}
        for key, mine, theirs in (("units", self.units, fitted_units.get("y")),
                                  ("input_units", self.input_units, fitted_units.get("u"))):
            if mine and isinstance(theirs, str) and theirs and mine != theirs:
                raise self._fail(key, f"= {mine!r} differs from the model's {theirs!r} ({model_file.name}): its "
                                 f"parameters are in its units; write {key} = {theirs!r}, or identify in {mine!r}")
        if isinstance(fitted_at, int | float) and not np.isclose(fitted_at, self.sample_period, rtol=1e-9, atol=0):
            raise self._fail("sample_period", f"= {self.sample_period:g} s differs from the {fitted_at:g} s the model "
                             f"was identified at ({model_file.name}): its dead time and creep count those samples; "
                             f"set sample_period = {fitted_at:g} or identify at the control rate")
        self.family = self.identified.family
        self.dynamics = self.identified.dynamics
        if "dynamics" in raw:
            self.dynamics = dynamics_from(raw["dynamics"], f"{where}: [dynamics]")
            if self.identified.dynamics.creep and not self.dynamics.creep and str(self.path) + "#creep" not in _WARNED:
                _WARNED.add(str(self.path) + "#creep")
                LOG.warning(f"actuator file {self.path}: [dynamics] replaces the model document's whole block, and "
                            "has no creep: the document's creep elements are left out (copy its dynamics.creep "
                            "into [dynamics] to keep them)")
        self._warn_above_nyquist()
        sensor, plant = raw.get("sensor", {}), raw.get("plant", {})
        self.noise = self._number(sensor, "noise_std", 0.0, key="sensor.noise_std")
        seed = plant.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise self._fail("plant.seed", f"must be an integer >= 0, got {seed!r}")
        self._document = document
        self._truths: dict[str, tuple[str, ActuatorModel]] = {}
        try:
            self.plant = ActuatorPlant(self._number(plant, "mismatch", 0.05, key="plant.mismatch"), seed, self.noise,
                                       plant.get("truth", "model"))
            self.truth(self.plant.truth)
            if self.runner_up() is not None:  # the tuning ensemble has it whatever the truth
                self.truth("runner-up")
        except ValueError as exc:
            raise ValueError(f"{where}: [plant] {exc}") from None
        scen = raw.get("scenarios", {})
        self.sine_hz = self._number(scen, "sine_hz", self._default_sine_hz(), positive=True, key="scenarios.sine_hz")
        if self.sine_hz >= 0.25 / self.sample_period:
            raise self._fail("scenarios.sine_hz", f"= {self.sine_hz:g} Hz leaves fewer than 4 samples per period; "
                             f"allowed: below {0.25 / self.sample_period:g} Hz at this sample_period")
        self.step_s = self._number(scen, "step_s", 0.5 / self.sine_hz, positive=True, key="scenarios.step_s")
        self.duration_s = self._number(scen, "duration_s", 4.5 / self.sine_hz, positive=True,
                                       key="scenarios.duration_s")
        self._warn_beyond_reach()
        self.table_values = [(f"{group}.{key}", value) for group in GROUP_TABLES
                             for key, value in _flatten(raw.get(group, {}))]
        """The file's ``[nmpc]``, ``[solver]``, ... values as ``(key, value)``, with their TOML types."""
        self._tuned: dict = {}
        try:
            self._configured()
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None

    def _read(self) -> dict:
        try:
            with self.path.open("rb") as fh:
                raw = tomllib.load(fh)
        except FileNotFoundError:
            raise ValueError(f"actuator file {self.path} does not exist") from None
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise ValueError(f"actuator file {self.path}: not valid TOML ({exc})") from None
        for key, value in raw.items():
            if key not in KEYS:
                raise ValueError(f"actuator file {self.path}: unknown key {key!r}; allowed: {', '.join(sorted(KEYS))}")
            if key in TABLES or key in GROUP_TABLES:
                if not isinstance(value, dict):
                    raise ValueError(f"actuator file {self.path}: {key!r} must be a table ([{key}])")
                for sub in value if key in TABLES else ():
                    if sub not in TABLES[key]:
                        raise ValueError(f"actuator file {self.path}: unknown key '{key}.{sub}'; allowed in "
                                         f"[{key}]: {', '.join(sorted(TABLES[key]))}")
        return raw

    def _warn_beyond_reach(self) -> None:
        """A warning when ``output_range`` reaches well beyond the model's output.

        Given once per file and process; the model's output is taken over a major loop of the input
        bounds: references there cannot be tracked, by any controller.
        """
        model, creep_order = self.identified.hysteresis()
        lo, hi = self.input_bounds
        loop = np.concatenate((np.linspace(lo, hi, 200), np.linspace(hi, lo, 200)))
        h = hysteresis_output(model, creep_order, loop, self.sample_period)
        reach_lo, reach_hi = float(np.min(h)), float(np.max(h))
        margin = 0.05 * (reach_hi - reach_lo)
        if (self.output_range[0] >= reach_lo - margin and self.output_range[1] <= reach_hi + margin) \
                or str(self.path) in _WARNED:
            return
        _WARNED.add(str(self.path))
        LOG.warning(f"actuator file {self.path}: output_range [{self.output_range[0]:g}, {self.output_range[1]:g}] "
                    f"reaches beyond the model's [{reach_lo:.4g}, {reach_hi:.4g}] {self.units} over input_bounds: "
                    "the scenarios' references there cannot be tracked")

    def _warn_above_nyquist(self) -> None:
        """Warn (once per file and process) when a second-order block resonates above Nyquist.

        Its ringing is then aliased. (A first-order lag shorter than a sample is only a static
        gain and a small delay, which is exact.)
        """
        d, nyquist = self.dynamics, 0.5 / self.sample_period
        if d.kind != "second-order" or d.natural_frequency_hz <= nyquist or f"{self.path}#nyquist" in _WARNED:
            return
        _WARNED.add(f"{self.path}#nyquist")
        LOG.warning(f"actuator file {self.path}: the second-order block's natural frequency, "
                    f"{d.natural_frequency_hz:.4g} Hz, is above the "
                    f"Nyquist frequency ({nyquist:.4g} Hz at sample_period {self.sample_period:g} s): the "
                    "controllers cannot resolve it; check the identification, or sample faster")

    def _unused_keys(self) -> dict[str, str]:
        """The keys ``--set`` and the file's tables cannot change, with why.

        They are the solver keys this file's NMPC cannot use (a model with creep is solved by single
        shooting, any other by multiple shooting), the dynamics' kind, and the other kinds'
        parameters.
        """
        solver = SINGLE_SHOOTING if self.identified.hysteresis()[1] > 0 else MULTIPLE_SHOOTING
        kind = self.dynamics.kind
        dynamics = {"model.dynamics.kind": f"it is the kind of the file's [dynamics] ({kind}); change it there, "
                                           "where the kind's own keys are checked"}
        dynamics["model.dynamics.creep"] = "it is a list of [share, time_constant] pairs; set it in the file's " \
                                           "[dynamics] or the model document"
        for key in {key for keys in KIND_KEYS.values() for key in keys} - set(KIND_KEYS[kind]):
            dynamics[f"model.dynamics.{key}"] = f"{kind} dynamics (the file's [dynamics]) have no {key}"
        return {**solver, **dynamics}

    def _fail(self, key: str, message: str) -> ValueError:
        return ValueError(f"actuator file {self.path}: {key} {message}")

    def _text(self, raw, key, default):
        if key not in raw:
            if default is None:
                raise self._fail(key, "is missing")
            return default
        if not isinstance(raw[key], str) or not raw[key].strip():
            raise self._fail(key, f"must be a non-empty string, got {raw[key]!r}")
        return raw[key]

    def _number(self, raw, name, default, positive=False, key=None):
        key = key or name
        if name not in raw:
            if default is None:
                raise self._fail(key, "is missing")
            return default
        value = raw[name]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or (
                value <= 0 if positive else value < 0):
            raise self._fail(key, f"must be a finite number {'> 0' if positive else '>= 0'}, got {value!r}")
        return value

    def _pair(self, raw, key):
        value = raw.get(key)
        if value is None:
            raise self._fail(key, "is missing ([low, high])")
        if (not isinstance(value, list) or len(value) != 2
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in value)
                or not value[0] < value[1]):
            raise self._fail(key, f"must be [low, high] with finite low < high, got {value!r}")
        return float(value[0]), float(value[1])

    def _default_sine_hz(self) -> float:
        """The default sine's frequency, from the linear block's speed.

        A fifteenth of a second-order block's natural frequency or a fifth of a first-order
        block's corner frequency (at most a 25th of the sample rate); a 100th of the sample rate
        without a block.
        """
        d = self.dynamics
        rate = 1.0 / self.sample_period
        if d.kind == "second-order":
            return min(d.natural_frequency_hz / 15, rate / 25)
        if d.kind == "first-order":
            return min(1 / (2 * np.pi * d.time_constant) / 5, rate / 25)
        return rate / 100

    # ----- what the bench is built from ------------------------------------------------------------
    def defaults(self) -> dict:
        """Fresh parameter groups, the file's own tables applied, the PID gains tuned.

        Returns
        -------
        dict
            The parameter groups by name.
        """
        config = self._configured()
        config |= self.tuned_gains(config)
        # the file's [pid] keys win over the tuned gains
        return apply_values(config, self.table_values, self._unused_keys())

    def _configured(self) -> dict:
        """The groups before tuning, the file's tables applied."""
        cls = parameter_class(self.family, self.model_parameters(), self.sample_period)
        model = ActuatorModel(cls(), self.dynamics)
        span_y = self.output_range[1] - self.output_range[0]
        span_u = self.input_bounds[1] - self.input_bounds[0]
        horizon = int(np.clip(self.dynamics.delay_samples + round(self._settling() / self.sample_period) + 2, 10, 40))
        nmpc_horizon = min(horizon, self._longest_horizon())
        config = {"plant": self.plant, "model": model,
                  # runtime auto: the generated whole controller in the loop, as it would be flashed;
                  # multistart: a second RTI plan from the inverse model's inputs where the first misses
                  # the reference by SECOND_START_SHARE of the span (RMS over the horizon and at its end),
                  # the cheaper plan kept; it pays where the identified model is off (docs/your-actuator.md)
                  "nmpc": NmpcSettings(horizon=nmpc_horizon, q_output=(100 / span_y) ** 2,
                                       r_rate=1e-3 * (100 / span_u) ** 2, solver="rti-c", runtime="auto",
                                       multistart=True, second_start_error=SECOND_START_SHARE * span_y,
                                       second_start_pause=nmpc_horizon // 4 if self._tight_period() else 0),
                  "smoothing": Smoothing(eps=1e-5 * span_u),
                  "solver": SolverSettings(rti=RtiSettings(line_search="descent")) if self._tight_period()
                  else SolverSettings(),
                  "pid": PidGains(), "inverse_ff_pid": FeedforwardPidGains(),
                  # the NMPC's weights and uncapped horizon (a Python baseline, not real time above
                  # 1 kHz either way), the rate weight on the virtual input (output units)
                  "lmpc": LinearMpcSettings(horizon=horizon, q_output=(100 / span_y) ** 2,
                                            r_rate=1e-3 * (100 / span_y) ** 2),
                  # the walks before tuning: the sensor noise per sample (tuned_gains keeps it or a tenth)
                  **dict.fromkeys(("estimator", "lmpc_estimator"), DisturbanceWalk(self._estimator_noise() ** 2))}
        return apply_values(config, self.table_values, self._unused_keys())

    def _longest_horizon(self) -> int:
        """The NMPC's longest default horizon: 40 samples up to 1 kHz, fewer above.

        In proportion to the rate (at least 10, and 2 samples beyond the dead time): the RTI step's
        work grows faster than the horizon, and the period shrinks.
        """
        cap = int(np.clip(round(40 * self.sample_period / 1e-3), 10, 40))
        return max(cap, min(self.dynamics.delay_samples + 2, 40))

    def _tight_period(self) -> bool:
        """Above 1 kHz: the NMPC trades a little optimality per sample for the period.

        There a second start that did not win pauses second starts for a quarter of the default
        horizon (a file's own ``[nmpc]`` horizon keeps it), and the RTI step takes its full step
        where it lowers the cost (line search ``descent``). On the
        held-out stages, both kept the 2 kHz stage's RMSE within 1 % and its p95 step under a
        quarter of the period, but each cost up to 17 % and 57 % on a 1 kHz stage where second
        starts win in a row (docs/your-actuator.md).
        """
        return self.sample_period < 1e-3

    def _settling(self) -> float:
        d = self.dynamics
        if d.kind == "second-order":
            return 3.0 / (d.damping * 2 * np.pi * d.natural_frequency_hz)
        return 3.0 * d.time_constant if d.kind == "first-order" else 0.0

    def model_parameters(self, identified=None) -> dict:
        """The model document's parameters (or ``identified``'s) and its offsets.

        The offsets come as ``input_offset`` and ``output_offset``.

        Parameters
        ----------
        identified : Identified, optional
            Another identified model (default: the file's).

        Returns
        -------
        dict
            Parameter names and values.
        """
        identified = identified or self.identified
        return {**identified.parameters, "input_offset": identified.offsets["input"],
                "output_offset": identified.offsets["output"]}

    def hysteresis(self, model: ActuatorModel):
        """``(hysteresis model, creep order)`` of a ``model`` group.

        Parameters
        ----------
        model : ActuatorModel
            The ``model`` group (of the file's family).

        Returns
        -------
        tuple
            The exact hysteresis model and its creep order (0 without creep).
        """
        return build_hysteresis(self.family, dataclasses.asdict(model.hysteresis), self.sample_period)

    def scenarios(self) -> dict[str, Scenario]:
        """``sine`` and ``staircase`` over the output range, from the output at rest.

        Returns
        -------
        dict
            The two :class:`Scenario` by name.
        """
        lo, hi = self.output_range
        span, mid = hi - lo, 0.5 * (lo + hi)
        hysteresis, _ = self.hysteresis(ActuatorModel(
            parameter_class(self.family, self.model_parameters(), self.sample_period)(), self.dynamics))
        rest = float(np.clip(0.0, *self.input_bounds))
        y_rest = float(np.clip(hysteresis.output(hysteresis.initial_state(rest)), lo, hi))
        f, amp = self.sine_hz, 0.4 * span
        approach = 0.5 / f
        start = mid - amp

        def sine(t):
            t = np.asarray(t, float)
            ramp = y_rest + (start - y_rest) * 0.5 * (1 - np.cos(np.pi * np.clip(t / approach, 0, 1)))
            return np.where(t < approach, ramp, mid - amp * np.cos(2 * np.pi * f * (t - approach)))

        levels = np.concatenate(([y_rest], lo + span * np.array([0.2, 0.6, 0.4, 0.8, 0.3, 0.7, 0.5])))

        def staircase(t):  # from rest: every step is ahead, none at t = 0
            index = np.minimum((np.asarray(t, float) / self.step_s).astype(int), len(levels) - 1)
            return levels[index]
        return {"sine": Scenario("sine", f"{f:g} Hz sine over 10–90 % of the output range after a "
                                         f"raised-cosine approach", self.duration_s, sine),
                "staircase": Scenario("staircase", f"seven steps of {self.step_s:g} s over the output range, "
                                                   f"from rest",
                                      self.step_s * len(levels), staircase)}

    def bench(self) -> Bench:
        """The actuator as a :class:`Bench`.

        Returns
        -------
        Bench
            With the ``pid``, ``inverse-ff-pid``, ``inverse-lmpc`` and ``nmpc`` controllers.
        """
        controllers = {
            "pid": ControllerSpec("pid", "PID, gains tuned on the tuning ensemble",
                                  lambda c: self.build_pid(c, False), ("model", "pid")),
            "inverse-ff-pid": ControllerSpec("inverse-ff-pid", "inverse hysteresis feed-forward + PID, gains tuned "
                                             "on the tuning ensemble", lambda c: self.build_pid(c, True),
                                             ("model", "inverse_ff_pid")),
            "inverse-lmpc": ControllerSpec("inverse-lmpc", "inverse hysteresis model in series with the input + "
                                           "linear MPC (OSQP) on the linear block, rate weight and walk tuned on the "
                                           "tuning ensemble", self.build_inverse_lmpc, LMPC_GROUPS),
            "nmpc": ControllerSpec("nmpc", "NMPC on the smoothed identified model, inverse warm start, walk tuned on "
                                   "the tuning ensemble", self.build_nmpc, NMPC_GROUPS, planner="inverse-lmpc"),
        }
        return Bench(name=self.name, description=self.description, paper="", output_name=self.output_name,
                     units=self.units, input_units=self.input_units, sample_period=self.sample_period,
                     scenarios=self.scenarios(), controllers=controllers, defaults=self.defaults,
                     untuned_defaults=self._configured,
                     make_plant=self.make_plant, plant_groups=("plant", "model"), output_range=self.output_range,
                     input_bounds=self.input_bounds, input_rate=self.input_rate,
                     loop=("input", "hysteresis_output", f"input [{self.input_units}]",
                           f"hysteresis output [{self.units}]"),
                     default_scenario="sine", source=str(self.path), fixed=self._unused_keys())


def _flatten(table: dict, prefix: str = ""):
    for key, value in table.items():
        if isinstance(value, dict):
            yield from _flatten(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", value


_CACHE: dict[tuple[str, float], Bench] = {}


def load_actuator(path: str | Path) -> Bench:
    """The bench of an actuator file (``ValueError`` naming the bad key).

    It is cached per file and modification time, so a command builds and tunes it once.

    Parameters
    ----------
    path : str or Path
        The actuator file (TOML).

    Returns
    -------
    Bench
        The bench.
    """
    path = Path(path).resolve()
    try:
        stamp = path.stat().st_mtime
    except OSError:
        raise ValueError(f"actuator file {path} does not exist") from None
    key = (str(path), stamp)
    if key not in _CACHE:
        _CACHE[key] = ActuatorSpec(path).bench()
    return _CACHE[key]
