"""katalenic2013's feed-forward linearisations of a reluctance actuator.

The single-valued polynomial inverse (its Fig. 5b baseline) and the hysteresis inverse
i = IH[Lut(F, g)] (eq. (12a), Fig. 10), both commanding the force wanted when their current
takes effect.
"""

from __future__ import annotations

import numpy as np

from hystmpc.models.reluctance import ReluctanceModel


class PolyInverse:
    """Feed-forward through the single-valued polynomial (the paper's baseline, Fig. 5b).

    Like every feed-forward here it commands the force wanted when the current takes
    effect, one sample ahead (``horizon = 1``); otherwise it would lag by one sample.

    Parameters
    ----------
    model : ReluctanceModel
        The identified model (its polynomial inverse).
    gap : float
        The air gap (m).
    current_limit : float
        Largest current (A).
    """

    horizon = 1

    def __init__(self, model: ReluctanceModel, gap: float, current_limit: float):
        self.model, self.gap, self.limit = model, gap, current_limit
        self.predicted_output = float("nan")

    def reset(self) -> None:
        """Stateless."""

    def step(self, measurement, ref_window) -> float:
        """Current for the reference force.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement (unused: feed-forward).
        ref_window : ndarray
            The force references (N); ``ref_window[1]`` is the one targeted.

        Returns
        -------
        float
            The current (A), within ``[0, current_limit]``.
        """
        return float(np.clip(self.model.poly_current(float(ref_window[1]), self.gap)[0], 0.0, self.limit))

    def stats(self) -> None:
        """None: nothing is solved."""
        return None


class HystInverse:
    """The hysteresis inverse i = IH[Lut(F_ref, g)] (eq. (12a)).

    The command is rate-limited to the slew limit and the operator's memory follows the current
    actually commanded. Targets the next sample's reference (``horizon = 1``), as
    :class:`PolyInverse`.

    Parameters
    ----------
    model : ReluctanceModel
        The identified model (its operator and look-up tables).
    gap : float
        The air gap (m).
    current_limit : float
        Largest current (A).
    slew_per_sample : float
        Largest current change per sample (A).
    """

    horizon = 1

    def __init__(self, model: ReluctanceModel, gap: float, current_limit: float, slew_per_sample: float):
        self.model, self.gap, self.limit, self.slew = model, gap, current_limit, slew_per_sample
        self.op = model.operator(gap)
        self.reset()

    def reset(self) -> None:
        """Demagnetised at zero current."""
        self._state = self.op.initial_state(0.0)
        self.predicted_output = float("nan")

    def step(self, measurement, ref_window) -> float:
        """Current for the reference force.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement (unused: feed-forward).
        ref_window : ndarray
            The force references (N); ``ref_window[1]`` is the one targeted.

        Returns
        -------
        float
            The current (A), within ``[0, current_limit]`` and within ``slew_per_sample`` of the last.
        """
        x_target = float(self.model.x_of_force(max(float(ref_window[1]), 0.0), self.gap))
        last = float(self._state[0])
        _, wanted = self.op.inverse_step(self._state, x_target)
        current = float(np.clip(wanted, max(0.0, last - self.slew), min(self.limit, last + self.slew)))
        self._state, x = self.op.step(self._state, current)
        self.predicted_output = float(self.model.force_of_x(x, self.gap))
        return current

    def stats(self) -> None:
        """None: nothing is solved."""
        return None
