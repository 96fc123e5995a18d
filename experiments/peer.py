"""The same NMPC problem in do-mpc and in acados, to check hystmpc against its peers and to time them.

Optional: needs the ``bench`` extra (``pip install -e '.[bench]'``). Used by the benchmark
in :func:`compare_with_do_mpc` and a slow test only.

The do-mpc problem is built from the bench's own discrete-time prediction model, horizon,
weights and bounds: the state is augmented with the last input so that the slew bound
``|u_k − u_{k−1}| <= du_max`` becomes two nonlinear constraints; the reference and the
disturbance are time-varying parameters; ``rterm`` is the rate weight; the stage cost on
``x_k`` (k = 1..N−1) plus the terminal cost on ``x_N`` is hystmpc's Σ_{k=1..N} q (y_k − r_k)²
(the k = 0 term is a constant).

The acados twin (:func:`acados_rti_timing`) takes one SQP_RTI step on the problems hystmpc's
generated step was called with in a closed-loop run, and times both on the same problems.
acados is not a dependency: it needs the ``comma-deps-acados`` wheel unpacked somewhere
(its ``acados`` folder; the wheel also carries its own CasADi, which must not replace ours).
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


ACADOS_QP_SOLVERS = ("FULL_CONDENSING_QPOASES", "FULL_CONDENSING_HPIPM", "PARTIAL_CONDENSING_HPIPM")


def acados_rti_timing(acados_package, bench_name: str = "pam", qp_solvers=ACADOS_QP_SOLVERS,
                      repeats: int = 3, rounds: int = 2, work=None) -> dict:
    """Acados' SQP_RTI step and hystmpc's generated RTI step on the same recorded problems.

    hystmpc's controller runs the bench's default scenario (``rti``, every ``(w, p)`` its step
    is called with recorded); acados gets the same OCP: the state augmented with the last
    input, the stage cost ``q (y(f(x_k, u_k)) − r_k)² + r_rate Δu_k² + r_input (u_k − u_ff,k)²``
    (Gauss–Newton), the input bounds, the rate bound as a linear constraint, the same
    regularisation (``levenberg_marquardt``), initialised with hystmpc's guess and its rollout.
    Each QP solver is built once and timed with acados' own ``time_tot`` over ``repeats``
    passes, each timing right after one of hystmpc's standalone C step (``rti_main``,
    ``repeats`` passes) on the same problems; ``rounds`` rounds over all the QP solvers.
    Needs a bench whose NMPC is a condensed multiple-shooting problem with a rate bound (pam,
    compliant, reluctance).

    Parameters
    ----------
    acados_package : path
        The ``acados`` folder of the unpacked ``comma-deps-acados`` wheel (``install/`` with
        the libraries, headers and ``t_renderer``; ``acados_template/``).
    bench_name : str, optional
        The bench.
    qp_solvers : tuple of str, optional
        Acados' QP solvers to time (default: :data:`ACADOS_QP_SOLVERS`).
    repeats : int, optional
        Passes over the recorded problems per timing.
    rounds : int, optional
        Rounds over all the QP solvers.
    work : path, optional
        Where the generated acados and hystmpc code goes (default: a temporary folder).

    Returns
    -------
    dict
        ``bench``, ``scenario``, ``problems``, ``repeats``, ``ca_version`` and ``rows``: per
        round and QP solver, acados' median and p95 (µs), its first inputs' differences from
        hystmpc's step, and hystmpc's median and p95 (µs) with ``acados_over_hystmpc``.
    """
    import ctypes
    import os
    import sys
    from pathlib import Path
    from tempfile import TemporaryDirectory

    from hystmpc.experiments.benches import get_bench
    from hystmpc.experiments.realtime import write_solver
    from hystmpc.mpc.codegen import RecordingStep, run_program
    from hystmpc.mpc.rti import REGULARISATION

    package = Path(acados_package).resolve()
    if not (package / "acados_template" / "acados_layout.json").is_file() or not (package / "install").is_dir():
        raise ValueError(f"{package} is not the acados folder of the comma-deps-acados wheel "
                         "(it needs acados_template/ and install/)")
    from hystmpc.mpc.multiple_shooting import MultipleShootingProblem
    bench = get_bench(bench_name)
    config = bench.configure(["nmpc.solver=rti"])
    prepared = bench.prepare(bench.default_scenario, "nmpc", config)
    problem = prepared.controller.problem
    if not (isinstance(problem, MultipleShootingProblem) and problem.condensed and np.isfinite(problem.du_max)):
        raise ValueError(f"bench {bench_name!r}: the acados twin needs a condensed multiple-shooting NMPC with a "
                         "rate bound (pam, compliant, reluctance)")
    problem.rti = RecordingStep(problem.rti)
    bench.run(bench.default_scenario, "nmpc", prepared=prepared)
    calls = np.asarray(problem.rti.calls)
    with contextlib.ExitStack() as stack:
        work = Path(work) if work else Path(stack.enter_context(TemporaryDirectory()))
        source = _acados_source_layout(package, work / "acados")
        importable = work / "import"
        importable.mkdir(parents=True, exist_ok=True)
        if not (importable / "acados").exists():
            (importable / "acados").symlink_to(package)  # acados alone: not the wheel's CasADi
        sys.path.insert(0, str(importable))
        stack.callback(sys.path.remove, str(importable))
        previous = os.environ.get("ACADOS_SOURCE_DIR")
        os.environ["ACADOS_SOURCE_DIR"] = str(source)
        stack.callback(_restore_environment, "ACADOS_SOURCE_DIR", previous)
        for library in ("libblasfeo.so", "libhpipm.so", "libqpOASES_e.so.3.1", "libacados.so"):
            ctypes.CDLL(str(package / "install" / "lib" / library), mode=ctypes.RTLD_GLOBAL)  # for the solver's
        write_solver(bench, config, work / "hystmpc")
        solvers = {qp: _acados_solver(problem, qp, work / qp.lower(), REGULARISATION, float(bench.sample_period))
                   for qp in qp_solvers}
        rows = []
        for _ in range(rounds):
            for qp, solver in solvers.items():
                _, ours = run_program(work / "hystmpc", calls, problem.settings.horizon, repeats=repeats)
                theirs = {"qp": qp, **_acados_timing(problem, solver, calls, repeats)}
                rows.append({**theirs, "hystmpc_median_us": ours["median_us"], "hystmpc_p95_us": ours["p95_us"],
                             "acados_over_hystmpc": theirs["median_us"] / ours["median_us"]})
    return {"bench": bench_name, "scenario": bench.default_scenario, "problems": len(calls), "repeats": repeats,
            "ca_version": ca.__version__, "rows": rows}


def _acados_source_layout(package, folder):
    """The folder layout acados_template expects of ACADOS_SOURCE_DIR, as links into the wheel."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("bin", "lib", "include"):
        if not (folder / name).exists():
            (folder / name).symlink_to(package / "install" / name)
    template = folder / "interfaces" / "acados_template"
    template.mkdir(parents=True, exist_ok=True)
    if not (template / "acados_template").exists():
        (template / "acados_template").symlink_to(package / "acados_template")
    return folder


