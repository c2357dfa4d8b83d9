"""Rerun recordings (.rrd) of a solve, written without a viewer. Imported only when a recording is asked for.

Timelines: ``iteration`` (one row per solver iteration: the implicit solver's pseudo-time steps, the explicit
solver's time steps at each residual check; several solves in one recording follow each other) and
``solve_time`` (wall-clock seconds since the recording started). A pseudo-time is not a useful timeline: the
implicit solver starts with Newton's method, a pseudo-time step of 1e30.

Entities:

* ``rest/centreline`` (static): the rest shape; ``rest/m1`` (static): its material directors;
* ``rod/centreline``: the centreline, one 2-point strip per edge, coloured by alpha (default) or by material
  twist (blue negative, white zero, red positive);
* ``rod/m1``: the material director m1 on (up to ``max_arrows``) edges;
* ``rod/start_frame``, ``rod/end_frame``: t, m1, m2 of the end edges (red, green, blue);
* ``energy/<term>``: time series; ``residual/log10``: log10 of the residual (rerun's plots have no log axis);
* ``ring/linking_number``, ``ring/twist``, ``ring/writhe`` (turns): time series, for rings of up to 2,000 edges,
  on the frames whose budget has room for the writhe (O(n^2): at n = 2,000 about 35 ms, several solver
  iterations; the old recorder's writhe on every frame made recording cost 17 times the solve);
* ``status``: the solver's verdict (text log).

The recording opens on a blueprint: the rod in 3-D beside the residual and energy plots.

Cost: by default a frame is skipped when writing it would take the time spent recording above 40 % of
``max_overhead`` (10 %) of the time since the recording started (the rest is for the first and final frames
and rerun's writer thread); the first and the final state are always
written, and the first 50 ms of frames are free (a short solve of a small rod still shows its iterations).
``max_overhead=None`` writes every iteration.
The file is flushed about once a second, so a killed run loses at most that; a SIGKILL also loses the footer
(``rerun rrd verify`` says "Missing RRD footer"): README, "Recordings", gives the command that rewrites it.

Replay with ``rerun file.rrd``. rerun stores float32: positions read back agree to ~1e-7 relative.
"""
import time
import uuid

import numpy as np

from . import diagnostics as dg
from .geometry import material_frames, tangents

WRITHE_MAX_EDGES = 2000
FLUSH_SECONDS = 1.0
MIN_BUDGET_SECONDS = 0.05   # a short solve of a small rod still shows its iterations (a frame costs ~1 ms there)


def _diverging(values, scale):
    """Blue-white-red colours (uint8 RGB) for values in [-scale, scale]; grey where NaN."""
    v = np.clip(np.nan_to_num(values, nan=0.0) / (scale if scale > 0 else 1.0), -1.0, 1.0)
    out = np.empty((v.size, 3))
    pos = v >= 0
    out[pos] = np.stack([np.ones(pos.sum()), 1 - v[pos], 1 - v[pos]], axis=1)
    out[~pos] = np.stack([1 + v[~pos], 1 + v[~pos], np.ones((~pos).sum())], axis=1)
    out[np.isnan(values)] = 0.6
    return (255 * out).astype(np.uint8)


def blueprint(ring=False):
    """The layout a recording opens with: the rod in 3-D (2/3 of the width) beside the residual, energy and, for
    a ring, Lk/Tw/Wr plots, on the ``iteration`` timeline."""
    import rerun.blueprint as rrb

    plots = [rrb.TimeSeriesView(origin="/residual", name="log10 residual"),
             rrb.TimeSeriesView(origin="/energy", name="energy")]
    if ring:
        plots.append(rrb.TimeSeriesView(origin="/ring", name="Lk, Tw, Wr (turns)"))
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Spatial3DView(origin="/", contents=["/rod/**", "/rest/**"], name="rod"),
                       rrb.Vertical(*plots), column_shares=[2, 1]),
        rrb.TimePanel(timeline="iteration"), collapse_panels=False)


