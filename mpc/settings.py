"""Settings of the NMPC: the problem (``nmpc``), the input bounds, and each solver's own (``solver``).

On the command line these are the ``--set`` groups ``nmpc.*`` and ``solver.<name>.*``; the
smoothing of the prediction model is a group of its own (``smoothing.*``), because it
belongs to the model, not to the controller.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

SOLVERS = ("ipopt", "sqp", "rti", "rti-c", "gn")
"""Solver variants: IPOPT; CasADi sqpmethod + qrqp; ``rti``, one Gauss–Newton
SQP step per sample as one CasADi Function (:mod:`hystmpc.mpc.rti`; on multiple-shooting
problems condensed onto the inputs, with DAQP or the interior-point QP of :mod:`hystmpc.mpc.qp`);
``rti-c`` (the default), the same generated as C, compiled and loaded (in-process, with a
notice, when there is no C compiler); ``gn``, Gauss–Newton SQP to convergence
(single-shooting problems only)."""
MULTISTART_SOLVERS = ("gn", "rti", "rti-c")
"""Solver variants that report the cost ``nmpc.multistart`` compares."""
INVERSE_PLANS = ("static", "linear-mpc")
WARM_STARTS = ("inverse", "shift", "cold")
RUNTIMES = ("python", "c", "auto")
"""Where the NMPC runs in closed loop (``nmpc.runtime``)."""
LINE_SEARCHES = ("best", "descent")
"""How the Gauss–Newton step picks its step length (``solver.rti.line_search``)."""


def _check_finite(obj, names, low: float = 0.0, strict: bool = False) -> None:
    for name in names:
        value = getattr(obj, name)
        ok = np.isfinite(value) and (value > low if strict else value >= low)
        if not ok:
            raise ValueError(f"{name} must be finite and {'>' if strict else '>='} {low:g}, got {value}")


@dataclass(frozen=True)
class NmpcSettings:
    """The tracking problem and its use in closed loop (``--set nmpc.KEY=VALUE``)."""

    horizon: int = 20
    """Prediction horizon N in samples."""
    q_output: float = 1.0
    """Weight on the squared tracking error of each predicted output."""
    r_rate: float = 0.3
    """Weight on the squared input change per sample (keeps sensor noise out of the input)."""
    r_input: float = 0.0
    """Weight on the squared deviation of the input from the inverse-model input."""
    solver: str = "rti-c"
    """Solver variant, one of :data:`SOLVERS`; its settings are ``solver.<name>``. The
    default, ``rti-c``, tracks about as well as IPOPT in a fraction of its time
    (docs/realtime.md); a bench may choose another."""
    preview: bool = True
    """Use the known future reference over the horizon; false holds the current one."""
    warm_start: str = "inverse"
    """Initial guess at start-up, after a reference jump and after a failure: 'inverse',
    'shift' (previous plan only, the last input at start) or 'cold' (zeros every step)."""
    inverse_plan: str = "static"
    """Where the inverse-model inputs (warm start, second start, ``r_input``'s target, the
    fallback) come from: ``static``: each previewed reference held at rest, through the
    inverse models; ``linear-mpc``: the plan of the bench's ``inverse-lmpc`` baseline (a
    linear MPC on the dynamics the inverse leaves, its virtual inputs through the inverse
    hysteresis model), which also sees the dynamics and the disturbance estimate (docs/dea.md).
    The generated controller generates that plan too, with ``lmpc.qp=ipm``
    (:mod:`hystmpc.mpc.embedded_planner`)."""
    multistart: bool = False
    """Also solve from the inverse model's inputs (unless that was the start) and keep the
    plan with the lower cost: on every sample, or only where the first plan misses
    (``second_start_error``). Across a hysteresis loop the tracking problem has several
    local minima, and the shifted plan can sit in the worse one (docs/dea.md). The iteration
    counts then add up both solves. Needs an inverse model and solver ``gn``, ``rti`` or
    ``rti-c`` (the RTI step condensed onto the inputs), which report the cost compared; the
    generated controller runs the second start's RTI steps only on the samples that take it."""
    second_start_error: float = 0.0
    """With ``multistart``, solve from the inverse model's inputs only on samples whose first
    plan failed, or both costs more than this RMS error over the horizon, ``q_output · horizon ·
    second_start_error²`` (output units; the cost includes the rate and input weights' terms),
    and ends further than this from the reference (``|y_N − r_N|``); 0: every sample. Where the
    shifted plan tracks, or misses only on the way to a reference it reaches, the second solve
    rarely wins; skipping it halves those samples' work (docs/your-actuator.md)."""
    second_start_pause: int = 0
    """With ``second_start_error``, the samples after a second start that did not win (the first
    plan kept, or both failed) that take no second start unless their first plan fails. A step in the reference
    keeps the plan off for several samples while the shifted plan is already the better one;
    a second start on each of them is work that rarely wins (docs/your-actuator.md)."""
    runtime: str = "python"
    """Where the controller runs in closed loop: ``python``; ``c``: the whole generated
    controller that ``hystmpc codegen`` writes (estimator, warm start, RTI steps,
    fallback), compiled once, cached, and called through ctypes; the same inputs, timed as
    a rig runs it, but no iteration counts in the results (needs solver ``rti`` or ``rti-c``
    and a C compiler); ``auto``: ``c`` with an RTI solver, else ``python`` (after a notice
    when the C compiler is missing or the controller cannot be generated)."""

    def __post_init__(self):
        if self.horizon < 2:
            raise ValueError(f"horizon must be >= 2, got {self.horizon}")
        if self.solver not in SOLVERS:
            raise ValueError(f"solver {self.solver!r} is unknown; allowed: {', '.join(SOLVERS)}")
        if self.runtime not in RUNTIMES:
            raise ValueError(f"runtime {self.runtime!r} is unknown; allowed: {', '.join(RUNTIMES)}")
        if self.warm_start not in WARM_STARTS:
            raise ValueError(f"warm_start {self.warm_start!r} is unknown; allowed: {', '.join(WARM_STARTS)}")
        if self.inverse_plan not in INVERSE_PLANS:
            raise ValueError(f"inverse_plan {self.inverse_plan!r} is unknown; allowed: {', '.join(INVERSE_PLANS)}")
        _check_finite(self, ("r_rate", "r_input"))
        _check_finite(self, ("q_output",), strict=True)
        _check_finite(self, ("second_start_error",))
        if self.second_start_pause < 0:
            raise ValueError(f"second_start_pause must be >= 0 (samples), got {self.second_start_pause}")

    def check_combination(self, solvers: SolverSettings | None = None) -> None:
        """``ValueError`` for settings that cannot go together, also with the ``solvers`` given.

        Checked when the controller is built, and before any work by the command line, after
        all ``--set``.

        Parameters
        ----------
        solvers : SolverSettings, optional
            The solvers' settings, to check against too (None: the NMPC settings alone).

        Raises
        ------
        ValueError
            ``multistart`` with a solver other than ``gn``, ``rti`` and ``rti-c``, or with
            ``solver.rti.condensed=false``.
        """
        if self.multistart and self.solver not in MULTISTART_SOLVERS:
            raise ValueError(f"nmpc.multistart compares the costs that solver gn or the RTI step reports, from the "
                             f"shifted plan and from the inverse model's inputs; nmpc.solver is {self.solver!r} "
                             f"(allowed with it: {', '.join(MULTISTART_SOLVERS)}; or set nmpc.multistart=false)")
        if (self.multistart and self.solver != "gn" and solvers is not None
                and not solvers.rti.condensed):
            raise ValueError("nmpc.multistart compares the costs of two RTI plans over the inputs; "
                             "solver.rti.condensed=false (multiple shooting only) plans the states too: drop it, or "
                             "set nmpc.multistart=false")


