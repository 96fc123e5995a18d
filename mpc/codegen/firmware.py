"""Generated controllers built as firmware: cross-compiled for a Cortex-M7 and sized.

DAQP's own C sources are compiled on a static arena (the firmware's QP, checked on this
machine too by :func:`static_qp_loop`).

DAQP allocates its workspace in each solve; the firmware compiles DAQP's sources with their
``malloc``, ``calloc`` and ``free`` taken from ``<name>_qp_arena.c`` (:func:`daqp_arena_doubles`
sizes it). The sources are those of :data:`DAQP_VERSION`: from ``$HYSTMPC_DAQP_SOURCES`` or the
hystmpc cache, else downloaded once from PyPI (:func:`daqp_sources`).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from hystmpc.mpc.codegen.toolchain import COMPILE_FLAGS, LOG, c_compiler, cache_dir, library_flags, run, template

CORTEX_M7_FLAGS = ("-mcpu=cortex-m7", "-mfpu=fpv5-d16", "-mfloat-abi=hard", "-mthumb", "-Os",
                   "-ffunction-sections", "-fdata-sections", "-ffp-contract=off")
"""A Cortex-M7 with a double-precision FPU, optimised for size; unused functions dropped at link."""
DAQP_VERSION = "0.5.1"
"""DAQP release whose C sources a cross build compiles: the one inside CasADi 3.8.2 (its
headers are 0.5.1's), so the firmware's QP computes what the host build's does."""


def daqp_arena_doubles(n: int, m: int, ms: int) -> int:
    """Doubles DAQP 0.5.1 allocates in one solve of a dense QP.

    No binaries, no soft constraints; each block is rounded up to whole doubles: the workspace
    (``allocate_daqp_workspace``) and the LDP (``setup_daqp_ldp`` with H and f given).

    Parameters
    ----------
    n : int
        Variables of the QP.
    m : int
        Constraints of the QP.
    ms : int
        How many of the ``m`` constraints are simple bounds.

    Returns
    -------
    int
        Doubles of the workspace and the LDP together.
    """
    def ints(k: int) -> int:
        return (4 * k + 7) // 8
    workspace = 5 * (n + 1) + ints(n + 1) + (n + 1) * (n + 2) // 2 + 2 * n
    ldp = 3 * m + n * (m - ms) + ints(m) + n * (n + 1) // 2 + n
    return workspace + ldp


class DaqpSourcesMissing(RuntimeError):
    """DAQP's C sources are not on this machine and could not be downloaded."""


def daqp_sources() -> Path:
    """DAQP's C sources (``include/`` and ``src/``) for a firmware build.

    From the folder ``$HYSTMPC_DAQP_SOURCES`` names, else the hystmpc cache, else downloaded
    once into the cache from PyPI (the sdist of :data:`DAQP_VERSION`, with pip, so pip's own
    index settings apply).

    Raises :class:`DaqpSourcesMissing` when none of these has them, and ``ValueError`` when
    ``$HYSTMPC_DAQP_SOURCES`` names a folder without ``include/api.h`` and ``src/``.

    Returns
    -------
    Path
        The folder holding ``include/`` and ``src/``.
    """
    import tarfile
    import tempfile

    given = os.environ.get("HYSTMPC_DAQP_SOURCES")
    if given:  # a folder named on purpose: a wrong one is an error, never a silent fallback
        if not ((Path(given) / "src").is_dir() and (Path(given) / "include" / "api.h").is_file()):
            raise ValueError(f"HYSTMPC_DAQP_SOURCES={given!r} has no include/api.h and src/ (DAQP "
                             f"{DAQP_VERSION}'s csrc/include and csrc/src folders)")
        return Path(given)
    target = cache_dir() / f"daqp-{DAQP_VERSION}"
    if (target / "src").is_dir() and (target / "include").is_dir():
        return target
    LOG.warning(f"downloading DAQP {DAQP_VERSION}'s C sources from PyPI once, into {target}")
    with tempfile.TemporaryDirectory() as tmp:
        done = subprocess.run([sys.executable, "-m", "pip", "download", "-q", f"daqp=={DAQP_VERSION}", "--no-deps",
                               "--no-binary", "daqp", "-d", tmp], capture_output=True, text=True)
        archives = sorted(Path(tmp).glob("daqp-*.tar.gz"))
        if done.returncode != 0 or not archives:
            said = [line for line in done.stderr.splitlines() if line.strip()] or ["no sdist found"]
            raise DaqpSourcesMissing(
                f"could not download DAQP {DAQP_VERSION}'s C sources (pip: {said[-1].strip()[:200]}); put its "
                f"csrc/include and csrc/src folders into {target}, or name a folder holding them in "
                "HYSTMPC_DAQP_SOURCES")
        with tarfile.open(archives[0]) as tar:
            members = [m for m in tar.getmembers() if "/csrc/" in m.name and m.isfile()]
            safe = {"filter": "data"} if hasattr(tarfile, "data_filter") else {}
            tar.extractall(tmp, members=members, **safe)
        csrc = next(Path(tmp).glob("daqp-*/csrc"))
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copytree(csrc, target, dirs_exist_ok=True)
    return target


def cross_compile(out: Path, name: str, compiler: str = "arm-none-eabi-gcc") -> dict:
    """Build the generated controller in ``out`` for a Cortex-M7 and measure it.

    The build uses :data:`CORTEX_M7_FLAGS`, newlib without system calls and libm, around the
    firmware loop template (``templates/firmware.c.in``), in ``out/cortex-m7``; DAQP's sources
    are compiled in where the step uses DAQP. Raises ``RuntimeError`` when the cross compiler
    is missing or the build fails.

    Parameters
    ----------
    out : Path
        The folder :func:`~hystmpc.mpc.codegen.controller.write_controller` wrote.
    name : str
        The controller's C name.
    compiler : str, optional
        The cross compiler; its ``size`` and ``nm`` are found by replacing ``gcc`` in its name.

    Returns
    -------
    dict
        ``target``, the ``elf`` path, its ``text``, ``data`` and ``bss`` in bytes (``size``),
        ``heap`` (whether a malloc or ``_sbrk`` is linked in), the ``flags``, the ``qp`` and the
        ``compiler`` version.
    """
    gcc = shutil.which(compiler)
    size_tool = shutil.which(compiler.replace("gcc", "size"))
    if gcc is None or size_tool is None:
        raise RuntimeError(f"{compiler} not found: install a cross compiler for the Cortex-M7 "
                           "(Debian/Ubuntu: apt-get install gcc-arm-none-eabi)")
    build = out / "cortex-m7"
    build.mkdir(exist_ok=True)
    (build / "firmware.c").write_text(template("firmware.c.in").format(name=name, NAME=name.upper()))
    sources = [build / "firmware.c", out / f"{name}.c", out / f"{name}_nmpc.c"]
    flags = [*CORTEX_M7_FLAGS, f"-I{out}"]
    uses_daqp = "daqp/api.h" in (out / f"{name}_nmpc.c").read_text()
    objects = []
    if uses_daqp:
        include, objects = daqp_on_arena([gcc], flags, name, build)
        flags += include
        sources.append(out / f"{name}_qp_arena.c")
    elf = build / f"{name}.elf"
    run([gcc, *flags, *map(str, sources), *objects, "--specs=nosys.specs", "-Wl,--gc-sections", "-lm",
          "-o", str(elf)], "cortex-m7 build")
    sized = subprocess.run([size_tool, str(elf)], capture_output=True, text=True, check=True).stdout.split("\n")
    text, data, bss = (int(v) for v in sized[1].split()[:3])
    nm = shutil.which(compiler.replace("gcc", "nm"))
    symbols = subprocess.run([nm, str(elf)], capture_output=True, text=True, check=True).stdout.split() if nm else []
    return {"target": "cortex-m7", "elf": str(elf), "text": text, "data": data, "bss": bss,
            "heap": bool({"malloc", "_malloc_r", "_sbrk", "_sbrk_r"} & set(symbols)),
            "flags": " ".join(CORTEX_M7_FLAGS), "qp": f"DAQP {DAQP_VERSION} sources" if uses_daqp else "generated",
            "compiler": subprocess.run([gcc, "-dumpversion"], capture_output=True, text=True).stdout.strip()}


def daqp_on_arena(cc: list[str], flags: list[str], name: str, build: Path) -> tuple[list[str], list[str]]:
    """Compile DAQP's sources into ``build`` with ``cc`` and ``flags``, on the static arena.

    Their malloc, calloc and free are taken from ``<name>_qp_arena.c``.

    Parameters
    ----------
    cc : list of str
        The C compiler command.
    flags : list of str
        Compiler flags.
    name : str
        The controller's C name (prefix of the arena's allocator).
    build : Path
        The folder of the headers' copy and the object files.

    Returns
    -------
    tuple of (list of str, list of str)
        The include flags for DAQP's headers, and the object files.
    """
    daqp = daqp_sources()
    headers = build / "include"
    shutil.copytree(daqp / "include", headers / "daqp", dirs_exist_ok=True)
    include = [f"-I{headers}", f"-I{headers / 'daqp'}"]
    arena = [f"-Dmalloc={name}_qp_malloc", f"-Dcalloc={name}_qp_calloc", f"-Dfree={name}_qp_free"]
    objects = []
    for source in sorted((daqp / "src").glob("*.c")):
        objects.append(str(build / f"daqp_{source.stem}.o"))
        run([*cc, *flags, *include, *arena, "-c", str(source), "-o", objects[-1]], "build of DAQP")
    return include, objects


def casadi_daqp_on_arena(name: str, build: Path) -> tuple[list[str], list[str]]:
    """CasADi's static DAQP library with its malloc, calloc and free renamed to the arena's.

    The renaming is ``objcopy --redefine-sym``, what ``-D`` does to the sources, for a check
    on this machine without DAQP's sources. Raises :class:`DaqpSourcesMissing` when there is no
    static library, objcopy or nm, or the renamed library still calls the system allocator.

    Parameters
    ----------
    name : str
        The controller's C name (prefix of the arena's allocator).
    build : Path
        The folder of the renamed library.

    Returns
    -------
    tuple of (list of str, list of str)
        The include flags, and the renamed library.
    """
    include, libraries = library_flags("#include <daqp/")
    objcopy = shutil.which("objcopy")
    if not (len(libraries) == 1 and libraries[0].endswith(".a") and objcopy):
        raise DaqpSourcesMissing("neither DAQP's sources nor a static DAQP library with objcopy to rename its "
                                 "allocator are on this machine")
    renamed = build / "libdaqp_arena.a"
    run([objcopy, *(f"--redefine-sym={f}={name}_qp_{f}" for f in ("malloc", "calloc", "free")), libraries[0],
         str(renamed)], "renaming DAQP's allocator")
    nm = shutil.which("nm")
    left = set(subprocess.run([nm, "-u", str(renamed)], capture_output=True, text=True).stdout.split()) if nm else {""}
    if not nm or left & {"malloc", "calloc", "free", "realloc"}:
        raise DaqpSourcesMissing("CasADi's DAQP library still calls the system allocator after renaming (or nm is "
                                 "missing): its static-arena check needs DAQP's sources")
    return include, [str(renamed)]


def static_qp_loop(out: Path, name: str, recording: Path) -> tuple[np.ndarray, str]:
    """The example loop built as the firmware is, for this machine, run on ``recording``.

    As the firmware: DAQP's own sources, their malloc from ``<name>_qp_arena.c``. Without DAQP's
    sources (offline, none cached) it links CasADi's DAQP library on the same arena instead
    (:func:`casadi_daqp_on_arena`), after a notice.

    Parameters
    ----------
    out : Path
        The folder :func:`~hystmpc.mpc.codegen.controller.write_controller` wrote.
    name : str
        The controller's C name.
    recording : Path
        The sensor file the example loop reads.

    Returns
    -------
    tuple of (ndarray, str)
        The loop's inputs, one per sample, and which DAQP it linked.
    """
    cc = c_compiler()
    build = out / "static-qp"
    build.mkdir(exist_ok=True)
    flags = [*COMPILE_FLAGS, f"-I{out}"]
    try:
        include, objects = daqp_on_arena(cc, flags, name, build)
        qp = f"DAQP {DAQP_VERSION} sources"
    except DaqpSourcesMissing as exc:
        LOG.warning(f"{exc}: the static-QP check links CasADi's DAQP library on the arena instead")
        include, objects = casadi_daqp_on_arena(name, build)
        qp = "CasADi's DAQP library"
    flags += include
    program = build / f"{name}_main"
    run([*cc, *flags, *(str(out / f) for f in ("main.c", f"{name}.c", f"{name}_nmpc.c", f"{name}_qp_arena.c")),
         *objects, "-o", str(program), "-lm"], "static-QP build")
    done = subprocess.run([str(program), str(recording), str(build / "inputs.txt")], capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{program.name} (static QP) failed: {done.stderr.strip()[:500]}")
    return np.loadtxt(build / "inputs.txt", ndmin=2)[:, 0], qp
