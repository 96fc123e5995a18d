"""Real time: RTI step, code-generated C solver round trip, CLI; full set and do-mpc twin (slow)."""

import json
import shutil

import numpy as np
import pytest

from hystmpc.experiments import runner
from hystmpc.experiments.benches import get_bench
from hystmpc.experiments.cli import main
from hystmpc.experiments.cli import run as run_module
from hystmpc.experiments.firmware import MICROCONTROLLER_SENSITIVITY_BLOCK
from hystmpc.experiments.realtime import codegen
from hystmpc.mpc.settings import NmpcSettings
from hystmpc.plants.base import Measurement


@pytest.mark.slow  # the whole-scenario check of every bench below covers it; kept for a quick local look
def test_codegen_round_trip_on_compliant(tmp_path):
    """The compiled RTI step and the in-process one give the same inputs in closed loop, and
    the standalone C program reproduces the in-process step."""
    bench = get_bench("compliant")
    report = codegen(bench, bench.configure(), tmp_path / "c", verify=True, duration=0.5)
    assert {"rti_step.c", "rti_step.h", "main.c", "Makefile", "librti_step.so", "rti_main"} <= set(report["files"])
    assert report["samples"] == 50
    assert report["max_input_difference"] <= 1e-8
    assert report["standalone"]["max_output_difference_first_200"] <= 1e-8
    assert report["standalone"]["median_us"] > 0


def test_codegen_and_speed_reject_what_they_cannot_do(capsys, tmp_path):
    assert main(["codegen", "compliant", "--solver", "ipopt", "--out", str(tmp_path)]) == 2
    assert "cannot be code-generated yet; allowed: rti" in capsys.readouterr().err
    assert main(["codegen", "dea", "--solver", "sqp", "--out", str(tmp_path)]) == 2
    assert "allowed: rti" in capsys.readouterr().err
    assert main(["speed", "pam", "--variants", "ipopt,fast"]) == 2
    assert "unknown solver variant 'fast'" in capsys.readouterr().err
    assert main(["speed", "pam", "--duration", "-1"]) == 2
    assert main(["speed", "pam", "--variants", "gn", "--duration", "0.1"]) == 2
    assert "'gn' is only available for single-shooting problems" in capsys.readouterr().err
    assert main(["speed", "pam", "--set", "solver.rti.iterations=0"]) == 2
    assert "iterations must be >= 1, got 0" in capsys.readouterr().err


def test_rti_stays_close_to_ipopt_on_a_short_run():
    bench = get_bench("compliant")
    scenario = bench.scenarios["sine-1"]
    rmse = {s: bench.run(scenario, "nmpc", bench.configure([f"nmpc.solver={s}"]),
                        duration=3.0).metrics["rmse"] for s in ("ipopt", "rti")}
    assert rmse["rti"] <= 1.1 * rmse["ipopt"], rmse


@pytest.mark.slow
@pytest.mark.parametrize("bench_name", ["pam", "compliant", "reluctance", "dea"])
def test_codegen_verify_over_the_whole_default_scenario(tmp_path, bench_name):
    out = tmp_path / "report.json"
    assert main(["codegen", bench_name, "--verify", "--out", str(tmp_path / "c"), "--json", str(out), "--quiet"]) == 0
    report = json.loads(out.read_text())
    assert report["max_input_difference"] <= 1e-8
    assert report["standalone"]["max_output_difference_first_200"] <= 1e-8
    controller = report["controller"]
    # the whole controller in C driving the Python plant, and the example loop on the recorded sensors
    verify = controller["verify"]
    assert verify["max_input_difference"] <= 1e-9
    assert verify["example_loop"]["max_input_difference"] <= 1e-9
    if bench_name in ("pam", "reluctance"):  # DAQP: the firmware's build (its sources, the static arena)
        assert verify["example_loop"]["static_qp"] == "DAQP 0.5.1 sources"
        assert verify["example_loop"]["static_qp_max_input_difference"] <= 1e-9
    assert verify["failures"]["c"] == verify["failures"]["python"]
    if bench_name == "dea":  # its second start: the linear MPC's plan, generated too
        assert verify["planner_failures"]["c"] == verify["planner_failures"]["python"]
        assert controller["generated_with"] == ["memory.window=200", "lmpc.qp=ipm"]
    name = controller["name"]
    assert {f"{name}.h", f"{name}.c", f"{name}_nmpc.c", "main.c", "Makefile", f"lib{name}.so",
            f"{name}_main"} <= set(controller["files"])
    header = (tmp_path / "c" / "controller" / f"{name}.h").read_text()
    documented = {"pam": ("#define PAM_NZ 2", "y, the measured angle (deg)", "pressure (bar", "to send (bar)"),
                  "compliant": ("#define COMPLIANT_NZ 2", "angle (rad", "y, the measured torque (N m)"),
                  "reluctance": ("#define RELUCTANCE_NZ 0", "none (NULL is fine)", "the exact hysteresis memory"),
                  "dea": ("#define DEA_NZ 1", "displacement (mm)", "to send (V)")}
    for text in (f"int {name}_step(", f"void {name}_prepare(", f"void {name}_init(", *documented[bench_name]):
        assert text in header


