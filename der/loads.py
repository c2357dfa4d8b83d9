"""External loads: what they are (small data records) and their generalized forces (numba kernels).

Every load becomes a generalized force ``f_ext`` on the state vector (node forces on x, moments about the
tangent on theta) and, where it depends on the configuration, a load stiffness ``-d f_ext / d q``.

A torque ``tau`` on the material frame of edge ``j`` acts through its two parts: ``tau . t_j`` on theta_j, and
the normal part as a couple of node forces ``+-(tau x t_j) / |e_j|`` on the edge's end nodes (so that
``e_j x f = tau - (tau . t_j) t_j``).

Sign conventions: a positive moment about t over-twists the rod (right-handed about t, the direction of
increasing arc length). Densities are per unit *rest* length.
"""
from dataclasses import dataclass

import numpy as np
from numba import njit

from .stencils import edge_dofs, scatter_band


@dataclass(frozen=True)
class PointForce:
    """A dead force ``force`` (3-vector, force units) on node ``node`` (negative indices count from the end)."""
    node: int
    force: tuple


@dataclass(frozen=True)
class EndForce:
    """A dead force ``force`` (3-vector) on the end cross-section ``end`` ("start" or "end").

    It acts at the end edge's midpoint -- the rod's end, xi = 0 or L -- as half the force on each of its nodes.
    """
    end: str
    force: tuple


@dataclass(frozen=True)
class DistributedForce:
    """A dead force per unit rest length ``density`` (3-vector), lumped to nodes by Voronoi length."""
    density: tuple


@dataclass(frozen=True)
class EndTorque:
    """A torque on the end cross-section at ``end`` ("start" or "end").

    ``follower=False``: a dead torque, ``torque`` a fixed 3-vector (force * length).
    ``follower=True``: ``torque`` a scalar T about the current end tangent (positive over-twists).
    """
    end: str
    torque: object
    follower: bool = False


@dataclass(frozen=True)
class TwistingMoment:
    """A distributed moment ``density`` (force * length / length) about the current tangent (a follower load)."""
    density: float


def point_force(node, force):
    return PointForce(int(node), tuple(float(f) for f in force))


def end_force(force, end="end"):
    return EndForce(end, tuple(float(f) for f in force))


def distributed_force(density):
    return DistributedForce(tuple(float(f) for f in density))


def end_torque(torque, end="end", follower=False):
    if follower:
        return EndTorque(end, float(torque), True)
    return EndTorque(end, tuple(float(f) for f in torque), False)


def twisting_moment(density):
    return TwistingMoment(float(density))


# ---------------------------------------------------------------------------------------------
# kernels
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def add_nodal_forces(nodal, fext):
    """fext[4k:4k+3] += nodal[k] (dead point and distributed forces, already lumped per node)."""
    for k in range(nodal.shape[0]):
        for i in range(3):
            fext[4 * k + i] += nodal[k, i]


@njit(cache=True)
def add_theta_moments(per_edge, fext):
    """fext[4j+3] += per_edge[j] (follower moments about the tangent, already integrated per edge)."""
    for j in range(per_edge.shape[0]):
        fext[4 * j + 3] += per_edge[j]


@njit(cache=True)
def add_dead_torques(q, edge_nodes, edges, torques, order, fext, ab, kl, ku, perm):
    """Dead torque vectors ``torques[i]`` on the material frames of ``edges[i]``; with order >= 2 also their
    load stiffness ``-d fext / d q`` into the band matrix."""
    dofs = np.empty(6, dtype=np.int64)
    K = np.zeros((7, 7))
    for i in range(edges.shape[0]):
        j = edges[i]
        a = 4 * edge_nodes[j, 0]
        b = 4 * edge_nodes[j, 1]
        e = np.empty(3)
        for k in range(3):
            e[k] = q[b + k] - q[a + k]
        le = np.sqrt(e[0] ** 2 + e[1] ** 2 + e[2] ** 2)
        t = e / le
        tau = torques[i]
        tt = tau[0] * t[0] + tau[1] * t[1] + tau[2] * t[2]
        fb = np.empty(3)   # force on the end node b of the couple
        fb[0] = (tau[1] * t[2] - tau[2] * t[1]) / le
        fb[1] = (tau[2] * t[0] - tau[0] * t[2]) / le
        fb[2] = (tau[0] * t[1] - tau[1] * t[0]) / le
        fext[4 * j + 3] += tt
        for k in range(3):
            fext[b + k] += fb[k]
            fext[a + k] -= fb[k]
        if order < 2:
            continue
        # d(tau.t)/de = (tau - (tau.t) t) / |e|
        # d fb / de = ([tau]_x (I - t t^T) - (tau x t) t^T) / |e|^2
        P = np.empty((3, 3))
        for r in range(3):
            for s in range(3):
                P[r, s] = (1.0 if r == s else 0.0) - t[r] * t[s]
        tx = np.zeros((3, 3))
        tx[0, 1] = -tau[2]
        tx[0, 2] = tau[1]
        tx[1, 0] = tau[2]
        tx[1, 2] = -tau[0]
        tx[2, 0] = -tau[1]
        tx[2, 1] = tau[0]
        dfb = tx @ P
        for r in range(3):
            for s in range(3):
                dfb[r, s] = (dfb[r, s] - fb[r] * le * t[s]) / (le * le)
        dtt = (tau - tt * t) / le
        # local DOFs: [x_a (3), x_b (3), theta_j]; e = x_b - x_a; stiffness = -d fext / d q
        for r in range(7):
            for s in range(7):
                K[r, s] = 0.0
        for r in range(3):
            for s in range(3):
                K[3 + r, 3 + s] = -dfb[r, s]
                K[3 + r, s] = dfb[r, s]
                K[r, 3 + s] = dfb[r, s]
                K[r, s] = -dfb[r, s]
            K[6, 3 + r] = -dtt[r]
            K[6, r] = dtt[r]
        edge_dofs(edge_nodes, j, dofs)
        full = np.empty(7, dtype=np.int64)
        for r in range(6):
            full[r] = dofs[r]
        full[6] = 4 * j + 3
        scatter_band(ab, kl, ku, perm, full, K, 1.0)
