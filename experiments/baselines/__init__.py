"""Every controller hystmpc compares the NMPC with, in one place.

For any actuator:

* :mod:`~hystmpc.experiments.baselines.pid`: :class:`PidController` (PID on the tracking error,
  optionally with a feed-forward term), :class:`InverseFeedforward` (the inverse hysteresis
  model turns the reference into an input; zhou2024 Fig. 14) and :func:`inverse_feedforward_pid`
  (the two together, the usual scheme for an actuator with hysteresis), and :class:`ModeNotch`
  (a filter on their command that damps the model's lightly damped mode);
* :mod:`~hystmpc.experiments.baselines.compensation`: :class:`HysteresisCompensation` (vo2012
  Fig. 1), and :class:`AdditiveCompensation` and :class:`InverseCompensation`, the two ways an
  inverse model sits in front of the linear MPC of ``inverse-lmpc``
  (:class:`hystmpc.mpc.linear_mpc.InverseLinearMpc`, an MPC, so it lives in ``mpc/``);
* :mod:`~hystmpc.experiments.baselines.replay`: :class:`Replay`, recorded inputs open loop.

The papers' own schemes, for their benches:

* :mod:`~hystmpc.experiments.baselines.reluctance_inverses`: katalenic2013's polynomial and
  hysteresis inverses;
* :mod:`~hystmpc.experiments.baselines.dea_backstepping`: wang2025's adaptive backstepping,
  with and without its compensation;
* :mod:`~hystmpc.experiments.baselines.dea_linear_mpc`: wang2025's linear MPC.
"""

from hystmpc.experiments.baselines.compensation import (
    AdditiveCompensation,
    HysteresisCompensation,
    InverseCompensation,
)
from hystmpc.experiments.baselines.pid import (
    Feedforward,
    FeedforwardPidGains,
    InverseFeedforward,
    ModeNotch,
    Pid,
    PidController,
    PidGains,
    inverse_feedforward_pid,
)
from hystmpc.experiments.baselines.reluctance_inverses import HystInverse, PolyInverse
from hystmpc.experiments.baselines.replay import Replay

__all__ = ["AdditiveCompensation", "Feedforward", "HystInverse", "HysteresisCompensation", "InverseCompensation",
           "FeedforwardPidGains", "InverseFeedforward", "ModeNotch", "Pid", "PidController", "PidGains", "PolyInverse",
           "Replay", "inverse_feedforward_pid"]
