"""Closed loops, baselines, benches, reports and the ``hystmpc`` command line.

* :func:`simulate` runs any plant with any controller along a reference; :class:`RunResult`
  holds the trajectories, metrics, ``to_json()`` and ``plot()``; :class:`InputGuard` keeps
  every input inside the actuator's physical limits.
* Baselines for any actuator: :class:`PidController`, :func:`inverse_feedforward_pid`,
  :class:`InverseFeedforward`, :class:`HysteresisCompensation`; the compensations of
  ``inverse-lmpc``, :class:`AdditiveCompensation` and :class:`InverseCompensation`.
* The four papers' benches: :func:`get_bench` (``pam``, ``compliant``, ``reluctance``, ``dea``).
"""

from hystmpc.experiments.baselines import (
    AdditiveCompensation,
    HysteresisCompensation,
    InverseCompensation,
    InverseFeedforward,
    PidController,
    PidGains,
    inverse_feedforward_pid,
)
from hystmpc.experiments.bench import Bench, ControllerSpec
from hystmpc.experiments.benches import BENCH_NAMES, get_bench
from hystmpc.experiments.runner import Controller, InputGuard, Labels, RunResult, Scenario, simulate

__all__ = ["BENCH_NAMES", "AdditiveCompensation", "Bench", "Controller", "ControllerSpec", "HysteresisCompensation",
           "InputGuard", "InverseCompensation", "InverseFeedforward", "Labels", "PidController", "PidGains",
           "RunResult", "Scenario", "get_bench", "inverse_feedforward_pid", "simulate"]
