"""What a bench is: plant, nominal model, scenarios, controllers and the paper's figures."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from plants.base import Measurement


class Controller(Protocol):
    """Shape shared by every controller: ``reset()``, then ``step(measurement, refs)``."""

    horizon: int
    """Future reference samples the controller wants beyond the current one (0: causal)."""

    def reset(self) -> None: ...

    def step(self, measurement: Measurement, ref_window: np.ndarray) -> float: ...

    def stats(self) -> dict | None: ...


@dataclass(frozen=True)
class Scenario:
    """A reference trajectory with a name and a duration."""

    name: str
    description: str
    duration: float
    """Length of the run (s)."""
    reference: Callable[[np.ndarray], np.ndarray]
    """Reference as a function of time (vectorised)."""
    conditions: tuple[str, ...] = ()
    """Operating conditions the scenario fixes, as ``--set`` assignments (``rig.gap_mm=1.2``)."""


@dataclass(frozen=True)
class ControllerSpec:
    """A named controller: how to build it from the bench configuration."""

    name: str
    description: str
    build: Callable[[dict[str, Any]], Controller]


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
    output_range: tuple[float, float]
    """References outside this range are rejected."""
    paper_figures: dict[tuple[str, str], dict[str, float]] = field(default_factory=dict)
    input_bounds: tuple[float, float] = (-np.inf, np.inf)
    loop: tuple[str, str, str, str] | None = None
    """Hysteresis-loop plot: (truth key on x, truth key on y, x label, y label)."""
    default_scenario: str = ""
    error_vs_reference: bool = False
    """Also plot the error against the reference (katalenic2013 Figs. 11–13 style)."""


class NmpcAdapter:
    """Runs a :class:`mpc.NmpcController` as a bench controller.

    Parameters
    ----------
    controller : mpc.NmpcController
        Estimator + NLP of the bench's nominal model.
    sensors : callable
        ``Measurement -> z``: the sensor vector the model's ``measure`` function predicts.
    """

    def __init__(self, controller, sensors: Callable[[Measurement], np.ndarray]):
        self.controller = controller
        self.sensors = sensors
        self.horizon = controller.horizon

    @property
    def predicted_output(self) -> float:
        """The model's one-step-ahead prediction of this sample's output."""
        return self.controller.predicted_output

    def reset(self) -> None:
        """Forget the estimate, plan and counters."""
        self.controller.reset()

    def step(self, measurement: Measurement, ref_window) -> float:
        """NMPC input for this sample."""
        return self.controller.step(self.sensors(measurement), ref_window)

    def stats(self) -> dict:
        """Solver statistics."""
        return self.controller.stats()
