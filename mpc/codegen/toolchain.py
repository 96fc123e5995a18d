"""The C toolchain: the compiler, its flags, the build cache, and the templates.

The templates are the files hystmpc writes around generated code.

:func:`compile_function` generates C for one CasADi Function, compiles it once per distinct
source (cached under :func:`cache_dir`) and loads it back: the ``rti-c`` solver and the
compiled warm starts use it. :func:`library_flags` adds DAQP (from the CasADi package) where
the source calls it; :func:`accept_last_qp_iterate` makes a generated QP call behave as the
in-process one.
"""

from __future__ import annotations

import hashlib
import logging
import os
import shlex
import shutil
import subprocess
import time
from importlib import resources
from pathlib import Path

import casadi as ca


def cache_dir() -> Path:
    """Where compiled solvers and controllers are kept.

    Returns
    -------
    Path
        ``$HYSTMPC_CACHE`` (compiled code only), else :func:`user_cache_dir`.
    """
    return Path(os.environ.get("HYSTMPC_CACHE") or user_cache_dir())


def user_cache_dir() -> Path:
    """Hystmpc's cache.

    Returns
    -------
    Path
        ``$HYSTMPC_CACHE_DIR``, else ``$XDG_CACHE_HOME/hystmpc`` (``~/.cache/hystmpc``).
    """
    if os.environ.get("HYSTMPC_CACHE_DIR"):
        return Path(os.environ["HYSTMPC_CACHE_DIR"])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "hystmpc"


COMPILE_FLAGS = ("-O2", "-ffp-contract=off")
"""Flags of the compiled step. ``-O2``: on pam's step (N = 20) it compiles faster than ``-O3``
and runs as fast (docs/realtime.md). ``-ffp-contract=off``: no fused
multiply-adds, so the compiled step rounds as the in-process one does on any CPU."""

LOG = logging.getLogger("hystmpc")


def c_compiler() -> list[str] | None:
    """The system C compiler as a command if its program is on the PATH, else None.

    Returns
    -------
    list of str or None
        ``CC`` (which may carry a launcher or options such as ``ccache gcc``), or ``cc``, with
        its program resolved on the PATH; None when it is not found or ``CC`` does not parse.
    """
    try:
        words = shlex.split(os.environ.get("CC", "")) or ["cc"]
    except ValueError:  # an unbalanced quote: no command to run
        return None
    program = shutil.which(words[0])
    return [program, *words[1:]] if program else None


def compile_function(fun: ca.Function, out_dir: Path | None = None, flags=COMPILE_FLAGS) -> ca.Function:
    """Generate C99 for ``fun``, compile it with the system C compiler and load it back.

    Builds are cached by the hash of the generated source, the compiler command, the
    flags and the QP library's include and link flags (:func:`library_flags`), so the same
    problem compiles once; a compilation says what it does on the ``hystmpc`` logger.
    Raises ``RuntimeError`` with the compiler's message on failure, and
    :class:`CompilerNotFound` when there is no compiler.

    Parameters
    ----------
    fun : casadi.Function
        The function to compile; its name names the source and the library.
    out_dir : Path, optional
        Folder of the builds (default: :func:`cache_dir`).
    flags : tuple of str, optional
        Compiler flags (default: :data:`COMPILE_FLAGS`).

    Returns
    -------
    casadi.Function
        The compiled library loaded with ``casadi.external``.
    """
    out_dir = Path(out_dir) if out_dir is not None else cache_dir()
    name = fun.name()
    gen = ca.CodeGenerator(f"{name}.c", {"with_header": True})
    gen.add(fun)
    source = accept_last_qp_iterate(gen.dump())
    compiler = c_compiler()
    include, libraries = library_flags(source)
    key = source + " ".join([*(compiler or []), *flags, *include, *libraries])
    digest = hashlib.sha256(key.encode()).hexdigest()[:16]
    build = out_dir / f"{name}_{digest}"
    library = build / f"{name}.so"
    if not library.exists():
        if compiler is None:
            raise CompilerNotFound(f"no C compiler found (looked for {os.environ.get('CC', 'cc')!r} on the PATH)")
        build.mkdir(parents=True, exist_ok=True)
        gen.generate(str(build) + os.sep)
        # private names, then an atomic rename: sweep workers may build the same step at once
        private = f"{name}.{os.getpid()}"
        (build / f"{private}.c").write_text(source)
        cmd = [*compiler, *flags, *include, "-fPIC", "-shared", f"{private}.c", "-o", f"{private}.so", *libraries,
               "-lm"]
        command = " ".join(cmd[:len(compiler) + len(flags)])
        LOG.info(f"compiling {name} ({len(source) / 1e3:.0f} kB of C) with {command}; once, cached in {build.parent}")
        start = time.perf_counter()
        done = subprocess.run(cmd, cwd=build, capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"C compiler failed ({' '.join(cmd)}): {done.stderr.strip()[:2000]}")
        os.replace(build / f"{private}.c", build / f"{name}.c")
        os.replace(build / f"{private}.so", library)
        LOG.info(f"compiled {name} in {time.perf_counter() - start:.1f} s")
    return ca.external(name, str(library))


