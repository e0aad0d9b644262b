"""Energy-safe warm start of the contact solver (contacts/solver.py, mixed into
ContactSolver).

Each step's velocity solve starts from the impulses lambda_0 of the same contacts in
the previous step (warm start, Catto's sequential impulses). In a resting bed they are
the answer and the solve converges in a few sweeps; right after an impact they can be
far too large (the previous step stopped a heavy ball), and a solve that stops at its
sweep cap then ends with more kinetic energy than it started with.

Projected Gauss–Seidel is coordinate descent on the convex function (with J the rows'
Jacobian, M the masses and inertias, t the rows' velocity targets, t <= 0)

    f(lambda) = 1/2 lambda^T J M^-1 J^T lambda + lambda^T (J v_pre - t),

and every update (over-relaxed by 0 < omega < 2 included, clamped to lambda >= 0)
lowers f. Since KE(lambda) - KE(v_pre) = f(lambda) + lambda^T t <= f(lambda) (lambda >=
0, t <= 0), a solve that starts where f <= 0 never ends with more kinetic energy than
v_pre had, however early it stops. f(0) = 0, and along the warm-start impulses

    f(alpha lambda_0) = alpha L + alpha^2 Q / 2,
    L = sum_i m_i dv_i . v_pre_i (+ I_i dw_i . w_pre_i) - lambda_0 . t,
    Q = sum_i m_i |dv_i|^2 (+ I_i |dw_i|^2),

with dv, dw the velocity and spin changes the warm start made. The solve scales the warm
start by the largest alpha <= 1 with f(alpha lambda_0) <= 0: alpha = min(1, -2 L / Q)
(0 if L >= 0). In a resting bed the warm start lowers f and alpha = 1 (bits unchanged);
after an impact it scales the leftover impulses down. Friction rows join f through
their velocity changes (their cone moves with lambda_n, so for them the sweeps lower f
only approximately). One alpha serves all contacts, and with friction any contact
whose sliding turns makes its warm friction impulse add energy, so in a flowing
frictional scene the bound keeps cutting the friction the warm start carries:
Rules.bounded_warm_start "auto" (the default) leaves it off with friction
(docs/algorithm.md, "Bounded warm start").

L and Q are summed in fixed chunks of WARM_CHUNK spheres and rows, the chunk sums in
order by one thread: the same bits for any thread count.
"""

import taichi as ti

__all__ = ["WarmStartEnergy", "WARM_CHUNK"]

#: spheres (and rows) one thread sums for L and Q
WARM_CHUNK = 256


@ti.data_oriented
class WarmStartEnergy:
    """The warm-start bound of the module docstring (a mixin of ContactSolver: uses its
    state, v_pre, w_pre, lam, lam_t, lam_r, target, n_rows, capacity, serial, f)."""

    def _allocate_warm_energy(self, cap: int, rows: int):
        """warm_sums: (chunks,) vec2 — L and Q of each chunk [J]; warm_alpha: () — the
        scale of this step's warm start."""
        chunks = (max(cap, rows) + WARM_CHUNK - 1) // WARM_CHUNK
        self.warm_sums = ti.Vector.field(2, self.real, shape=chunks)
        self.warm_alpha = ti.field(self.real, shape=())

    @ti.func
    def warm_energy_terms(self, c, n, rows):
        """(L, Q) of chunk c [J]: spheres and rows c * WARM_CHUNK onward, below n and rows."""
        lin = ti.cast(0, self.real)
        quad = ti.cast(0, self.real)
        for j in range(WARM_CHUNK):
            i = c * WARM_CHUNK + j
            if i < n:
                dv = self.state.v[i] - self.v_pre[i]
                m = self.state.mass_of(i)
                lin += m * dv.dot(self.v_pre[i])
                quad += m * dv.norm_sqr()
                if ti.static(self.f.friction):
                    dw = self.state.omega[i] - self.w_pre[i]
                    inertia = 1 / self.state.inv_inertia_of(i)
                    lin += inertia * dw.dot(self.w_pre[i])
                    quad += inertia * dw.norm_sqr()
            if i < rows:
                lin -= self.lam[i] * self.target[i]
        return ti.Vector([lin, quad])

    @ti.func
    def chunk_total(self, chunks):
        """The sum of warm_sums[0:chunks], added in order (one thread: fixed bits)."""
        total = ti.Vector.zero(self.real, 2)
        for c in range(chunks):
            total += self.warm_sums[c]
        return total

    @ti.func
    def warm_scale(self, chunks):
        """alpha = min(1, -2 L / Q) from the chunk sums, in order (one thread); 1 if the
        warm start changed nothing, 0 if it only adds to f. Counts a scaled warm start."""
        total = self.chunk_total(chunks)
        alpha = ti.cast(1, self.real)
        if total[1] > 0:
            alpha = ti.min(ti.max(-2 * total[0] / total[1], 0), 1)
        self.warm_alpha[None] = alpha
        if alpha < 1:
            self.params.warm_starts_scaled[None] = 1

    @ti.func
    def bound_warm_start(self):
        """Scale the warm start just applied by alpha (module docstring): velocities and
        spins back towards v_pre, w_pre, and the rows' impulses (kernel top level)."""
        n = self.state.n_spheres[None]
        rows = ti.min(self.n_rows[None], ti.static(self.capacity))
        chunks = (ti.max(n, rows) + WARM_CHUNK - 1) // WARM_CHUNK
        ti.loop_config(serialize=ti.static(self.serial))
        for c in range(chunks):
            self.warm_sums[c] = self.warm_energy_terms(c, n, rows)
        ti.loop_config(serialize=True)
        for _ in range(1):
            self.warm_scale(chunks)
        ti.loop_config(serialize=ti.static(self.serial))
        for i in range(n):
            alpha = self.warm_alpha[None]
            if alpha < 1:
                self.state.v[i] = self.v_pre[i] + alpha * (self.state.v[i] - self.v_pre[i])
                if ti.static(self.f.friction):
                    spin = self.state.omega[i] - self.w_pre[i]
                    self.state.omega[i] = self.w_pre[i] + alpha * spin
        ti.loop_config(serialize=ti.static(self.serial))
        for s in range(rows):
            alpha = self.warm_alpha[None]
            if alpha < 1:
                self.lam[s] *= alpha
                if ti.static(self.f.friction):
                    self.lam_t[s] *= alpha
                if ti.static(self.f.rolling):
                    self.lam_r[s] *= alpha
