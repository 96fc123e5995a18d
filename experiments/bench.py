"""What a bench is: plant, nominal model, scenarios, controllers and the paper's figures.

A bench file only wires these together; the physics and each actuator's prediction model
live in ``plants/`` and ``models/``, the controllers in ``mpc/`` and
:mod:`hystmpc.experiments.baselines`. Its parameters are configuration groups (frozen
dataclasses, ``--set GROUP.KEY=VALUE``); every builder declares the groups it reads and
gets only those, so a key a bench accepts is one something uses.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from hystmpc.experiments.config import apply_overrides, apply_values
from hystmpc.experiments.own_plant import check_plant, describe_plant
from hystmpc.experiments.report import version
from hystmpc.experiments.runner import Controller, InputGuard, Labels, RunResult, Scenario, simulate
from hystmpc.mpc.codegen import Signals
from hystmpc.mpc.linear_mpc import LinearMpcSettings
from hystmpc.mpc.runtime import CodeLabels, assemble_nmpc, validate_nmpc
from hystmpc.mpc.settings import GaussNewtonSettings, NmpcSettings

MULTIPLE_SHOOTING = {f"solver.gn.{f.name}": "solver gn solves single-shooting problems; this bench's NMPC is "
                     "multiple shooting (use ipopt, sqp, rti or rti-c)" for f in fields(GaussNewtonSettings)}
"""Keys a bench with a multiple-shooting NMPC cannot use."""
SINGLE_SHOOTING = {"solver.rti.condensed": "this bench's NMPC is single shooting: its RTI step has the inputs "
                                           "as its only unknowns"}
"""Keys a bench with a single-shooting NMPC cannot use."""


@dataclass(frozen=True)
class ControllerSpec:
    """A named controller: how to build it from the groups it reads."""

    name: str
    description: str
    build: Callable[[dict[str, Any]], Controller]
    """Gets a configuration holding ``groups`` only."""
    groups: tuple[str, ...]
    """Configuration groups the controller reads."""
    planner: str = "inverse-lmpc"
    """The bench's controller whose plan this one takes as its inverse-model inputs when its
    NMPC settings say ``inverse_plan=linear-mpc`` (``""``: none; read only by a controller
    that reads NMPC settings)."""


@dataclass(frozen=True)
class Bench:
    """One actuator from one paper, ready to simulate."""

    name: str
    description: str
    paper: str
    output_name: str
    """Name of the reference column in a reference CSV (``angle``, ``torque``, ...)."""
    units: str
    input_units: str
    sample_period: float
    scenarios: dict[str, Scenario]
    controllers: dict[str, ControllerSpec]
    defaults: Callable[[], dict[str, Any]]
    """Fresh parameter groups (``plant``, ``model``, controller groups) for ``--set``."""
    make_plant: Callable[[dict[str, Any]], Any]
    plant_groups: tuple[str, ...]
    """Configuration groups ``make_plant`` reads."""
    output_range: tuple[float, float]
    """References outside this range are rejected."""
    paper_figures: dict[tuple[str, str], dict[str, float]] = field(default_factory=dict)
    input_bounds: tuple[float, float] = (-np.inf, np.inf)
    """The actuator's physical input range: the plant guard clips any controller to it,
    whatever ``--set model.*`` says."""
    input_rate: float = np.inf
    """The actuator's largest input change per sample (the guard's rate; ``inf``: none)."""
    loop: tuple[str, str, str, str] | None = None
    """Hysteresis-loop plot: (truth key on x, truth key on y, x label, y label)."""
    default_scenario: str = ""
    error_vs_reference: bool = False
    """Also plot the error against the reference (katalenic2013 Figs. 11–13 style)."""
    fixed: dict[str, str] = field(default_factory=dict)
    """Keys of the groups that cannot be set on this bench, with the reason."""
    sensor_units: tuple[tuple[str, str], ...] = ()
    """Units of the sensors other than the tracked output, ``((name, units), ...)``."""
    source: str = ""
    """Where the bench comes from when it is not built in: an actuator file's path, or a
    plugin's entry point (``module:attribute``); :func:`hystmpc.experiments.benches.get_bench`
    finds it again by this (sweep workers do)."""
    untuned_defaults: Callable[[], dict[str, Any]] | None = None
    """:attr:`defaults` before the baselines' gains are tuned (an actuator file: seconds to
    minutes saved where no baseline runs, and where the settings are only checked)."""
    generated: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    """``config -> config``: what the generated controller needs changed, where the bench needs
    something (dea: a creep window of 200 samples for the full memory, which a fixed C memory
    cannot hold); see :meth:`generated_config`."""

    @property
    def guard(self) -> InputGuard:
        """The plant guard of every run on this bench (:attr:`input_bounds`, :attr:`input_rate`)."""
        return InputGuard(*self.input_bounds, self.input_rate)

    @property
    def labels(self) -> Labels:
        """Names and units of the bench's signals."""
        return Labels(self.output_name, self.units, self.input_units, self.loop, f"{self.name}: {self.description}",
                      self.sensor_units)

    def configure(self, assignments=(), tuned: bool = True) -> dict[str, Any]:
        """The default configuration with settings applied.

        Parameters
        ----------
        assignments : iterable of str, or dict
            ``KEY=VALUE`` texts, as ``--set`` takes them, or a dict of typed values
            (``{"nmpc.horizon": 30, "nmpc.multistart": True}``).
        tuned : bool
            False: with :attr:`untuned_defaults` where the bench has them (for the NMPC
            alone, or to check the settings).

        Returns
        -------
        dict
            A fresh configuration (parameter groups) with the settings applied.

        Raises
        ------
        ValueError
            Naming a bad or fixed key, or a bad value.
        """
        defaults = self.defaults if tuned or self.untuned_defaults is None else self.untuned_defaults
        if isinstance(assignments, dict):
            return apply_values(defaults(), assignments, self.fixed, source="setting")
        return apply_overrides(defaults(), list(assignments), self.fixed)

    def _groups(self, config: dict[str, Any], groups: tuple[str, ...], who: str) -> dict[str, Any]:
        missing = [g for g in groups if g not in config]
        if missing:
            raise ValueError(f"{who} reads configuration group(s) {missing} the configuration lacks")
        return {g: config[g] for g in groups}

    def build_plant(self, config: dict[str, Any]):
        """The simulated plant of ``config``.

        Parameters
        ----------
        config : dict
            The configuration; ``make_plant`` gets its :attr:`plant_groups` only.

        Returns
        -------
        Plant
            What ``make_plant`` builds.
        """
        return self.make_plant(self._groups(config, self.plant_groups, "the plant"))

    def plant_only_groups(self) -> tuple[str, ...]:
        """The configuration groups only the bench's plant reads (no controller does).

        Returns
        -------
        tuple of str
            Those of :attr:`plant_groups` that no controller spec lists.
        """
        read_by_controllers = {g for spec in self.controllers.values() for g in spec.groups}
        return tuple(g for g in self.plant_groups if g not in read_by_controllers)

    def sensors(self, config: dict[str, Any] | None = None) -> tuple[str, ...]:
        """The measured signals besides ``y`` that the bench's plant gives (a controller may read them).

        Parameters
        ----------
        config : dict, optional
            The configuration of the plant (default: :meth:`configure` with no changes).

        Returns
        -------
        tuple of str
            The sensor names of the plant's first measurement (reset with seed 0).
        """
        config = self.configure() if config is None else config
        return tuple(self.build_plant(config).reset(0).sensors)

    def generated_config(self, config: dict[str, Any]) -> dict[str, Any]:
        """``config`` as the generated controller is built from it.

        Every linear MPC solves with the generated interior-point QP (``lmpc.qp=ipm``: the
        planner of ``nmpc.inverse_plan=linear-mpc`` is generated with it), then the bench's
        :attr:`generated` applies. The NMPC settings are left as they are.

        Parameters
        ----------
        config : dict
            The configuration.

        Returns
        -------
        dict
            A new configuration.
        """
        out = {key: replace(value, qp="ipm") if isinstance(value, LinearMpcSettings) else value
               for key, value in config.items()}
        return self.generated(out) if self.generated is not None else out

    def generated_changes(self, config: dict[str, Any], name: str = "nmpc") -> tuple[str, ...]:
        """The settings :meth:`generated_config` changes for controller ``name``, as ``KEY=VALUE``.

        Only the groups it reads count (and its planner's, where it takes a linear MPC's plan).

        Parameters
        ----------
        config : dict
            The configuration.
        name : str, optional
            The controller.

        Returns
        -------
        tuple of str
            ``("memory.window=200", "lmpc.qp=ipm")`` on dea's defaults, ``()`` where nothing changes.
        """
        spec = self._spec(name)
        groups = list(spec.groups)
        planned = any(getattr(config.get(g), "inverse_plan", "") == "linear-mpc" for g in groups)
        if planned and spec.planner in self.controllers:
            groups += [g for g in self.controllers[spec.planner].groups if g not in groups]
        if not planned:  # a linear MPC's settings matter to the generated NMPC only as its planner
            groups = [g for g in groups if not isinstance(config.get(g), LinearMpcSettings)]
        generated = self.generated_config(config)
        return tuple(f"{group}.{f.name}={getattr(generated[group], f.name)}" for group in groups if group in config
                     for f in fields(config[group])
                     if getattr(generated[group], f.name) != getattr(config[group], f.name))

    def build_controller(self, name: str, config: dict[str, Any]) -> Controller:
        """Controller ``name`` built from ``config``.

        A controller that reads NMPC settings (a group holding
        :class:`~hystmpc.mpc.settings.NmpcSettings`) runs where they say
        (``nmpc.runtime``; generated from :meth:`generated_config`) and takes its inverse-model
        inputs from where they say (``nmpc.inverse_plan``: its spec's
        :attr:`ControllerSpec.planner`): :func:`hystmpc.mpc.runtime.assemble_nmpc`.

        Parameters
        ----------
        name : str
            One of :attr:`controllers`.
        config : dict
            The configuration; the controller gets only the groups its spec lists.

        Returns
        -------
        Controller
            The controller, ready for a run.

        Raises
        ------
        ValueError
            An unknown ``name``, a group ``config`` lacks, or NMPC settings that cannot run.
        """
        spec = self._spec(name)
        groups = self._groups(config, spec.groups, f"controller {name!r}")
        nmpc = [g for g, settings in groups.items() if isinstance(settings, NmpcSettings)]
        if not nmpc:
            return spec.build(groups)
        if len(nmpc) > 1:
            raise ValueError(f"controller {name!r} reads two NMPC settings groups ({', '.join(nmpc)}); one is allowed")
        [group] = nmpc
        labels = self.labels
        code_labels = CodeLabels(Signals(labels.output_name, labels.units, labels.input_units,
                                         tuple(labels.sensor_units)), self.sample_period, self.name, version(),
                                 self.generated_changes(config, name))
        generated = self.generated_config(config)
        generated_groups = self._groups(generated, spec.groups, f"controller {name!r}")

        def build(settings: NmpcSettings, for_code: bool = False) -> Controller:
            return spec.build({**(generated_groups if for_code else groups), group: settings})

        def planner(for_code: bool = False) -> Controller:
            return self._planner(spec, generated if for_code else config, groups[group])
        return assemble_nmpc(build, groups[group], code_labels, planner=planner)

    def _spec(self, name: str) -> ControllerSpec:
        if name not in self.controllers:
            raise ValueError(f"unknown controller {name!r}; allowed: {', '.join(self.controllers)}")
        return self.controllers[name]

    def _planner(self, spec: ControllerSpec, config: dict[str, Any], nmpc: NmpcSettings) -> Controller:
        """The controller whose plan ``spec``'s NMPC takes (``nmpc.inverse_plan=linear-mpc``)."""
        if not spec.planner:
            raise ValueError(f"nmpc.inverse_plan=linear-mpc takes the plan of a linear MPC baseline, and controller "
                             f"{spec.name!r} names none; set nmpc.inverse_plan=static")
        why = f"nmpc.inverse_plan=linear-mpc takes the plan of the {spec.planner} baseline"
        if spec.planner not in self.controllers:
            raise ValueError(f"{why}, which bench {self.name!r} lacks; set nmpc.inverse_plan=static")
        planner_spec = self.controllers[spec.planner]
        horizons = [(f"{g}.horizon", config[g].horizon) for g in planner_spec.groups
                    if hasattr(config.get(g), "horizon")]
        for key, horizon in horizons:
            if horizon != nmpc.horizon:
                raise ValueError(f"{why} over the NMPC's horizon: {key}={horizon} differs from "
                                 f"nmpc.horizon={nmpc.horizon}; set {key}={nmpc.horizon} (or drop it where it was "
                                 f"set), or set nmpc.inverse_plan=static")
        try:
            return self.build_controller(spec.planner, config)
        except ValueError as exc:
            raise ValueError(f"{exc} ({why}; or set nmpc.inverse_plan=static)") from None

    def validate(self, config: dict[str, Any], controllers=None) -> None:
        """``ValueError`` for settings that cannot run, before any work.

        Checks the NMPC settings of ``controllers`` with their solver settings
        (:func:`hystmpc.mpc.runtime.validate_nmpc`); the dataclasses checked each value when
        they were made.

        Parameters
        ----------
        config : dict
            The configuration.
        controllers : iterable of str, optional
            Names of the controllers to check (default: all of the bench's).
        """
        for name in self.controllers if controllers is None else controllers:
            for group in self._spec(name).groups:
                if isinstance(config.get(group), NmpcSettings):
                    validate_nmpc(config[group], config.get("solver"))

    def scenario(self, name: str) -> Scenario:
        """Scenario ``name``.

        Parameters
        ----------
        name : str
            One of :attr:`scenarios`.

        Returns
        -------
        Scenario
            The scenario (``ValueError`` naming the allowed ones when there is none).
        """
        if name not in self.scenarios:
            raise ValueError(f"unknown scenario {name!r}; allowed: {', '.join(self.scenarios)}")
        return self.scenarios[name]

    def prepare(self, scenario: Scenario | str, controller: str, config: dict[str, Any] | None = None,
                plant=None) -> Prepared:
        """The plant and controller for a run, with the scenario's conditions applied.

        Parameters
        ----------
        scenario : Scenario or str
            A scenario (or its name); its conditions are applied to ``config``.
        controller : str
            One of :attr:`controllers`.
        config : dict, optional
            Parameter groups (default: :meth:`configure` with no changes).
        plant : Plant, optional
            Your own plant (a rig, your own simulator) instead of the bench's; see :meth:`run`.

        Returns
        -------
        Prepared
            The scenario, configuration, plant and controller of the run.

        Raises
        ------
        ValueError
            For settings the plant or controller cannot take, before anything runs.
        """
        scenario = self.scenario(scenario) if isinstance(scenario, str) else scenario
        config = self.configure() if config is None else config
        if scenario.conditions:
            from hystmpc.experiments.config import get_value
            defaults = self.configure()
            fixed = apply_overrides(defaults, list(scenario.conditions))
            for condition in scenario.conditions:
                key = condition.split("=", 1)[0]
                if get_value(config, key) not in (get_value(defaults, key), get_value(fixed, key)):
                    raise ValueError(f"{key}={get_value(config, key)} conflicts with scenario {scenario.name!r}, "
                                     f"which fixes {condition}; use another reference for other conditions")
            if plant is not None:
                reaching = [c for c in scenario.conditions if c.split(".", 1)[0] in self.plant_only_groups()]
                if reaching:
                    raise ValueError(f"scenario {scenario.name!r} sets {', '.join(reaching)} on the bench's plant, "
                                     "which your own plant does not read; run it on the bench's plant")
            config = apply_overrides(config, list(scenario.conditions))
        self.validate(config, [controller])
        if plant is not None:
            check_plant(plant, self.sample_period, self.sensors(config))
        return Prepared(scenario, controller, config, self.build_plant(config) if plant is None else plant,
                        self.build_controller(controller, config), own_plant=plant is not None)

    def run(self, scenario: Scenario | str, controller: str, config: dict[str, Any] | None = None, seed: int = 0,
            duration: float | None = None, progress=None, prepared: Prepared | None = None,
            plant=None) -> RunResult:
        """Run ``controller`` on ``scenario`` against the bench's plant, or against ``plant``.

        Parameters
        ----------
        scenario : Scenario or str
            A scenario (or its name); its conditions are applied to ``config``.
        controller : str
            One of ``controllers``.
        config : dict, optional
            Parameter groups (default: :meth:`configure` with no changes).
        seed : int
            Seed of the plant's sensor noise.
        duration : float, optional
            Override of the scenario's duration (s).
        progress : callable, optional
            Called with 1 after each sample.
        prepared : Prepared, optional
            What :meth:`prepare` gave for the same arguments (code-generation checks wrap
            its controller's solver first).
        plant : Plant, optional
            Your own plant (a rig, your own simulator; :class:`hystmpc.plants.base.Plant`,
            checked by :func:`hystmpc.experiments.own_plant.check_plant`) instead of the bench's,
            or in ``prepared``.
            The controller is the bench's, tuned as usual; the plant guard still applies.

        Returns
        -------
        RunResult
            The closed-loop run with its metrics, its parameters and the paper's figures
            (none with your own plant).
        """
        if prepared is None:
            prepared = self.prepare(scenario, controller, config, plant)
        elif plant is not None and plant is not prepared.plant:
            raise ValueError("plant= and prepared= name different plants; give the plant to prepare() only")
        from hystmpc.experiments.config import describe
        run = simulate(prepared.plant, prepared.controller, prepared.scenario, duration, seed, name=controller,
                       labels=self.labels, progress=progress, guard=self.guard)
        run.parameters = describe(prepared.config)
        run.paper = self.paper_figures.get((prepared.scenario.name, controller))
        if prepared.own_plant:  # the bench's plant group did not make this plant, nor is it the paper's
            run.parameters["plant"] = {"own_plant": describe_plant(prepared.plant)}
            run.paper = None
        run.bench = self.name
        return run


@dataclass(frozen=True)
class Prepared:
    """A run ready to start: :meth:`Bench.prepare`'s result."""

    scenario: Scenario
    controller_name: str
    config: dict[str, Any]
    """The configuration with the scenario's conditions applied."""
    plant: Any
    controller: Controller
    own_plant: bool = False
    """Whether ``plant`` is the caller's own (a rig, their simulator), not the bench's."""
