"""CPU time of moving supports in der.simulate: cosseratbench's twist experiment (six rods, each with a clamp
turned and sliding, 1600 steps of 0.01 s each) through der's adapter, for whichever der is on the path.

Side by side, old and new der in one command (numba caches warmed by the first, untimed, run of each):

    git archive c7c4f2b der | tar -x -C /tmp/old
    for i in 1 2; do for p in /tmp/old .; do PYTHONPATH=$p python tools/bench_moving_supports.py; done; done

Prints the CPU time (time.process_time) of the run, the wall time, the load, der's path and the metric.
"""
import os
import time

import der
from cosseratbench.experiments.twist import critical_twist_error, twist
from der.bench import DerSolver


def main():
    scenario = twist.scenario
    solver = DerSolver()
    import dataclasses

    solver.run(dataclasses.replace(scenario, duration=0.05), n_elements=twist.n_elements, n_frames=2)   # JIT/cache
    c0, w0 = time.process_time(), time.perf_counter()
    traj = solver.run(scenario, n_elements=twist.n_elements, n_frames=twist.n_frames)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    print(f"{os.path.dirname(der.__file__)}: twist CPU {cpu:.2f} s, wall {wall:.2f} s, critical_twist_error "
          f"{critical_twist_error(scenario, traj):.4e}, load {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
