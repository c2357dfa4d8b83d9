"""Bitwise fingerprint of the energy kernels, to check that a refactoring changed no floating-point operation.

    PYTHONPATH=<checkout> python tools/kernel_fingerprint.py out.npz        # on each checkout, separate processes
    python tools/kernel_fingerprint.py --compare old.npz new.npz             # np.array_equal on every array

Saves, for a helix, a ring, rods with varying stiffnesses (A1, A2, A1'), a rod with natural twist and a ring
welded with a twist, each at a random displaced state: ``solvers.system.evaluate_system`` at order 0, 1 (with
and without the forces pair) and 2 (energies, gradients, the band ``system.ab``, forces), the separate kernels
(bend/twist/stretch energy, gradient and Hessian, ``bend_twist_hessian``, ``stretch_bend_twist_*``),
``diagnostics._edge_forces`` and ``material_curvatures_all``. The solver's Newton paths follow round-off, so a
refactoring of the kernels should compare ALL BITWISE EQUAL (the one-vertex helpers of energies.bend / twist /
stretch: compared against fc425f3).
"""
import sys

import numpy as np

if len(sys.argv) == 4 and sys.argv[1] == "--compare":
    a, b = np.load(sys.argv[2]), np.load(sys.argv[3])
    assert sorted(a.files) == sorted(b.files), "different cases"
    bad = [k for k in a.files if not np.array_equal(a[k], b[k])]
    print(len(a.files), "arrays compared;", "ALL BITWISE EQUAL" if not bad else "DIFFER: %s" % bad)
    sys.exit(1 if bad else 0)

import der
from der.solvers import SolverOptions
from der.solvers.system import build_system, prepare_state, evaluate_system
from der.geometry import edge_array, edge_frames
from der.energies.bend import bend_energy, bend_gradient, bend_hessian, material_curvatures_all
from der.energies.twist import twist_energy, twist_gradient, twist_hessian
from der.energies.stretch import stretch_energy, stretch_gradient, stretch_hessian
from der.energies.vertex import bend_twist_hessian, stretch_bend_twist_hessian, stretch_bend_twist_gradient
from der import diagnostics as dg


def rods():
    yield "helix", der.rod_from_shape(der.shapes.helix(1.0, 0.5, 0.5, 200), 1.0, 1.5, EA=1e3)
    yield "ring", der.rod_from_shape(der.shapes.ring(1.0, 200), 1.0, 1.5, EA=1e3)
    nv = 199
    yield "varying", der.rod(der.shapes.helix(1.0, 0.5, 0.5, 200), A1=np.linspace(1.0, 2.0, nv),
                             A2=np.linspace(1.5, 0.5, nv), A1prime=np.linspace(0.7, 1.3, nv), EA=1e3)
    yield "varying_inext", der.rod(der.shapes.helix(1.0, 0.5, 0.5, 200), A1=np.linspace(1.0, 2.0, nv), A2=0.8)
    yield "twisted", der.rod(der.shapes.strains(3.0, 150, kappa1=0.5, kappa2=0.2, omega=0.7), A1=1.0, A2=1.5,
                             EA=1e3)
    yield "welded_ring", der.rod(der.shapes.strains(6.0, 120, kappa1=1.0, omega=0.37, closed=True),
                                 der.shapes.ring(6.0 / (2 * np.pi), 120), A1=1.0,
                                 A2=1.5, A1prime=2.0, EA=1e3).with_imposed_twist(2.5)