class Recorder:
    """Writes a solve to ``path`` (.rrd). Use as ``der.solve(..., record=path)`` or pass an instance.

    color_by : "alpha" or "twist"; max_arrows : how many m1 arrows per step at most.
    max_overhead : the largest fraction of the elapsed time spent writing frames (frames beyond it are skipped;
        the first and last are always written); None writes every iteration.
    """

    def __init__(self, path, rod, scene=None, color_by="alpha", max_arrows=200, application_id="der",
                 max_overhead=0.1):
        import rerun as rr

        if color_by not in ("alpha", "twist"):
            raise ValueError(f"color_by must be 'alpha' or 'twist'; got {color_by!r}")
        if max_overhead is not None and not (isinstance(max_overhead, (int, float)) and max_overhead > 0):
            raise ValueError(f"max_overhead must be None or a number > 0; got {max_overhead!r}")
        self.rr = rr
        self.rod = rod
        self.color_by = color_by
        self.path = str(path)
        self.max_overhead = max_overhead
        self.stride = max(1, int(np.ceil(rod.n_edges / max_arrows)))
        self.arrow_length = 0.5 * max(rod.l_bar.mean(), 0.02 * rod.length)
        self.rec = rr.RecordingStream(application_id, recording_id=str(uuid.uuid4()))
        self.rec.save(self.path, default_blueprint=blueprint(rod.closed))
        self.closed = False
        self.offset = 0   # added to iteration numbers (several solves in one recording)
        self.t_start = time.perf_counter()
        self.spent = 0.0            # seconds spent writing frames
        self.last_flush = self.t_start
        self.pending = None         # the newest state of the current iteration, written when the next begins
        self.last_written = None    # timeline value of the last row written
        self.frames = self.skipped = 0
        self.frame_cost = 0.0

    def _strips(self, x):
        e = self.rod.edge_nodes
        return np.stack([x[e[:, 0]], x[e[:, 1]]], axis=1)

    def log_rest(self):
        rod, rr = self.rod, self.rr
        state = rod.rest_state()
        x = state.positions
        self.rec.log("rest/centreline", rr.LineStrips3D(self._strips(x), colors=[[150, 150, 150]]), static=True)
        mid = 0.5 * (x[rod.edge_nodes[:, 0]] + x[rod.edge_nodes[:, 1]])
        sel = slice(None, None, self.stride)
        self.rec.log("rest/m1", rr.Arrows3D(origins=mid[sel], vectors=self.arrow_length * rod.rest_d1[sel],
                                            colors=[[120, 200, 120]]), static=True)

    def log_step(self, iteration, state, residual, energies):
        """Note the state of an iteration. A solver may report one iteration more than once (a multiplier
        update, a restart): the newest report of an iteration is the one written, once, when the next one
        begins (or at ``log_final``)."""
        seq = int(iteration) + self.offset
        if self.pending is not None and self.pending[0] != seq:
            self._write_pending()
        self.pending = (seq, state.copy(), float(residual), dict(energies), time.perf_counter() - self.t_start)

    def _within_budget(self, cost=None):
        """Whether a frame of ``cost`` seconds (default: the last frame's) fits in 40 % of the overhead budget; the
        rest is for the first and final frames (and a final writhe) and rerun's writer thread."""
        if self.max_overhead is None:
            return True
        cost = self.frame_cost if cost is None else cost
        budget = max(0.4 * self.max_overhead * (time.perf_counter() - self.t_start), MIN_BUDGET_SECONDS)
        return self.spent + cost <= budget

    def _write_pending(self, force=False):
        seq, state, residual, energies, elapsed = self.pending
        self.pending = None
        if self.last_written is not None and seq <= self.last_written:
            return   # a restart re-reports an iteration already written; the timeline stays one row per value
        if not (force or self.last_written is None or self._within_budget()):
            self.skipped += 1
            return
        t0 = time.perf_counter()
        self._write(seq, state, residual, energies, elapsed, final=force)
        self.frame_cost = time.perf_counter() - t0
        if self.frames:   # the first frame pays rerun's one-off setup (schemas, the writer): not a frame's cost
            self.spent += self.frame_cost
        self.frames += 1
        self.last_written = seq
        if time.perf_counter() - self.last_flush > FLUSH_SECONDS:
            self.rec.flush()
            self.last_flush = time.perf_counter()

    def _write(self, seq, state, residual, energies, elapsed, final):
        self.rec.set_time("iteration", sequence=seq)
        self.rec.set_time("solve_time", duration=elapsed)
        self._write_rod(self.rod, state, "rod")
        self._write_scalars(state, residual, energies, final)

    def _write_rod(self, rod, state, entity):
        """The centreline (coloured), material vectors m1 and end frames of one rod under ``entity``."""
        rr, rec = self.rr, self.rec
        x = state.positions
        if self.color_by == "alpha":
            values = dg.alpha(rod, state)
            scale = np.pi / 2
        else:
            tw = dg.material_twist_density(rod, state) - rod.twist_bar / rod.voronoi
            values = np.zeros(rod.n_edges)
            np.add.at(values, rod.vertex_edges[:, 0], 0.5 * tw)
            np.add.at(values, rod.vertex_edges[:, 1], 0.5 * tw)
            scale = np.nanmax(np.abs(values)) if values.size else 1.0
        strips = np.stack([x[rod.edge_nodes[:, 0]], x[rod.edge_nodes[:, 1]]], axis=1)
        rec.log(f"{entity}/centreline", rr.LineStrips3D(strips, colors=_diverging(values, scale)))
        t = tangents(state.q, rod.edge_nodes)
        m1, m2 = material_frames(state.q, t, state.d1)
        mid = 0.5 * (x[rod.edge_nodes[:, 0]] + x[rod.edge_nodes[:, 1]])
        sel = slice(None, None, self.stride)
        rec.log(f"{entity}/m1", rr.Arrows3D(origins=mid[sel], vectors=self.arrow_length * m1[sel],
                                      colors=[[40, 180, 40]]))
        L = 2 * self.arrow_length
        for name, j in ((f"{entity}/start_frame", 0), (f"{entity}/end_frame", rod.n_edges - 1)):
            rec.log(name, rr.Arrows3D(origins=np.repeat(mid[j:j + 1], 3, axis=0),
                                      vectors=L * np.stack([t[j], m1[j], m2[j]]),
                                      colors=[[230, 40, 40], [40, 200, 40], [40, 80, 230]]))

    def _write_scalars(self, state, residual, energies, final):
        """Energies, residual and (rings) Lk, Tw, Wr of a frame."""
        rod, rr, rec = self.rod, self.rr, self.rec
        for term, value in energies.items():
            rec.log(f"energy/{term}", rr.Scalars(float(value)))
        if np.isfinite(residual) and residual > 0:
            rec.log("residual/log10", rr.Scalars(float(np.log10(residual))))
        if rod.closed and rod.n_edges <= WRITHE_MAX_EDGES:
            # O(n^2), tens of ms at n = 2,000: only when the budget has room for it (the final frame of a solve
            # may use 80 % of the budget, the others 40 %), and always at the end of a solve when it costs less than
            # a frame (small rings: each solve of a continuation ends with its Lk, Tw, Wr)
            cost = self.spent_per_writhe()
            final_ok = final and (cost <= self.frame_cost or
                                  self.spent + cost <= 0.8 * self.max_overhead * (time.perf_counter() - self.t_start))
            if self.max_overhead is None or final_ok or self._within_budget(self.frame_cost + cost):
                t0 = time.perf_counter()
                lk, tw, wr = dg.linking_number(rod, state)
                self._writhe_cost = time.perf_counter() - t0
                for name, value in (("linking_number", lk), ("twist", tw), ("writhe", wr)):
                    rec.log(f"ring/{name}", rr.Scalars(float(value)))

    def spent_per_writhe(self):
        """The measured cost of the last writhe (a first estimate before any: 1e-8 s n^2)."""
        return getattr(self, "_writhe_cost", 1e-8 * self.rod.n_edges ** 2)

    def log_final(self, result):
        """Write the returned state (always, as the row of the last iteration), the verdict, and flush."""
        rr = self.rr
        seq = int(result.iterations) + self.offset
        if self.pending is not None and self.pending[0] != seq:
            self._write_pending()
        self.pending = (seq, result.state.copy(), float(result.residual), dict(result.energy or {}),
                        time.perf_counter() - self.t_start)
        self._write_pending(force=True)
        self.rec.log("status", rr.TextLog(f"{result.solver}: {result.status} after {result.iterations} iterations, "
                                          f"residual {result.residual:.3e}; {result.message}"))
        self.rec.flush()
        self.last_flush = time.perf_counter()
        last = getattr(self, "last_logged", None)
        if last is None or last[0] != result.iterations or not np.array_equal(last[1], result.state.q):
            self.log_step(result.iterations, result.state, result.residual, result.energy)
        if getattr(result, "contact", None):
            self.log_contact(result.contact)

    def log_contact(self, contact):
        """Contact points (``contact/<term>/points``) and, for self-contact, the force on each pair as arrows
        along the contact normal, scaled to the largest force (``contact/<term>/forces``); from
        ``result.contact`` at the final state."""
        rr = self.rr
        for k, term in enumerate(contact["terms"]):
            name = f"contact/{k}_{term['kind']}"
            pts = np.asarray(term["points"], float).reshape(-1, 3)
            self.rec.log(f"{name}/points", rr.Points3D(pts, colors=[[255, 200, 0]], radii=term["radius"]))
            forces = np.asarray(term["force"], float)
            if "normals" in term and forces.size and np.isfinite(forces).all() and forces.max() > 0:
                v = np.asarray(term["normals"], float).reshape(-1, 3) * (forces / forces.max())[:, None]
                self.rec.log(f"{name}/forces", rr.Arrows3D(origins=pts, vectors=self.arrow_length * v,
                                                           colors=[[255, 120, 0]]))
            self.rec.log(f"{name}/n_contacts", rr.Scalars(float(term["n_contacts"])))

    def flush(self):
        if not self.closed:
            if self.pending is not None:
                self._write_pending(force=True)
            self.rec.flush()

    def close(self):
        if not self.closed:
            if self.pending is not None:
                self._write_pending(force=True)
            self.rec.flush()
            self.rec.disconnect()
            self.closed = True

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class MultiRecorder(Recorder):
    """A Recorder for a scene of several rods: rod i is written under ``rod{i}/`` (centreline, m1, end frames,
    rest shape under ``rest{i}/``), with the scene's energies, residual and contact as for one rod."""

    def __init__(self, path, rods, scene=None, **kwargs):
        self.rods = tuple(rods)
        # the base class sizes arrows and picks the blueprint from one rod: the longest
        super().__init__(path, max(self.rods, key=lambda r: r.length), scene=scene, **kwargs)
        self.strides = [max(1, int(np.ceil(r.n_edges / 200))) for r in self.rods]

    def log_rest(self):
        rr = self.rr
        for i, rod in enumerate(self.rods):
            x = rod.rest_state().positions
            strips = np.stack([x[rod.edge_nodes[:, 0]], x[rod.edge_nodes[:, 1]]], axis=1)
            self.rec.log(f"rest{i}/centreline", rr.LineStrips3D(strips, colors=[[150, 150, 150]]), static=True)

    def _write(self, seq, state, residual, energies, elapsed, final):
        self.rec.set_time("iteration", sequence=seq)
        self.rec.set_time("solve_time", duration=elapsed)
        for i, (rod, s) in enumerate(zip(self.rods, state.rods)):
            self.stride = self.strides[i]
            self._write_rod(rod, s, f"rod{i}")
        rr = self.rr
        for term, value in energies.items():
            self.rec.log(f"energy/{term}", rr.Scalars(float(value)))
        if np.isfinite(residual) and residual > 0:
            self.rec.log("residual/log10", rr.Scalars(float(np.log10(residual))))