@pytest.mark.slow
@pytest.mark.parametrize("bench_name", ["pam", "compliant", "reluctance", "dea"])
def test_the_whole_controller_fits_a_cortex_m7(tmp_path, bench_name):
    """Flash (text + data) within 256 KiB and RAM (bss) within 64 KiB at the bench's defaults
    (.ci/run installs the cross compiler; DAQP's C sources come from PyPI where the step uses it)."""
    if shutil.which("arm-none-eabi-gcc") is None:
        pytest.skip("arm-none-eabi-gcc is not installed (Debian: gcc-arm-none-eabi)")
    out = tmp_path / "report.json"
    assert main(["codegen", bench_name, "--target", "cortex-m7", "--out", str(tmp_path / "c"), "--json", str(out),
                 "--quiet"]) == 0
    m7 = json.loads(out.read_text())["controller"]["cortex-m7"]
    assert m7["text"] > 50_000  # the controller was linked in, not dropped as unused
    assert m7["text"] + m7["data"] <= 256 * 1024, m7
    assert not m7["heap"]  # no malloc linked: DAQP allocates from the controller's static arena
    assert m7["bss"] <= 64 * 1024, m7
    report = json.loads(out.read_text())["controller"]
    assert MICROCONTROLLER_SENSITIVITY_BLOCK == 7  # pam needs 65,584 B with 5 (three learned model errors)
    assert report["sensitivity_block"] == (0 if bench_name == "dea" else 7)  # dea: single shooting, nothing to pad


@pytest.mark.slow
def test_a_microcontroller_build_keeps_the_exact_widths_when_told(tmp_path):
    """``--set solver.rti.sensitivity_block=0`` is obeyed: pam's fastest step, the straight-line
    condensing, over 256 KiB of flash."""
    if shutil.which("arm-none-eabi-gcc") is None:
        pytest.skip("arm-none-eabi-gcc is not installed (Debian: gcc-arm-none-eabi)")
    out = tmp_path / "report.json"
    assert main(["codegen", "pam", "--target", "cortex-m7", "--out", str(tmp_path / "c"), "--json", str(out),
                 "--quiet", "--set", "solver.rti.sensitivity_block=0"]) == 0
    report = json.loads(out.read_text())["controller"]
    assert report["sensitivity_block"] == 0
    size = report["cortex-m7"]
    assert size["text"] + size["data"] > 256 * 1024  # why a microcontroller build pads by default


