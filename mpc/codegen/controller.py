"""The whole NMPC controller as C files: written, built, cached, and driven from Python.

:func:`write_controller` takes a :class:`ControllerCode` (the controller's two CasADi
Functions and what its files say about it; :func:`hystmpc.mpc.embedded.controller_code` makes
one from an NMPC controller) and writes, into one folder: ``<name>_nmpc.c/.h`` (the Functions,
generated), ``<name>.h/.c`` (the firmware interface: ``<name>_init``, ``<name>_step``,
``<name>_prepare``; all memory in one caller-owned struct, sizes as macros, no malloc in
hystmpc's code), ``main.c`` (an example loop that runs the controller on a recorded sensor file
and times it), a Makefile and, where the QP is DAQP, ``<name>_qp_arena.c`` (DAQP's allocations
from a static arena). The texts are the templates in ``templates/``.
:func:`build_cached` builds one such folder once per distinct source; :class:`CompiledController`
drives the library through ``ctypes`` as a controller of the closed-loop runner.
"""

from __future__ import annotations

import ctypes
import hashlib
import re
import shlex
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from hystmpc.mpc.codegen.firmware import DAQP_VERSION, daqp_arena_doubles
from hystmpc.mpc.codegen.toolchain import (
    COMPILE_FLAGS,
    LOG,
    accept_last_qp_iterate,
    c_compiler,
    library_flags,
    template,
)

STATUS_CODES = {0: "solved", 1: "solver failed: fallback input sent",
                2: "estimate not finite: restarted from the sensors, fallback input sent"}
"""The ``status`` output of ``feedback`` (and of the generated ``<name>_step``)."""

WARM_START_DOCS = {
    "inverse": "the shifted plan, or the inverse model at start-up,\n   after a reference jump and after a failure",
    "shift": "the shifted plan; the last input held at start-up and after a failure",
    "cold": "zeros",
}

ALLOCATION = {
    "daqp": "\n   No malloc in this code, but the QP library it calls (DAQP, solver.rti.qp=daqp) allocates\n"
            "   its workspace in each solve (malloc/free). For firmware, compile DAQP's sources with\n"
            "   -Dmalloc={name}_qp_malloc -Dcalloc={name}_qp_calloc -Dfree={name}_qp_free and link\n"
            "   {name}_qp_arena.c: a static arena of {arena} bytes, exactly what one solve takes, emptied\n"
            "   when the solve frees it (hystmpc codegen --target cortex-m7 does so).",
    "ipm": "No malloc anywhere (solver.rti.qp=ipm: the QP is generated code too).",
}


@dataclass(frozen=True)
class ControllerCode:
    """What the C files of one controller hold and say: its two Functions and its facts."""

    feedback: ca.Function
    """``feedback(mem, z, ref_preview) -> (mem_next, u, status, predicted)``."""
    prepare: ca.Function
    """``prepare(mem) -> mem_next``."""
    initial_memory: tuple[float, ...]
    """The memory before the first step (its length is the memory's size)."""
    offsets: dict[str, int]
    """Where ``failures``, ``u_last``, ``estimator_resets`` and, with a linear MPC's plan,
    ``planner_failures`` sit in the memory."""
    horizon: int
    sensor_names: tuple[str, ...]
    bounds: tuple[float, float, float]
    """Input ``(lower, upper, rate per sample)``."""
    iterations: int
    """Gauss-Newton steps per sample."""
    extra_step_tolerance: float
    warm_start: str
    """``inverse``, ``shift`` or ``cold`` (:data:`WARM_START_DOCS`)."""
    qp: str
    """``daqp`` or ``ipm`` (:data:`ALLOCATION`)."""
    sensitivity_block: int
    estimator_docs: dict[str, str] = field(default_factory=dict)
    """``feedback_doc``, ``prepare_doc`` and ``init_doc``: the estimator's part, in the header's words."""
    qp_dimensions: tuple[int, int, int] | None = None
    """``(n, m, ms)`` of the DAQP QP the step calls (None: no DAQP)."""


@dataclass(frozen=True)
class Signals:
    """Names and units the header uses for the controller's signals."""

    output_name: str
    units: str
    input_units: str
    sensor_units: tuple[tuple[str, str], ...] = ()


def c_name(name: str) -> str:
    """``name`` as a C identifier: other characters turn into ``_``, a leading digit gets ``c_``.

    Parameters
    ----------
    name : str
        Any non-empty name.

    Returns
    -------
    str
        The identifier.
    """
    name = re.sub(r"\W", "_", name, flags=re.ASCII)
    return f"c_{name}" if name[0].isdigit() else name


