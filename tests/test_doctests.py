"""The worked examples in the docstrings are true."""

import doctest
import importlib

import pytest

MODULES = ["snakekit.kinematics", "snakekit.trajectory", "snakekit.robot", "snakekit.profile_planner",
           "snakekit.viewer.scene", "snakekit.emulator", "snakekit.emulator.bus",
           "snakekit.hardware.registers", "snakekit.hardware.bus", "snakekit.validate"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.failed == 0 and result.attempted > 0