@pytest.mark.slow
def test_codegen_verify_needs_no_network_and_a_wrong_daqp_folder_is_an_error(tmp_path, monkeypatch, capsys):
    """Without DAQP's sources (offline, none cached) the static-arena check links CasADi's DAQP
    library with its allocator renamed, and gives the same inputs; a wrong
    ``HYSTMPC_DAQP_SOURCES`` is exit 2 naming it, not a quiet fallback."""
    from hystmpc.mpc.codegen import firmware

    def offline():
        raise firmware.DaqpSourcesMissing("no network (test)")

    monkeypatch.setattr(firmware, "daqp_sources", offline)
    out = tmp_path / "report.json"
    assert main(["codegen", "pam", "--verify", "--duration", "0.5", "--out", str(tmp_path / "c"), "--json",
                 str(out), "--quiet"]) == 0
    loop = json.loads(out.read_text())["controller"]["verify"]["example_loop"]
    assert loop["static_qp"] == "CasADi's DAQP library"
    assert loop["static_qp_max_input_difference"] <= 1e-9
    monkeypatch.undo()
    monkeypatch.setenv("HYSTMPC_DAQP_SOURCES", str(tmp_path / "nowhere"))
    capsys.readouterr()
    assert main(["codegen", "pam", "--verify", "--duration", "0.5", "--out", str(tmp_path / "d"), "--quiet"]) == 2
    assert "HYSTMPC_DAQP_SOURCES=" in capsys.readouterr().err


def test_the_generated_configuration_says_what_it_changes():
    dea = get_bench("dea")
    config = dea.configure()
    generated = dea.generated_config(config)
    assert generated["memory"].window == 200 and generated["lmpc"].qp == "ipm"  # C's creep window, C's QP
    assert config["memory"].window == 0 and config["lmpc"].qp == "osqp"  # the user's, unchanged
    assert dea.generated_changes(config) == ("memory.window=200", "lmpc.qp=ipm")
    assert dea.generated_changes(dea.configure(["memory.window=50", "nmpc.inverse_plan=static"])) == ()
    pam = get_bench("pam")
    assert pam.generated_changes(pam.configure()) == ()


def test_codegen_refuses_an_unknown_target_and_a_target_without_a_controller(tmp_path, capsys):
    assert main(["codegen", "pam", "--target", "avr", "--out", str(tmp_path / "a")]) == 2
    assert "--target 'avr' is unknown; allowed: cortex-m7" in capsys.readouterr().err
    assert main(["codegen", "reluctance", "--target", "cortex-m7", "--out", str(tmp_path / "b"),
                 "--set", "nmpc.inverse_plan=linear-mpc"]) == 2  # a planner whose inverse has no CasADi form
    err = capsys.readouterr().err
    assert "--target cortex-m7 builds the whole controller, which cannot be generated: the linear MPC's" in err
    assert main(["codegen", "pam", "--target", "cortex-m7", "--out", str(tmp_path / "c"),
                 "--set", "solver.rti.qp_iterations=20"]) == 2  # a setting the step would not use
    assert "solver.rti.qp_iterations=20 applies to solver.rti.qp=ipm only" in capsys.readouterr().err


@pytest.mark.slow
def test_do_mpc_solves_the_same_problem():
    pytest.importorskip("do_mpc")
    from hystmpc.experiments.peer import compare_with_do_mpc
    result = compare_with_do_mpc("pam", samples=3, duration=3.0)
    for case in result["cases"]:
        assert case["relative_difference"] <= 1e-4, case


def test_rti_step_lengths_take_the_best_of_the_shortened_steps():
    """An overshooting Gauss–Newton step (r = w³ − 1 from w = 0.1) is cut back to the best trial."""
    import casadi as ca

    from hystmpc.mpc.rti import rti_function
    w, p = ca.SX.sym("w"), ca.SX.sym("p")
    residual = ca.Function("r", [w, p], [w**3 - 1])
    constraints = ca.Function("g", [w, p], [ca.SX(0, 1)])
    full = rti_function(residual, constraints, [], [], [-10.0], [10.0])
    searched = rti_function(residual, constraints, [], [], [-10.0], [10.0], step_lengths=(0.5, 0.25, 0.125))
    assert float(full(0.1, 0)[0]) == pytest.approx(10.0)  # the QP step, clipped at the bound
    assert float(searched(0.1, 0)[0]) == pytest.approx(0.1 + 0.125 * 9.9)  # lowest cost of 10, 5.05, 2.575, 1.3375


