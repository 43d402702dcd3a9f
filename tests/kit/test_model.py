"""The robot description: the spec's numbers, and the generated URDF/MJCF kept current."""

import xml.etree.ElementTree as ET

import numpy as np
import pytest

import snakekit
from snakekit import model
from snakekit.cli import main
from tests.conftest import need


def test_spec_holds_the_arms_numbers():
    s = snakekit.SPEC
    assert s.n_joints == 5 and s.servo_ids == (1, 2, 3, 4, 5)
    assert s.link_length == 0.071 and s.tool_offset == 0.0475
    assert s.reach == pytest.approx(4 * 0.071 + 0.0475) == pytest.approx(0.3315)
    assert (s.lower, s.upper, s.velocity_limit) == (-1.57, 1.57, 1.5)
    assert s.servo.mass == 0.077 and s.servo.stall_torque == 2.5 and s.servo.model_number == 30


def test_committed_files_match_the_spec():
    assert model.stale_files() == [], "run `snakekit generate` and commit snakekit/assets"
    assert main(["generate", "--check"]) == 0


def test_check_reports_a_stale_file(tmp_path, monkeypatch, capsys):
    stale = tmp_path / "snake.urdf"
    stale.write_text(model.urdf().replace("0.071", "0.072"))
    monkeypatch.setattr(model, "GENERATED", {stale: model.urdf, model.MJCF_PATH: model.mjcf})
    assert model.main(["--check"]) == 1
    assert "snake.urdf is stale" in capsys.readouterr().err


def test_urdf_joints_carry_the_limits():
    root = ET.fromstring(model.urdf())
    joints = [j for j in root.iter("joint") if j.get("type") == "revolute"]
    assert [j.get("name") for j in joints] == list(snakekit.SPEC.joint_names)
    for j in joints:
        lim = j.find("limit")
        assert float(lim.get("lower")) == -1.57 and float(lim.get("upper")) == 1.57
        assert float(lim.get("velocity")) == 1.5 and float(lim.get("effort")) == 2.5
        assert j.find("axis").get("xyz") == "0 0 1"


def test_urdf_and_mjcf_have_the_same_masses():
    mujoco = need("mujoco")
    root = ET.fromstring(model.urdf())
    urdf_masses = [float(link.find("inertial/mass").get("value"))
                   for link in root.iter("link") if link.find("inertial") is not None]
    m = mujoco.MjModel.from_xml_path(str(model.MJCF_PATH))
    mj_masses = [m.body(f"link{i + 1}").mass[0] for i in range(5)]
    np.testing.assert_allclose(mj_masses, urdf_masses, rtol=1e-5)
    # each link but the last carries the next servo (77 g) and its bracket
    assert all(0.077 < x < 0.1 for x in mj_masses[:4])
    assert sum(mj_masses) == pytest.approx(4 * (0.077 + 0.012) + 0.012 + 0.005, rel=1e-5)


def test_composite_inertia_matches_parallel_axis_by_hand():
    # one box of 1 kg (size 0.1 x 0.2 x 0.3) at x=1 and a point-like 1 kg box at x=-1
    mass, com, inertia = model._combine([(1.0, (1, 0, 0), (0.1, 0.2, 0.3)), (1.0, (-1, 0, 0), (0, 0, 0))])
    assert mass == 2 and np.allclose(com, 0)
    assert inertia[2, 2] == pytest.approx((0.1**2 + 0.2**2) / 12 + 2 * 1.0)
    assert inertia[0, 0] == pytest.approx((0.2**2 + 0.3**2) / 12)