def second_start_cost(settings: NmpcSettings) -> float | None:
    """The first plan's cost above which ``multistart`` solves again if it also ends off (None: every sample).

    Parameters
    ----------
    settings : NmpcSettings
        The NMPC's settings (``q_output``, ``horizon``, ``second_start_error``).

    Returns
    -------
    float or None
        ``q_output · horizon · second_start_error²``; None when ``second_start_error`` is 0.
    """
    if settings.second_start_error == 0:
        return None
    return settings.q_output * settings.horizon * settings.second_start_error ** 2


@dataclass(frozen=True)
class InputBounds:
    """What the actuator accepts: ``lower <= u <= upper`` and ``|u_k − u_{k−1}| <= rate``."""

    lower: float
    """Smallest input."""
    upper: float
    """Largest input."""
    rate: float = np.inf
    """Largest change per sample (``inf``: none)."""

    def __post_init__(self):
        if not (np.isfinite(self.lower) and np.isfinite(self.upper) and self.lower < self.upper):
            raise ValueError(f"need finite lower < upper, got {self.lower}, {self.upper}")
        if not self.rate > 0:
            raise ValueError(f"rate must be > 0 (inf for none), got {self.rate}")

    def clip(self, u: float, last: float | None = None) -> float:
        """``u`` moved inside the bounds (and within ``rate`` of ``last``, if given).

        Parameters
        ----------
        u : float
            The input.
        last : float, optional
            The previous input (None: no rate limit).

        Returns
        -------
        float
            The clipped input; the bounds win over the rate.
        """
        if last is not None:
            u = float(np.clip(u, last - self.rate, last + self.rate))
        return float(np.clip(u, self.lower, self.upper))


