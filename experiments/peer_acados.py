"""An acados twin of a bench's RTI step, timed C against C with randomised placement.

Optional: needs the acados folder of the ``comma-deps-acados`` wheel (acados 0.2.2 with BLASFEO,
HPIPM and qpOASES; ``pip download --no-deps comma-deps-acados`` and unzip it). Used by
``python -m hystmpc.experiments.peer acados ACADOS_FOLDER [BENCH]`` and docs/realtime.md.

The twin is fair by construction:

- **The same OCP, encoded alike.** The state is augmented with the last input; stage ``k``
  costs ``q (y(x_k) − r_k)² + r_rate (u_k − u_{k−1})² + r_input (u_k − u_ff,k)²`` and the
  terminal stage ``q (y(x_N) − r_N)²``: the tracking term sits on the state, one model step per
  stage, as hystmpc's condensed step has it. hystmpc's regularisation of the inputs (and of
  nothing else) is folded into the input term, whose target moves to the weighted mean of
  ``u_ff,k`` and the linearisation point: the same QP, where acados' ``levenberg_marquardt``
  would regularise the states too.
- **The same problems, the same starts.** Every ``(w, p)`` hystmpc's step is called with in the
  bench's default scenario is recorded; acados starts from the same inputs and their rollout.
- **C against C, in one program.** hystmpc's generated step and acados' generated solver are
  linked into one replay program, built with the same compiler and flags; each solver's time
  is its own call, read with ``clock_gettime``. They take turns over blocks of the problems,
  in a random order per block, so that the machine's changes of speed (on a shared machine,
  up to 2 × for minutes) hit both, and each reads the problems from a warm cache as a
  standalone program would.
- **Placement randomised and repeated.** Each launch relinks the program with the two
  solvers' code in a random order, each after a random padding, and runs it under an
  environment of random size (which moves the stack), so that no one lucky or unlucky layout
  decides the ratio; the ratio is read per launch, and its median and range are reported.
  (acados' shared libraries stay where the loader puts them; DAQP's archive is linked with
  hystmpc's step.)
"""

from __future__ import annotations

import contextlib
import os
import shlex
import shutil
import subprocess
import sys
from importlib import resources
from pathlib import Path
from tempfile import TemporaryDirectory

import casadi as ca
import numpy as np

from hystmpc.mpc.rti import REGULARISATION

ACADOS_VARIANTS = (("FULL_CONDENSING_QPOASES", None), ("FULL_CONDENSING_HPIPM", "BALANCE"),
                   ("FULL_CONDENSING_HPIPM", "SPEED_ABS"), ("PARTIAL_CONDENSING_HPIPM", "SPEED_ABS"))
"""acados' QP solver and HPIPM mode per variant timed (acados' default HPIPM mode is BALANCE)."""

PADDING_BYTES = 4096
"""Largest padding before each solver's code, and largest environment added (bytes)."""

BLOCK = 50
"""Problems each solver replays in turn before the other takes over."""


