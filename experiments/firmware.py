"""A bench's NMPC as its generated C controller.

Written for ``hystmpc codegen``, run by ``run``, ``compare`` and ``sweep`` (``nmpc.runtime``),
and checked against the Python controller.

The C itself is :mod:`hystmpc.mpc.codegen`'s (from the controller's CasADi Functions,
:mod:`hystmpc.mpc.embedded`); this module picks the bench's controller and configuration
for it (:func:`controller_config`, :func:`firmware_config`), decides where it runs
(:func:`runs_generated`, :func:`compiled_controller`), and :func:`verify_controller` runs the
bench's default scenario with the compiled controller driving the Python plant (through
``ctypes``) and with the Python controller, and compares the inputs.
"""

from __future__ import annotations

import subprocess
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hystmpc.mpc import codegen
from hystmpc.mpc.codegen import (
    CompiledController,
    Signals,
    build_cached,
    c_compiler,
    c_name,
    cache_dir,
    static_qp_loop,
)
from hystmpc.mpc.codegen.toolchain import LOG, no_compiler_reason
from hystmpc.mpc.embedded import NotGeneratable, controller_code

if TYPE_CHECKING:  # the bench builds its NMPC through this module (nmpc.runtime)
    from hystmpc.experiments.bench import Bench


def controller_config(bench: Bench, config: dict) -> dict:
    """``config`` with ``nmpc.solver=rti`` and the controller run in Python.

    The generated controller embeds the RTI step, and the controller run in Python is the one
    generated.
    """
    if "nmpc" not in config:
        raise ValueError(f"bench {bench.name!r} has no nmpc settings")
    return {**config, "nmpc": replace(config["nmpc"], solver="rti", runtime="python")}


MICROCONTROLLER_SENSITIVITY_BLOCK = 7
"""``solver.rti.sensitivity_block`` of a microcontroller build where the user set none: pam's
controller at N = 20 (with its three learned model errors) needs 63,960 B of RAM instead of
65,584 B with blocks of 5 and more without padding (Cortex-M7), with the same inputs to the
last bit; padding makes its step about 20 % longer on x86."""


def firmware_config(bench: Bench, config: dict) -> dict:
    """``config`` for a microcontroller: RAM before speed.

    A condensed multiple-shooting step gets its sensitivities padded
    (:data:`MICROCONTROLLER_SENSITIVITY_BLOCK`); other controllers are returned as they are.
    """
    from hystmpc.mpc.multiple_shooting import MultipleShootingProblem
    solver = config.get("solver")
    if solver is None or solver.rti.sensitivity_block:
        return config
    problem = getattr(bench.build_controller("nmpc", controller_config(bench, config)), "problem", None)
    if not (isinstance(problem, MultipleShootingProblem) and problem.condensed):
        return config
    rti = replace(solver.rti, sensitivity_block=MICROCONTROLLER_SENSITIVITY_BLOCK)
    return {**config, "solver": replace(solver, rti=rti)}


def write_controller(bench: Bench, config: dict, out: Path, name: str | None = None, build: bool = True) -> dict:
    """Write the bench's whole NMPC controller as C into ``out`` and build it.

    The build makes the shared library and example loop. This is
    :func:`hystmpc.mpc.codegen.write_controller` on the controller ``config`` builds. Returns
    what was written: names, sizes, the memory layout.

    Raises :class:`~hystmpc.mpc.embedded.NotGeneratable` (a ``ValueError``) when the bench's
    controller cannot be generated, ``RuntimeError`` when the build fails. ``name`` (default:
    the bench's name) becomes a C identifier (:func:`hystmpc.mpc.codegen.c_name`). ``build``
    false writes the sources and the Makefile only.
    """
    from hystmpc.experiments.report import version
    name = c_name(name or bench.name)
    controller = bench.build_controller("nmpc", controller_config(bench, config))
    labels = bench.labels
    signals = Signals(labels.output_name, labels.units, labels.input_units, tuple(labels.sensor_units))
    return codegen.write_controller(controller_code(controller, f"{name}_nmpc"), out, name, signals,
                                    bench.sample_period, bench.name, version(), build)


RTI_SOLVERS = ("rti", "rti-c")
"""The solvers the generated controller has (its RTI step)."""


def runs_generated(config: dict) -> bool:
    """Whether ``run``, ``compare`` and ``sweep`` drive the generated controller.

    They do with ``nmpc.runtime=c``, or ``auto`` with an RTI solver.
    """
    settings = config.get("nmpc")
    runtime = getattr(settings, "runtime", "python")
    if runtime == "auto" and settings.solver in RTI_SOLVERS and settings.inverse_plan != "static":
        _say_once(f"nmpc.runtime=auto: the controller runs in Python, since nmpc.inverse_plan="
                  f"{settings.inverse_plan} has no generated form yet")
        return False
    return runtime == "c" or (runtime == "auto" and settings.solver in RTI_SOLVERS)


def check_runtime(config: dict) -> None:
    """``ValueError`` when ``nmpc.runtime=c`` cannot run.

    The reasons: a solver the generated controller does not have, or no C compiler. Cheap: no
    code is generated.
    """
    settings = config.get("nmpc")
    if settings is None or settings.runtime != "c":
        return
    if settings.solver not in RTI_SOLVERS:
        raise ValueError(f"nmpc.runtime=c runs the generated controller, whose solver is the RTI step; nmpc.solver is "
                         f"{settings.solver!r} (allowed with it: {', '.join(RTI_SOLVERS)}; or set nmpc.runtime=python "
                         "or auto)")
    if settings.inverse_plan != "static":
        raise ValueError(f"nmpc.runtime=c runs the generated controller, whose inverse-model inputs come from the "
                         f"static inverse; nmpc.inverse_plan is {settings.inverse_plan!r} (set "
                         "nmpc.inverse_plan=static, or nmpc.runtime=python)")
    if c_compiler() is None:
        raise ValueError(f"nmpc.runtime=c needs a C compiler ({no_compiler_reason()}); set nmpc.runtime=python or auto")