@dataclass(frozen=True)
class NlpSettings:
    """IPOPT or CasADi's sqpmethod (``--set solver.ipopt.KEY=VALUE``, ``solver.sqp.*``)."""

    max_iter: int = 100
    """Iteration limit per sample."""
    tol: float = 1e-6
    """Convergence tolerance."""
    warm_multipliers: bool = False
    """Also start from the previous solve's multipliers (IPOPT: warm_start_init_point)."""
    options: dict[str, Any] = field(default_factory=dict)
    """Extra options passed to the solver as they are: IPOPT's own names for ``ipopt``
    (``mu_strategy``), sqpmethod's for ``sqp`` (``hessian_approximation``)."""

    def __post_init__(self):
        if self.max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {self.max_iter}")
        _check_finite(self, ("tol",), strict=True)
        if not isinstance(self.options, dict) or not all(isinstance(k, str) for k in self.options):
            raise ValueError(f"options must map option names to values, got {self.options!r}")


@dataclass(frozen=True)
class GaussNewtonSettings:
    """Gauss–Newton SQP to convergence, single-shooting problems (``--set solver.gn.KEY=VALUE``)."""

    max_iter: int = 100
    """Iteration limit per sample."""
    tol: float = 1e-6
    """Stop when the step is below ``tol·(1 + max|u|)``."""
    ftol: float = 0.0
    """Also stop (converged) when a step lowers the cost by less than ``ftol`` times the cost:
    Gauss–Newton crawling with tiny step fractions on a large residual (0: never)."""

    def __post_init__(self):
        if self.max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {self.max_iter}")
        _check_finite(self, ("tol",), strict=True)
        if not (np.isfinite(self.ftol) and 0.0 <= self.ftol < 1.0):
            raise ValueError(f"ftol must be in [0, 1), got {self.ftol}")