def acados_rti_timing(acados_package, bench_name: str = "pam", variants=ACADOS_VARIANTS, launches: int = 8,
                      repeats: int = 3, seed: int = 0, work=None) -> dict:
    """Time the generated RTI step and acados' SQP_RTI on the same recorded problems.

    One program per acados variant holds both solvers; it replays the problems in blocks of
    :data:`BLOCK`, the two solvers taking turns in a random order per block, so that a change
    of the machine's speed hits both. Each launch relinks it with a new placement.

    Parameters
    ----------
    acados_package : path
        The ``acados`` folder of the unpacked ``comma-deps-acados`` wheel (``install/`` with the
        libraries, headers and ``t_renderer``; ``acados_template/``).
    bench_name : str, optional
        The bench: its NMPC must be a condensed multiple-shooting RTI step with a rate bound
        (pam, compliant, reluctance).
    variants : tuple of (str, str or None), optional
        acados' QP solver and HPIPM mode per variant (default :data:`ACADOS_VARIANTS`).
    launches : int, optional
        Launches of every program, each with its own placement.
    repeats : int, optional
        Passes over the recorded problems per launch.
    seed : int, optional
        Seed of the placements and of the launch order.
    work : path, optional
        Where the generated code goes (default: a temporary folder).

    Returns
    -------
    dict
        ``bench``, ``scenario``, ``problems``, ``launches``, ``repeats``, ``block``, ``seed``,
        ``ca_version``, ``compile_flags`` and ``variants``: per variant, its launches (both
        solvers' median and p95 in µs, the placement), the ratio of acados' median to hystmpc's
        per launch (``acados_over_hystmpc``) and their median and range, acados' failed solves,
        and how far its first inputs are from hystmpc's.
    """
    from hystmpc.experiments.realtime import write_solver
    from hystmpc.mpc.codegen import RecordingStep
    from hystmpc.mpc.codegen.toolchain import COMPILE_FLAGS, library_flags
    flags = [*COMPILE_FLAGS, "-std=c99"]  # both solvers' code alike; acados' headers need C99

    package = Path(acados_package).resolve()
    if not (package / "acados_template" / "acados_layout.json").is_file() or not (package / "install").is_dir():
        raise ValueError(f"{package} is not the acados folder of the comma-deps-acados wheel "
                         "(it needs acados_template/ and install/)")
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        raise RuntimeError("no C compiler (cc or gcc) on the PATH")
    bench, config, prepared = _rti_bench(bench_name)
    problem = prepared.controller.problem
    problem.rti = RecordingStep(problem.rti)
    bench.run(bench.default_scenario, "nmpc", prepared=prepared)
    calls = np.asarray(problem.rti.calls)
    N = problem.settings.horizon
    rng = np.random.default_rng(seed)
    with contextlib.ExitStack() as stack:
        work = Path(work) if work else Path(stack.enter_context(TemporaryDirectory()))
        ours = work / "hystmpc"
        write_solver(bench, config, ours)
        np.savetxt(work / "hystmpc_inputs.txt", calls, fmt="%.17g",
                   header=f"{N} {calls.shape[1] - N} {len(calls)}", comments="")
        _write_problems(problem, calls, work / "acados_inputs.txt")
        include, libraries = library_flags((ours / "rti_step.c").read_text())
        ours_objects = _compile(ours, compiler, flags, ["rti_step.c"], include)
        generate = _acados_generator(package, work / "acados", stack)
        programs = {}
        for number, (qp, mode) in enumerate(variants, start=1):
            name = f"twin_{number}"
            folder = work / name
            generate(_twin_ocp(problem, qp, mode, name, folder), folder)
            programs[_variant_label(qp, mode)] = _twin_program(folder, name, package, ours, ours_objects, libraries,
                                                               compiler, flags)
        launches_of = {label: [] for label in programs}
        outputs = {}
        for _ in range(launches):
            for label in rng.permutation(list(programs)):
                timing, outputs[label] = _launch(programs[label], work, compiler, repeats, rng)
                launches_of[label].append(timing)
    rows = []
    for qp, mode in variants:
        label = _variant_label(qp, mode)
        ours_first, status, theirs_first = outputs[label].T
        difference = np.abs(theirs_first - ours_first)
        ratio = np.array([t["acados_median_us"] / t["hystmpc_median_us"] for t in launches_of[label]])
        rows.append({"variant": label, "qp_solver": qp, "hpipm_mode": mode, "launches": launches_of[label],
                     "acados_over_hystmpc": ratio.tolist(), "ratio_median": float(np.median(ratio)),
                     "ratio_min": float(ratio.min()), "ratio_max": float(ratio.max()),
                     "failed_solves": int(np.count_nonzero(status)),
                     "first_input_difference_median": float(np.median(difference)),
                     "first_input_difference_max": float(difference.max())})
    return {"bench": bench_name, "scenario": bench.default_scenario, "problems": len(calls), "launches": launches,
            "repeats": repeats, "block": BLOCK, "seed": seed, "ca_version": ca.__version__,
            "compile_flags": flags, "variants": rows}


def _rti_bench(bench_name: str):
    """The bench, its configuration with the RTI step, and its default scenario's prepared NMPC."""
    from hystmpc.experiments.benches import get_bench
    from hystmpc.mpc.multiple_shooting import MultipleShootingProblem
    bench = get_bench(bench_name)
    config = bench.configure(["nmpc.solver=rti"])
    in_python = bench.configure(["nmpc.solver=rti", "nmpc.runtime=python"])  # records the step, not the C controller
    prepared = bench.prepare(bench.default_scenario, "nmpc", in_python)
    problem = prepared.controller.problem
    if not (isinstance(problem, MultipleShootingProblem) and problem.condensed and np.isfinite(problem.du_max)):
        raise ValueError(f"bench {bench_name!r}: the acados twin needs a condensed multiple-shooting NMPC with a "
                         "rate bound (pam, compliant, reluctance)")
    return bench, config, prepared


