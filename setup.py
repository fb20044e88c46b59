"""Build hook: a built wheel carries the top-level ``static/`` folder as ``webapp/static``.

Everything else about the distribution is declared in pyproject.toml; package data cannot name a
folder outside its package, and ``static/`` stays at the top of the repository. A checkout
(editable install included) serves ``static/`` where it is: see ``webapp.app.static_dir``.
"""

from __future__ import annotations

from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

STATIC = "static"  # the repository's folder, and its name inside the installed webapp package


class BuildPyWithStatic(build_py):
    """``build_py`` that also copies ``static/`` into the built ``webapp`` package."""

    def run(self) -> None:
        super().run()
        if not self.editable_mode:  # an editable install reads the checkout's static/ in place
            self.copy_tree(STATIC, str(self._packaged_static()))

    def get_outputs(self, include_bytecode: bool = True) -> list[str]:
        """Also the copied files, so that an install's record lists them."""
        extra = [] if self.editable_mode else [str(self._packaged_static() / path.relative_to(STATIC))
                                               for path in sorted(Path(STATIC).rglob("*")) if path.is_file()]
        return [*super().get_outputs(include_bytecode), *extra]

    def _packaged_static(self) -> Path:
        return Path(self.build_lib) / "webapp" / STATIC


setup(cmdclass={"build_py": BuildPyWithStatic})