def test_descent_line_search_takes_a_full_step_that_lowers_the_cost():
    """``line_search='descent'`` keeps a full step that lowers the cost, where ``best`` takes
    a shorter one that lowers it more; a full step that raises the cost is cut back as by ``best``."""
    import casadi as ca

    from hystmpc.mpc.rti import rti_function
    w, p = ca.SX.sym("w"), ca.SX.sym("p")
    residual = ca.Function("r", [w, p], [w**3 - 1])
    constraints = ca.Function("g", [w, p], [ca.SX(0, 1)])
    steps = {mode: rti_function(residual, constraints, [], [], [-10.0], [10.0], step_lengths=(0.5, 0.25, 0.125),
                                line_search=mode) for mode in ("best", "descent")}
    gn_step = (1 - 0.7**3) / (3 * 0.7**2)  # from 0.7: cost 0.432 → 0.259 at the full step, 0.045 at half of it
    assert float(steps["descent"](0.7, 0)[0]) == pytest.approx(0.7 + gn_step)
    assert float(steps["best"](0.7, 0)[0]) == pytest.approx(0.7 + 0.5 * gn_step)
    for mode in ("best", "descent"):  # from 0.1 the full step (to the bound, 10) raises the cost
        assert float(steps[mode](0.1, 0)[0]) == pytest.approx(0.1 + 0.125 * 9.9)
    # a full step whose cost is NaN (sqrt of a negative w) loses to any finite trial
    root = ca.Function("r", [w, p], [ca.sqrt(w) - p])
    for mode in ("best", "descent"):
        step = rti_function(root, constraints, [], [], [-10.0], [10.0], step_lengths=(0.5, 0.25, 0.125),
                            line_search=mode)
        assert float(step(1.0, 0)[0]) == pytest.approx(0.0, abs=1e-6)  # the full step goes to -1, its half to 0
    with pytest.raises(ValueError, match="line_search 'newton' is unknown; allowed: best, descent"):
        rti_function(residual, constraints, [], [], [-10.0], [10.0], step_lengths=(0.5,), line_search="newton")


@pytest.mark.parametrize("condensed, qp", [(True, "daqp"), (True, "ipm"), (False, "daqp")])
def test_repeated_rti_steps_reach_the_converged_solution_or_say_they_failed(condensed, qp):
    """Iterated, the condensed RTI step (inputs only, DAQP or the interior-point QP) solves the
    same problem as IPOPT (a smooth two-state model with active rate bounds). The
    multiple-shooting step's qrqp gets this QP wrong, and the step reports it instead of
    passing it on."""
    import casadi as ca
    import numpy as np

    from hystmpc.models import PredictionModel
    from hystmpc.mpc import InputBounds, MultipleShootingProblem, NlpSettings, NmpcSettings, RtiSettings, SolverSettings
    x, u, d = ca.SX.sym("x", 2), ca.SX.sym("u"), ca.SX.sym("d")
    x_next = ca.vertcat(0.8 * x[0] + 0.2 * x[1], 0.7 * x[1] + 0.3 * ca.tanh(u))
    model = PredictionModel(step=ca.Function("f", [x, u, d], [x_next]),
                            output=ca.Function("y", [x, d], [x[0] + d]),
                            measure=ca.Function("z", [x, d], [x[0] + d]), sample_period=0.01,
                            state_names=("a", "b"))
    common = {"horizon": 8, "q_output": 100.0, "r_rate": 0.1}
    bounds = InputBounds(-2.0, 2.0, 0.15)
    ipopt = MultipleShootingProblem(model, NmpcSettings(solver="ipopt", **common), bounds,
                                    SolverSettings(ipopt=NlpSettings(tol=1e-12, max_iter=500)))
    rti = MultipleShootingProblem(model, NmpcSettings(solver="rti", **common), bounds,
                                  SolverSettings(rti=RtiSettings(condensed=condensed, iterations=30, qp=qp)))
    assert rti.condensed == condensed
    x0, dist = np.array([0.1, -0.2]), np.array([0.05])
    ref = 0.25 * np.sin(np.linspace(0.3, 2.0, 8))
    reference = ipopt.solve(np.concatenate((x0, dist)), 0.0, ref, np.zeros(8))
    assert reference.success
    assert np.any(np.isclose(np.abs(np.diff(np.r_[0.0, reference.u_plan[:, 0]])), 0.15))  # a rate bound binds
    result = rti.solve(np.concatenate((x0, dist)), 0.0, ref, np.zeros(8))
    if not condensed:
        assert not result.success and result.status == "RTI_QP_Failed"
        return
    assert result.success
    assert np.max(np.abs(result.u_plan - reference.u_plan)) < 1e-6
    assert np.max(np.abs(result.x_plan - reference.x_plan)) < 1e-6