def _restore_environment(key: str, value: str | None) -> None:
    import os
    if value is None:
        os.environ.pop(key, None)
    else:
        os.environ[key] = value


def _acados_solver(problem, qp: str, folder, regularisation: float, dt: float):
    """Acados' SQP_RTI solver of ``problem`` with the QP solver ``qp``, generated and built in ``folder``."""
    from acados.acados_template import AcadosModel, AcadosOcp, AcadosOcpSolver
    m, s = problem.model, problem.settings
    N, nx, nd = s.horizon, m.nx, m.nd
    x, u_last, u = ca.SX.sym("x", nx), ca.SX.sym("u_last"), ca.SX.sym("u")
    d, ref, u_ff = ca.SX.sym("d", nd), ca.SX.sym("ref"), ca.SX.sym("u_ff")
    x_next = m.step(x, u, d)
    model = AcadosModel()
    model.name = f"twin_{qp.lower()}"
    model.x, model.u, model.p = ca.vertcat(x, u_last), u, ca.vertcat(d, ref, u_ff)
    model.disc_dyn_expr = ca.vertcat(x_next, u)
    model.cost_y_expr = ca.vertcat(m.output(x_next, d) - ref, u - u_last, u - u_ff)
    ocp = AcadosOcp()
    ocp.model = model
    ocp.dims.N = N
    ocp.solver_options.tf = N * dt
    ocp.cost.cost_type, ocp.cost.cost_type_e = "NONLINEAR_LS", "LINEAR_LS"
    ocp.cost.W, ocp.cost.yref = np.diag([s.q_output, s.r_rate, s.r_input]), np.zeros(3)
    ocp.cost.Vx_e, ocp.cost.W_e, ocp.cost.yref_e = np.zeros((0, nx + 1)), np.zeros((0, 0)), np.zeros(0)
    ocp.constraints.idxbu = np.array([0])
    ocp.constraints.lbu, ocp.constraints.ubu = np.array([problem.u_min]), np.array([problem.u_max])
    ocp.constraints.C = np.concatenate((np.zeros((1, nx)), [[-1.0]]), axis=1)
    ocp.constraints.D = np.array([[1.0]])
    ocp.constraints.lg, ocp.constraints.ug = np.array([-problem.du_max]), np.array([problem.du_max])
    ocp.constraints.x0 = np.zeros(nx + 1)
    ocp.parameter_values = np.zeros(nd + 2)
    options = ocp.solver_options
    options.integrator_type, options.nlp_solver_type, options.hessian_approx = "DISCRETE", "SQP_RTI", "GAUSS_NEWTON"
    options.levenberg_marquardt, options.qp_solver = regularisation, qp
    ocp.code_export_directory = str(folder)
    with contextlib.redirect_stdout(None):
        return AcadosOcpSolver(ocp, json_file=str(folder) + ".json", verbose=False)


