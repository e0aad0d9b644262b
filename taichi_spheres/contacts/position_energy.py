"""Energy-bounded position pass of the contact solver (contacts/solver.py, mixed into
ContactSolver; Rules.bounded_position_pass).

After the velocity solve, the trapezoidal move and the closing of support gaps, the
split-impulse sweeps give every sphere a pseudo-velocity w that pushes overlaps apart
(``x += h w``, velocities untouched). Under gravity that push can lift spheres: the
potential energy it adds,

    lift = - sum_i m_i h g . w_i,

is energy the step did not have. A velocity solve stopped early leaves larger overlaps,
and pushing them out can raise the total energy above where the step started (a
settling block at 60 velocity sweeps: docs/bench.md, "Settings"). With the bound, the
pass may spend only what the solve has taken out of the step so far,

    budget = sum_i m_i (|v_pre_i|^2 - |v_i|^2) / 2 (+ spin) + m_i g . (x_i - x_pre_i),

the kinetic energy the sweeps removed and the potential energy the moves released:
where lift > max(budget, 0), every w is scaled by max(budget, 0) / lift, and the
overlap left is pushed out as later steps' solves take energy out (an overlap a
resting scene starts with has no energy to be lifted by, and stays). The solve then
never raises the total energy of a step.

Both sums are taken in fixed chunks of WARM_CHUNK spheres (the warm start's chunk sums,
whose storage they reuse), the chunk sums in order by one thread: the same bits for any
thread count.
"""

import taichi as ti

from .warm_energy import WARM_CHUNK

__all__ = ["PositionEnergy"]


@ti.data_oriented
class PositionEnergy:
    """The bound of the module docstring (a mixin of ContactSolver: uses its state,
    params, x_pre, w, serial, kinetic_spent, and WarmStartEnergy's warm_sums and
    chunk_total)."""

    def _allocate_position_energy(self):
        """lift_scale: () — the factor of this step's pseudo-velocities."""
        self.lift_scale = ti.field(self.real, shape=())

    @ti.func
    def position_energy_terms(self, c, n, h):
        """(budget, lift) of chunk c [J]: spheres c * WARM_CHUNK onward, below n."""
        budget = ti.cast(0, self.real)
        lift = ti.cast(0, self.real)
        g = self.params.gravity[None]
        for j in range(WARM_CHUNK):
            i = c * WARM_CHUNK + j
            if i < n:
                m = self.state.mass_of(i)
                budget += m * (self.kinetic_spent(i) + g.dot(self.state.x[i] - self.x_pre[i]))
                lift -= m * h * g.dot(self.w[i])
        return ti.Vector([budget, lift])

    @ti.func
    def bound_position_pass(self):
        """lift_scale: the factor (at most 1) that keeps the pseudo-velocities' lift within
        the budget (module docstring; kernel top level, before finish's x += h w, which
        scales w by it)."""
        n = self.state.n_spheres[None]
        h = self.params.h[None]
        chunks = (n + WARM_CHUNK - 1) // WARM_CHUNK
        ti.loop_config(serialize=ti.static(self.serial))
        for c in range(chunks):
            self.warm_sums[c] = self.position_energy_terms(c, n, h)
        ti.loop_config(serialize=True)
        for _ in range(1):
            total = self.chunk_total(chunks)
            scale = ti.cast(1, self.real)
            if total[1] > ti.max(total[0], 0):
                scale = ti.max(total[0], 0) / total[1]
            self.lift_scale[None] = scale
