"""What every hysteresis model shares beyond its own step."""

from __future__ import annotations

import numpy as np


class SteppedModel:
    """Mixin for models with ``initial_state(u0)`` and ``step(state, u) -> (state, y)``."""

    def simulate(self, inputs, state=None) -> tuple[np.ndarray, np.ndarray]:
        """Exact response to an input sequence; returns ``(outputs, final_state)``.

        Starts from ``initial_state(inputs[0])`` unless ``state`` is given.
        """
        state = self.initial_state(inputs[0]) if state is None else np.asarray(state, float)
        out = np.empty(len(inputs))
        for i, u in enumerate(inputs):
            state, out[i] = self.step(state, u)
        return out, state
