#!/usr/bin/env python3
"""How far the contact solver's velocity sweeps are from the converged solution in a
flowing bed, and what an accelerated projected gradient method reaches for the same
work.

Runs scenes/pour.toml (2,000 frictionless spheres, e = 0.5) to ``--at`` s (1 thread)
and captures the velocity problem of the next step as the engine builds it: the rows
(spheres, normals, effective masses, targets) in the order the colour sweeps visit
them, the warm-started impulses and the velocities after the warm start. Then, in
numpy:

- projected Gauss-Seidel exactly as contacts/pgs.py updates a row (checked: its
  velocities after the engine's own sweeps match the engine's to round-off), also
  over-relaxed (Rules.relaxation 1.5 and 1.8) and in other row orders (by height from
  the floor up or from the top down, and symmetric forward-backward sweeps);
- the same sweeps accelerated by NNCG, the nonsmooth nonlinear conjugate gradient
  method (Silcowitz, Niebe & Erleben 2010): a Fletcher-Reeves step along the
  impulse changes of the previous sweeps after each sweep;
- APGD, Nesterov-accelerated projected gradient descent with adaptive restart and
  backtracking (Mazhar, Heyn, Negrut, Tasora 2015, "Using Nesterov's method to
  accelerate multibody dynamics with friction and contact", ACM TOG 34(3)), from the
  same warm start; one iteration costs about two products with the Delassus matrix,
  each about as much memory traffic as one sweep;
- the converged solution: APGD run until its projected-gradient residual stops
  falling (reported).

Reported per method and amount of work: the largest and the rms sphere velocity error
against the converged solution [m/s], and the largest error times the step over the
diameter (how much overlap one step of that error opens).

Then how smooth the error the sweeps leave is (``--smooth-sweeps``, over-relaxation
1.8 as the defaults): the spheres are grouped into aggregates (cubes of 2, 4 and 8
diameters, horizontal layers one diameter high, the whole bed), each aggregate's mean
error is taken, and the share of the error's energy (sum of |e|^2) those means carry
is reported, with the share a random error of the same size would give (the number
of aggregates over the number of spheres). A multilevel solver's coarse levels (one
velocity per aggregate) can correct only that share; where the error is rough on every
scale, only more fine sweeps reduce it. Last, the share the 1, 10 and 30 % of spheres
with the largest error carry (how concentrated it is: extra sweeps where the error
sits could help only a concentrated one).

Last, a direct solve (``--direct-eps``): the Delassus matrix W = J M^-1 J^T of the
rows (scipy.sparse), the rows the converged solution holds active (lambda > 0) solved
exactly, W_AA lambda_A = -(J v_free - target)_A, by a sparse LU factorization
(SuperLU, scipy.sparse.linalg.splu), then the active set changed (rows with lambda < 0
leave it, inactive rows that approach faster than their target join it) and solved
again until no row violates either, an active set comes back or 30 solves (an
active-set method); from the rows with a warm impulse too. W_AA is
near singular where the bed holds about as many contacts as degrees of freedom, so
eps times W's mean diagonal is added to it (a compliance, as a soft constraint's).
Reported per eps and start (the converged solution's active set, or the rows with a
warm impulse: what a solver knows before it solves): solves, the factorization's time,
its fill and the error against the converged solution, beside the wall time of the
engine's own sweeps of the same step (timed in capture(), parallel solver path, 1
thread).

    python tools/solver_convergence.py            # ~2 min
    python tools/solver_convergence.py --write    # into docs/bench.md
"""
from __future__ import annotations

import argparse
import datetime
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import taichi_spheres as ts  # noqa: E402
from taichi_spheres.config import Tuning  # noqa: E402
from taichi_spheres.contacts.pgs import VELOCITY  # noqa: E402
from machine import FORMER_DEFAULTS, cpu_name, publish  # noqa: E402  (tools/machine.py)


#: the settings capture() runs with by default: plain sweeps without substeps, as the
#: numpy sweeps here (pgs) and the figures of docs/bench.md (the contact solver's
#: former defaults)
FORMER = FORMER_DEFAULTS


