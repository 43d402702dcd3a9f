"""Kinematics on Pinocchio, checked against a closed form and against MuJoCo."""

import numpy as np
import pytest

import snakekit
from snakekit import SPEC, kinematics
from tests.conftest import need

RNG = np.random.default_rng(42)
CONFIGS = RNG.uniform(SPEC.lower, SPEC.upper, (200, 5))
# limits and random poses mixed, so the sample reaches the workspace's edges
WORKSPACE_CONFIGS = np.concatenate([RNG.uniform(SPEC.lower, SPEC.upper, (20000, 5)),
                                    RNG.choice([SPEC.lower, 0.0, SPEC.upper], (3000, 5))])


def planar_fk(q):
    """Independent closed form: x = sum l_i cos(q_1 + ... + q_i), and the same for y."""
    angles = np.cumsum(q)
    L = np.array([0.071] * 4 + [0.0475])
    return np.array([(L * np.cos(angles)).sum(), (L * np.sin(angles)).sum(), angles[-1]])


def planar_jacobian_closed_form(q):
    angles = np.cumsum(q)
    L = np.array([0.071] * 4 + [0.0475])
    J = np.zeros((3, 5))
    for i in range(5):
        J[0, i] = -(L[i:] * np.sin(angles[i:])).sum()
        J[1, i] = (L[i:] * np.cos(angles[i:])).sum()
        J[2, i] = 1.0
    return J


def wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def test_home_pose_is_straight_along_x():
    T = snakekit.forward_kinematics(np.zeros(5))
    np.testing.assert_allclose(T, [[1, 0, 0, 0.3315], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], atol=1e-15)


def test_fk_matches_closed_form_to_1e12():
    for q in CONFIGS:
        T = snakekit.forward_kinematics(q)
        x, y, th = planar_fk(q)
        assert abs(T[0, 3] - x) < 1e-12 and abs(T[1, 3] - y) < 1e-12 and abs(T[2, 3]) < 1e-12
        assert abs(wrap(np.arctan2(T[1, 0], T[0, 0]) - th)) < 1e-12
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)


def test_joint_frames_sit_on_the_joint_axes():
    q = CONFIGS[0]
    frames = snakekit.joint_frames(q)
    assert frames.shape == (6, 4, 4)
    angles = np.concatenate([[0], np.cumsum(q)])
    expected = np.cumsum([[0.071 * np.cos(a), 0.071 * np.sin(a)] for a in angles[1:5]], axis=0)
    np.testing.assert_allclose(frames[0, :2, 3], 0, atol=1e-15)
    np.testing.assert_allclose(frames[1:5, :2, 3], expected, atol=1e-12)
    np.testing.assert_allclose(frames[5], snakekit.forward_kinematics(q), atol=1e-15)


def test_fk_matches_mujoco_on_the_generated_mjcf():
    mujoco = need("mujoco")
    from snakekit.model import MJCF_PATH

    m = mujoco.MjModel.from_xml_path(str(MJCF_PATH))
    d = mujoco.MjData(m)
    for q in CONFIGS[:50]:
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        T = snakekit.forward_kinematics(q)
        np.testing.assert_allclose(d.site("tool").xpos, T[:3, 3], atol=1e-12)
        np.testing.assert_allclose(d.site("tool").xmat.reshape(3, 3), T[:3, :3], atol=1e-12)
        for i, F in enumerate(snakekit.joint_frames(q)[:5]):
            np.testing.assert_allclose(d.body(f"link{i + 1}").xpos, F[:3, 3], atol=1e-12)


def test_jacobian_matches_closed_form_and_finite_differences():
    for q in CONFIGS[:50]:
        J = snakekit.jacobian(q)
        assert J.shape == (6, 5)
        np.testing.assert_allclose(snakekit.planar_jacobian(q), planar_jacobian_closed_form(q), atol=1e-12)
        # planar arm: no z motion, no roll/pitch
        np.testing.assert_allclose(J[[2, 3, 4]], 0, atol=1e-12)
        h = 1e-7
        fd = np.stack([(planar_fk(q + h * e) - planar_fk(q - h * e)) / (2 * h) for e in np.eye(5)], 1)
        np.testing.assert_allclose(snakekit.planar_jacobian(q), fd, atol=1e-7)


def test_ik_round_trips_on_random_reachable_targets():
    failures = 0
    for q in CONFIGS[:150]:
        target = planar_fk(q)[:2]
        try:
            sol = snakekit.inverse_kinematics(target)
        except snakekit.UnreachableTargetError:
            failures += 1
            continue
        assert np.all(sol >= SPEC.lower) and np.all(sol <= SPEC.upper)
        np.testing.assert_allclose(planar_fk(sol)[:2], target, atol=2e-6)
    assert failures <= 1


def test_ik_with_heading_reaches_position_and_heading():
    for q in CONFIGS[:40]:
        x, y, th = planar_fk(q)
        sol = snakekit.inverse_kinematics([x, y], heading=th)
        got = planar_fk(sol)
        np.testing.assert_allclose(got[:2], [x, y], atol=2e-6)
        assert abs(wrap(got[2] - th)) < 2e-6


