"""Obstacle surfaces (hpcwedge/models/obstacle.py) against a brute force: the distance of a
point to a cone's nappe and the normal there, from the nearest of densely sampled surface
points refined by a local minimisation; the nearest surface chosen, a far point or the apex
named, normals turned into the body, every bad table named by its key."""
import math

import numpy as np
import pytest
from scipy.optimize import minimize

from hpcwedge.models.obstacle import Cone, Plane, obstacle_frames, orient_into_body, parse_obstacles


def _nappe_point(cone: Cone, s: float, theta: float, e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
    """The point of the nappe at slant length s >= 0 and azimuth theta (3D)."""
    radial = math.cos(theta) * e1 + math.sin(theta) * e2
    return cone.apex + s * (math.cos(cone.alpha) * cone.axis + math.sin(cone.alpha) * radial)


def _nearest_on_nappe(cone: Cone, x: np.ndarray) -> np.ndarray:
    """The foot of x on the nappe by brute force: the best of a 400 x 720 grid in (s, theta),
    polished by Nelder-Mead (s kept >= 0 by |s|)."""
    e1 = np.cross(cone.axis, [1.0, 0.0, 0.0] if abs(cone.axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(cone.axis, e1)
    S, T = np.meshgrid(np.linspace(0.0, 4.0, 400), np.linspace(0.0, 2 * math.pi, 720), indexing="ij")
    R = np.cos(T)[..., None] * e1 + np.sin(T)[..., None] * e2
    P = cone.apex + S[..., None] * (math.cos(cone.alpha) * cone.axis + math.sin(cone.alpha) * R)
    k = np.unravel_index(np.argmin(np.linalg.norm(P - x, axis=-1)), S.shape)
    res = minimize(lambda v: np.linalg.norm(_nappe_point(cone, abs(v[0]), v[1], e1, e2) - x),
                   [S[k], T[k]], method="Nelder-Mead", options={"xatol": 1e-12, "fatol": 1e-14, "maxiter": 4000})
    return _nappe_point(cone, abs(res.x[0]), res.x[1], e1, e2)


def test_cone_distance_and_normal_are_the_nearest_surface_point_3d():
    rng = np.random.default_rng(3)
    axis = np.array([0.2, -0.1, 1.0]) / np.linalg.norm([0.2, -0.1, 1.0])
    cone = Cone(np.array([0.1, 0.2, -0.3]), axis, math.radians(25.0))
    X = cone.apex + rng.uniform(-1.5, 1.5, (12, 3)) + 1.2 * axis
    X = np.vstack([X, cone.apex - 0.7 * axis + [0.05, 0.0, 0.0]])      # behind the apex: the apex is nearest
    d = cone.distance(X)
    n, t1 = cone.frame(X)
    for x, dx, nx, tx in zip(X, d, n, t1):
        foot = _nearest_on_nappe(cone, x)
        assert abs(dx - np.linalg.norm(x - foot)) <= 1e-7 * max(1.0, dx)
        if dx > 1e-3 and np.linalg.norm(foot - cone.apex) > 1e-3:     # the normal of the foot's tangent plane
            v = (x - foot) / np.linalg.norm(x - foot)
            assert abs(abs(v @ nx) - 1.0) <= 1e-6
            assert abs(tx @ nx) <= 1e-14 and abs(tx @ axis) <= 1e-14 and abs(np.linalg.norm(tx) - 1) <= 1e-14


def test_plane_and_2d_v_against_their_definitions():
    plane = Plane(np.array([0.0, 1.0]), np.array([0.6, 0.8]))
    X = np.array([[1.0, 2.0], [-3.0, 0.5], [0.0, 1.0]])
    np.testing.assert_allclose(plane.distance(X), np.abs((X - [0.0, 1.0]) @ [0.6, 0.8]), rtol=0, atol=1e-15)
    assert plane.frame(X)[1] is None
    # a V with apex 0, axis +y, half-angle 30 deg: its walls are the rays at +-30 deg from +y
    v = Cone(np.zeros(2), np.array([0.0, 1.0]), math.radians(30.0))
    walls = [np.array([math.sin(math.radians(a)), math.cos(math.radians(a))]) for a in (30.0, -30.0)]
    for x in np.array([[0.3, 1.0], [-0.8, 0.4], [2.0, 0.1], [0.0, -1.0]]):
        feet = [max(x @ w, 0.0) * w for w in walls]                     # projection onto each ray
        want = min(np.linalg.norm(x - f) for f in feet)
        assert abs(v.distance(x[None])[0] - want) <= 1e-14
    n, t = v.frame(np.array([[0.5, 1.0], [-0.5, 1.0]]))
    assert t is None
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose([n[0] @ walls[0], n[1] @ walls[1]], 0.0, atol=1e-15)


def test_obstacle_frames_takes_the_nearest_surface_and_names_bad_points():
    floor = Plane(np.zeros(3), np.array([0.0, 0.0, 1.0]))
    wall = Plane(np.array([1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]))
    X = np.array([[0.2, 0.3, 0.0], [1.0, 0.5, 0.7], [1.0, 0.2, 0.0]])
    n, t1 = obstacle_frames(X, [floor, wall], 1e-6, np.array([10, 11, 12]))
    np.testing.assert_allclose(n, [[0, 0, 1], [1, 0, 0], [0, 0, 1]], atol=0)      # ties: the first surface
    assert t1 is None                                                              # planes prefer no tangent
    with pytest.raises(ValueError, match=r"obstacle: contact node 11 \(contact position 1\) is 0.1 from"):
        obstacle_frames(np.array([[0.2, 0.3, 0.0], [0.3, 0.5, 0.1]]), [floor], 1e-6, np.array([10, 11]))
    cone = Cone(np.zeros(3), np.array([0.0, 0.0, 1.0]), math.radians(20.0))
    with pytest.raises(ValueError, match=r"obstacle\[0\]: contact node 7 .* apex"):
        obstacle_frames(np.zeros((1, 3)), [cone], 1e-6, np.array([7]))
    # a cone node gets the circumferential tangent, a plane node in the same body the default one
    x = np.array([[math.sin(math.radians(20.0)), 0.0, math.cos(math.radians(20.0))], [0.0, 0.0, -5.0]])
    n, t1 = obstacle_frames(x, [cone, Plane(np.array([0.0, 0.0, -5.0]), np.array([0.0, 0.0, 1.0]))], 1e-9,
                            np.array([0, 1]))
    np.testing.assert_allclose(t1[0], [0.0, 1.0, 0.0], atol=1e-15)
    assert abs(t1[1] @ n[1]) <= 1e-15 and abs(np.linalg.norm(t1[1]) - 1.0) <= 1e-15


def test_orient_into_body():
    n = np.array([[0.0, 1.0], [0.0, 1.0]])
    out = orient_into_body(n, np.array([[0.1, 1.0], [0.3, -2.0]]), np.array([4, 5]))
    np.testing.assert_array_equal(out, [[0.0, 1.0], [0.0, -1.0]])
    with pytest.raises(ValueError, match=r"contact node 5 \(contact position 1\): its elements are tangent"):
        orient_into_body(n, np.array([[0.0, 1.0], [1.0, 1e-9]]), np.array([4, 5]))


@pytest.mark.parametrize("tables,msg", [
    ([], r"obstacle: expected a non-empty list"),
    ([{"type": "sphere"}], r"obstacle\[0\].type: must be \"plane\" or \"cone\""),
    ([{"type": "plane", "point": [0, 0]}], r"obstacle\[0\].normal: required for a plane"),
    ([{"type": "plane", "point": [0, 0], "normal": [0, 1], "apex": [0, 0]}], r"obstacle\[0\].apex: unknown key"),
    ([{"type": "plane", "point": [0, 0], "normal": [0, 0]}], r"obstacle\[0\].normal: zero vector"),
    ([{"type": "plane", "point": [0, 0, 0], "normal": [0, 1]}], r"obstacle\[0\].point: expected 2 coordinates"),
    ([{"type": "cone", "apex": [0, 0], "axis": [0, 1], "half_angle_deg": 90}], r"half_angle_deg: must be a number in \(0, 90\)"),
    ([{"type": "cone", "apex": [0, 0], "axis": [0, 1], "half_angle_deg": True}], r"half_angle_deg: must be a number"),
])
def test_parse_obstacles_names_the_key(tables, msg):
    with pytest.raises(ValueError, match=msg):
        parse_obstacles(tables, 2)


def test_parse_obstacles_units():
    (p, c) = parse_obstacles([{"type": "plane", "point": [0, 1], "normal": [0, 2]},
                              {"type": "cone", "apex": [0, 0], "axis": [3, 4], "half_angle_deg": 45}], 2)
    np.testing.assert_array_equal(p.normal, [0.0, 1.0])
    np.testing.assert_allclose(c.axis, [0.6, 0.8], atol=1e-16)
    assert c.alpha == math.radians(45)