def _variant_label(qp: str, mode: str | None) -> str:
    return qp.lower().replace("_", " ") + (f" ({mode.lower().replace('_', ' ')})" if mode else "")


def twin_least_squares(problem) -> dict | None:
    """The twin's linear least-squares cost matrices, or None where it needs the nonlinear one.

    Residuals per stage: ``Vx [x; u_last] + Vu u − yref`` = ``(y(x) − r, u − u_last, u −
    target)``, weighted by ``W``; at the end ``Vx_e [x; u_last] − r`` weighted by ``W_e``.
    Linear where ``y`` is ``C x`` (no offset, no disturbance), as on pam, compliant and
    reluctance.

    Parameters
    ----------
    problem : MultipleShootingProblem
        The bench's condensed problem.

    Returns
    -------
    dict or None
        ``Vx``, ``Vu``, ``W``, ``Vx_e``, ``W_e`` (:func:`twin_weights`).
    """
    m = problem.model
    nx, nd = m.nx, m.nd
    x, d = ca.SX.sym("x", nx), ca.SX.sym("d", nd)
    y = m.output(x, d)
    at_zero = ca.substitute(y, x, ca.DM.zeros(nx))
    if not (ca.is_linear(y, x) and not ca.depends_on(y, d) and at_zero.is_zero()):
        return None
    output_row = np.asarray(ca.DM(ca.jacobian(y, x))).reshape(1, nx)
    return {"Vx": np.block([[output_row, np.zeros((1, 1))], [np.zeros((1, nx)), -np.ones((1, 1))],
                            [np.zeros((1, nx + 1))]]),
            "Vu": np.array([[0.0], [1.0], [1.0]]), "Vx_e": np.concatenate((output_row, np.zeros((1, 1))), axis=1),
            **twin_weights(problem.settings)}


def twin_weights(settings) -> dict:
    """``W`` (stage: output, rate, input with hystmpc's regularisation) and ``W_e`` (the last output).

    Parameters
    ----------
    settings : NmpcSettings
        The NMPC's weights.

    Returns
    -------
    dict
        ``W`` (3 × 3) and ``W_e`` (1 × 1).
    """
    return {"W": np.diag([settings.q_output, settings.r_rate, settings.r_input + REGULARISATION]),
            "W_e": np.array([[settings.q_output]])}


def _twin_ocp(problem, qp: str, mode: str | None, name: str, folder: Path):
    """The acados OCP of ``problem``: the cost on the states, inputs regularised as hystmpc's.

    The residuals are ``(y(x_k), u_k − u_{k−1}, u_k)`` with the references ``(r_k, 0, target_k)``
    per stage, ``y(x_N)`` at the end: linear least squares where :func:`twin_least_squares`
    gives them (acados then evaluates no cost function), nonlinear otherwise.
    """
    from acados_template import AcadosModel, AcadosOcp
    m, s = problem.model, problem.settings
    N, nx, nd = s.horizon, m.nx, m.nd
    x, u_last, u, d = ca.SX.sym("x", nx), ca.SX.sym("u_last"), ca.SX.sym("u"), ca.SX.sym("d", nd)
    y = m.output(x, d)
    model = AcadosModel()
    model.name = name
    model.x, model.u, model.p = ca.vertcat(x, u_last), u, d
    model.disc_dyn_expr = ca.vertcat(m.step(x, u, d), u)
    ocp = AcadosOcp()
    ocp.model = model
    ocp.dims.N = N
    ocp.solver_options.tf = float(N)  # steps of 1: acados weighs stage costs by the step, not the terminal one
    linear = twin_least_squares(problem)
    if linear is not None:
        ocp.cost.cost_type, ocp.cost.cost_type_e = "LINEAR_LS", "LINEAR_LS"
        ocp.cost.Vx, ocp.cost.Vu, ocp.cost.Vx_e = linear["Vx"], linear["Vu"], linear["Vx_e"]
    else:
        ocp.cost.cost_type, ocp.cost.cost_type_e = "NONLINEAR_LS", "NONLINEAR_LS"
        model.cost_y_expr, model.cost_y_expr_e = ca.vertcat(y, u - u_last, u), y
    weights = twin_weights(s)
    ocp.cost.W, ocp.cost.yref = weights["W"], np.zeros(3)
    ocp.cost.W_e, ocp.cost.yref_e = weights["W_e"], np.zeros(1)
    ocp.constraints.idxbu = np.array([0])
    ocp.constraints.lbu, ocp.constraints.ubu = np.array([problem.u_min]), np.array([problem.u_max])
    ocp.constraints.C = np.concatenate((np.zeros((1, nx)), [[-1.0]]), axis=1)
    ocp.constraints.D = np.array([[1.0]])
    ocp.constraints.lg, ocp.constraints.ug = np.array([-problem.du_max]), np.array([problem.du_max])
    ocp.constraints.x0 = np.zeros(nx + 1)
    ocp.parameter_values = np.zeros(nd)
    options = ocp.solver_options
    options.integrator_type, options.nlp_solver_type, options.hessian_approx = "DISCRETE", "SQP_RTI", "GAUSS_NEWTON"
    options.qp_solver, options.levenberg_marquardt = qp, 0.0
    if mode:
        options.hpipm_mode = mode
    ocp.code_export_directory = str(folder)
    return ocp


