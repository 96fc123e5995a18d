"""Shared fixtures: fresh objects for every test, nothing stateful at import."""

import numpy as np
import pytest

from hystmpc.models.maxwell_slip import MaxwellSlip


@pytest.fixture
def table1() -> MaxwellSlip:
    """vo2012 Table 1."""
    return MaxwellSlip(k=(0.0557, 0.0170, 0.0021, 0.0033), w=(0.1680, 0.1383, 0.0342, 0.1335))


@pytest.fixture
def reversing_input():
    """A random walk in degrees with many reversals, starting at 0."""
    rng = np.random.default_rng(7)
    u = np.cumsum(rng.normal(0.0, 2.5, 400))
    u[0] = 0.0
    return u


@pytest.fixture(scope="session", autouse=True)
def private_cache(tmp_path_factory):
    """Tuned baseline gains are cached on disk; the tests use their own cache, fresh per session.
    Compiled solvers stay where they were (they depend on nothing a test changes)."""
    import os

    from hystmpc.mpc.codegen import cache_dir
    os.environ["HYSTMPC_CACHE"] = str(cache_dir())
    os.environ["HYSTMPC_CACHE_DIR"] = str(tmp_path_factory.mktemp("cache"))


def numpy_uses_the_c_library(name: str) -> bool:
    """Whether NumPy's float64 ``name`` (``exp``, ``log`` or ``power``) on arrays returns
    ``math``'s results bit for bit. On AVX-512 machines NumPy has its own vectorised versions,
    within an ulp of the C library's but not equal to them."""
    import math

    x = np.random.default_rng(0).uniform(0.1, 20.0, 4000)
    if name == "power":
        return bool(np.array_equal(np.power(x, 0.25), [math.pow(v, 0.25) for v in x]))
    return bool(np.array_equal(getattr(np, name)(x), [getattr(math, name)(v) for v in x]))