def capture(scene_path: str, at: float, changes=None) -> dict:
    """The velocity problem of the first step after ``at`` s (numpy arrays), and the
    engine's velocities after its own sweeps of it, with ``Tuning().with_(**changes)``
    (default FORMER); also its velocity tolerance ``tol`` [m/s]."""
    scene = ts.load_scene(scene_path)
    # the parallel solver path (same bits as the serial one) runs its sweeps from
    # Python, where the problem can be read between the warm start and the sweeps
    tuning = Tuning().with_(serial_heavy_below=0, serial_solver_below=0,
                            **(FORMER if changes is None else changes))
    sim = ts.Simulation(scene, threads=1, tuning=tuning)
    sim.advance_to(at)
    solver = sim._engine.solver
    box = {}
    inner = solver._iterate

    def grab(mode, cap, last, tol):
        if mode != VELOCITY or "rows" in box:
            return inner(mode, cap, last, tol)
        n, k = solver.n_rows[None], scene.n
        start = solver.cell_start.to_numpy()
        cells = solver.active_cells.to_numpy()[:solver.colour_active[solver.n_colours]]
        order = np.concatenate([np.arange(start[c], start[c + 1]) for c in cells])
        box["rows"] = dict(order=order, a=solver.row_a.to_numpy()[:n],
                           b=solver.row_b.to_numpy()[:n], normal=solver.normal.to_numpy()[:n],
                           meff=solver.meff.to_numpy()[:n], target=solver.target.to_numpy()[:n],
                           lam=solver.lam.to_numpy()[:n], v=solver.state.v.to_numpy()[:k],
                           x=solver.state.x.to_numpy()[:k],
                           inv_mass=1.0 / np.asarray(scene.mass, dtype=np.float64),
                           h=float(solver.params.h[None]), sweeps=int(cap[None]),
                           plain=int(last[None]), tol=float(tol[None]))
        t0 = time.perf_counter()
        done = inner(mode, cap, last, tol)
        box["rows"]["engine_seconds"] = time.perf_counter() - t0
        box["rows"]["engine_v"] = solver.state.v.to_numpy()[:k]
        box["rows"]["engine_sweeps"] = done
        return done

    solver._iterate = grab
    sim.step(sim.max_step())
    p = box["rows"]
    p["d"] = 2 * float(np.min(scene.radius))
    return p


class Problem:
    """The captured rows as a bound-constrained QP in the impulses lambda >= 0:
    u_n(lambda) = J v(lambda) >= target, v(lambda) = v_free + M^-1 J^T lambda."""

    def __init__(self, p):
        self.p = p
        self.a, self.b, self.n = p["a"], p["b"], p["normal"]
        self.pair = self.b >= 0
        self.bb = np.where(self.pair, self.b, 0)
        self.im = p["inv_mass"]
        self.N = len(p["v"])
        self.v_free = p["v"] - self.scatter(p["lam"])
        self.lists = tuple(p[k].tolist() for k in ("a", "b", "normal", "meff", "target"))
        self.linear = self.gather(self.v_free) - p["target"]     # J v_free - target

    def scatter(self, lam):
        """M^-1 J^T lam as sphere velocities (N, 3)."""
        out = np.zeros((self.N, 3))
        f = lam[:, None] * self.n
        for ax in range(3):
            out[:, ax] += np.bincount(self.a, f[:, ax], self.N)
            out[:, ax] -= np.bincount(self.b[self.pair], f[self.pair, ax], self.N)
        return out * self.im[:, None]

    def gather(self, v):
        """J v: the rows' normal relative velocities (separating > 0)."""
        rel = v[self.a] - np.where(self.pair[:, None], v[self.bb], 0.0)
        return np.einsum("ij,ij->i", rel, self.n)

    def velocities(self, lam):
        return self.v_free + self.scatter(lam)

    def grad(self, lam):
        """Gradient of 1/2 lam W lam - (target - J v_free) lam: J v(lam) - target."""
        return self.gather(self.velocities(lam)) - self.p["target"]

    def value(self, lam):
        return 0.5 * lam @ (self.gather(self.scatter(lam))) + lam @ self.linear

    def residual(self, lam):
        """Largest projected-gradient component [m/s] (0 at the solution)."""
        g = self.grad(lam)
        return float(np.max(np.abs(lam - np.maximum(lam - g, 0.0))))


