"""Bench-level claims of the pam issue. Fast guard in the default suite; the full comparison is slow."""

import json

import numpy as np
import pytest

from hystmpc.experiments.benches.pam import BENCH
from hystmpc.experiments.cli import main
from hystmpc.experiments.report import validate_document


def test_compensation_helps_on_every_scenario():
    """vo2012's finding on our plant: PI + HC beats plain PI (same gains) on every scenario."""
    config = BENCH.configure()
    for name, scenario in BENCH.scenarios.items():
        pi = BENCH.run(scenario, "pi", config).metrics["rmse"]
        pi_hc = BENCH.run(scenario, "pi-hc", config).metrics["rmse"]
        assert pi_hc < pi, f"{name}: RMSE pi-hc {pi_hc:.4f} >= pi {pi:.4f}"


@pytest.mark.slow
def test_full_comparison_meets_the_issue(tmp_path, capsys):
    doc_path = tmp_path / "out.json"
    code = main(["compare", "pam", "--json", str(doc_path), "--out", str(tmp_path / "res"), "--quiet"])
    assert code == 0
    doc = json.loads(doc_path.read_text())
    validate_document(doc)
    runs = {(r["scenario"], r["controller"]): r for r in doc["runs"]}
    assert len(runs) == 15
    for scenario in BENCH.scenarios:
        rmse = {c: runs[(scenario, c)]["metrics"]["rmse"] for c in ("pi", "pi-hc", "nmpc")}
        assert rmse["nmpc"] <= 0.5 * rmse["pi-hc"], (scenario, rmse)
        assert rmse["pi-hc"] < rmse["pi"], (scenario, rmse)
        solver = runs[(scenario, "nmpc")]["solver"]
        assert solver["failures"] == 0 and solver["fallbacks"] == 0, (scenario, solver)
        assert (tmp_path / "res" / f"{scenario}.png").is_file()
        for c in ("pi", "pi-hc", "nmpc"):
            data = np.genfromtxt(tmp_path / "res" / "runs" / f"{scenario}__{c}.csv", delimiter=",", names=True)
            for column in ("t", "reference", "output", "input"):
                assert np.all(np.isfinite(data[column])), (scenario, c, column)
    assert (tmp_path / "res" / "rmse.png").is_file()
