"""The same NMPC problem in do-mpc, to check hystmpc against a peer and to time both.

Optional: needs the ``bench`` extra (``pip install -e '.[bench]'``). Used by the benchmark
in :func:`compare_with_do_mpc` and a slow test only.

The do-mpc problem is built from the bench's own discrete-time prediction model, horizon,
weights and bounds: the state is augmented with the last input so that the slew bound
``|u_k − u_{k−1}| <= du_max`` becomes two nonlinear constraints; the reference and the
disturbance are time-varying parameters; ``rterm`` is the rate weight; the stage cost on
``x_k`` (k = 1..N−1) plus the terminal cost on ``x_N`` is hystmpc's Σ_{k=1..N} q (y_k − r_k)²
(the k = 0 term is a constant).

The acados twin is :mod:`hystmpc.experiments.peer_acados`; ``python -m
hystmpc.experiments.peer acados ACADOS_FOLDER [BENCH]`` runs it.
"""

from __future__ import annotations

import contextlib
import time
import warnings
from dataclasses import replace

import casadi as ca
import numpy as np


def do_mpc_problem(nmpc, solver_options: dict | None = None):
    """A do-mpc MPC with the problem of ``nmpc``.

    Parameters
    ----------
    nmpc : MultipleShootingProblem
        hystmpc's problem (:class:`hystmpc.mpc.MultipleShootingProblem`) with ``r_input = 0``.
    solver_options : dict, optional
        IPOPT options added to do-mpc's ``nlpsol_opts``.

    Returns
    -------
    tuple of (do_mpc.controller.MPC, dict)
        The MPC, set up, and its time-varying parameters: set ``refs`` (``horizon + 1``
        references, one per do-mpc stage) and ``d`` (the disturbance) before each step.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import do_mpc
    m, s = nmpc.model, nmpc.settings
    if s.r_input != 0:
        raise ValueError("the do-mpc twin supports r_input = 0 only")
    model = do_mpc.model.Model("discrete", symvar_type="SX")
    x = model.set_variable("_x", "x", (m.nx, 1))
    model.set_variable("_x", "u_last")
    u = model.set_variable("_u", "u")
    d = model.set_variable("_tvp", "d", (m.nd, 1))
    model.set_variable("_tvp", "ref")
    model.set_rhs("x", m.step(x, u, d))
    model.set_rhs("u_last", u)
    model.set_expression("y", m.output(x, d))
    model.setup()
    mpc = do_mpc.controller.MPC(model)
    mpc.settings.n_horizon = s.horizon
    mpc.settings.t_step = m.sample_period
    mpc.settings.store_full_solution = False
    mpc.settings.nlpsol_opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
                                **(solver_options or {})}
    err = s.q_output * (model.aux["y"] - model.tvp["ref"]) ** 2
    mpc.set_objective(lterm=err, mterm=err)
    mpc.set_rterm(u=s.r_rate)
    mpc.bounds["lower", "_u", "u"] = nmpc.u_min
    mpc.bounds["upper", "_u", "u"] = nmpc.u_max
    mpc.set_nl_cons("slew_up", model.u["u"] - model.x["u_last"], ub=nmpc.du_max)
    mpc.set_nl_cons("slew_down", model.x["u_last"] - model.u["u"], ub=nmpc.du_max)
    template = mpc.get_tvp_template()
    state = {"refs": np.zeros(s.horizon + 1), "d": np.zeros(m.nd)}

    def tvp(t_now):  # the caller sets the window before each step; time is not used
        for k in range(s.horizon + 1):
            template["_tvp", k, "ref"] = state["refs"][k]
            template["_tvp", k, "d"] = state["d"]
        return template

    mpc.set_tvp_fun(tvp)
    with _quiet_peer():
        mpc.setup()
    return mpc, state


@contextlib.contextmanager
def _quiet_peer():
    """Silence do-mpc's warnings (a context manager).

    do-mpc calls numpy on casadi values, which casadi 3.8 flags with a FutureWarning per call
    site: not ours to fix, and harmless to the result (checked against hystmpc).
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        warnings.simplefilter("ignore", UserWarning)
        yield