def test_condensed_rti_step_without_a_rate_bound():
    """An unbounded rate leaves only the input bounds in the QP."""
    import casadi as ca
    import numpy as np

    from hystmpc.models import PredictionModel
    from hystmpc.mpc import InputBounds, MultipleShootingProblem, NmpcSettings, RtiSettings, SolverSettings
    x, u, d = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("d")
    model = PredictionModel(step=ca.Function("f", [x, u, d], [0.5 * x + 0.5 * u]),
                            output=ca.Function("y", [x, d], [x]), measure=ca.Function("z", [x, d], [x]),
                            sample_period=0.01, state_names=("x",))
    rti = MultipleShootingProblem(model, NmpcSettings(horizon=4, solver="rti", r_rate=0.0), InputBounds(-1.0, 1.0),
                                  SolverSettings(rti=RtiSettings(iterations=3)))
    result = rti.solve(np.zeros(2), 0.0, np.full(4, 2.0), np.zeros(4))
    assert result.success
    assert result.u_plan.ravel() == pytest.approx(np.ones(4), abs=1e-6)  # the target is out of reach: u at its bound


def test_the_straight_line_condensing_is_the_product_of_the_propagated_sensitivities():
    """``condensing_function`` gives JᵀJ and Jᵀe of J built row by row from S_k = [A_k S_{k−1}, B_k]
    with dense products, on random matrices with structural zeros (which it skips)."""
    import casadi as ca

    from hystmpc.mpc.multiple_shooting import condensing_function
    rng = np.random.default_rng(3)
    N, nx = 6, 4
    pattern = rng.random((nx, nx)) < 0.6
    A_sparsity = ca.DM(pattern.astype(float)).sparsity()
    B_sparsity, C_sparsity = ca.Sparsity.dense(nx, 1), ca.Sparsity.triplet(1, nx, [0, 0], [0, 2])
    As = [np.where(pattern, rng.normal(size=(nx, nx)), 0.0) for _ in range(N)]
    Bs = [rng.normal(size=(nx, 1)) for _ in range(N)]
    Cs = [np.array([[rng.normal(), 0.0, rng.normal(), 0.0]]) for _ in range(N)]
    e = rng.normal(size=N)
    J, S = np.zeros((N, N)), None
    for k in range(N):
        S = Bs[k] if S is None else np.hstack((As[k] @ S, Bs[k]))
        J[k, : k + 1] = (Cs[k] @ S).ravel()
    condense = condensing_function(A_sparsity, B_sparsity, C_sparsity, N)
    inputs = []
    for A, B, C in zip(As, Bs, Cs, strict=True):
        inputs += [ca.project(ca.DM(A), A_sparsity), ca.DM(B), ca.project(ca.DM(C), C_sparsity)]
    JtJ, Jte = condense(*inputs, e)
    assert np.asarray(JtJ) == pytest.approx(J.T @ J, rel=1e-12, abs=1e-12)
    assert np.asarray(Jte).ravel() == pytest.approx(J.T @ e, rel=1e-12, abs=1e-12)
    assert np.abs(J.T @ J).max() > 0.1


