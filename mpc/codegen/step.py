"""One CasADi Function (the RTI step) as C with a standalone replay program.

The files: ``rti_step.c/.h``, ``main.c`` (replays recorded solver inputs without Python and
times them) and a Makefile.
"""

from __future__ import annotations

import shlex
import shutil
import subprocess
from pathlib import Path

import casadi as ca
import numpy as np

from hystmpc.mpc.codegen.toolchain import (
    COMPILE_FLAGS,
    LOG,
    accept_last_qp_iterate,
    c_compiler,
    library_flags,
    template,
)


class RecordingStep:
    """Wraps an RTI Function: records every ``(w0, p)`` it is called with.

    Parameters
    ----------
    fun : callable
        The RTI step, called as ``fun(w0, p)``; ``calls`` holds each call's ``w0`` and ``p``,
        flattened and joined.
    """

    def __init__(self, fun):
        self.fun = fun
        self.calls: list[np.ndarray] = []

    def __call__(self, w0, p):
        """Record ``(w0, p)`` and call the step."""
        self.calls.append(np.concatenate((np.ravel(w0), np.ravel(p))))
        return self.fun(w0, p)


def write_step(step: ca.Function, out: Path) -> ca.Function:
    """Write ``step`` (named ``rti_step``) as C into ``out``, build it, and load it back.

    Writes a header, ``main.c`` and a Makefile too; builds the shared library and the replay
    program. ``RuntimeError`` when there is no C compiler or the build fails.

    Parameters
    ----------
    step : casadi.Function
        The RTI step, ``(w0, p) -> w_next``.
    out : Path
        The folder (made if missing).

    Returns
    -------
    casadi.Function
        ``rti_step`` loaded from ``out/librti_step.so``.
    """
    out.mkdir(parents=True, exist_ok=True)
    gen = ca.CodeGenerator("rti_step.c", {"with_header": True})
    gen.add(step)
    gen.generate(str(out) + "/")
    (out / "rti_step.c").write_text(accept_last_qp_iterate((out / "rti_step.c").read_text()))
    (out / "main.c").write_text(template("step_main.c"))
    include, libraries = library_flags((out / "rti_step.c").read_text())
    makefile = template("step.mk.in").replace("{cflags}", " ".join(COMPILE_FLAGS))
    (out / "Makefile").write_text(makefile.replace("{qp_include}", shlex.join(include))
                                  .replace("{qp_libs}", shlex.join(libraries)))
    _compile(out)
    return ca.external("rti_step", str(out / "librti_step.so"))


def _compile(out: Path) -> None:
    gcc = shutil.which("gcc")
    cc = c_compiler() or ([gcc] if gcc else None)
    if cc is None:
        raise RuntimeError("no C compiler (cc or gcc) on the PATH")
    size = (out / "rti_step.c").stat().st_size
    LOG.info(f"compiling rti_step.c ({size / 1e3:.0f} kB) and the replay program with "
             f"{' '.join(cc)} {' '.join(COMPILE_FLAGS)} in {out}")
    include, libraries = library_flags((out / "rti_step.c").read_text())
    for cmd in (["make", f"CC={shlex.join(cc)}", "-s"],) if shutil.which("make") else (
            [*cc, *COMPILE_FLAGS, *include, "-fPIC", "-shared", "rti_step.c", "-o", "librti_step.so", *libraries,
             "-lm"],
            [*cc, *COMPILE_FLAGS, *include, "main.c", "rti_step.c", "-o", "rti_main", *libraries, "-lm"]):
        done = subprocess.run(cmd, cwd=out, capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"build failed ({' '.join(cmd)}): {done.stderr.strip()[:2000]}")


def run_program(out: Path, calls: np.ndarray, n_w: int, repeats: int = 1) -> tuple[np.ndarray, dict]:
    """Run the standalone program on recorded calls.

    Parameters
    ----------
    out : Path
        The folder :func:`write_step` built.
    calls : ndarray
        One row per call: ``w0`` then ``p`` (``RecordingStep.calls``).
    n_w : int
        Length of ``w0``.
    repeats : int, optional
        How many times the program replays all the calls.

    Returns
    -------
    tuple of (ndarray, dict)
        ``w_next`` per call (one row each), and the timing per call: ``median_us``, ``p95_us``,
        ``max_us`` (µs) and ``calls``.
    """
    inputs, outputs = out / "inputs.txt", out / "outputs.txt"
    header = f"{n_w} {calls.shape[1] - n_w} {calls.shape[0]}"
    np.savetxt(inputs, calls, fmt="%.17g", header=header, comments="")
    done = subprocess.run([str(out / "rti_main"), str(inputs), str(outputs), str(repeats)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"rti_main failed: {done.stderr.strip()[:500]}")
    timing = {k: float(v) for k, v in (line.split() for line in done.stdout.split("\n") if line)}
    return np.loadtxt(outputs, ndmin=2), timing
