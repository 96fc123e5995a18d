"""inverse-lmpc: the inverse compensation + linear MPC baseline on every bench."""

from __future__ import annotations

import numpy as np
import pytest

from hystmpc.experiments.baselines import InverseCompensation
from hystmpc.experiments.benches import get_bench
from hystmpc.models.power_function import PowerFunctionHysteresis
from hystmpc.mpc import InputBounds
from hystmpc.mpc.linear_mpc import InverseLinearMpc, LinearMpcSettings, one_sample_delay
from hystmpc.mpc.linear_mpc_matrices import linearise
from hystmpc.plants.base import Measurement
from hystmpc.plants.pam_joint import PamJointParams, linear_model


def test_linearise_reproduces_a_linear_model_exactly():
    model = linear_model(PamJointParams())
    lin = linearise(model)
    rng = np.random.default_rng(0)
    x, v, d = rng.normal(size=model.nx), rng.normal(), rng.normal()
    exact = np.asarray(model.step(x, v, d)).ravel()
    assert np.allclose(lin["A"] @ x + lin["B"].ravel() * v + lin["Bd"].ravel() * d + lin["f0"], exact,
                       rtol=0, atol=1e-12)


class _Identity:
    """A compensation that changes nothing, with no sensors."""

    def reset(self): ...
    def update(self, measurement): ...
    def to_input(self, v): return v
    def to_virtual(self, u): return u
    def applied(self, u): ...
    def sensors(self, measurement): return []


def _run_delay_lmpc(refs, rate):
    lmpc = InverseLinearMpc(one_sample_delay(0.01), _Identity(), InputBounds(0.0, 10.0, rate),
                            LinearMpcSettings(horizon=8, r_rate=1e-9), process_noise=[0.0], measurement_noise=[],
                            initial_state=lambda z: np.zeros(1), initial_covariance=[0.0])
    lmpc.reset()
    m = Measurement(t=0.0, y=0.0, sensors={}, truth={})
    return np.array([lmpc.step(m, refs[k: k + 9]) for k in range(len(refs) - 9)]), lmpc


def test_without_a_binding_rate_the_linear_mpc_is_the_inverse():
    refs = np.concatenate((np.zeros(5), np.full(20, 4.0)))
    u, lmpc = _run_delay_lmpc(refs, np.inf)
    assert lmpc.failures == 0
    assert np.allclose(u, refs[1: len(u) + 1], atol=1e-5)  # u_k makes y_{k+1} = r_{k+1}


def test_with_a_rate_limit_it_starts_moving_before_the_step():
    refs = np.concatenate((np.zeros(10), np.full(20, 4.0)))
    u, _ = _run_delay_lmpc(refs, 1.0)
    assert np.all(np.abs(np.diff(np.concatenate(([0.0], u)))) <= 1.0 + 1e-9)
    # the preview shows the step (r_10 = 4): the least-squares ramp is centred on it
    assert np.allclose(u[6:12], [0.0, 0.5, 1.5, 2.5, 3.5, 4.0], atol=1e-5)
    assert np.all((u >= 0.0) & (u <= 10.0))


def test_inverse_compensation_inverts_its_hysteresis_from_any_memory():
    model = PowerFunctionHysteresis()
    comp = InverseCompensation(model, sensors=lambda m, c: [])
    comp.update(None)
    rng = np.random.default_rng(1)
    s_range = (float(model.s_descending(-2.0)), float(model.s_ascending(2.0)))
    for s in rng.uniform(*s_range, 30):
        comp.applied(s)  # memory with reversals
        for target in (-1.0, 0.3, 1.5):
            u = comp.to_input(target)
            assert abs(comp.to_virtual(u) - target) < 1e-9


@pytest.mark.parametrize("bench_name, baseline, duration", [
    ("pam", "pi-hc", 6.0), ("compliant", "inverse-ff-pid", 4.0), ("dea", "linear-mpc", 6.0)])
