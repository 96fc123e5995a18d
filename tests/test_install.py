"""A (non-editable) install puts one package, ``hystmpc``, into site-packages, and it works
from any directory (the C templates of code generation included)."""

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PARTS = ("models", "plants", "mpc", "experiments")


def test_install_holds_hystmpc_only_and_imports_from_elsewhere(tmp_path):
    source = tmp_path / "source"  # a copy: the build writes build/ and egg-info next to the sources
    source.mkdir()
    for name in ("pyproject.toml", "README.md", *PARTS):
        copy = shutil.copytree if (ROOT / name).is_dir() else shutil.copy
        copy(ROOT / name, source / name)
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation",
                    "--target", str(site), str(source)], check=True, capture_output=True, timeout=300)
    top = {p.name for p in site.iterdir()} - {"bin"}
    assert {p for p in top if not p.endswith(".dist-info")} == {"hystmpc"}, top
    assert not (set(PARTS) & top)
    assert {p.name for p in (site / "hystmpc").iterdir()} >= set(PARTS)
    assert (site / "hystmpc" / "experiments" / "benches" / "pam.py").is_file()
    probe = ("import hystmpc.mpc, hystmpc.models, hystmpc.plants, hystmpc.experiments, hystmpc.experiments.benches.dea;"
             "import hystmpc.experiments.cli, hystmpc.experiments.baselines;"
             "from hystmpc.mpc.codegen.toolchain import template;"
             "assert '{name}_init' in template('controller.h.in') and 'rti_step' in template('step_main.c');"
             "print(hystmpc.models.__file__)")
    done = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, capture_output=True, text=True, timeout=120,
                          env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin"})
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == str(site / "hystmpc" / "models" / "__init__.py")