def write_controller(code: ControllerCode, out: Path, name: str, signals: Signals, sample_period: float,
                     origin: str, version: str, build: bool = True) -> dict:
    """Write the controller's C files into ``out`` and build them (shared library and example loop).

    Raises ``RuntimeError`` when the build fails.

    Parameters
    ----------
    code : ControllerCode
        The controller (:func:`hystmpc.mpc.embedded.controller_code`).
    out : Path
        The folder (made if missing).
    name : str
        The C name (a valid identifier, :func:`c_name`).
    signals : Signals
        Names and units for the header.
    sample_period : float
        Seconds per sample.
    origin, version : str
        Where the controller comes from (a bench's name) and the hystmpc version, for the header.
    build : bool, optional
        False: write the sources and the Makefile only.

    Returns
    -------
    dict
        What was written: the ``name``, the ``folder``, its ``files``, ``memory_doubles``, the
        ``sensitivity_block`` and ``c_kB`` (kB of the two generated C files).
    """
    feedback, prepare = code.feedback, code.prepare
    out.mkdir(parents=True, exist_ok=True)
    gen = ca.CodeGenerator(f"{name}_nmpc.c", {"with_header": True})
    gen.add(feedback)
    gen.add(prepare)
    gen.generate(str(out) + "/")
    source = accept_last_qp_iterate((out / f"{name}_nmpc.c").read_text())
    (out / f"{name}_nmpc.c").write_text(source)
    sizes = {key: max(getattr(f, key)() for f in (feedback, prepare)) for key in ("sz_arg", "sz_res", "sz_iw", "sz_w")}
    sizes = {k: max(v, 1) for k, v in sizes.items()}
    lower, upper, rate = code.bounds
    memory = len(code.initial_memory)
    sensors = ", ".join(_sensor_doc(sensor, signals) for sensor in code.sensor_names) or "none (NULL is fine)"
    NAME = name.upper()
    status_macros = "\n".join(f"#define {NAME}_{key} {status}  /* {STATUS_CODES[status]} */" for key, status in
                              (("SOLVED", 0), ("FALLBACK", 1), ("ESTIMATOR_RESTARTED", 2)))
    status_macros += (f"\n#define {NAME}_INTERNAL_ERROR (-1)  /* the generated code refused the call (not expected): "
                      "u_out holds the last input */")
    n_bytes = 8 * (2 * memory + sizes["sz_w"] + sizes["sz_arg"] + sizes["sz_res"]) + 8 * sizes["sz_iw"]
    fields = dict(name=name, NAME=NAME, bench=origin, version=version, N=code.horizon,
                  nz=len(code.sensor_names), mem=memory, dt=float(sample_period),
                  lower=float(lower), upper=float(upper), rate=float(rate),
                  input_units=signals.input_units or "input units", units=signals.units or "output units",
                  output=signals.output_name, sensors=sensors, iterations=code.iterations,
                  extra_step_doc=_extra_step_doc(code.extra_step_tolerance),
                  status_macros=status_macros, bytes=n_bytes, **code.estimator_docs,
                  warm_start_doc=WARM_START_DOCS[code.warm_start],
                  allocation=ALLOCATION[code.qp],
                  initial=", ".join(repr(float(v)) for v in code.initial_memory),
                  failures=code.offsets["failures"], u_last=code.offsets["u_last"],
                  resets=code.offsets["estimator_resets"],
                  planner_failures=(f"(long)ctrl->mem[{code.offsets['planner_failures']}]"
                                    if "planner_failures" in code.offsets else "-1"),
                  **sizes)
    if code.qp_dimensions is not None:
        n, m, ms = code.qp_dimensions
        doubles = daqp_arena_doubles(n, m, ms)
        fields["allocation"] = fields["allocation"].format(name=name, arena=8 * doubles)
        (out / f"{name}_qp_arena.c").write_text(template("qp_arena.c.in").format(
            name=name, NAME=NAME, n=n, m=m, ms=ms, doubles=doubles, arena=8 * doubles, daqp_version=DAQP_VERSION))
    (out / f"{name}.h").write_text(template("controller.h.in").format(**fields))
    (out / f"{name}.c").write_text(template("controller.c.in").format(**fields))
    (out / "main.c").write_text(template("controller_main.c.in").format(**fields))
    include, libraries = library_flags(source)
    (out / "Makefile").write_text(template("controller.mk.in").format(
        name=name, cflags=" ".join(COMPILE_FLAGS), qp_include=shlex.join(include), qp_libs=shlex.join(libraries)))
    if build:
        build_controller_library(out, name, include, libraries)
    c_bytes = sum((out / f).stat().st_size for f in (f"{name}_nmpc.c", f"{name}.c"))
    return {"name": name, "folder": str(out), "files": sorted(p.name for p in out.iterdir()),
            "memory_doubles": memory, "sensitivity_block": code.sensitivity_block,
            "c_kB": round(c_bytes / 1e3, 1)}