def test_inverse_lmpc_runs_inside_the_bounds_and_beats_the_papers_baseline(bench_name, baseline, duration):
    bench = get_bench(bench_name)
    scenario = bench.default_scenario
    lmpc = bench.run(scenario, "inverse-lmpc", duration=duration)
    base = bench.run(scenario, baseline, duration=duration)
    lo, hi = bench.input_bounds
    assert np.all(np.isfinite(lmpc.input)) and np.all((lmpc.input >= lo) & (lmpc.input <= hi))
    assert lmpc.solver["failures"] == 0
    assert lmpc.metrics["rmse"] < 0.8 * base.metrics["rmse"], (lmpc.metrics["rmse"], base.metrics["rmse"])


def test_inverse_lmpc_is_offset_free_on_pam():
    """The plant's payload, gains and creep differ from the model: the disturbance estimate
    takes them up, so a held reference is reached."""
    bench = get_bench("pam")
    run = bench.run("square-20", "inverse-lmpc", duration=4.5)
    settled = run.t > 3.5
    assert abs(np.mean(run.output[settled] - run.reference[settled])) < 0.1


@pytest.mark.parametrize("bench_name", ["pam", "compliant", "reluctance", "dea"])
def test_inverse_lmpc_predicts_over_the_nmpcs_horizon_unless_told_otherwise(bench_name):
    bench = get_bench(bench_name)
    assert bench.configure()["lmpc"].horizon == bench.configure()["nmpc"].horizon
    assert bench.configure(["nmpc.horizon=13"])["lmpc"].horizon == 13
    both = bench.configure(["lmpc.horizon=9", "nmpc.horizon=13"])
    assert (both["lmpc"].horizon, both["nmpc"].horizon) == (9, 13)
    assert bench.configure(["lmpc.horizon=9"])["nmpc"].horizon == bench.configure()["nmpc"].horizon


def test_a_plan_begins_with_the_input_step_sends_and_leaves_the_memory_as_it_was():
    """``plan`` + ``applied`` (the NMPC's ``inverse_plan=linear-mpc``) is ``step`` split in
    two: the plan's first input is the one ``step`` sends (bisection against the ζ search:
    about 1e-12 V), and the compiled chain gives the Python loop's inputs."""
    bench = get_bench("dea")
    config = bench.configure()
    stepped, planned = (bench.build_controller("inverse-lmpc", config) for _ in range(2))
    plant = bench.build_plant(config)
    measurement = plant.reset(0)
    n = stepped.horizon
    for k in range(60):
        refs = 1.0 + 0.2 * np.sin(0.3 * (k + np.arange(n + 1)))
        u = stepped.step(measurement, refs)
        plan = planned.plan(measurement, refs)
        memory = planned.compensation._state.copy()
        assert plan.shape == (n,) and abs(plan[0] - u) < 1e-9, (k, plan[0], u)
        if k % 20 == 19:  # the same chain, run as the Python loop
            virtual = planned._plan
            compiled = planned.compensation.inputs_along(virtual)
            planned.compensation._chains[n] = None
            assert np.max(np.abs(planned.compensation.inputs_along(virtual) - compiled)) < 1e-9
            del planned.compensation._chains[n]
        assert np.array_equal(planned.compensation._state, memory)
        planned.applied(u)
        measurement = plant.step(u)


def test_nmpc_with_a_linear_mpc_plan_needs_the_planner():
    bench = get_bench("dea")
    config = bench.configure()
    assert config["nmpc"].inverse_plan == "linear-mpc"  # dea's default
    attached = bench.build_controller("nmpc", config)
    assert isinstance(attached.planner, InverseLinearMpc)
    bare = bench.controllers["nmpc"].build(config)  # the bench's builder alone attaches nothing
    bare.reset()
    measurement = bench.build_plant(config).reset(0)
    with pytest.raises(ValueError, match="nmpc.inverse_plan=linear-mpc .* set nmpc.inverse_plan=static"):
        bare.step(measurement, np.ones(bare.horizon + 1))
    with pytest.raises(ValueError, match="lmpc.horizon=9 differs from nmpc.horizon=15; set lmpc.horizon=15"):
        bench.build_controller("nmpc", bench.configure(["lmpc.horizon=9"]))
    static = bench.configure(["nmpc.inverse_plan=static"])
    assert bench.build_controller("nmpc", static).planner is None
    with pytest.raises(ValueError, match="nmpc.inverse_plan is 'static': set it, or give no planner"):
        type(bare)(bare.model, bare.bounds, static["nmpc"], static["solver"], observer=bare.observer,
                   planner=attached.planner)