def _acados_timing(problem, solver, calls, repeats: int) -> dict:
    """``solver`` timed on ``calls`` (µs, its own ``time_tot``); its first inputs against hystmpc's step."""
    m, N = problem.model, problem.settings.horizon
    nx, nd = m.nx, m.nd
    times, differences = [], []
    for repeat in range(repeats):
        for call in calls:
            w0, p = call[:N], call[N:]
            x0, d0, u_prev = p[:nx], p[nx:nx + nd], p[nx + nd]
            refs, u_ffs = p[nx + nd + 1: nx + nd + 1 + N], p[nx + nd + 1 + N:]
            states = np.asarray(problem.rollout(w0, p))
            lasts = np.concatenate(([u_prev], w0))
            for k in range(N + 1):
                solver.set(k, "x", np.concatenate((states[k], [lasts[k]])))
                solver.set(k, "p", np.concatenate((d0, [refs[min(k, N - 1)], u_ffs[min(k, N - 1)]])))
                if k < N:
                    solver.set(k, "u", np.array([w0[k]]))
            solver.constraints_set(0, "lbx", np.concatenate((x0, [u_prev])))
            solver.constraints_set(0, "ubx", np.concatenate((x0, [u_prev])))
            solver.solve()
            times.append(1e6 * solver.get_stats("time_tot"))
            if repeat == 0:
                ours = float(np.asarray(problem.rti.fun(w0, p)[0]).ravel()[0])
                differences.append(abs(float(solver.get(0, "u")[0]) - ours))
    differences = np.asarray(differences)
    return {"median_us": float(np.median(times)), "p95_us": float(np.percentile(times, 95)),
            "first_input_difference_median": float(np.median(differences)),
            "first_input_difference_max": float(differences.max()),
            "share_within_1e-6": float(np.mean(differences <= 1e-6))}


if __name__ == "__main__":  # python -m hystmpc.experiments.peer [BENCH | acados ACADOS_FOLDER]: as JSON
    import json
    import sys
    if sys.argv[1:2] == ["acados"]:
        if len(sys.argv) != 3:
            print("usage: python -m hystmpc.experiments.peer acados ACADOS_FOLDER (the unpacked wheel's acados/)",
                  file=sys.stderr)
            sys.exit(2)
        print(json.dumps(acados_rti_timing(sys.argv[2]), indent=1))
    else:
        print(json.dumps(benchmark(sys.argv[1] if len(sys.argv) > 1 else "pam"), indent=1))