def test_condensed_rti_plan_keeps_the_rate_bound_from_an_infeasible_guess():
    """A guess that jumps (an inverse model after a reference step) is made rate-feasible
    before the step, so the backtracking's shortened steps keep the rate bound too."""
    import casadi as ca
    import numpy as np

    from hystmpc.models import PredictionModel
    from hystmpc.mpc import InputBounds, MultipleShootingProblem, NmpcSettings
    x, u, d = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("d")
    model = PredictionModel(step=ca.Function("f", [x, u, d], [0.6 * x + 0.4 * ca.sinh(2 * u)]),
                            output=ca.Function("y", [x, d], [x]), measure=ca.Function("z", [x, d], [x]),
                            sample_period=0.01, state_names=("x",))
    rti = MultipleShootingProblem(model, NmpcSettings(horizon=6, solver="rti", r_rate=0.01),
                                  InputBounds(-2.0, 2.0, 0.1))
    rng = np.random.default_rng(4)
    for _ in range(40):
        guess = rng.uniform(-2.0, 2.0, 6)
        result = rti.solve(np.concatenate((rng.normal(size=1), np.zeros(1))), 0.0, rng.uniform(-3, 3, 6), guess)
        rates = np.diff(np.r_[0.0, result.u_plan[:, 0]])
        assert result.success
        assert np.max(np.abs(rates)) <= 0.1 + 1e-7


def test_a_microcontroller_build_pads_the_sensitivities_unless_told_otherwise():
    from hystmpc.experiments.firmware import MICROCONTROLLER_SENSITIVITY_BLOCK, firmware_config
    pam, dea = get_bench("pam"), get_bench("dea")
    padded = firmware_config(pam, pam.configure())
    assert padded["solver"].rti.sensitivity_block == MICROCONTROLLER_SENSITIVITY_BLOCK
    assert firmware_config(pam, pam.configure(["solver.rti.sensitivity_block=3"]))["solver"].rti.sensitivity_block == 3
    assert firmware_config(dea, dea.configure())["solver"].rti.sensitivity_block == 0  # single shooting


@pytest.mark.slow  # 6 s: builds pam's whole controller in a fresh cache (CI runs it)
def test_runtime_c_runs_the_generated_controller_with_the_python_controllers_inputs(tmp_path, monkeypatch):
    """``nmpc.runtime=c``: the whole generated controller in the loop, built once and cached
    (a damaged cache entry is built again); the same inputs as the Python controller to the
    last bit, its failures counted."""
    import numpy as np

    from hystmpc.experiments.benches import get_bench
    from hystmpc.mpc.codegen import c_compiler
    if c_compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv("HYSTMPC_CACHE", str(tmp_path))
    bench = get_bench("pam")
    python = bench.run("square-20", "nmpc", duration=2.0)
    config = bench.configure(["nmpc.runtime=c"])
    generated = bench.run("square-20", "nmpc", config, duration=2.0)
    assert np.array_equal(python.input, generated.input)
    assert np.array_equal(python.predicted, generated.predicted)  # the model's one-step prediction, as well
    assert generated.solver["name"] == "generated C" and generated.solver["fallbacks"] == 0
    again = bench.build_controller("nmpc", config)  # from the cache: a second instance runs as well
    assert np.array_equal(bench.run("square-20", "nmpc", config, duration=2.0,
                                    prepared=bench.prepare("square-20", "nmpc", config)).input, python.input)
    assert type(again).__name__ == "CompiledController"
    [entry] = (tmp_path / "controllers").iterdir()
    (entry / "libcontroller.so").unlink()  # as the cached Makefile's 'clean' would
    assert np.array_equal(bench.run("square-20", "nmpc", config, duration=2.0).input, python.input)
    assert (entry / "libcontroller.so").exists() and not list((tmp_path / "controllers").glob("building-*"))


def test_runtime_auto_runs_python_without_a_compiler_where_runtime_c_is_refused(tmp_path, monkeypatch, caplog):
    from hystmpc.mpc import runtime
    monkeypatch.setattr(runtime, "_SAID", set())  # each notice is said once per process
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    bench = get_bench("reluctance")
    with caplog.at_level("WARNING", logger="hystmpc"):
        fallback = bench.build_controller("nmpc", bench.configure(tuned=False))
    assert bench.configure(tuned=False)["nmpc"].runtime == "auto"
    assert type(fallback).__name__ == "NmpcController"
    assert "nmpc.runtime=auto runs the controller in Python" in caplog.text
    with pytest.raises(ValueError, match="nmpc.runtime=c needs a C compiler"):
        bench.build_controller("nmpc", bench.configure(["nmpc.runtime=c"], tuned=False))