def first_inputs(nmpc, mpc, state, x0, d, u_prev: float, refs) -> tuple[float, float, float, float]:
    """First input of both for one problem instance, and each solve's wall time (s).

    Parameters
    ----------
    nmpc : MultipleShootingProblem
        hystmpc's problem.
    mpc : do_mpc.controller.MPC
        Its do-mpc twin (:func:`do_mpc_problem`).
    state : dict
        The twin's time-varying parameters (:func:`do_mpc_problem`).
    x0 : ndarray
        The state estimate.
    d : ndarray
        The disturbance estimate.
    u_prev : float
        The last input.
    refs : array_like
        r_{k+1..k+N} as :meth:`hystmpc.mpc.MultipleShootingProblem.solve` takes them.

    Returns
    -------
    tuple of float
        ``(hystmpc's first input, do-mpc's, hystmpc's solve time, do-mpc's)`` (s).
    """
    refs = np.asarray(refs, float)
    start = time.perf_counter()
    ours = nmpc.solve(np.concatenate((x0, d)), u_prev, refs, np.full(len(refs), u_prev))
    t_ours = time.perf_counter() - start
    # do-mpc's stage k costs x_k against its tvp ref_k: shift by one (the k = 0 term is constant)
    state["refs"] = np.concatenate(([refs[0]], refs))
    state["d"] = np.asarray(d, float).ravel()
    mpc.reset_history()
    mpc.x0 = np.concatenate((np.asarray(x0, float).ravel(), [u_prev]))
    mpc.u0 = np.array([u_prev])
    mpc.set_initial_guess()
    with _quiet_peer():
        start = time.perf_counter()
        theirs = float(np.asarray(mpc.make_step(mpc.x0)).ravel()[0])
        t_theirs = time.perf_counter() - start
    return float(ours.u_plan[0, 0]), theirs, t_ours, t_theirs


class _Recorder:
    """Wraps a problem's ``solve``: keeps ``(x0, d, u_prev, refs)`` of every call."""

    def __init__(self, problem):
        self.problem, self.calls = problem, []
        self._solve, problem.solve = problem.solve, self

    def __call__(self, condition, u_prev, refs, *args, **kwargs):
        nx = self.problem.model.nx
        self.calls.append((condition[:nx].copy(), condition[nx:].copy(), float(u_prev), np.array(refs, float)))
        return self._solve(condition, u_prev, refs, *args, **kwargs)