def test_a_steady_correction_is_refused_where_the_dynamics_do_not_read_d():
    from dataclasses import replace

    from hystmpc.experiments.benches.dea import NOMINAL
    from hystmpc.models.fckp import Fckp
    from hystmpc.models.prediction import Dynamics, build_prediction_model
    dynamics = Dynamics(state_names=("x",), rhs=lambda x, u, h, d: [h - x[0]], output=lambda x, h: x[0],
                        steady_input=lambda y: y, steady_correction=lambda h, d: h - d[0])
    with pytest.raises(ValueError, match="here d enters as 'hysteresis'"):
        build_prediction_model(Fckp(NOMINAL.fckp), 0.01, dynamics=dynamics, eps=1e-3, disturbance="hysteresis")
    build_prediction_model(Fckp(NOMINAL.fckp), 0.01, dynamics=replace(dynamics, steady_correction=None), eps=1e-3,
                           disturbance="hysteresis")


def _dea_planner(qp: str, rate: float = np.inf, **compensation) -> InverseLinearMpc:
    """dea's ``inverse-lmpc`` (its settings), with an input rate bound if given."""
    from hystmpc.experiments.benches.dea import NOMINAL
    from hystmpc.models.fckp import Fckp
    from hystmpc.plants.dea import linear_model
    return InverseLinearMpc(
        linear_model(NOMINAL), InverseCompensation(Fckp(NOMINAL.fckp), **({"sensors": ("y",)} | compensation)),
        InputBounds(0.0, NOMINAL.fckp.u_max, rate), LinearMpcSettings(horizon=15, q_output=1e4, r_rate=0.03, qp=qp),
        process_noise=[1e-10, 1e-4, 1e-6], measurement_noise=[1e-6], initial_state=lambda z: np.array([z[0], 0.0]),
        initial_covariance=[1e-6, 1e-4, 1e-2])