def library_flags(source: str) -> tuple[list[str], list[str]]:
    """``(include flags, libraries)`` that generated C needs beyond libm.

    Parameters
    ----------
    source : str
        The generated C.

    Returns
    -------
    tuple of (list of str, list of str)
        DAQP's headers and library from the CasADi package (its static library when there is
        one, else the shared one with an rpath) when the source includes DAQP, else two empty lists.
    """
    if "#include <daqp/" not in source:
        return [], []
    casadi_dir = Path(ca.__file__).parent
    static = casadi_dir / "libdaqpstat.a"
    if static.exists():
        return [f"-I{casadi_dir / 'include'}"], [str(static)]
    return [f"-I{casadi_dir / 'include'}"], [f"-L{casadi_dir}", "-ldaqp", f"-Wl,-rpath,{casadi_dir}"]


class CompilerNotFound(RuntimeError):
    """There is no C compiler to build the ``rti-c`` step with."""


def compiled_or_slower(fun: ca.Function, notice: str, flags=COMPILE_FLAGS) -> ca.Function:
    """``fun`` compiled (cached; the same numbers to the last bit), or ``fun`` itself.

    Where it cannot be compiled (no compiler, one that fails, a cache it cannot write), a
    one-line notice says ``<why>: <notice>``.

    Parameters
    ----------
    fun : casadi.Function
        The function to compile.
    notice : str
        The end of the warning logged when it cannot be compiled.
    flags : tuple of str, optional
        Compiler flags (default: :data:`COMPILE_FLAGS`).

    Returns
    -------
    casadi.Function
        The compiled function, or ``fun`` itself.
    """
    try:
        return compile_function(fun, flags=flags)
    except (RuntimeError, OSError) as exc:
        LOG.warning(f"{str(exc)[:300]}: {notice}")
        return fun


def compiled_or_in_process(fun: ca.Function) -> tuple[ca.Function, bool]:
    """``(fun compiled, True)``, or ``(fun, False)`` with a one-line notice without a compiler.

    Without a C compiler, ``rti-c`` runs the same step in-process, as ``rti``.

    Parameters
    ----------
    fun : casadi.Function
        The function to compile.

    Returns
    -------
    tuple of (casadi.Function, bool)
        The function to call, and whether it is compiled.
    """
    try:
        return compile_function(fun), True
    except CompilerNotFound as exc:
        LOG.warning(f"{exc}: solver rti-c runs the same step in-process (as rti), slower")
        return fun, False


def accept_last_qp_iterate(source: str) -> str:
    """Make generated QP calls return their last iterate when they stop short.

    The in-process solvers do so with ``error_on_fail: False``; CasADi's C output ignores that
    option and makes the whole call fail. The RTI step is then the same function in C and in
    Python, and a failed QP is counted by ``qp_error`` instead of aborting the step.

    qrqp: every status returns 0. DAQP: the step goes on whatever DAQP's exit, and when its
    setup fails (an H that is not positive definite) the answer is NaN, so ``qp_error`` is
    infinite.

    Parameters
    ----------
    source : str
        Generated C from CasADi.

    Returns
    -------
    str
        The patched source (unchanged when it calls neither qrqp nor DAQP).
    """
    patched = source
    if "casadi_qrqp" in source:
        failing = "  } else if (d.status == QP_NO_SEARCH_DIR) {\n    return 4;\n  } else {\n    return -1;\n  }"
        patched = patched.replace(failing, "  } else {\n    return 0;\n  }")
        if "QP_NO_SEARCH_DIR) {\n    return 4;" in patched:
            raise RuntimeError("could not patch the generated qrqp return codes; CasADi's output changed")
    if "casadi_daqp_solve" in source:
        setup_failed = "  if (flag<0) return 1;\n"
        not_optimal = "  casadi_daqp_solve(d, arg, res, iw, w);\n  if (!d_qp.success) {\n    return -1;\n  }\n"
        if setup_failed not in patched or not_optimal not in patched:
            raise RuntimeError("could not patch the generated DAQP call; CasADi's output changed")
        patched = patched.replace(setup_failed, "  if (flag<0) {\n    for (i=0;i<p_qp->nx;++i) d_qp->x[i] = 0.0/0.0;\n"
                                                "    d_qp->success = 0;\n    return 1;\n  }\n")
        patched = patched.replace(not_optimal, "  casadi_daqp_solve(d, arg, res, iw, w);\n")
    return patched


def template(name: str) -> str:
    """The text of template ``name``.

    Parameters
    ----------
    name : str
        A file name in this package's ``templates/`` folder.

    Returns
    -------
    str
        The file's text.
    """
    return resources.files("hystmpc.mpc.codegen").joinpath("templates", name).read_text(encoding="utf-8")


def no_compiler_reason() -> str:
    """Why :func:`c_compiler` found nothing, in a few words.

    Returns
    -------
    str
        That ``CC`` is not an executable, or that there is no ``cc`` on the PATH.
    """
    return f"CC={os.environ['CC']!r} is not an executable" if os.environ.get("CC") else "no cc on the PATH"


def run(cmd: list[str], what: str) -> None:
    """Run a build command; ``RuntimeError`` naming ``what`` with the end of its message on failure.

    Parameters
    ----------
    cmd : list of str
        The command and its arguments.
    what : str
        What the command does, for the error message.
    """
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{what} failed: {done.stderr.strip()[-1500:]}")