out = {}
for name, rod in rods():
    rng = np.random.default_rng(1)
    st = rod.displaced(rod.start_state() if hasattr(rod, "start_state") else rod.rest_state(),
                       1e-2 * rng.standard_normal((rod.n_nodes, 3)), 1e-2 * rng.standard_normal(rod.n_edges))
    scene = der.Scene(rod, loads=[der.twisting_moment(1e-3)])
    system = build_system(scene, SolverOptions())
    s = prepare_state(system, st)
    nv = rod.vertex_edges.shape[0]
    e0 = evaluate_system(system, s, 0)
    e1 = evaluate_system(system, s, 1); out[name + "_g1"] = system.grad.copy()
    F = (np.zeros((rod.n_edges, 3)), np.zeros(nv))
    e1f, forces = evaluate_system(system, s, 1, F); out[name + "_g1f"] = system.grad.copy()
    e2 = evaluate_system(system, s, 2); out[name + "_g2"] = system.grad.copy(); out[name + "_ab"] = system.ab.copy()
    out[name + "_e"] = np.array([e0, e1, e1f, e2])
    assert forces is not None, name
    out[name + "_F"] = forces[0].copy(); out[name + "_M"] = forces[1].copy()
    # the separate kernels
    p = system.plan
    q, lam, rt = s.q, s.lam, s.reference_twist
    E = edge_array(q, p.edge_nodes, s.q_lo, True)
    ed = edge_frames(q, p.edge_nodes, s.d1, E)
    ab = np.zeros_like(system.ab); kl, ku, perm = system.kl, system.ku, system.perm
    es = []
    es.append(bend_energy(ed, p.vertex_edges, p.weld, p.kappa_bar, p.voronoi, p.A1))
    es.append(twist_energy(q, p.vertex_edges, rt, p.weld, p.twist_bar, p.voronoi, p.A2))
    es.append(stretch_energy(q, p.edge_nodes, p.l_bar, p.k_stretch, lam, E))
    for k, fn, args in (
            ("bg", bend_gradient, (ed, p.vertex_nodes, p.vertex_edges, p.weld, p.kappa_bar, p.voronoi, p.A1)),
            ("tg", twist_gradient, (q, ed, p.vertex_nodes, p.vertex_edges, rt, p.weld, p.twist_bar, p.voronoi, p.A2)),
            ("sg", stretch_gradient, (q, p.edge_nodes, p.l_bar, p.k_stretch, lam))):
        g = np.zeros_like(system.grad)
        es.append(fn(*args, g, E) if k == "sg" else fn(*args, g)); out[name + "_" + k] = g
    for k, fn, args in (
            ("bh", bend_hessian, (ed, p.vertex_nodes, p.vertex_edges, p.weld, p.kappa_bar, p.voronoi, p.A1)),
            ("th", twist_hessian, (q, ed, p.vertex_nodes, p.vertex_edges, rt, p.weld, p.twist_bar, p.voronoi, p.A2)),
            ("sh", stretch_hessian, (q, p.edge_nodes, p.l_bar, p.k_stretch, lam))):
        g = np.zeros_like(system.grad); a = np.zeros_like(system.ab)
        r = fn(*args, g, a, kl, ku, perm, E) if k == "sh" else fn(*args, g, a, kl, ku, perm)
        es.append(r); out[name + "_" + k + "_g"] = g; out[name + "_" + k + "_ab"] = a
    g = np.zeros_like(system.grad); a = np.zeros_like(system.ab)
    es.extend(bend_twist_hessian(q, ed, p.vertex_nodes, p.vertex_edges, rt, p.weld, p.kappa_bar, p.twist_bar, p.voronoi,
                                 p.A1, p.A2, g, a, kl, ku, perm))
    out[name + "_bth_g"] = g; out[name + "_bth_ab"] = a
    g = np.zeros_like(system.grad); a = np.full_like(system.ab, 7.0)
    es.extend(stretch_bend_twist_hessian(q, ed, p.edge_nodes, p.vertex_nodes, p.vertex_edges, p.l_bar, p.k_stretch,
                                         lam, rt, p.weld, p.kappa_bar, p.twist_bar, p.voronoi, p.A1, p.A2, g, a, kl,
                                         ku, perm, E, False))
    out[name + "_sbth_g"] = g; out[name + "_sbth_ab"] = a
    g = np.zeros_like(system.grad)
    es.extend(stretch_bend_twist_gradient(q, ed, p.edge_nodes, p.vertex_nodes, p.vertex_edges, p.l_bar, p.k_stretch,
                                          lam, rt, p.weld, p.kappa_bar, p.twist_bar, p.voronoi, p.A1, p.A2, g, E))
    out[name + "_sbtg_g"] = g
    out[name + "_es"] = np.array(es, dtype=float)
    Fd, Md = dg._edge_forces(q, s.d1, rt, lam, p.edge_nodes, p.vertex_nodes, p.vertex_edges, p.l_bar, p.k_stretch,
                             p.kappa_bar, p.twist_bar, p.weld, p.voronoi, p.A1, p.A2, True, True, True, s.q_lo)
    out[name + "_dgF"] = Fd; out[name + "_dgM"] = Md
    out[name + "_kall"] = material_curvatures_all(ed, p.vertex_edges, p.weld)
    out[name + "_weld"] = np.asarray(p.weld, float)
np.savez(sys.argv[1], **out)
print("saved", len(out), "arrays; welds", [float(abs(out[k]).max()) for k in out if k.endswith("_weld")])