def _write_problems(problem, calls: np.ndarray, path: Path) -> None:
    """The recorded calls as the replay program's problems (the layout is in templates/twin_replay.c)."""
    m, s = problem.model, problem.settings
    N, nx, nd = s.horizon, m.nx, m.nd
    layout = problem.parameter_layout()
    rows = []
    for call in calls:
        w0, p = call[:N], call[N:]
        condition, u_prev = p[layout["condition"]], float(p[layout["u_prev"]][0])
        x0, d = condition[:nx], condition[nx:]
        refs, u_ff = p[layout["ref"]], p[layout["u_ff"]]
        lasts = np.concatenate(([u_prev], w0))
        states = np.column_stack((np.asarray(problem.rollout(w0, p)), lasts))
        # r_input (u - u_ff)² + ε (u - w0)² = (r_input + ε) (u - target)² + constant
        target = (s.r_input * u_ff + REGULARISATION * w0) / (s.r_input + REGULARISATION)
        # stage k >= 1 tracks refs[k - 1] at x_k, as hystmpc's step; stage 0's x_0 is fixed (a placeholder)
        stage_refs = np.concatenate(([refs[0]], refs[:-1]))
        yref = np.column_stack((stage_refs, np.zeros(N), target))
        rows.append(np.concatenate((x0, [u_prev], states.ravel(), w0, np.tile(d, N + 1), yref.ravel(), refs[-1:])))
    header = f"{nx + 1} 1 {nd} 3 1 {N} {len(rows)}"
    np.savetxt(path, np.asarray(rows), fmt="%.17g", header=header, comments="")


def _acados_generator(package: Path, source: Path, stack: contextlib.ExitStack):
    """``generate(ocp, folder)``: acados' code for ``ocp`` in ``folder``, with acados importable."""
    for name in ("bin", "lib", "include"):
        (source / name).parent.mkdir(parents=True, exist_ok=True)
        if not (source / name).exists():
            (source / name).symlink_to(package / "install" / name)
    template = source / "interfaces" / "acados_template"
    template.mkdir(parents=True, exist_ok=True)
    if not (template / "acados_template").exists():
        (template / "acados_template").symlink_to(package / "acados_template")
    sys.path.insert(0, str(template))  # acados_template alone: not the wheel's CasADi
    stack.callback(sys.path.remove, str(template))
    previous = os.environ.get("ACADOS_SOURCE_DIR")
    os.environ["ACADOS_SOURCE_DIR"] = str(source)
    stack.callback(_restore_environment, "ACADOS_SOURCE_DIR", previous)

    def generate(ocp, folder: Path) -> None:
        from acados_template import AcadosOcpSolver
        with contextlib.redirect_stdout(None):
            AcadosOcpSolver.generate(ocp, json_file=str(folder) + ".json")
    return generate


def _restore_environment(key: str, value: str | None) -> None:
    if value is None:
        os.environ.pop(key, None)
    else:
        os.environ[key] = value


