"""Every public name (each part's ``__all__``) and every public method of a public class has a
docstring: the API reference (``mkdocs build --strict`` in CI) is generated from them."""

import importlib
import inspect

import pytest

PARTS = ("hystmpc.models", "hystmpc.plants", "hystmpc.mpc", "hystmpc.mpc.codegen", "hystmpc.experiments",
         "hystmpc.experiments.baselines")


def _undocumented(part: str) -> list[str]:
    module = importlib.import_module(part)
    missing = []
    for name in module.__all__:
        obj = getattr(module, name)
        if (inspect.isclass(obj) or inspect.isfunction(obj)) and not (obj.__doc__ or "").strip():
            missing.append(name)
        if inspect.isclass(obj):
            for attr, value in vars(obj).items():
                method = value.__func__ if isinstance(value, (staticmethod, classmethod)) else value
                if (not attr.startswith("_") and inspect.isfunction(method) and method.__name__ != "<lambda>"
                        and not (method.__doc__ or "").strip()):
                    missing.append(f"{name}.{attr}")
    return missing


@pytest.mark.parametrize("part", PARTS)
def test_every_public_name_has_a_docstring(part):
    assert _undocumented(part) == []