@pytest.mark.slow  # 30 s: builds reluctance's and dea's generated controllers into an empty cache
def test_runtime_auto_runs_the_generated_controller_where_it_can(tmp_path, monkeypatch, caplog):
    """``nmpc.runtime=auto`` (reluctance's default): the generated controller with an RTI
    solver and a C compiler; the Python controller with another solver, and without a
    compiler after a notice, where ``runtime=c`` is refused (the last two also in
    :func:`test_runtime_auto_runs_python_without_a_compiler_where_runtime_c_is_refused`)."""
    from hystmpc.mpc import runtime
    from hystmpc.mpc.codegen import c_compiler
    if c_compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv("HYSTMPC_CACHE", str(tmp_path))
    monkeypatch.setattr(runtime, "_SAID", set())  # each notice is said once per process
    bench = get_bench("reluctance")
    assert bench.configure()["nmpc"].runtime == "auto"
    assert type(bench.build_controller("nmpc", bench.configure())).__name__ == "CompiledController"
    assert type(bench.build_controller("nmpc", bench.configure(["nmpc.solver=sqp"]))).__name__ == "NmpcController"
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    with caplog.at_level("WARNING", logger="hystmpc"):
        fallback = bench.build_controller("nmpc", bench.configure())
    assert type(fallback).__name__ == "NmpcController"
    assert "nmpc.runtime=auto runs the controller in Python" in caplog.text
    with pytest.raises(ValueError, match="nmpc.runtime=c needs a C compiler"):
        bench.build_controller("nmpc", bench.configure(["nmpc.runtime=c"]))
    monkeypatch.delenv("CC")
    dea = get_bench("dea")  # the full creep memory: generated with a window, the linear MPC's plan included
    with caplog.at_level("WARNING", logger="hystmpc"):
        generated = dea.build_controller("nmpc", dea.configure(["nmpc.runtime=auto", "nmpc.solver=rti-c"]))
    assert type(generated).__name__ == "CompiledController"
    assert "the generated controller is built with memory.window=200, lmpc.qp=ipm" in caplog.text
    runtime._SAID.clear()  # said once per process
    caplog.clear()
    with caplog.at_level("WARNING", logger="hystmpc"):  # a planner whose inverse has no CasADi form: in Python
        planned = bench.build_controller("nmpc", bench.configure(["nmpc.inverse_plan=linear-mpc"]))
    assert type(planned).__name__ == "NmpcController" and planned.planner.settings.qp == "osqp"  # the user's
    assert "the linear MPC's compensation (InverseCompensation) does not accept CasADi expressions" in caplog.text
    assert "nmpc.runtime=auto runs the controller in Python" in caplog.text


def test_speed_keeps_two_starts_only_for_the_solvers_that_report_a_cost():
    """dea solves from two starts; ``speed`` times IPOPT and sqp with one (they report no
    cost to compare) and labels the rows that have two."""
    from hystmpc.experiments.realtime import _rti_config, speed_table
    bench = get_bench("dea")
    config = bench.configure()
    assert config["nmpc"].multistart
    starts = {v: _rti_config(bench, config, v)["nmpc"].multistart for v in ("gn", "rti", "rti-c", "ipopt", "sqp")}
    assert starts == {"gn": True, "rti": True, "rti-c": True, "ipopt": False, "sqp": False}
    row = {"rmse": 1e-3, "step_ms_median": 1.0, "step_ms_p95": 2.0, "step_ms_max": 3.0, "solve_ms_median": 1.0,
           "solve_ms_p95": 2.0, "solve_ms_max": 3.0, "failures": 0}
    table = speed_table({"bench": "dea", "scenario": "single-sine", "sample_period_ms": 10.0,
                         "variants": [{"variant": "gn", "multistart": True, **row},
                                      {"variant": "ipopt", "multistart": False, **row}]})
    assert "| gn, two starts |" in table and "| ipopt |" in table


