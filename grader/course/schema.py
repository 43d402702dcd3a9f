"""The gradebook's schema version, read in this process rather than in a new one.

nbgrader stamps a new gradebook with the head of its alembic migrations, which it reads by running
``alembic heads`` in a new Python process (``nbgrader.api.get_alembic_version``): about 2 s, paid by
the first command in every new course folder (and by every test that makes one). :func:`install`
has nbgrader read the same head here, with alembic's own ``ScriptDirectory`` over nbgrader's own
migration scripts: the same answer, without the process. Installed when :mod:`grader.course` is
imported; nbgrader itself is imported only when a command needs it (this module imports neither).
"""

from __future__ import annotations

import functools
import importlib.abc
import sys

__all__ = ["alembic_head", "install"]

_MODULE = "nbgrader.api"


@functools.cache
def alembic_head() -> str:
    """The head revision of nbgrader's gradebook migrations (what ``alembic heads`` prints first)."""
    from alembic.config import Config
    from alembic.script import ScriptDirectory
    from nbgrader.dbutil import ALEMBIC_DIR

    config = Config()
    config.set_main_option("script_location", ALEMBIC_DIR)
    heads = ScriptDirectory.from_config(config).get_heads()
    return heads[0]


def _patch(module) -> None:
    module.get_alembic_version = alembic_head


class _OnImport(importlib.abc.MetaPathFinder):
    """Patches ``nbgrader.api`` as soon as it is imported, wherever that happens first."""

    def find_spec(self, fullname, path, target=None):
        if fullname != _MODULE:
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(fullname, path, target)
            if spec is not None and spec.loader is not None and hasattr(spec.loader, "exec_module"):
                run = spec.loader.exec_module

                def exec_module(module, run=run):
                    run(module)
                    _patch(module)

                spec.loader.exec_module = exec_module
                return spec
        return None


_HOOK = _OnImport()


def install() -> None:
    """From now on, nbgrader stamps a new gradebook with :func:`alembic_head` (idempotent)."""
    module = sys.modules.get(_MODULE)
    if module is not None:
        _patch(module)
    elif _HOOK not in sys.meta_path:
        sys.meta_path.insert(0, _HOOK)
