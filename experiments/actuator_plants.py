"""The plants an actuator file builds: the simulated truth and the tuning ensemble.

:class:`ActuatorPlants` is the part of :class:`~hystmpc.experiments.actuator_file.ActuatorSpec`
that turns a model into a simulated actuator: the model itself, another model document, or the
model blended with the ``identify auto`` ranking's runner-up by what the model missed on the
validation record, perturbed and with sensor noise.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from hystmpc.experiments.actuator_groups import ActuatorModel, ActuatorPlant, parameter_class, perturb
from hystmpc.models.document import read_model_document
from hystmpc.models.identification import build_hysteresis
from hystmpc.plants.actuator import BlendedActuator, HysteresisActuator


class ActuatorPlants:
    """Plant builders of an actuator file (mixed into :class:`~hystmpc.experiments.actuator_file.ActuatorSpec`)."""

    def plant_of(self, model: ActuatorModel, noise: float, family: str | None = None) -> HysteresisActuator:
        """The exact model (of the file's family, or ``family``) as a plant.

        Parameters
        ----------
        model : ActuatorModel
            Hysteresis parameters and dynamics.
        noise : float
            Sensor noise standard deviation (output units).
        family : str, optional
            The hysteresis family of ``model`` (default: the file's).

        Returns
        -------
        HysteresisActuator
            The plant, at rest at input 0 clipped into the input bounds.
        """
        hysteresis, creep_order = build_hysteresis(family or self.family, dataclasses.asdict(model.hysteresis),
                                                   self.sample_period)
        rest = float(np.clip(0.0, *self.input_bounds))
        return HysteresisActuator(hysteresis, self.sample_period,
                                  model.dynamics.discrete(self.sample_period, hold=creep_order > 0),
                                  model.dynamics.delay_samples, noise, self.input_bounds, rest_input=rest,
                                  creep_order=creep_order)

    def runner_up(self) -> dict | None:
        """The ranking's second row, with its model document.

        A row of the model's family fitted with another creep, or with none where the model has
        one (or one where it has none), is passed over: it differs from the model by the creep
        alone, not as another model of the record does.

        Returns
        -------
        dict or None
            The ``identify auto`` ranking's second row so counted (None when the document has no
            ranking with one).
        """
        candidates = self._document.get("candidates")
        if not isinstance(candidates, list):
            return None
        rows = [c for c in candidates if isinstance(c, dict) and isinstance(c.get("model"), dict)
                and isinstance(c.get("distance_to_best"), int | float)]
        best = rows[0] if rows else {}
        others = [c for c in rows[1:] if c.get("family") != best.get("family") or c.get("creep") == best.get("creep")]
        return others[0] if others else None

    def runner_up_weight(self) -> float:
        """How far the ``runner-up`` plant moves from the model toward the runner-up, in [0, 1].

        The weight is the model's validation error without the sensor noise, ``sqrt(v² − σ²)``,
        over the two models' RMS distance on the validation record, so that the plant differs from
        the model by what the model missed on the record.

        Returns
        -------
        float
            The weight; 1 when the document has no finite validation RMSE or the distance is 0.
        """
        row = self.runner_up()
        validation = self._document.get("validation")
        v = validation.get("rmse") if isinstance(validation, dict) else None
        if not isinstance(v, int | float) or not np.isfinite(v):
            return 1.0  # no measured error to scale by: the runner-up whole
        error = np.sqrt(max(v**2 - self.noise**2, 0.0))
        distance = float(row["distance_to_best"])
        return float(min(1.0, error / distance)) if distance > 0 else 1.0

    def truth(self, name: str) -> tuple[str, ActuatorModel] | None:
        """``(family, model)`` of ``plant.truth`` before the perturbation.

        It is the runner-up's model for ``runner-up``, a document's for a path, None for ``model``
        (it follows the ``model`` group); ``ValueError`` naming what is wrong. A truth's dynamics
        are the file's ``[dynamics]`` when it has one, else its document's.

        Parameters
        ----------
        name : str
            ``model``, ``runner-up`` or a model document's path (relative to the actuator file).

        Returns
        -------
        tuple of (str, ActuatorModel) or None
            The truth's family and model (read once, then kept).
        """
        if name == "model":
            return None
        if name not in self._truths:
            if name == "runner-up":
                row = self.runner_up()
                if row is None:
                    raise ValueError("plant.truth = 'runner-up' needs a model document written by identify auto with a "
                                     "second family ranked; allowed here: model, or a model document's path")
                source = row["model"]
            else:
                source = (self.path.parent / name).resolve()
                if source.suffix != ".json":
                    raise ValueError(f"plant.truth = {name!r}: allowed: runner-up, model, or a model document's path "
                                     "(.json)")
            try:
                identified = read_model_document(source, self.sample_period)
            except ValueError as exc:
                raise ValueError(f"plant.truth = {name!r}: {exc}") from None
            cls = parameter_class(identified.family, self.model_parameters(identified), self.sample_period)
            dynamics = self.dynamics if "dynamics" in self.raw else identified.dynamics
            self._truths[name] = (identified.family, ActuatorModel(cls(), dynamics))
        return self._truths[name]

    def make_plant(self, config: dict):
        """The simulated truth, perturbed by ``plant.mismatch``, with the sensor noise.

        For ``plant.truth = runner-up`` it is the ``model`` group and the runner-up in parallel,
        blended by :meth:`runner_up_weight`; else the truth's model (:meth:`truth`; the ``model``
        group for ``model``).

        Parameters
        ----------
        config : dict
            Parameter groups (``plant`` and ``model`` are read).

        Returns
        -------
        HysteresisActuator or BlendedActuator
            The plant.
        """
        plant: ActuatorPlant = config["plant"]
        nominal = perturb(config["model"], self.family, plant.mismatch, plant.seed)
        truth = self.truth(plant.truth)
        if truth is None:
            return self.plant_of(nominal, plant.noise)
        family, model = truth
        other = perturb(model, family, plant.mismatch, plant.seed)
        if plant.truth != "runner-up":
            return self.plant_of(other, plant.noise, family)
        return BlendedActuator(self.plant_of(nominal, 0.0), self.plant_of(other, 0.0, family),
                               self.runner_up_weight(), plant.noise)

    def tuning_ensemble(self, model: ActuatorModel, noise: float) -> list:
        """The plants the baselines are tuned on: what the identification knows of the model's error.

        They are the ``model`` group exact, and where the document ranks a runner-up the
        ``runner-up`` plant unperturbed (the model moved toward the runner-up by
        :meth:`runner_up_weight`).

        Parameters
        ----------
        model : ActuatorModel
            The ``model`` group.
        noise : float
            Sensor noise standard deviation of the plants (output units).

        Returns
        -------
        list
            One or two plants.
        """
        plants = [self.plant_of(model, noise)]
        if self.runner_up() is not None:
            family, other = self.truth("runner-up")
            plants.append(BlendedActuator(self.plant_of(model, 0.0), self.plant_of(other, 0.0, family),
                                          self.runner_up_weight(), noise))
        return plants
