"""An actuator file's ``plant`` and ``model`` groups, and the perturbation that makes its truth.

``model`` is what the controllers believe: the identified family's parameters (a frozen
dataclass made from the model document, :func:`parameter_class`) and the linear block;
``plant`` says how the simulated truth differs from it (:func:`perturb`, seeded).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from hystmpc.models.identification import FAMILIES, build_hysteresis
from hystmpc.models.linear_dynamics import LinearDynamics


@dataclass(frozen=True)
class ActuatorPlant:
    """The simulated truth of an actuator file (``--set plant.*``)."""

    mismatch: float = 0.05
    """Relative perturbation of every model parameter, uniform in ±mismatch (0: the model itself)."""
    seed: int = 0
    """Seed of the perturbation."""
    noise: float = 0.0
    """Sensor noise standard deviation (output units)."""
    truth: str = "model"
    """What is perturbed: ``model`` (the controllers' own model), ``runner-up`` (the model and
    the second family of an ``identify auto`` ranking in parallel, blended by what the model
    missed on the validation record), or the path of another model document (relative to
    the actuator file)."""

    def __post_init__(self):
        if not (isinstance(self.truth, str) and self.truth.strip()):
            raise ValueError(f"truth must be runner-up, model or a model document's path, got {self.truth!r}")
        if not (np.isfinite(self.mismatch) and 0 <= self.mismatch <= 0.5):
            raise ValueError(f"mismatch must be in [0, 0.5], got {self.mismatch}")
        if not (np.isfinite(self.noise) and self.noise >= 0):
            raise ValueError(f"noise must be finite and >= 0, got {self.noise}")
        if not (isinstance(self.seed, int) and self.seed >= 0):
            raise ValueError(f"seed must be an integer >= 0, got {self.seed}")


@dataclass(frozen=True)
class DisturbanceWalk:
    """How fast a controller's estimator lets the model's error move.

    ``--set estimator.*`` for the NMPC's EKF, ``lmpc_estimator.*`` for ``inverse-lmpc``'s
    Kalman filter.
    """

    disturbance: float = 1.0
    """Variance per sample of the output disturbance's random walk (output units²): tuned to the
    sensor noise squared or a hundredth of it, unless set."""

    def __post_init__(self):
        if not (np.isfinite(self.disturbance) and self.disturbance > 0):
            raise ValueError(f"disturbance must be finite and > 0, got {self.disturbance}")


@dataclass(frozen=True)
class ActuatorModel:
    """What the controllers believe (``--set model.hysteresis.*``, ``model.dynamics.*``)."""

    hysteresis: Any
    """The family's parameters (a frozen dataclass made from the model document)."""
    dynamics: LinearDynamics = LinearDynamics()
    """The linear block after the hysteresis and the dead time."""


def _frozen(value):
    if isinstance(value, list):
        return tuple(_frozen(v) for v in value)
    return value


def parameter_class(family: str, parameters: dict, sample_period: float):
    """A frozen dataclass holding ``parameters`` (defaults), validated by building the model.

    Parameters
    ----------
    family : str
        The hysteresis family.
    parameters : dict
        Parameter names and default values (lists become tuples).
    sample_period : float
        Sample period (s) the model is built at.

    Returns
    -------
    type
        The dataclass ``<Family>Parameters``; a bad value raises ``ValueError`` on construction.
    """
    def check(self):
        try:
            build_hysteresis(family, dataclasses.asdict(self), sample_period)
        except (KeyError, TypeError) as exc:
            raise ValueError(f"bad {family} parameters: {exc}") from None

    fields = [(name, type(_frozen(value)), dataclasses.field(default=_frozen(value)))
              for name, value in parameters.items()]
    cls_name = "".join(part.title() for part in family.split("-")) + "Parameters"
    return dataclasses.make_dataclass(cls_name, fields, frozen=True, namespace={"__post_init__": check})


def _perturbed(value, rng, mismatch: float):
    if isinstance(value, tuple) and value and isinstance(value[0], tuple):  # points: scale the outputs together
        factor = 1 + mismatch * rng.uniform(-1, 1)
        return tuple((p[0], p[1] * factor) for p in value)
    if isinstance(value, tuple):
        return tuple(v * (1 + mismatch * rng.uniform(-1, 1)) for v in value)
    return value * (1 + mismatch * rng.uniform(-1, 1))


def perturb(model: ActuatorModel, family: str, mismatch: float, seed: int) -> ActuatorModel:
    """``model`` with its parameters and time constants perturbed by ±``mismatch``, seeded.

    The perturbed values are the family's parameters (:attr:`Family.mismatch`, polylines' outputs
    as a whole), the dynamics' time constants and its creep elements' shares and time constants.

    Parameters
    ----------
    model : ActuatorModel
        The model to perturb.
    family : str
        Its hysteresis family.
    mismatch : float
        Relative amplitude: each value is scaled by a factor uniform in ``1 ± mismatch``.
    seed : int
        Seed of the perturbation.

    Returns
    -------
    ActuatorModel
        The perturbed copy.
    """
    rng = np.random.default_rng(seed)
    names = FAMILIES[family].mismatch + (("ascending", "descending") if family == "power-function" else ())
    h = dataclasses.replace(model.hysteresis, **{n: _perturbed(getattr(model.hysteresis, n), rng, mismatch)
                                                  for n in names})
    dyn = model.dynamics
    dyn = dataclasses.replace(dyn, **{n: _perturbed(getattr(dyn, n), rng, mismatch)
                                      for n in ("time_constant", "natural_frequency_hz", "damping")})
    if dyn.creep:  # drawn after the others, so a model without creep perturbs as before
        creep = [(_perturbed(share, rng, mismatch), _perturbed(tau, rng, mismatch)) for share, tau in dyn.creep]
        total = sum(share for share, _ in creep)
        scale = min(1.0, 0.99 / total) if total > 0 else 1.0  # the shares must stay below 1 together
        dyn = dataclasses.replace(dyn, creep=tuple((share * scale, tau) for share, tau in creep))
    return ActuatorModel(h, dyn)