def test_a_slow_run_is_announced_with_its_expected_time_after_its_first_steps(caplog, monkeypatch):
    notice = runner._slow_run_notice
    assert notice([0.02] * 5, 1000, 1e-3) == ("20 ms per step (median of steps 2–6), 20 × the 1 ms period: the "
                                             "controller alone needs about 20 s for the remaining 1,000 samples")
    assert notice([0.02] * 5, 400, 1e-3) is None  # 8 s: not worth a line
    assert notice([0.009] * 5, 10 ** 6, 1e-3) is None  # 9 periods: not slow
    assert "about 2.8 h" in notice([0.01, 0.01, 5.0], 10 ** 6, 1e-3)  # the median, not the mean
    assert notice([], 10 ** 6, 1e-3) is None and notice([0.5, float("nan")], 10 ** 6, 1e-3) is None

    class Still:  # a plant that never moves
        sample_period = 1e-3

        def reset(self, seed):
            return Measurement(0.0, 0.0)

        def step(self, u):
            return Measurement(0.0, 0.0)

    class Idle:
        horizon = 0

        def reset(self):
            pass

        def step(self, measurement, ref_window):
            return 0.0

    class Clock:  # each read 15 ms after the last: every step takes 15 ms as the run measures it
        now = 0.0

        @classmethod
        def perf_counter(cls):
            cls.now += 0.015
            return cls.now

    monkeypatch.setattr(runner, "time", Clock)
    with caplog.at_level("INFO", logger="hystmpc"):
        runner.simulate(Still(), Idle(), np.zeros(2000), name="idle", scenario="flat")
        runner.simulate(Still(), Idle(), np.zeros(600))  # 9 s left: quiet
    assert [r.getMessage() for r in caplog.records] == [
        "slow run: flat · idle: 15 ms per step (median of steps 2–6), 15 × the 1 ms period: the controller alone "
        "needs about 30 s for the remaining 1,994 samples"]
    assert caplog.records[0].levelname == "INFO" and caplog.records[0].live  # a notice, written at once by workers


def _slow_clock(seconds_per_read: float):
    class Clock:  # each read ``seconds_per_read`` after the last: a step takes that long as the run measures it
        now = 0.0

        @classmethod
        def perf_counter(cls):
            cls.now += seconds_per_read
            return cls.now
    return Clock


def test_an_nmpc_run_late_at_p95_says_what_shortens_its_step(tmp_path, monkeypatch, capsys):
    args = ["run", "pam", "square-20", "--controller", "nmpc", "--duration", "0.5", "--no-plots"]
    monkeypatch.setattr(runner, "time", _slow_clock(0.05))  # 50 ms a step: 2.5 periods of pam's 20 ms
    assert main([*args, "--out", str(tmp_path / "late"), "--set", "nmpc.horizon=12"]) == 0
    err = capsys.readouterr().err
    assert "not real time on this machine: square-20 · nmpc: median 50 ms" in err
    assert ("nmpc: its p95 step is up to 250% of the period; a shorter nmpc.horizon (now 12) shortens it "
            "('hystmpc speed pam' with the same --set options times it alone)") in err
    monkeypatch.setattr(runner, "time", _slow_clock(0.005))  # 5 ms: in time, no hint
    assert main([*args, "--out", str(tmp_path / "in-time")]) == 0
    assert "nmpc:" not in capsys.readouterr().err
    assert "nmpc.solver=rti-c (now ipopt)" in run_module._shorter_step_hint(
        NmpcSettings(solver="ipopt"), "pam", [_late(1.3)])
    assert run_module._shorter_step_hint(NmpcSettings(multistart=True), "x.toml", [_late(1.3), _late(2.0)]) == (
        "nmpc: its p95 step is up to 200% of the period; a shorter nmpc.horizon (now 20), or a larger "
        "nmpc.second_start_error (now 0: the second start on fewer samples), or nmpc.multistart=false "
        "(one start per sample) shortens it ('hystmpc speed x.toml' with the same --set options times it alone)")


def _late(share: float):
    class Late:
        timing = {"p95_share_of_period": share}
    return Late()