def read_centrelines(path, entity="rod"):
    """(iterations, positions list) of ``<entity>/centreline`` in a recording (float32 from the file); a scene of
    several rods writes rod i as ``rod{i}``."""
    from rerun.chunk import RrdReader

    out = []
    for chunk in RrdReader(path).stream().to_chunks():
        if chunk.entity_path != f"/{entity}/centreline":
            continue
        rb = chunk.to_record_batch()
        its = rb.column("iteration").to_pylist()
        strips = rb.column("LineStrips3D:strips").to_pylist()
        for it, s in zip(its, strips):
            segs = np.asarray(s, dtype=float)   # (n_edges, 2, 3)
            pts = np.concatenate([segs[:, 0, :], segs[-1:, 1, :]], axis=0)
            if np.array_equal(pts[0], pts[-1]):   # a ring: the last edge closes on the first node
                pts = pts[:-1]
            out.append((it, pts))
    out.sort(key=lambda p: p[0])
    return [p[0] for p in out], [p[1] for p in out]


def read_scalars(path, entity):
    """(iterations, values) of a scalar time series in a recording, e.g. ``ring/linking_number`` (float64)."""
    from rerun.chunk import RrdReader

    out = []
    for chunk in RrdReader(path).stream().to_chunks():
        if chunk.entity_path != "/" + entity.strip("/"):
            continue
        rb = chunk.to_record_batch()
        its = rb.column("iteration").to_pylist()
        for it, v in zip(its, rb.column("Scalars:scalars").to_pylist()):
            out.append((it, float(v[0])))
    out.sort(key=lambda p: p[0])
    return [p[0] for p in out], np.array([p[1] for p in out])
