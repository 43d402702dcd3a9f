"""The worked examples in the docstrings are true."""

import doctest
import importlib

import pytest

MODULES = ["snakekit.kinematics", "snakekit.trajectory", "snakekit.robot", "snakekit.servo"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.failed == 0
    if name != "snakekit.robot" and name != "snakekit.servo":
        assert result.attempted > 0
