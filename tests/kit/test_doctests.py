"""The worked examples in the docstrings are true: every module that has some is run."""

import doctest
import importlib
import pkgutil
from pathlib import Path

import pytest

import snakekit

PACKAGE = Path(snakekit.__file__).parent
MODULES = sorted(
    info.name for info in pkgutil.walk_packages([str(PACKAGE)], "snakekit.")
    if ">>>" in (PACKAGE.joinpath(*info.name.split(".")[1:]).with_suffix(".py").read_text()
                 if not info.ispkg else (PACKAGE.joinpath(*info.name.split(".")[1:]) / "__init__.py").read_text())
)


def test_the_modules_with_examples_are_found():
    for name in ("snakekit.kinematics", "snakekit.trajectory", "snakekit.hardware.registers", "snakekit.validate"):
        assert name in MODULES


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.failed == 0