def sweep_rows(prob: Problem, lam_l: list, vl: list, order, omega: float = 1.0) -> None:
    """One sweep of contacts/pgs.py's row update over the rows in ``order``, in place on
    the impulses lam_l and the sphere velocities vl (Python lists: fast per row)."""
    a, b, n, meff, tgt = prob.lists
    im = prob.im
    for s in order:
        update_row(s, a[s], b[s], n[s], meff[s], tgt[s], omega, lam_l, vl, im)


def update_row(s, ai, bi, ns, meff, tgt, omega, lam, vl, im) -> float:
    """contacts/pgs.py's update of row s (spheres ai, bi < 0 a wall; normal ns, effective
    mass meff [kg], target tgt [m/s]) in place on the impulses lam [N s] and sphere
    velocities vl [m/s] (Python lists), the engine's order of operations (the same
    bits); im: inverse masses [1/kg]. Returns the impulse change [N s]."""
    va = vl[ai]
    if bi >= 0:
        vb = vl[bi]
        un = (va[0] - vb[0]) * ns[0] + (va[1] - vb[1]) * ns[1] + (va[2] - vb[2]) * ns[2]
    else:
        un = va[0] * ns[0] + va[1] * ns[1] + va[2] * ns[2]
    old = lam[s]
    new = max(old + omega * meff * (tgt - un), 0.0)
    lam[s] = new
    dl = new - old
    ca = dl * im[ai]
    vl[ai] = [va[0] + ca * ns[0], va[1] + ca * ns[1], va[2] + ca * ns[2]]
    if bi >= 0:
        cb = dl * im[bi]
        vb = vl[bi]
        vl[bi] = [vb[0] - cb * ns[0], vb[1] - cb * ns[1], vb[2] - cb * ns[2]]
    return dl


def pgs(prob: Problem, sweeps: list[int], omega: float = 1.0, orders=None) -> dict:
    """contacts/pgs.py's velocity sweeps (over-relaxation ``omega``, Rules.relaxation),
    sweep k visiting the rows in ``orders[k % len(orders)]`` (default: the engine's
    order); velocities after each requested number of sweeps."""
    p = prob.p
    orders = [p["order"]] if orders is None else orders
    orders = [o.tolist() for o in orders]
    lam_l = p["lam"].tolist()
    vl = p["v"].tolist()
    out = {}
    for k in range(1, max(sweeps) + 1):
        sweep_rows(prob, lam_l, vl, orders[(k - 1) % len(orders)], omega)
        if k in sweeps:
            out[k] = np.array(vl)
    return out


def nncg(prob: Problem, sweeps: list[int]) -> dict:
    """The nonsmooth nonlinear conjugate gradient method (Silcowitz, Niebe & Erleben
    2010, "A nonsmooth nonlinear conjugate gradient method for interactive contact
    force problems", The Visual Computer 26): the engine's sweep is the nonlinear map,
    its change of the impulses -r_k the (negative) gradient, and each sweep after the
    first adds beta_k p_{k-1} with beta_k = |r_k|^2 / |r_{k-1}|^2 (Fletcher-Reeves;
    restart, p = 0, when beta_k > 1), p_k = beta_k p_{k-1} - r_k. Velocities after
    each requested number of sweeps (each sweep also pays a pass over the rows that
    applies beta_k p_{k-1}). The step is not projected (as in the paper): impulses may
    be negative between sweeps, and so the velocities reported after one."""
    p = prob.p
    order = p["order"].tolist()
    lam = p["lam"].astype(np.float64).copy()
    v = p["v"].astype(np.float64).copy()
    direction, last = np.zeros_like(lam), None
    out = {}
    for k in range(1, max(sweeps) + 1):
        lam_l, vl = lam.tolist(), v.tolist()
        sweep_rows(prob, lam_l, vl, order)
        new, v = np.array(lam_l), np.array(vl)
        r = lam - new                      # the gradient of the nonlinear map
        lam = new
        rr = float(r @ r)
        if last is None:
            direction = -r
        elif rr > last:                    # beta > 1: restart
            direction = np.zeros_like(lam)
        else:
            step = (rr / last) * direction
            lam = lam + step
            v = v + prob.scatter(step)
            direction = step - r
        last = rr
        if k in sweeps:
            out[k] = v.copy()
    return out


