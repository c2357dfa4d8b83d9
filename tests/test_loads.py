"""The load protocol (der/loads.py): every load record answers the Scene's check, make_plan, the solvers' load
scale and equilibrium check and the stability analysis itself; these tests pin each answer to its meaning, so
that a record answering wrongly (or a new load type without answers) fails here."""
import numpy as np
import pytest

import der
from der.loads import LOAD_TYPES, Load, LoadSums
from der.solvers.stability import _dead_directions, symmetry_modes
from der.solvers.system import build_system, prepare_state

ROD = der.rod_from_shape(der.shapes.straight(1.2, 8), A1=1.0, A2=1.5)
RING = der.rod_from_shape(der.shapes.ring(1.0, 12), A1=1.0, A2=1.0)
F = (0.3, -0.4, 1.2)          # |F| = 1.3
TAU = (-0.6, 0.0, 0.8)        # |TAU| = 1.0
L = ROD.length


def _sums(load, rod=ROD):
    sums = LoadSums(rod)
    load.add_to(sums, rod)
    return sums


# each constructor with the answers of its meaning: (record, dead vector, net (force, torque, follower),
# scale (force, moment), turns with the sections, keeps a ring's sliding)
W = float(ROD.node_weights().sum())
CASES = [
    (der.point_force(3, F), F, (F, None, False), (1.3, 0.0), False, False),
    (der.end_force(F), F, (F, None, False), (1.3, 0.0), False, False),
    (der.distributed_force(F), F, (np.multiply(F, W), None, False), (1.3 * L, 0.0), False, True),
    (der.end_torque(TAU, "start"), TAU, (None, TAU, False), (0.0, 1.0), False, False),
    (der.end_torque(-2.0, follower=True), None, (None, None, True), (0.0, 2.0), False, False),
    (der.twisting_moment(-0.5), None, (None, None, True), (0.0, 0.5 * L), False, True),
    (der.point_torque(4, TAU), TAU, (None, TAU, False), (0.0, 1.0), False, False),
    (der.point_torque(4, 2.0, follower=True), None, (None, None, True), (0.0, 2.0), False, False),
    (der.point_torque(4, (0.0, 0.0, 3.0), follower=True), None, (None, None, True), (0.0, 3.0), False, False),
    (der.point_torque(4, (0.6, 0.0, 0.8), follower=True), None, (None, None, True), (0.0, 1.0), True, False),
    (der.point_torque(4, (0.0, -1.0, 0.0), follower=True), None, (None, None, True), (0.0, 1.0), True, False),
    (der.follower_force((0.0, 0.0, -1.3)), None, (None, None, True), (1.3 * L, 0.0), False, False),
    (der.follower_force((-1.3, 0.0)), None, (None, None, True), (1.3 * L, 0.0), True, False),
    (der.follower_force((0.0, 0.5, 1.2)), None, (None, None, True), (1.3 * L, 0.0), True, False),
]


def test_every_load_type_is_covered_and_complete():
    """The table names every registered load type (a new one needs its row), and each is a complete Load."""
    assert {type(case[0]) for case in CASES} == set(LOAD_TYPES)
    assert all(issubclass(cls, Load) and not cls.__abstractmethods__ for cls in LOAD_TYPES)


@pytest.mark.parametrize("case", CASES, ids=lambda c: repr(c[0]))
def test_each_load_answers_the_protocol_with_its_meaning(case):
    load, dead, (force, torque, follower), (f, m), turns, sliding = case
    load.check(ROD)
    if dead is None:
        assert load.dead_vector() is None
    else:
        assert np.array_equal(load.dead_vector(), dead)
    got = load.net(ROD)
    assert (got[0] is None) == (force is None) and (got[1] is None) == (torque is None) and got[2] is follower
    if force is not None:
        assert np.allclose(got[0], force, rtol=1e-15, atol=0)
    if torque is not None:
        assert np.array_equal(got[1], torque)
    assert load.scale(L) == pytest.approx((f, m), rel=1e-15)
    assert load.turns_with_sections() is turns
    assert load.keeps_ring_sliding() is sliding


def test_each_load_adds_its_share_to_the_plan_sums():
    """add_to puts each load where its meaning says: dead forces on nodes, moments about the tangent on theta,
    dead torque vectors and material-frame follower torques on their edges, follower densities summed."""
    nw, ew, last = ROD.node_weights(), ROD.edge_weights(), ROD.n_edges - 1
    s = _sums(der.point_force(-2, F))
    assert s.has_nodal and np.array_equal(s.nodal[ROD.n_nodes - 2], F) and np.count_nonzero(s.nodal) == 3
    s = _sums(der.end_force(F, "start"))
    assert np.array_equal(s.nodal[:2], 0.5 * np.array([F, F])) and not s.nodal[2:].any()
    s = _sums(der.distributed_force(F))
    assert np.array_equal(s.nodal, nw[:, None] * np.array(F)[None, :])
    s = _sums(der.end_torque(TAU))
    assert s.dead_edges == [last] and s.dead_torques == [TAU] and not s.has_theta
    s = _sums(der.end_torque(-2.0, "start", follower=True))
    assert s.has_theta and s.theta[0] == -2.0 and not s.theta[1:].any() and s.dead_edges == []
    s = _sums(der.twisting_moment(-0.5))
    assert s.has_theta and np.array_equal(s.theta, -0.5 * ew)
    s = _sums(der.point_torque(-1, (0.6, 0.0, 0.8), follower=True))
    assert s.follower_torque_edges == [last] and s.follower_torques == [(0.6, 0.0, 0.8)] and not s.has_theta
    s = _sums(der.point_torque(4, 2.0, follower=True))
    assert s.theta[4] == 2.0 and s.follower_torque_edges == []
    s = LoadSums(ROD)
    for load in (der.follower_force((-1.0, 0.0)), der.follower_force((0.0, 0.5, 2.0))):
        load.add_to(s, ROD)
    assert s.has_follower and np.array_equal(s.follower_density, [-1.0, 0.5, 2.0])
    assert not (s.has_nodal or s.has_theta)