def _planned(planner: InverseLinearMpc, rate: float, samples: int = 120, failing: tuple[int, ...] = (),
             lost: tuple[int, ...] = ()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each sample's planned inputs, virtual plan and first virtual input, on a fixed measured sine and
    fixed inputs sent.

    At the samples ``failing`` a NaN reference makes the QP fail (the fallback's samples); at the
    samples ``lost`` a NaN measurement makes the filter start again.
    """
    planner.reset()
    t = 0.01 * np.arange(samples + 16)
    refs, measured = 1.0 + 0.3 * np.sin(3 * t), 1.0 + 0.28 * np.sin(3 * t - 0.2)
    measured[list(lost)] = np.nan
    first = []
    solve = planner._solve
    planner._solve = lambda *args: first.append(solve(*args)) or first[-1]
    sent = np.clip(np.cumsum(np.clip(np.diff(3.0 + 2.0 * np.sin(3 * t), prepend=0.0), -rate, rate)), 0.0, 10.0)
    plans, virtual = [], []
    for k in range(samples):
        window = refs[k: k + 16].copy()
        window[-1] = np.nan if k in failing else window[-1]
        plans.append(planner.plan(Measurement(t=t[k], y=measured[k], sensors={}, truth={}), window))
        virtual.append(planner._plan if planner._plan is not None else np.full(planner.horizon, np.nan))
        planner.applied(float(sent[k]))
    del planner._solve
    return np.array(plans), np.array(virtual), np.array(first)


@pytest.mark.parametrize("rate", [np.inf, 0.05])
def test_the_generated_planners_functions_repeat_its_numpy_sample(rate):
    """``lmpc.qp=ipm`` runs the Functions a generated NMPC embeds (filter, bounds, the QP with the
    rate rows, fallback, inverse chain); the NumPy sample with the same QP gives the same plans,
    and OSQP nearly the same."""
    generated = _dea_planner("ipm", rate)
    assert generated.functions is not None and generated.stats()["name"] == "ipm"
    numpy_sample = _dea_planner("ipm", rate)
    numpy_sample.functions = None  # its NumPy code with the interior-point QP
    osqp = _dea_planner("osqp", rate)
    plans, virtual, _ = _planned(generated, rate)
    assert np.ptp(virtual[:, 0]) > 0.1 and generated.failures == 0  # the plans moved, every QP solved
    assert np.max(np.abs(plans - _planned(numpy_sample, rate)[0])) <= 1e-8
    # failed QPs: the last plan's next virtual input instead, and after two in a row the present virtual input
    # held (its inverse is not unique in a flat part of the loop: round-off picks the input there, so the
    # virtual inputs are compared); a NaN measurement: the filter starts again from the sensors
    failing, lost = (60, 61, 90), (100,)
    plans, _, first = _planned(generated, rate, failing=failing, lost=lost)
    assert generated.failures == 4 and np.all(np.isfinite(plans))  # the NaN sample fails its QP too
    numpy_plans, _, numpy_first = _planned(numpy_sample, rate, failing=failing, lost=lost)
    assert np.max(np.abs(first - numpy_first)) <= 1e-10  # mm; round-off in the QP reaches ~1e-12
    assert np.max(np.abs(np.delete(plans - numpy_plans, 61, axis=0))) <= 1e-8
    # the same QP's solution to OSQP's accuracy (eps 1e-7 relative to a gradient of ~1e4): the first virtual
    # input, which is sent, to 1e-4 mm; the plan's tail, weakly determined at r_rate 0.03, to 1e-2 mm
    other = _planned(osqp, rate)[1]
    assert np.max(np.abs(virtual[:, 0] - other[:, 0])) <= 1e-4 and np.max(np.abs(virtual - other)) <= 1e-2


def test_a_linear_mpc_qp_must_be_known():
    with pytest.raises(ValueError, match="qp 'daqp' is unknown; allowed: osqp, ipm"):
        LinearMpcSettings(qp="daqp")


def test_a_planner_without_a_casadi_form_runs_in_numpy_and_says_why_it_cannot_be_generated():
    from hystmpc.mpc.embedded_planner import PlannerExpressions, PlannerFunctions
    from hystmpc.mpc.expressions import NotGeneratable
    with pytest.raises(ValueError, match="sensors must be a function .* or a sequence of measured signals' names "
                                         "such as \\('y',\\); got 'y'"):
        _dea_planner("ipm", sensors="y")
    with pytest.raises(ValueError, match="the compensation reads 2 signals \\(y, y\\); the linear model has 1 sensors"):
        _dea_planner("ipm", sensors=("y", "y"))
    with pytest.raises(NotGeneratable, match="plans over 15 samples and the NMPC over 10: give both the same horizon; "
                                             "or set nmpc.inverse_plan=static"):
        PlannerExpressions(_dea_planner("ipm"), ("y",), 10)
    computed = _dea_planner("ipm", sensors=lambda m, comp: [m.y])
    driven = _dea_planner("ipm", driven_by=lambda m: m.sensors["voltage"])
    for planner, reason in ((computed, "computes its sensors with a function; give it the measured signals' names"),
                            (driven, "cannot be generated: .* memory follows a measured signal, not the inputs sent"),
                            (_dea_planner("osqp"), "lmpc.qp is 'osqp': set lmpc.qp=ipm")):
        assert planner.functions is None
        with pytest.raises(NotGeneratable, match=reason):
            PlannerFunctions(planner)
    generated = _dea_planner("ipm")
    assert np.max(np.abs(_planned(computed, np.inf)[0] - _planned(generated, np.inf)[0])) <= 1e-8