def sweep_orders(p) -> dict:
    """Other row orders for the same sweeps: by the height of the contact point from
    the floor up, from the top down, and symmetric (the engine's order, then reversed)."""
    r = 0.5 * p["d"]
    height = p["x"][p["a"], 2] - r * p["normal"][:, 2]
    up = np.argsort(height, kind="stable")
    return {"rows from the floor up": [up], "rows from the top down": [up[::-1]],
            "symmetric (forward, then backward)": [p["order"], p["order"][::-1]]}


def apgd(prob: Problem, iterations: int, keep=()) -> tuple:
    """APGD (Mazhar et al. 2015, Algorithm 1 with adaptive restart), from the warm
    start. Returns (lambda, {iteration: (velocities, Delassus products so far)})."""
    g = prob.p["lam"].copy()
    y = g.copy()
    theta = 1.0
    probe = np.full(len(g), 1e-6)
    L = np.linalg.norm(prob.gather(prob.scatter(probe))) / np.linalg.norm(probe)
    products, out = 1, {}
    for k in range(1, iterations + 1):
        gy = prob.grad(y)
        fy = prob.value(y)
        products += 2
        while True:
            t = 1.0 / L
            gn = np.maximum(y - t * gy, 0.0)
            step = gn - y
            products += 1
            if prob.value(gn) <= fy + gy @ step + 0.5 * L * step @ step:
                break
            L *= 2.0
        theta_n = 0.5 * (-theta * theta + theta * np.sqrt(theta * theta + 4.0))
        beta = theta * (1.0 - theta) / (theta * theta + theta_n)
        y = gn + beta * (gn - g)
        if gy @ (gn - g) > 0:          # adaptive restart
            y, theta_n = gn.copy(), 1.0
        g, theta = gn, theta_n
        L *= 0.9
        if k in keep:
            out[k] = (prob.velocities(g), products)
    return g, out


def delassus(prob: Problem):
    """The Delassus matrix W = J M^-1 J^T of the rows (scipy.sparse CSC, rows x rows)
    [1/kg]: W lambda = prob.gather(prob.scatter(lambda))."""
    import scipy.sparse as sparse
    p, n, N = prob.p, len(prob.a), prob.N
    rows = np.repeat(np.arange(n), 3)
    on_a = sparse.csr_matrix((prob.n.ravel(),
                              (rows, (3 * prob.a[:, None] + np.arange(3)).ravel())),
                             shape=(n, 3 * N))
    pairs = np.flatnonzero(prob.pair)
    on_b = sparse.csr_matrix((prob.n[pairs].ravel(), (np.repeat(pairs, 3),
                              (3 * prob.b[pairs][:, None] + np.arange(3)).ravel())),
                             shape=(n, 3 * N))
    J = on_a - on_b
    return (J @ sparse.diags(np.repeat(p["inv_mass"], 3)) @ J.T).tocsc()