def _sensor_doc(sensor: str, labels: Signals) -> str:
    if sensor == "y":
        return f"y, the measured {labels.output_name} ({labels.units or 'output units'})"
    unit = dict(labels.sensor_units).get(sensor)
    return f"{sensor} ({unit})" if unit else sensor


def _extra_step_doc(tolerance: float) -> str:
    """The header's words for ``solver.rti.extra_step_tolerance`` (empty when never)."""
    if not np.isfinite(tolerance):
        return ""
    return (f" (one more where the last still moved a planned input by more than {tolerance:g}: budget the "
            "longest sample for it)")


def build_controller_library(out: Path, name: str, include: list[str], libraries: list[str],
                             example: bool = True) -> None:
    """Build ``lib<name>.so`` (and, with ``example``, ``<name>_main``) in ``out``.

    Uses the system compiler; ``RuntimeError`` when there is none or the build fails.

    Parameters
    ----------
    out : Path
        The folder :func:`write_controller` wrote.
    name : str
        The controller's C name.
    include : list of str
        Include flags of the QP library (:func:`~hystmpc.mpc.codegen.toolchain.library_flags`).
    libraries : list of str
        Its link flags.
    example : bool, optional
        Also build the example loop ``<name>_main``.
    """
    cc = c_compiler()
    if cc is None:
        raise RuntimeError("no C compiler (cc, or CC) on the PATH to build the controller")
    sources = [f"{name}.c", f"{name}_nmpc.c"]
    commands = [[*cc, *COMPILE_FLAGS, *include, "-fPIC", "-shared", *sources, "-o", f"lib{name}.so", *libraries,
                 "-lm"]]
    if example:
        commands.append([*cc, *COMPILE_FLAGS, *include, "main.c", *sources, "-o", f"{name}_main", *libraries, "-lm"])
    for cmd in commands:
        done = subprocess.run(cmd, cwd=out, capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"build failed ({' '.join(cmd)}): {done.stderr.strip()[:2000]}")


STALE_BUILD_S = 3600.0
"""A build folder left this long under ``<cache>/controllers/`` (a killed build) is removed."""


def build_cached(written: Path, name: str, root: Path, reason: str) -> Path:
    """``lib<name>.so`` of the controller written in ``written``, built once per distinct source.

    The source is hashed with the compiler, its flags and the QP library's, and built into
    ``root/<hash>`` by an atomic rename.

    Parameters
    ----------
    written : Path
        The folder :func:`write_controller` wrote.
    name : str
        The controller's C name.
    root : Path
        The folder of the cached builds.
    reason : str
        Why it is built, said on the log when it is.

    Returns
    -------
    Path
        ``root/<hash>/lib<name>.so``.
    """
    cc = c_compiler()
    include, libraries = library_flags((written / f"{name}_nmpc.c").read_text())
    digest = hashlib.sha256(" ".join([*cc, *COMPILE_FLAGS, *include, *libraries]).encode())
    for path in sorted(written.iterdir()):
        digest.update(path.name.encode() + path.read_bytes())
    folder = root / digest.hexdigest()[:20]
    if (folder / f"lib{name}.so").exists():
        return folder / f"lib{name}.so"
    LOG.info(f"building the generated controller ({sum(p.stat().st_size for p in written.iterdir()) // 1000} kB "
             f"of C) for {reason}; once, cached in {root}")
    build_controller_library(written, name, include, libraries, example=False)
    root.mkdir(parents=True, exist_ok=True)
    for stale in root.glob("building-*"):  # left by a killed build
        if time.time() - stale.stat().st_mtime > STALE_BUILD_S:
            shutil.rmtree(stale, ignore_errors=True)
    staging = Path(tempfile.mkdtemp(prefix="building-", dir=root))
    try:
        shutil.copytree(written, staging, dirs_exist_ok=True)
        staging.chmod(0o755)
        if folder.exists() and not (folder / f"lib{name}.so").exists():  # damaged: replace it
            shutil.rmtree(folder, ignore_errors=True)
        try:  # atomic: a folder there is always a whole build (another process may have made it first)
            staging.rename(folder)
        except OSError:
            pass
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return folder / f"lib{name}.so"


