"""The README's Python API example runs as written."""

import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_api_example_runs(tmp_path, monkeypatch, capsys):
    section = README.read_text().split("## Python API", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "readme"}
    exec(compile(code, "README.md", "exec"), namespace)
    assert re.search(r"RMSE [0-9.]+ um, 0 failed solves", capsys.readouterr().out)
    run = namespace["run"]
    assert run.metrics["rmse"] < 0.05  # 2–13 um at 5 Hz (noise 0.005 um)
    error = (run.reference - run.output)[100:]  # after the first 0.1 s (the start)
    assert np.sqrt(np.mean(error**2)) < 0.03
    assert (tmp_path / "piezo.png").stat().st_size > 10_000
