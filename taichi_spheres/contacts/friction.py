"""Coulomb friction and spin at a contact point: the tangential part of impacts (Walton's
model) and of the contact solver's rows (docs/algorithm.md, "Friction and rotation").

Conventions: a contact between sphere a (centre x_a, radius r_a) and sphere b, or a
wall or geometry surface, has the unit normal n pointing from b (or the surface) to a;
the contact point lies at x_a - r_a n on a and at x_b + r_b n on b. Its relative
velocity is ``u_c = v_a - v_b - (r_a w_a + r_b w_b) x n`` (w: spin [rad/s]; for a
surface v_b = w_b = 0). An impulse P [N s] at the contact, acting on a (-P on b),
changes ``v_a += P / m_a``, ``v_b -= P / m_b`` and both spins by ``-(r / I) n x P``,
with I = 2/5 m r^2 (solid spheres). For P tangent to the contact the relative
tangential velocity changes by ``P (1/m_a + 1/m_b)(1 + 5/2)`` = ``7/2 P / m_eff``:
the tangential effective mass is ``2/7`` of the normal one, in every direction.

Walton's impact model (Walton 1993; Foerster, Louge, Chang & Allia 1994, Phys. Fluids
6, 1108): normal restitution e, friction coefficient mu and tangential restitution
beta0 for sticking impacts. With J_n = (1 + e) m_eff |u_n| the normal impulse and u_t
the tangential contact velocity before the impact, the tangential impulse is
``-min((1 + beta0) 2/7 m_eff |u_t|, mu J_n) u_t / |u_t|``: sticking impacts reverse
u_t to ``-beta0 u_t``, sliding ones are slowed by Coulomb's ``mu J_n``. beta0 = -1 (the
default of Scene.tangential_restitution) is read as Coulomb friction without
tangential elasticity (beta0 = 0 in the sticking bound: slip is slowed, never
reversed), so that a scene with friction and default settings has frictional impacts.
The impulse acts at the contact point, so the angular momentum of the pair about it
is conserved, and it never adds energy (|beta| <= 1).

Rolling resistance at impacts (rolling friction mu_r > 0): after Walton's impulse, an
angular impulse P_r on a (-P_r on b) opposes the relative spin w_a - w_b, up to
stopping it; its rolling part (about the tangent plane) and its twisting part (about
n) are each bounded by ``mu_r r_eff J_n`` (r_eff = r_a r_b / (r_a + r_b), r_a on a
wall), as the contact solver's rolling rows: the impulse of a rolling torque and of a
twisting torque each bounded by mu_r r_eff times the normal force, over the impact. Equal
and opposite on the pair, it conserves their angular momentum; it only removes
energy.
"""

import taichi as ti

#: tangential effective mass / normal effective mass of two solid spheres (1 / (1 + 5/2))
TANGENTIAL_MASS = 2.0 / 7.0


@ti.func
def contact_velocity(va, vb, wa, wb, ra, rb, n):
    """Relative velocity of the contact point, a's minus b's [m/s] (module docstring)."""
    return va - vb - (ra * wa + rb * wb).cross(n)


@ti.func
def tangential_part(u, n):
    """u minus its component along the unit vector n."""
    return u - u.dot(n) * n


@ti.func
def walton_impulse(ut, jn, meff, mu, beta_max):
    """Tangential impulse on sphere a of an impact [N s] (module docstring): ut the
    tangential contact velocity before it [m/s], jn >= 0 the normal impulse [N s], meff
    the normal effective mass [kg], mu the friction coefficient, beta_max the sticking
    bound of the tangential restitution (beta0, or 0 for beta0 = -1)."""
    speed = ut.norm()
    out = ut * 0
    if speed > 0:
        stick = (1 + beta_max) * ti.static(TANGENTIAL_MASS) * meff * speed
        out = -ti.min(stick, mu * jn) / speed * ut
    return out


@ti.func
def clamped(vec, limit):
    """vec scaled down to length limit (>= 0) if longer."""
    size = vec.norm()
    out = vec
    if size > limit:
        out = vec * (limit / size)
    return out


@ti.func
def rolling_bounded(vec, n, limit):
    """An angular impulse vec [N m s] bounded as rolling and twisting resistance: its
    part about the tangent plane (rolling) shortened to ``limit`` if longer, its part
    about the normal n (twisting) likewise, each on its own (LAMMPS's rolling and
    twisting models, Project Chrono's rolling and spinning friction). The inverse
    inertias are scalars, so this is the nearest bounded impulse in the energy's
    metric: it never adds energy."""
    twist = vec.dot(n)
    return clamped(vec - twist * n, limit) + ti.min(ti.max(twist, -limit), limit) * n


@ti.func
def rolling_impulse(rel_spin, inv_ia, inv_ib, n, limit):
    """Angular impulse [N m s] on sphere a opposing the relative spin rel_spin = w_a -
    w_b [rad/s] (module docstring): the one that stops it, -rel_spin / (1/I_a + 1/I_b),
    bounded by ``limit`` (mu_r r_eff J_n) in rolling and in twisting about the normal
    n (rolling_bounded); inv_ib = 0 for a wall."""
    return rolling_bounded(rel_spin / (inv_ia + inv_ib) * -1, n, limit)


@ti.func
def rolling_loss(rel_spin, inv_ia, inv_ib, impulse):
    """Rotational energy [J] the angular impulse on a (minus it on b) removes: -P.(w_a -
    w_b) - |P|^2 (1/I_a + 1/I_b) / 2 (>= 0 for rolling_impulse's P)."""
    return -impulse.dot(rel_spin) - 0.5 * (inv_ia + inv_ib) * impulse.norm_sqr()


@ti.func
def spin_change(r, inv_inertia, n, impulse):
    """Spin change [rad/s] of a sphere of radius r [m] and 1/I [1/(kg m^2)] from an
    impulse [N s] at its contact point -r n from its centre (n: the contact normal
    towards the sphere)."""
    return -r * inv_inertia * n.cross(impulse)