def test_ik_out_of_reach_names_the_closest_point():
    with pytest.raises(snakekit.UnreachableTargetError) as e:
        snakekit.inverse_kinematics([0.5, 0.0])
    err = e.value
    assert "out of reach" in str(err) and "0.3315 m" in str(err)
    np.testing.assert_allclose(err.closest, [SPEC.reach, 0.0], atol=1e-4)
    np.testing.assert_allclose(planar_fk(err.q_closest)[:2], err.closest, atol=1e-12)


@pytest.mark.parametrize("target", [(0.5, 0.0), (0.0, 0.5), (-0.4, 0.1), (-0.3, -0.3), (0.0, -0.34),
                                    (-0.2, 0.3), (-0.33, 0.0)])
@pytest.mark.parametrize("q0", [None, [1.0, -1.2, 1.3, 0.5, -0.4], [1.5] * 5])
def test_ik_closest_point_is_the_closest_whatever_the_start(target, q0):
    """Independent check: no point of a dense sample of the workspace lies closer to the target."""
    angles = np.cumsum(WORKSPACE_CONFIGS, axis=1)
    L = np.array([0.071] * 4 + [0.0475])
    samples = np.column_stack([(L * np.cos(angles)).sum(axis=1), (L * np.sin(angles)).sum(axis=1)])
    with pytest.raises(snakekit.UnreachableTargetError) as e:
        snakekit.inverse_kinematics(target, q0=q0)
    got = np.linalg.norm(np.subtract(e.value.closest, target))
    best_sampled = np.linalg.norm(samples - target, axis=1).min()
    assert got <= best_sampled + 1e-6, (e.value.closest, got, best_sampled)
    assert np.all(np.abs(e.value.q_closest) <= SPEC.upper)
    np.testing.assert_allclose(planar_fk(e.value.q_closest)[:2], e.value.closest, atol=1e-12)


def test_ik_target_behind_the_base_blocked_by_limits():
    # Straight behind joint 1 at full reach needs joint 1 at pi: outside +-1.57.
    with pytest.raises(snakekit.UnreachableTargetError, match="joint limits|out of reach"):
        snakekit.inverse_kinematics([-0.33, 0.0])


def test_workspace_points_lie_inside_the_reach():
    pts = snakekit.workspace_points(2000)
    assert pts.shape == (2000, 2)
    assert np.linalg.norm(pts, axis=1).max() <= SPEC.reach + 1e-12
    q = np.random.default_rng(0).uniform(SPEC.lower, SPEC.upper, (2000, 5))
    np.testing.assert_allclose(pts[:5], [planar_fk(x)[:2] for x in q[:5]], atol=1e-12)


@pytest.mark.parametrize("bad, err, text", [
    (np.zeros(4), snakekit.ShapeError, "shape (5,), got shape (4,)"),
    (np.zeros((5, 1)), snakekit.ShapeError, "shape (5,)"),
    ([0, 0, np.nan, 0, 0], snakekit.NotFiniteError, "NaN"),
])
def test_fk_rejects_bad_configurations(bad, err, text):
    with pytest.raises(err) as e:
        snakekit.forward_kinematics(bad)
    assert text in str(e.value)


def test_check_limits_names_the_joint():
    with pytest.raises(snakekit.LimitError) as e:
        kinematics.check_limits([0, 0, 2.0, 0, 0])
    assert "joint 3 = 2.0000 rad" in str(e.value)
    assert e.value.violations == [(3, 2.0, -1.57, 1.57)]


def test_ik_rejects_a_malformed_target():
    with pytest.raises(snakekit.ShapeError, match=r"target_xy must have shape \(2,\)"):
        snakekit.inverse_kinematics([0.1, 0.1, 0.0])
    with pytest.raises(snakekit.NotFiniteError):
        snakekit.inverse_kinematics([np.inf, 0.1])


def test_dls_step_is_the_damped_least_squares_step_of_lesson_3():
    """q + J^T (J J^T + lambda^2 I)^-1 e, with J and e from the closed form."""
    from snakekit.errors import ShapeError
    from snakekit.kinematics import dls_step

    rng = np.random.default_rng(3)
    for q, target, lam in [(np.zeros(5), np.array([0.25, 0.1]), 1e-3)] + [
            (rng.uniform(-1.2, 1.2, 5), rng.uniform(-0.2, 0.25, 2), 10 ** rng.uniform(-3, -1)) for _ in range(5)]:
        J = planar_jacobian_closed_form(q)[:2]
        expected = q + J.T @ np.linalg.solve(J @ J.T + lam ** 2 * np.eye(2), target - planar_fk(q)[:2])
        assert np.allclose(dls_step(q, target, lam), expected, rtol=1e-9, atol=1e-9)
    with pytest.raises(ShapeError, match=r"target_xy must have shape \(2,\)"):
        dls_step(np.zeros(5), (0.1, 0.2, 0.3))