def active_set_solve(W, q, active, eps, most=30) -> tuple:
    """The complementarity problem lambda >= 0, W lambda + q >= 0, lambda (W lambda + q)
    = 0 by active-set iterations from the rows ``active`` (bool): each solves (W_AA + eps
    I) lambda_A = -q_A by a sparse LU (SuperLU), drops the rows with lambda < 0 and adds
    the inactive rows with W lambda + q < 0, until none changes, an active set comes
    back (a cycle), the block is singular or ``most`` solves. Returns (lambda >= 0,
    solves, seconds of each factorization (none for an empty active set), fill
    nnz(L + U) of the last, outcome: "yes" (converged), "cycle", "singular" or "no")."""
    import scipy.sparse as sparse
    from scipy.sparse.linalg import splu
    active = active.copy()
    seconds, fill, seen = [], 0, set()
    lam = np.zeros(len(q))
    for solve in range(1, most + 1):
        seen.add(active.tobytes())
        idx = np.flatnonzero(active)
        lam = np.zeros(len(q))
        if len(idx):                         # none active: lambda = 0, no factorization
            block = (W[idx][:, idx] + eps * sparse.eye(len(idx))).tocsc()
            t0 = time.perf_counter()
            try:
                lu = splu(block, permc_spec="COLAMD")
            except RuntimeError:             # exactly singular
                return lam, solve, seconds, fill, "singular"
            seconds.append(time.perf_counter() - t0)
            fill = lu.L.nnz + lu.U.nnz
            lam[idx] = lu.solve(-q[idx])
        negative, violated = lam < 0, ~active & (W @ lam + q < 0)
        if not negative.any() and not violated.any():
            return lam, solve, seconds, fill, "yes"
        active = (active & ~negative) | violated
        if active.tobytes() in seen:
            return np.maximum(lam, 0.0), solve, seconds, fill, "cycle"
    return np.maximum(lam, 0.0), most, seconds, fill, "no"


def direct_rows(prob: Problem, lam_true, truth, eps_list) -> list:
    """(start, eps [relative to W's mean diagonal], solves, outcome, median
    factorization seconds, fill, errors against truth) of active_set_solve for each eps,
    started from the converged solution's active set and from the warm start's (the
    rows with a warm impulse: what a solver knows before it solves)."""
    W = delassus(prob)
    scale = float(W.diagonal().mean())
    out = []
    for start, active in (("converged", lam_true > 0), ("warm start", prob.p["lam"] > 0)):
        for eps in eps_list:
            lam, solves, seconds, fill, done = active_set_solve(W, prob.linear, active,
                                                                eps * scale)
            out.append((start, eps, solves, done,
                        float(np.median(seconds)) if seconds else 0.0, fill,
                        errors(prob.velocities(lam), truth, prob.p["h"], prob.p["d"])))
    return out


def direct_report(p, lam_true, rows) -> list:
    """The markdown lines of the direct-solve table (direct_rows's rows)."""
    held = len(np.unique(np.concatenate([p["a"], p["b"][p["b"] >= 0]])))
    lines = ["", f"Direct solve of the active contacts: {int((lam_true > 0).sum())} of the "
             f"{len(p['a'])} rows active in the converged solution, on {held} spheres "
             f"({3 * held} degrees of freedom), {int((p['lam'] > 0).sum())} with a warm "
             f"impulse. The engine's {p['engine_sweeps']} sweeps of this step took "
             f"{1e3 * p['engine_seconds']:.1f} ms (1 thread, the parallel solver path: one "
             "launch per sweep).", "",
             "| active set from | eps / mean diagonal | solves | converged | one "
             "factorization [ms] | fill nnz(L+U) | largest velocity error [m/s] | rms [m/s] |",
             "|---|---|---|---|---|---|---|---|"]
    for start, eps, solves, done, seconds, fill, e in rows:
        lines.append(f"| {start} | {eps:.0e} | {solves} | {done} | "
                     f"{1e3 * seconds:.0f} | {fill:,} | {e['max']:.1e} | {e['rms']:.1e} |")
    return lines


def errors(v, truth, h, d) -> dict:
    e = np.linalg.norm(v - truth, axis=1)
    return dict(max=float(e.max()), rms=float(np.sqrt(np.mean(e * e))), overlap=float(e.max() * h / d))


def smooth_share(err, labels) -> tuple:
    """(share of sum |err|^2 carried by the aggregates' mean errors, the share a random
    error would give: the number of aggregates over the number of spheres) for the
    sphere velocity errors err (N, 3) [m/s] grouped by integer ``labels`` (N,)."""
    _, inverse, counts = np.unique(labels, return_inverse=True, return_counts=True)
    means = np.stack([np.bincount(inverse, err[:, ax]) for ax in range(3)], axis=1) / \
        counts[:, None]
    carried = float(np.sum(counts[:, None] * means ** 2))
    return carried / float(np.sum(err ** 2)), len(counts) / len(labels)


