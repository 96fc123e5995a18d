"""A bench's NMPC as its generated C controller.

Written for ``hystmpc codegen`` and checked against the Python controller.

The C itself is :mod:`hystmpc.mpc.codegen`'s (from the controller's CasADi Functions,
:mod:`hystmpc.mpc.embedded`); this module picks the bench's controller and configuration
for it (:func:`controller_config`, :func:`firmware_config`), and :func:`verify_controller`
runs the bench's default scenario with the compiled controller driving the Python plant
(through ``ctypes``) and with the Python controller, and compares the inputs. Where a run
drives the generated controller (``nmpc.runtime``) is :mod:`hystmpc.mpc.runtime`'s.
"""

from __future__ import annotations

import subprocess
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hystmpc.mpc import codegen
from hystmpc.mpc.codegen import CompiledController, Signals, c_name, static_qp_loop
from hystmpc.mpc.embedded import controller_code
from hystmpc.mpc.runtime import generated_settings

if TYPE_CHECKING:  # the bench builds its NMPC through this module (nmpc.runtime)
    from hystmpc.experiments.bench import Bench


def controller_config(bench: Bench, config: dict) -> dict:
    """``config`` as the generated controller is built from it, with ``nmpc.solver=rti`` run in Python.

    The generated controller embeds the RTI step, and the controller run in Python is the one
    generated (:meth:`Bench.generated_config <hystmpc.experiments.bench.Bench.generated_config>`:
    the linear MPC planner's QP, and what the bench needs).

    Parameters
    ----------
    bench : Bench
        The bench (named in the error).
    config : dict
        Its configuration.

    Returns
    -------
    dict
        ``config`` with its ``nmpc`` group replaced (``ValueError`` when it has none).
    """
    if "nmpc" not in config:
        raise ValueError(f"bench {bench.name!r} has no nmpc settings")
    return {**bench.generated_config(config), "nmpc": generated_settings(config["nmpc"])}


MICROCONTROLLER_SENSITIVITY_BLOCK = 7
"""``solver.rti.sensitivity_block`` of a microcontroller build where the user set none: pam's
controller at N = 20 (with its three learned model errors) needs less RAM with it than with
blocks of 5 or without padding (Cortex-M7), with the same inputs to the last bit; padding
makes its step longer on x86 (docs/realtime.md)."""


def firmware_config(bench: Bench, config: dict) -> dict:
    """``config`` for a microcontroller: RAM before speed.

    A condensed multiple-shooting step gets its sensitivities padded
    (:data:`MICROCONTROLLER_SENSITIVITY_BLOCK`); other controllers are returned as they are.

    Parameters
    ----------
    bench : Bench
        The bench, whose ``nmpc`` controller is built to see its problem.
    config : dict
        Its configuration.

    Returns
    -------
    dict
        ``config``, or a copy with ``solver.rti.sensitivity_block`` set where it was 0.
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
    :func:`hystmpc.mpc.codegen.write_controller` on the controller ``config`` builds.

    Parameters
    ----------
    bench : Bench
        The bench.
    config : dict
        Its configuration (:func:`controller_config` is applied).
    out : Path
        The folder.
    name : str, optional
        Becomes a C identifier (:func:`hystmpc.mpc.codegen.c_name`; default: the bench's name).
    build : bool, optional
        False: write the sources and the Makefile only.

    Returns
    -------
    dict
        What was written: names, sizes, the memory layout, and ``generated_with``: the settings
        it was built with where they differ from ``config``'s
        (:meth:`~hystmpc.experiments.bench.Bench.generated_changes`).

    Raises
    ------
    NotGeneratable
        A ``ValueError``, when the bench's controller cannot be generated.
    RuntimeError
        When the build fails.
    """
    from hystmpc.experiments.report import version
    name = c_name(name or bench.name)
    controller = bench.build_controller("nmpc", controller_config(bench, config))
    labels = bench.labels
    signals = Signals(labels.output_name, labels.units, labels.input_units, tuple(labels.sensor_units))
    report = codegen.write_controller(controller_code(controller, f"{name}_nmpc"), out, name, signals,
                                      bench.sample_period, bench.name, version(), build)
    return {**report, "generated_with": list(bench.generated_changes(config))}


def verify_controller(bench: Bench, config: dict, out: Path, name: str, duration: float | None = None) -> dict:
    """The default scenario closed loop with the Python controller and with the compiled one.

    The Python controller (``rti-c``: the same compiled RTI step) and the compiled controller
    drive the same Python plant; the example loop then runs on the recorded sensors for its
    timing.

    Parameters
    ----------
    bench : Bench
        The bench.
    config : dict
        Its configuration (:func:`controller_config` is applied).
    out : Path
        The folder :func:`write_controller` built the controller in.
    name : str
        The controller's C name there.
    duration : float, optional
        Override of the scenario's duration (s).

    Returns
    -------
    dict
        The largest input difference, both runs' RMSE and failures (and the linear MPC
        planner's, where it is the second start), and the example loop's timing and input
        difference (``RuntimeError`` when the loop fails).
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
            **({"planner_failures": {"python": python.solver["planner_failures"],
                                     "c": c_run.solver["planner_failures"]}}
               if "planner_failures" in python.solver else {}),
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