def test_an_object_that_is_no_load_record_is_refused_naming_the_constructors():
    """A hand-made object (even one with the protocol's methods but not registered) is refused before any work
    with the error that lists every constructor."""
    class Handmade:
        def __repr__(self):
            return "Handmade()"

    class LooksLikeALoad(Handmade):
        def check(self, rod):
            pass

    msg = ("der.Scene: loads: unknown load Handmade(); use der.point_force, der.end_force, der.distributed_force, "
           "der.end_torque, der.twisting_moment, der.point_torque or der.follower_force")
    for load in (Handmade(), LooksLikeALoad()):
        with pytest.raises(ValueError) as info:
            der.Scene(ROD, loads=[der.point_force(1, F), load])
        assert str(info.value) == msg
    with pytest.raises(ValueError, match=r"unknown load \(1.0, 2.0, 3.0\); use der.point_force, .* or "
                                         r"der.follower_force$"):
        der.Scene(RING, loads=[(1.0, 2.0, 3.0)])


def test_a_load_class_that_leaves_out_an_answer_cannot_be_made():
    class Partial(Load):
        def check(self, rod):
            pass

    with pytest.raises(TypeError, match="abstract"):
        Partial()


def _n_modes(scene):
    """The rank of the scene's symmetry modes at a state moved off the rest shape (on the straight rest shape the
    turn about the axis is the section turn, on the circle the sliding lies in the rigid rotation and spin)."""
    rod = scene.rod
    move = 0.05 * np.sin(np.arange(rod.n_nodes)[:, None] * np.array([0.7, 1.3, 2.1]))
    system = build_system(scene, der.SolverOptions())
    modes = symmetry_modes(system, prepare_state(system, rod.displaced(rod.rest_state(), move, np.zeros(rod.n_edges))))
    return np.linalg.matrix_rank(np.array(modes)) if modes else 0


def test_the_stability_symmetries_follow_the_loads_answers():
    """Through the stability analysis: a follower force along the tangent keeps the uniform section turn of a free
    straight rod, one with an m1 (or m2) component breaks it (so does a follower torque along m2); a dead torque
    breaks the rotations about every other axis (a follower one does not); a twisting moment keeps a uniform
    ring's sliding, a tangential follower force breaks it."""
    free = 6 + 1                               # rigid motions and the uniform section turn of a straight rod
    assert _n_modes(der.Scene(ROD)) == free
    assert _n_modes(der.Scene(ROD, loads=[der.follower_force((0.0, 0.0, -1.0))])) == free
    assert _n_modes(der.Scene(ROD, loads=[der.follower_force((-1.0, 0.0))])) == free - 1
    assert _n_modes(der.Scene(ROD, loads=[der.follower_force((0.0, 0.5))])) == free - 1
    assert _n_modes(der.Scene(ROD, loads=[der.point_torque(3, (0.0, 1.0, 0.0), follower=True)])) == free - 1
    assert _n_modes(der.Scene(ROD, loads=[der.point_torque(3, (0.0, 0.0, 1.0), follower=True)])) == free
    assert _n_modes(der.Scene(ROD, loads=[der.end_torque(1.0, follower=True)])) == free
    # a dead torque: translations, the rotation about its direction, the section turn
    assert _n_modes(der.Scene(ROD, loads=[der.end_torque((2.0, 0.0, 0.0))])) == 3 + 1 + 1
    assert _n_modes(der.Scene(ROD, loads=[der.point_torque(2, (0.0, 0.0, 2.0))])) == 3 + 1 + 1
    dirs = _dead_directions(der.Scene(ROD, loads=[der.end_torque((0.0, 0.0, 2.0)), der.end_torque(1.0, follower=True),
                                                  der.point_torque(3, (3.0, 0.0, 0.0)),
                                                  der.point_torque(2, 1.0, follower=True)]))
    assert np.array_equal(np.array(dirs), [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    ring = 6 + 1                               # rigid motions and the sliding of a uniform ring
    assert _n_modes(der.Scene(RING)) == ring
    assert _n_modes(der.Scene(RING, loads=[der.twisting_moment(0.3)])) == ring
    assert _n_modes(der.Scene(RING, loads=[der.follower_force((0.0, 0.0, 0.3))])) == ring - 1
    # a dead distributed force: translations, the rotation about it, the sliding
    assert _n_modes(der.Scene(RING, loads=[der.distributed_force((0.0, 0.0, 0.3))])) == 3 + 1 + 1


def test_register_refuses_a_class_that_is_no_load_record():
    """@register takes only Load subclasses with a constructor name: anything else would later be refused by the
    Scene with the misleading "unknown load" error."""
    from der.loads import register

    before = list(LOAD_TYPES)
    with pytest.raises(TypeError, match="subclass of der.loads.Load"):
        register(type("NotALoad", (), {"constructor": "not_a_load"}))
    with pytest.raises(TypeError, match="constructor"):
        register(type("Nameless", (Load,), {}))
    assert LOAD_TYPES == before