_SAID: set[str] = set()


def _say_once(notice: str) -> None:
    """A notice of ``nmpc.runtime=auto``, once per process (not once per scenario)."""
    if notice not in _SAID:
        _SAID.add(notice)
        LOG.warning(notice)


def compiled_controller(bench: Bench, config: dict):
    """The bench's NMPC as its whole generated controller (``nmpc.runtime=c`` or ``auto``).

    It is written to a temporary folder, built once per distinct source into
    ``<cache>/controllers/`` (:func:`hystmpc.mpc.codegen.build_cached`), then loaded as a
    :class:`~hystmpc.mpc.codegen.CompiledController`.

    ``ValueError`` when it cannot run (:func:`check_runtime`) or cannot be generated. With
    ``auto``, no C compiler or a model that cannot be generated gives the same controller in
    Python instead, after a one-line notice.
    """
    import tempfile

    check_runtime(config)

    def in_python():  # runtime=auto where the C controller cannot run: the user's solver, in Python
        return bench.build_controller("nmpc", {**config, "nmpc": replace(config["nmpc"], runtime="python")})
    if c_compiler() is None:  # runtime=auto: check_runtime refuses runtime=c without a compiler
        _say_once(f"no C compiler ({no_compiler_reason()}): nmpc.runtime=auto runs the controller in Python, slower")
        return in_python()
    python = bench.build_controller("nmpc", controller_config(bench, config))
    name = "controller"
    with tempfile.TemporaryDirectory(prefix="hystmpc-controller-") as scratch:  # a cache hit writes nothing there
        written = Path(scratch) / "c"
        try:
            write_controller(bench, config, written, name, build=False)
        except NotGeneratable as exc:
            if config["nmpc"].runtime == "auto":
                _say_once(f"{exc}: nmpc.runtime=auto runs the controller in Python")
                return in_python()
            raise ValueError(f"nmpc.runtime=c: {exc}; or set nmpc.runtime=python or auto") from None
        library = build_cached(written, name, cache_dir() / "controllers", f"nmpc.runtime={config['nmpc'].runtime}")
    return CompiledController(library, name, python)


def verify_controller(bench: Bench, config: dict, out: Path, name: str, duration: float | None = None) -> dict:
    """The default scenario closed loop with the Python controller and with the compiled one.

    The Python controller (``rti-c``: the same compiled RTI step) and the compiled controller
    drive the same Python plant. Returns the largest input difference, and runs the example loop
    on the recorded sensors for its timing.
    """
    config = controller_config(bench, config)
    scenario = bench.scenarios[bench.default_scenario]
    # the Python controller with the compiled RTI step: the same QP library build as the C controller's
    compiled_step = {**config, "nmpc": replace(config["nmpc"], solver="rti-c")}
    python = bench.run(scenario, "nmpc", compiled_step, duration=duration)
    prepared = bench.prepare(scenario, "nmpc", config)
    c_controller = CompiledController(out / f"lib{name}.so", name, prepared.controller)
    c_run = bench.run(scenario, "nmpc", duration=duration, prepared=replace(prepared, controller=c_controller))
    diff = float(np.max(np.abs(python.input - c_run.input)))
    # the example loop on the sensors the C controller saw: the same inputs again, and its timing
    sensors = _recorded_sensors(bench, scenario, config, c_run, prepared.controller)
    recording = out / "sensors.txt"
    np.savetxt(recording, sensors, fmt="%.17g", header=str(len(sensors)), comments="")
    done = subprocess.run([str(out / f"{name}_main"), str(recording), str(out / "inputs.txt")],
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{name}_main failed: {done.stderr.strip()[:500]}")
    loop = {k: float(v) for k, v in (line.split() for line in done.stdout.split("\n") if line)}
    loop_inputs = np.loadtxt(out / "inputs.txt", ndmin=2)[:, 0]
    loop["max_input_difference"] = float(np.max(np.abs(loop_inputs - c_run.input)))
    if (out / f"{name}_qp_arena.c").exists():  # the firmware's QP: DAQP's sources on the static arena
        static_inputs, loop["static_qp"] = static_qp_loop(out, name, recording)
        loop["static_qp_max_input_difference"] = float(np.max(np.abs(static_inputs - c_run.input)))
    return {"scenario": scenario.name, "samples": int(len(c_run.input)), "max_input_difference": diff,
            "rmse": {"python": python.metrics["rmse"], "c": c_run.metrics["rmse"]},
            "failures": {"python": python.solver["failures"], "c": c_run.solver["failures"]},
            "sample_period_us": 1e6 * bench.sample_period, "example_loop": loop}


def _recorded_sensors(bench: Bench, scenario, config: dict, run, python_controller) -> np.ndarray:
    """``[sensors..., ref]`` per sample of ``run``, re-measured by replaying its inputs on the plant.

    The replay uses the same seed (the plant is deterministic given its seed and inputs).
    """
    prepared = bench.prepare(scenario, "nmpc", config)
    plant = prepared.plant
    meas = plant.reset(run.seed)
    rows = []
    for k, u in enumerate(run.input):
        rows.append([*python_controller.sensors(meas), run.reference[k]])
        if k < len(run.input) - 1:
            meas = plant.step(u)
    return np.asarray(rows)