@dataclass(frozen=True)
class RtiSettings:
    """Real-time iteration, ``rti`` and ``rti-c`` (``--set solver.rti.KEY=VALUE``)."""

    iterations: int = 1
    """Gauss–Newton steps per sample (1 is the classic real-time iteration)."""
    extra_step_tolerance: float = np.inf
    """One more step when the last of the ``iterations`` moved a planned input by more than
    this (in input units); ``inf``, never. A convergence test: the typical sample keeps
    ``iterations`` steps, the worst case takes one more."""
    condensed: bool = True
    """Multiple-shooting problems: eliminate the states by a rollout inside the step, so the
    QP has the N inputs only and the step backtracks on the cost; false: the QP over states
    and inputs with the shooting gaps as constraints, full step (qrqp). Single-shooting
    problems are condensed by construction and reject false."""
    qp: str = "daqp"
    """QP solver of the condensed and single-shooting steps: ``daqp`` (a dual active-set
    solver; its answers match qpOASES' on these small dense QPs) or ``ipm`` (the
    interior-point QP of :mod:`hystmpc.mpc.qp`, ``qp_iterations`` iterations). The step over
    states and inputs (``condensed=false``) solves with qrqp and refuses ``ipm``."""
    qp_iterations: int = 30
    """Interior-point iterations of the ``ipm`` QP (fixed: real time); refused with ``daqp``."""
    sensitivity_block: int = 0
    """Condensed multiple-shooting step: 0 computes the sensitivities of the predicted states to
    the inputs as straight-line code of the Jacobians' nonzeros (fastest; past a size limit,
    matrix products of their exact widths: :func:`hystmpc.mpc.multiple_shooting.condensing_function`);
    ``b > 0`` propagates them as matrix products padded with explicit zeros to a multiple of
    ``b`` columns (``b >= N``: dense), so generated code reuses its work memory from sample to
    sample (less RAM, more arithmetic on zeros; the same numbers to the last bit while the
    Jacobians are finite). ``codegen --target`` picks 7 for a microcontroller where none is set
    (:data:`hystmpc.experiments.firmware.MICROCONTROLLER_SENSITIVITY_BLOCK`)."""

    line_search: str = "best"
    """Step length of the condensed and single-shooting steps, among 1, 1/2, 1/4 and 1/8:
    ``best``, the one with the lowest cost (four cost evaluations per step); ``descent``,
    the full step whenever it does not raise the cost, else the best of the four (one
    evaluation on most steps: a faster step, and a different one where a shorter step
    would have lowered the cost more)."""

    def check_step(self, condensed: bool) -> None:
        """Refuse the settings this RTI step would not use (``ValueError``).

        Parameters
        ----------
        condensed : bool
            Whether the step is condensed onto the inputs (single shooting, or multiple
            shooting with ``condensed``).

        Raises
        ------
        ValueError
            ``qp_iterations`` without ``qp=ipm``; ``sensitivity_block``, a ``line_search`` other
            than ``best``, a finite ``extra_step_tolerance`` or ``qp=ipm`` on a step that is not
            condensed.
        """
        if self.qp != "ipm" and self.qp_iterations != RtiSettings.qp_iterations:
            raise ValueError(f"solver.rti.qp_iterations={self.qp_iterations} applies to solver.rti.qp=ipm only "
                             f"(qp is {self.qp})")
        if self.sensitivity_block and not condensed:
            raise ValueError(f"solver.rti.sensitivity_block={self.sensitivity_block} applies to the condensed step "
                             "only (solver.rti.condensed=true)")
        if self.line_search != RtiSettings.line_search and not condensed:
            raise ValueError(f"solver.rti.line_search={self.line_search} applies to the condensed step only: the step "
                             "over states and inputs takes the full step (set solver.rti.line_search=best with it)")
        if np.isfinite(self.extra_step_tolerance) and not condensed:
            raise ValueError(f"solver.rti.extra_step_tolerance={self.extra_step_tolerance:g} applies to the condensed "
                             "step only, whose iterate is the planned inputs (solver.rti.condensed=true)")
        if self.qp == "ipm" and not condensed:
            raise ValueError("solver.rti.qp=ipm needs solver.rti.condensed=true: the step over states and inputs "
                             "has unbounded states and solves with qrqp (set solver.rti.qp=daqp with it)")

    def __post_init__(self):
        if self.qp not in ("daqp", "ipm"):
            raise ValueError(f"qp must be one of daqp, ipm, got {self.qp!r}")
        if self.line_search not in LINE_SEARCHES:
            raise ValueError(f"line_search must be one of {', '.join(LINE_SEARCHES)}, got {self.line_search!r}")
        if self.iterations < 1:
            raise ValueError(f"iterations must be >= 1, got {self.iterations}")
        if not self.extra_step_tolerance > 0:
            raise ValueError(f"extra_step_tolerance must be > 0 (inf: no extra step), got {self.extra_step_tolerance}")
        if self.sensitivity_block < 0:
            raise ValueError(f"sensitivity_block must be >= 0 (0: exact widths), got {self.sensitivity_block}")
        if self.qp_iterations < 10:
            raise ValueError(f"qp_iterations must be >= 10, got {self.qp_iterations}")


@dataclass(frozen=True)
class SolverSettings:
    """Every solver's settings; ``nmpc.solver`` picks the one in use (``--set solver.NAME.KEY=VALUE``)."""

    ipopt: NlpSettings = NlpSettings()
    """``ipopt``."""
    sqp: NlpSettings = NlpSettings()
    """``sqp``."""
    gn: GaussNewtonSettings = GaussNewtonSettings()
    """``gn``."""
    rti: RtiSettings = RtiSettings()
    """``rti`` and ``rti-c``."""

    def uniform(self, **changes) -> SolverSettings:
        """The same ``changes`` (``max_iter``, ``tol``, ...) applied to every solver that has them.

        Parameters
        ----------
        **changes
            Setting names and values; each group takes those among its own fields.

        Returns
        -------
        SolverSettings
            A copy with the changes.
        """
        from dataclasses import fields, replace
        out = {}
        for f in fields(self):
            group = getattr(self, f.name)
            names = {g.name for g in fields(group)}
            out[f.name] = replace(group, **{k: v for k, v in changes.items() if k in names})
        return SolverSettings(**out)