def smoothness(p, v, truth) -> tuple:
    """For the error v - truth (velocities (N, 3) [m/s]) over the spheres with a row
    (the bed): rows (aggregate, spheres per aggregate, share carried, random share) of
    smooth_share over cubes of 2, 4 and 8 diameters, layers one diameter high and the
    whole bed; and rows (percent, share of sum |e|^2) carried by the given percent of
    spheres with the largest error."""
    held = np.zeros(len(v), dtype=bool)
    held[p["a"]] = True
    held[p["b"][p["b"] >= 0]] = True
    err, x, d = (v - truth)[held], p["x"][held], p["d"]
    groups = [(f"cubes of {k} diameters", cube_labels(x, k * d)) for k in (2, 4, 8)]
    groups += [("layers one diameter high", np.floor((x[:, 2] - x[:, 2].min()) / d).astype(np.int64)),
               ("the whole bed", np.zeros(len(x), dtype=np.int64))]
    smooth = []
    for name, labels in groups:
        share, random = smooth_share(err, labels)
        smooth.append((name, len(labels) / len(np.unique(labels)), share, random))
    energy = np.sort(np.sum(err ** 2, axis=1))[::-1]
    top = [(percent, float(energy[:max(1, round(len(energy) * percent / 100))].sum() /
                           energy.sum())) for percent in (1, 10, 30)]
    return smooth, top


def cube_labels(x, size) -> np.ndarray:
    """(N,) int64 label of the cube of side ``size`` [m] holding each centre of x (N, 3)
    [m], cubes counted from the lowest corner of x."""
    cell = np.floor((x - x.min(axis=0)) / size).astype(np.int64)
    return cell @ np.array([1, 1 << 20, 1 << 40], dtype=np.int64)


def smooth_report(sweeps, smooth, top) -> list:
    """The markdown lines of the smoothness and concentration tables (smoothness's
    rows) for the error after ``sweeps`` over-relaxed sweeps."""
    lines = ["", f"Smoothness of the error after {sweeps} over-relaxed sweeps (ω 1.8), over "
             "the spheres with a row: the share of its energy (Σ|e|²) that one mean error "
             "per aggregate carries.", "",
             "| aggregates | spheres per aggregate | share carried | share of a random error |",
             "|---|---|---|---|"]
    for name, size, share, random in smooth:
        lines.append(f"| {name} | {size:.1f} | {share:.2f} | {random:.2f} |")
    lines += ["", "How concentrated it is: the share of Σ|e|² on the spheres with the "
              "largest error.", "", "| spheres with the largest error | share of Σ|e|² |",
              "|---|---|"]
    lines += [f"| {percent} % | {share:.2f} |" for percent, share in top]
    return lines


def direct_option(eps_list) -> str:
    """' --direct-eps ...' for the report's command where it is not the default."""
    if list(eps_list) == [1e-8, 1e-6, 1e-4]:
        return ""
    return " --direct-eps" + "".join(f" {e:g}" for e in eps_list)