def _compile(folder: Path, compiler: str, flags, sources, include=()) -> list[Path]:
    objects = []
    for source in sources:
        target = folder / "objects" / (Path(source).stem + ".o")
        target.parent.mkdir(exist_ok=True)
        command = [compiler, *flags, *include, "-c", str(source), "-o", str(target)]
        done = subprocess.run(command, cwd=folder, capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"build failed ({shlex.join(command)}): {done.stderr.strip()[:2000]}")
        objects.append(target)
    return objects


def _twin_program(folder: Path, name: str, package: Path, ours: Path, ours_objects, ours_libraries, compiler: str,
                  flags) -> dict:
    """Compile the replay program's parts: hystmpc's step, acados' solver ``name`` in ``folder``."""
    (folder / "replay_model.h").write_text(f'#include "acados_solver_{name}.h"\n#define CALL(suffix) {name}##suffix\n')
    (folder / "replay.c").write_text(resources.files("hystmpc.experiments").joinpath("templates/twin_replay.c")
                                     .read_text())
    root = package / "install" / "include"
    include = [f"-I{folder}", f"-I{ours}", f"-I{root}", f"-I{root / 'acados'}", f"-I{root / 'blasfeo' / 'include'}",
               f"-I{root / 'hpipm' / 'include'}", f"-I{root / 'qpOASES_e'}", "-DACADOS_WITH_QPOASES"]
    generated = sorted(str(p.relative_to(folder)) for p in folder.rglob("*.c")
                       if not p.name.startswith(("main_", "acados_sim_solver")) and p.name != "replay.c")
    main, *theirs = _compile(folder, compiler, flags, ["replay.c", *generated], include)
    lib = package / "install" / "lib"
    # RPATH, not RUNPATH: libacados finds libqpOASES_e there too
    rpath = ["-Wl,--disable-new-dtags", f"-Wl,-rpath,{lib}"]
    return {"folder": folder, "main": main, "parts": [list(ours_objects), theirs],
            "libraries": [*ours_libraries, f"-L{lib}", *rpath, "-lacados", "-lhpipm", "-lblasfeo", "-lqpOASES_e",
                          "-lm"]}


def _launch(program: dict, work: Path, compiler: str, repeats: int,
            rng: np.random.Generator) -> tuple[dict, np.ndarray]:
    """Relink ``program`` with a new placement and run it.

    The two solvers' code comes in a random order, each after a random padding, and the
    program runs under an environment of random size.
    """
    folder = program["folder"]
    paddings = [int(b) for b in rng.integers(0, PADDING_BYTES, 2)]
    order = [int(i) for i in rng.permutation(2)]
    objects = [str(program["main"])]
    for number, (part, padding) in enumerate(zip([program["parts"][i] for i in order], paddings, strict=True)):
        pad = folder / "objects" / f"padding_{number}.s"
        pad.write_text(f".text\n.globl hystmpc_padding_{number}\nhystmpc_padding_{number}:\n.skip {padding}, 0x90\n")
        objects += [str(pad), *map(str, part)]
    binary = folder / "replay"
    command = [compiler, *objects, "-o", str(binary), *program["libraries"]]
    done = subprocess.run(command, cwd=folder, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"link failed ({shlex.join(command)}): {done.stderr.strip()[:2000]}")
    environment_bytes = int(rng.integers(0, PADDING_BYTES))
    environment = {**os.environ, "HYSTMPC_PLACEMENT": "x" * environment_bytes}
    seed = int(rng.integers(0, 2**31 - 1))
    command = [str(binary), str(work / "hystmpc_inputs.txt"), str(work / "acados_inputs.txt"), "outputs.txt",
               "times.txt", str(repeats), str(BLOCK), str(seed)]
    done = subprocess.run(command, cwd=folder, capture_output=True, text=True, env=environment)
    if done.returncode != 0:
        raise RuntimeError(f"{binary} failed: {done.stderr.strip()[:500]}")
    ours_us, theirs_us = np.loadtxt(folder / "times.txt", ndmin=2).T
    timing = {"hystmpc_median_us": float(np.median(ours_us)), "hystmpc_p95_us": float(np.percentile(ours_us, 95)),
              "acados_median_us": float(np.median(theirs_us)), "acados_p95_us": float(np.percentile(theirs_us, 95)),
              "code_order": ["hystmpc", "acados"] if order == [0, 1] else ["acados", "hystmpc"],
              "code_padding_bytes": paddings, "environment_bytes": environment_bytes}
    return timing, np.loadtxt(folder / "outputs.txt", ndmin=2)
