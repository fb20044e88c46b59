"""The pinned dependency set: every install takes its versions from constraints.txt."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _canonical(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _pins() -> dict[str, str]:
    pins: dict[str, str] = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            name, sep, version = line.partition("==")
            assert sep, f"constraints.txt: {line!r} is not an exact pin"
            pins[_canonical(name)] = version
    return pins


def test_every_declared_dependency_is_pinned() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    declared = list(project["dependencies"])
    for extra in project["optional-dependencies"].values():
        declared += extra
    pins = _pins()
    names = {_canonical(re.split(r"[\s\[<>=!~;]", spec, maxsplit=1)[0]) for spec in declared}
    missing = sorted(names - pins.keys())
    assert not missing, f"not pinned in constraints.txt (run `make lock`): {missing}"


def test_torch_is_pinned_without_a_build_label() -> None:
    # "2.13.0" accepts both the CPU and the CUDA build of that release; "2.13.0+cpu" would make
    # a machine without PyTorch's CPU wheel index fail to install.
    assert "+" not in _pins()["torch"]


def test_every_install_step_uses_the_constraints() -> None:
    makefile = (ROOT / "Makefile").read_text()
    installs = [line for line in makefile.splitlines() if "$(PIP)" in line]
    assert installs and "-c $(CONSTRAINTS)" in makefile