def report(args, p, res_true, pgs_rows, apgd_rows, check, variant_rows=()) -> str:
    lines = [f"Measured {datetime.date.today()} on {cpu_name()}: "
             f"`python tools/solver_convergence.py{' --at ' + str(args.at) if args.at != 1.0 else ''}"
             f"{' --smooth-sweeps ' + str(args.smooth_sweeps) if args.smooth_sweeps != 100 else ''}"
             f"{direct_option(args.direct_eps)}`",
             "",
             f"`scenes/pour.toml` (frictionless, e = 0.5), the velocity problem of the step after "
             f"t = {args.at} s: {len(p['a'])} rows for {len(p['v'])} spheres, step "
             f"{p['h'] * 1e3:.2f} ms. Converged solution: APGD, {args.truth} iterations "
             f"(projected-gradient residual {res_true:.1e} m/s). The numpy sweeps reproduce the "
             f"engine's {p['engine_sweeps']} sweeps to {check:.1e} m/s.",
             "",
             "| method | work (sweeps or Delassus products) | largest velocity error [m/s] | rms [m/s] | largest error x step / d |",
             "|---|---|---|---|---|"]
    for k, e in pgs_rows:
        lines.append(f"| PGS (the engine's sweeps) | {k} | {e['max']:.1e} | {e['rms']:.1e} | {e['overlap']:.1e} |")
    for name, k, e in variant_rows:
        lines.append(f"| PGS, {name} | {k} | {e['max']:.1e} | {e['rms']:.1e} | {e['overlap']:.1e} |")
    for k, (work, e) in apgd_rows:
        lines.append(f"| APGD, {k} iterations | {work} | {e['max']:.1e} | {e['rms']:.1e} | {e['overlap']:.1e} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default=os.path.join(HERE, "..", "scenes", "pour.toml"))
    ap.add_argument("--at", type=float, default=1.0)
    ap.add_argument("--sweeps", type=int, nargs="+", default=[10, 30, 100, 300, 1000])
    ap.add_argument("--apgd", type=int, nargs="+", default=[50, 100, 200, 500])
    ap.add_argument("--omega", type=float, nargs="*", default=[1.5, 1.8],
                    help="over-relaxation factors to compare (Rules.relaxation)")
    ap.add_argument("--variant-sweeps", type=int, nargs="+", default=[30, 100, 300],
                    help="sweeps reported for the over-relaxed and reordered variants")
    ap.add_argument("--truth", type=int, default=5000, help="APGD iterations for the converged solution")
    ap.add_argument("--smooth-sweeps", type=int, default=100,
                    help="over-relaxed sweeps (1.8) whose error the smoothness table splits")
    ap.add_argument("--direct-eps", type=float, nargs="*", default=[1e-8, 1e-6, 1e-4],
                    help="regularizations of the direct solve, relative to the Delassus "
                         "matrix's mean diagonal (none: no direct solve)")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args(argv)
    ts.runtime.ensure("cpu", "f64", threads=1)
    p = capture(args.scene, args.at)
    prob = Problem(p)
    lam_true, _ = apgd(prob, args.truth)
    truth = prob.velocities(lam_true)
    res_true = prob.residual(lam_true)
    sweeps = sorted(set(args.sweeps) | {p["engine_sweeps"]})
    by_pgs = pgs(prob, sweeps)
    check = float(np.abs(by_pgs[p["engine_sweeps"]] - p["engine_v"]).max())
    pgs_rows = [(k, errors(by_pgs[k], truth, p["h"], p["d"])) for k in sorted(args.sweeps)]
    variant_rows = []
    for omega in args.omega:
        by = pgs(prob, args.variant_sweeps, omega=omega)
        variant_rows += [(f"over-relaxation {omega:g}", k, errors(by[k], truth, p["h"], p["d"]))
                         for k in args.variant_sweeps]
    for name, orders in sweep_orders(p).items():
        by = pgs(prob, args.variant_sweeps, orders=orders)
        variant_rows += [(name, k, errors(by[k], truth, p["h"], p["d"]))
                         for k in args.variant_sweeps]
    by = nncg(prob, args.variant_sweeps)
    variant_rows += [("accelerated by NNCG (one pass over the rows more per sweep)", k,
                      errors(by[k], truth, p["h"], p["d"])) for k in args.variant_sweeps]
    _, kept = apgd(prob, max(args.apgd), keep=set(args.apgd))
    apgd_rows = [(k, (kept[k][1], errors(kept[k][0], truth, p["h"], p["d"]))) for k in args.apgd]
    by = pgs(prob, [args.smooth_sweeps], omega=1.8)
    text = report(args, p, res_true, pgs_rows, apgd_rows, check, variant_rows)
    text += "\n" + "\n".join(smooth_report(args.smooth_sweeps,
                                           *smoothness(p, by[args.smooth_sweeps], truth)))
    if args.direct_eps:
        text += "\n" + "\n".join(direct_report(
            p, lam_true, direct_rows(prob, lam_true, truth, args.direct_eps)))
    publish(text, "solver-convergence", args.write)


if __name__ == "__main__":
    main()
