"""mkdocs hook: the API reference reads the sources as the package ``hystmpc`` they install as.

The repository keeps the four parts as top-level folders (``models/`` ... installed as
``hystmpc.models`` ...), so before the build this lays out ``build/api/hystmpc/<part>`` as links
to them, where mkdocstrings (``paths: [build/api]``) finds them.
"""

from pathlib import Path

PARTS = ("models", "plants", "mpc", "experiments")


def on_startup(command, dirty):
    """Link ``build/api/hystmpc/<part>`` to each part's folder (before mkdocstrings looks)."""
    root = Path(__file__).resolve().parents[1]
    package = root / "build" / "api" / "hystmpc"
    package.mkdir(parents=True, exist_ok=True)
    for part in PARTS:
        link = package / part
        if not link.is_symlink():
            link.symlink_to(root / part, target_is_directory=True)
