"""Everything that writes, compiles, caches and cross-compiles C.

* :mod:`~hystmpc.mpc.codegen.toolchain`: the C compiler and its flags, the build cache,
  :func:`compile_function` (one CasADi Function compiled and loaded back: the ``rti-c``
  solver), and the templates (``templates/``: the C and Makefile texts written around
  generated code);
* :mod:`~hystmpc.mpc.codegen.controller`: the whole NMPC controller as C files
  (:func:`write_controller` from a :class:`ControllerCode`, which
  :func:`hystmpc.mpc.embedded.controller_code` makes from a controller), built once per
  source (:func:`build_cached`) and driven from Python (:class:`CompiledController`);
* :mod:`~hystmpc.mpc.codegen.step`: the RTI step alone, with a replay program;
* :mod:`~hystmpc.mpc.codegen.firmware`: the Cortex-M7 cross build and DAQP's sources on a
  static arena.

Nothing here imports the rest of :mod:`hystmpc.mpc`: it turns CasADi Functions into C.
"""

from hystmpc.mpc.codegen.controller import (
    STATUS_CODES,
    CompiledController,
    ControllerCode,
    Signals,
    build_cached,
    c_name,
    write_controller,
)
from hystmpc.mpc.codegen.firmware import cross_compile, daqp_sources, static_qp_loop
from hystmpc.mpc.codegen.step import RecordingStep, run_program, write_step
from hystmpc.mpc.codegen.toolchain import (
    COMPILE_FLAGS,
    CompilerNotFound,
    c_compiler,
    cache_dir,
    compile_function,
    compiled_or_in_process,
    compiled_or_slower,
    library_flags,
    user_cache_dir,
)

__all__ = ["COMPILE_FLAGS", "STATUS_CODES", "CompiledController", "CompilerNotFound", "ControllerCode", "RecordingStep",
           "Signals", "build_cached", "c_compiler", "c_name", "cache_dir", "compile_function", "compiled_or_in_process",
           "compiled_or_slower", "cross_compile", "daqp_sources", "library_flags", "run_program", "static_qp_loop",
           "user_cache_dir", "write_controller", "write_step"]