def compare_with_do_mpc(bench_name: str = "pam", samples: int = 5, duration: float = 4.0) -> dict:
    """Solve a few closed-loop states of the bench's default scenario with both; time both.

    The states come from an IPOPT run of hystmpc's NMPC; both solvers then start from the
    same state, disturbance estimate, last input and reference window.

    Parameters
    ----------
    bench_name : str, optional
        The bench.
    samples : int, optional
        How many states (at most: repeated picks count once), evenly spread from a quarter of the run to its end.
    duration : float, optional
        Length of the closed-loop run (s).

    Returns
    -------
    dict
        ``bench`` and ``cases``: per state, both first inputs, their ``relative_difference`` and
        both solve times (ms).
    """
    from hystmpc.experiments.benches import get_bench
    bench = get_bench(bench_name)
    config = bench.configure(["nmpc.solver=ipopt", "solver.ipopt.tol=1e-10", "solver.ipopt.max_iter=500"])
    prepared = bench.prepare(bench.default_scenario, "nmpc", config)
    problem = prepared.controller.problem
    recorder = _Recorder(problem)
    bench.run(bench.default_scenario, "nmpc", duration=duration, prepared=prepared)
    problem.solve = recorder._solve
    picks = np.linspace(len(recorder.calls) // 4, len(recorder.calls) - 1, samples).astype(int)
    mpc, state = do_mpc_problem(problem, {"ipopt.tol": 1e-10})
    rows = []
    for k in sorted(set(picks)):
        ours, theirs, t_ours, t_theirs = first_inputs(problem, mpc, state, *recorder.calls[k])
        rows.append({"hystmpc": ours, "do_mpc": theirs,
                     "relative_difference": abs(ours - theirs) / max(abs(theirs), 1e-12),
                     "hystmpc_ipopt_ms": 1e3 * t_ours, "do_mpc_ms": 1e3 * t_theirs})
    return {"bench": bench_name, "cases": rows}


class DoMpcController:
    """do-mpc solving hystmpc's problem, behind hystmpc's own observer (a :class:`Controller`).

    Parameters
    ----------
    nmpc_controller : NmpcController
        hystmpc's controller: its problem, observer and sensors.
    """

    def __init__(self, nmpc_controller):
        self.inner = nmpc_controller
        self.horizon = nmpc_controller.horizon
        self.mpc, self.state = do_mpc_problem(nmpc_controller.problem)
        self.solve_times: list[float] = []

    def reset(self) -> None:
        """Start again: the observer, the first-step initial guess, the timings."""
        self.inner.observer.reset()
        self._u_last = None
        self.solve_times = []
        self.predicted_output = float("nan")

    def step(self, measurement, ref_window) -> float:
        """do-mpc's input for this sample.

        Parameters
        ----------
        measurement : Measurement
            This sample's measurement.
        ref_window : ndarray
            The references ``r_k..r_{k+N}``.

        Returns
        -------
        float
            The input to send.
        """
        observer = self.inner.observer
        observer.update(self.inner.sensors(measurement), self._u_last)
        est = observer.estimate(self.horizon)
        u_last = 0.0 if self._u_last is None else self._u_last
        self.state["refs"] = np.concatenate(([ref_window[1]], ref_window[1:]))
        self.state["d"] = est.d.copy()
        x0 = np.concatenate((est.x, [u_last]))
        if self._u_last is None:
            self.mpc.x0 = x0
            self.mpc.u0 = np.array([u_last])
            self.mpc.set_initial_guess()
        with _quiet_peer():
            start = time.perf_counter()
            u = float(np.asarray(self.mpc.make_step(x0)).ravel()[0])
            self.solve_times.append(time.perf_counter() - start)
        self._u_last = u
        return u

    def stats(self) -> None:
        """None: do-mpc's own statistics are not collected."""
        return None


def time_do_mpc_closed_loop(bench_name: str = "pam", duration: float = 4.0) -> dict:
    """do-mpc's per-step time over a closed-loop run (the same plant and EKF as hystmpc).

    Parameters
    ----------
    bench_name : str, optional
        The bench; its default scenario runs.
    duration : float, optional
        Length of the run (s).

    Returns
    -------
    dict
        ``bench``, ``steps``, ``step_ms_median``, ``step_ms_p95`` (ms) and ``ca_version``.
    """
    from hystmpc.experiments.benches import get_bench
    bench = get_bench(bench_name)
    prepared = bench.prepare(bench.default_scenario, "nmpc")
    peer = DoMpcController(prepared.controller)
    bench.run(bench.default_scenario, "nmpc", duration=duration, prepared=replace(prepared, controller=peer))
    ms = 1e3 * np.asarray(peer.solve_times)
    return {"bench": bench_name, "steps": len(ms), "step_ms_median": float(np.median(ms)),
            "step_ms_p95": float(np.percentile(ms, 95)), "ca_version": ca.__version__}


def benchmark(bench_name: str = "pam", duration: float = 20.0) -> dict:
    """do-mpc and hystmpc's ``rti-c`` on the same closed-loop scenario, timed in one run.

    Parameters
    ----------
    bench_name : str, optional
        The bench; its default scenario runs.
    duration : float, optional
        Length of each run (s).

    Returns
    -------
    dict
        The medians (ms) of do-mpc's step and of ``rti-c``'s solve, step and standalone C
        program, and do-mpc's step over the two ``rti-c`` times (``ratio_solve``,
        ``ratio_standalone``).
    """
    from pathlib import Path
    from tempfile import TemporaryDirectory

    from hystmpc.experiments.benches import get_bench
    from hystmpc.experiments.realtime import speed
    bench = get_bench(bench_name)
    theirs = time_do_mpc_closed_loop(bench_name, duration)
    with TemporaryDirectory() as tmp:
        ours = speed(bench, bench.configure(), ["rti-c"], duration, Path(tmp))
    rti_c = ours["variants"][0]
    return {"bench": bench_name, "duration_s": duration, "do_mpc_step_ms_median": theirs["step_ms_median"],
            "rti_c_solve_ms_median": rti_c["solve_ms_median"], "rti_c_step_ms_median": rti_c["step_ms_median"],
            "rti_c_standalone_ms_median": ours["standalone_c"]["median_us"] / 1e3,
            "ratio_solve": theirs["step_ms_median"] / rti_c["solve_ms_median"],
            "ratio_standalone": theirs["step_ms_median"] / (ours["standalone_c"]["median_us"] / 1e3)}


if __name__ == "__main__":  # python -m hystmpc.experiments.peer [BENCH | acados ACADOS_FOLDER]: as JSON
    import json
    import sys
    if sys.argv[1:2] == ["acados"]:
        if len(sys.argv) not in (3, 4):
            print("usage: python -m hystmpc.experiments.peer acados ACADOS_FOLDER [BENCH] (ACADOS_FOLDER: the "
                  "unpacked wheel's acados/)", file=sys.stderr)
            sys.exit(2)
        from hystmpc.experiments.peer_acados import acados_rti_timing
        print(json.dumps(acados_rti_timing(sys.argv[2], *sys.argv[3:]), indent=1))
    else:
        print(json.dumps(benchmark(sys.argv[1] if len(sys.argv) > 1 else "pam"), indent=1))