class CompiledController:
    """The built controller library driven from Python (``ctypes``), as a runner controller.

    Parameters
    ----------
    library : Path
        ``lib<name>.so`` from :func:`write_controller` or :func:`build_cached`.
    name : str
        The controller's C name.
    python_controller : NmpcController
        The controller it was generated from (for ``horizon``, the sensor vector and the bounds).
    """

    def __init__(self, library: Path, name: str, python_controller):
        self._lib = ctypes.CDLL(str(library))
        self._name, self._python = name, python_controller
        self.horizon = python_controller.horizon
        self.sensor_names = python_controller.sensor_names
        self.bounds = python_controller.bounds
        """The input bounds and rate it keeps its inputs within (its generator's ``InputBounds``)."""
        self._lib[f"{name}_controller_size"].restype = ctypes.c_ulong
        size = self._lib[f"{name}_controller_size"]()
        self._ctrl = (ctypes.c_double * (size // 8 + 1))()
        self._step = self._lib[f"{name}_step"]
        self._step.restype = ctypes.c_int
        self._step.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_double),
                               ctypes.POINTER(ctypes.c_double)]
        self._prepare = self._lib[f"{name}_prepare"]
        self._prepare.argtypes = [ctypes.c_void_p]
        self._init = self._lib[f"{name}_init"]
        self._init.argtypes = [ctypes.c_void_p]
        self._failures = self._lib[f"{name}_failures"]
        self._failures.restype = ctypes.c_long
        self._failures.argtypes = [ctypes.c_void_p]
        self._resets = self._lib[f"{name}_estimator_resets"]
        self._resets.restype = ctypes.c_long
        self._resets.argtypes = [ctypes.c_void_p]
        self._planner_failures = self._lib[f"{name}_planner_failures"]
        self._planner_failures.restype = ctypes.c_long
        self._planner_failures.argtypes = [ctypes.c_void_p]
        self._predicted = self._lib[f"{name}_predicted_output"]
        self._predicted.restype = ctypes.c_double
        self._predicted.argtypes = [ctypes.c_void_p]
        self._z = (ctypes.c_double * len(self.sensor_names))()
        self._refs = (ctypes.c_double * (self.horizon + 1))()
        self._u = ctypes.c_double()
        self.reset()

    def reset(self) -> None:
        """``<name>_init``."""
        self._init(self._ctrl)
        self.statuses: dict[int, int] = {}

    def step(self, measurement, ref_window) -> float:
        """``<name>_step`` then ``<name>_prepare``.

        Parameters
        ----------
        measurement : Measurement
            This sample's sensors.
        ref_window : ndarray
            The references ``r_k..r_{k+N}`` (``horizon + 1`` samples).

        Returns
        -------
        float
            The input to send.
        """
        refs = np.asarray(ref_window, float).ravel()
        if len(refs) != self.horizon + 1:
            raise ValueError(f"ref_window needs {self.horizon + 1} samples, got {len(refs)}")
        self._z[:] = self._python.sensors(measurement).tolist()  # the buffers are reused: less time in ctypes
        self._refs[:] = refs.tolist()
        u = self._u
        status = self._step(self._ctrl, self._z, self._refs, ctypes.byref(u))
        if status < 0:
            raise RuntimeError(f"{self._name}_step refused the call (status {status}): one controller instance per "
                               "loaded library")
        self._prepare(self._ctrl)
        self.statuses[status] = self.statuses.get(status, 0) + 1
        return u.value

    @property
    def predicted_output(self) -> float:
        """``<name>_predicted_output``: the model's prediction of the last measured output."""
        return float(self._predicted(self._ctrl))

    def stats(self) -> dict:
        """Failures and estimator restarts counted in C, and the statuses seen.

        Each failure is a fallback; there are no iteration counts (the RTI steps per sample
        are fixed).

        Returns
        -------
        dict
            ``name``, ``failures``, ``fallbacks``, ``estimator_resets``, ``statuses`` (count per
            status, named as in :data:`STATUS_CODES`) and, with a linear MPC's plan as the
            second start, ``planner_failures``.
        """
        failures, planner_failures = int(self._failures(self._ctrl)), int(self._planner_failures(self._ctrl))
        return {"name": "generated C", "failures": failures, "fallbacks": failures,
                "estimator_resets": int(self._resets(self._ctrl)),
                "statuses": {STATUS_CODES.get(code, str(code)): n for code, n in self.statuses.items()},
                **({"planner_failures": planner_failures} if planner_failures >= 0 else {})}
