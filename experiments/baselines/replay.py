"""Recorded inputs played open loop (offline optima, a measured run replayed)."""

from __future__ import annotations

import numpy as np


class Replay:
    """Plays a precomputed input sequence open loop (offline optima; not a controller).

    Parameters
    ----------
    inputs : array_like
        The inputs, one per sample.
    """

    horizon = 0

    def __init__(self, inputs):
        self.inputs = np.asarray(inputs, float)
        self.reset()

    def reset(self) -> None:
        """Back to the first input."""
        self._k = 0
        self.predicted_output = float("nan")

    def step(self, measurement, ref_window) -> float:
        """The next input of the sequence (the last one once it runs out).

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement (unused).
        ref_window : ndarray
            The references (unused).

        Returns
        -------
        float
            The input to send.
        """
        u = float(self.inputs[min(self._k, len(self.inputs) - 1)])
        self._k += 1
        return u

    def stats(self) -> None:
        """None: nothing is solved."""
        return None
