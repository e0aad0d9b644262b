"""Observe: diagnostics computed from a State snapshot (numpy, float64).

Energies in J, momentum in kg m/s; potential energy is -m g.x (zero at the origin).
"""
from __future__ import annotations

import hashlib

import numpy as np

__all__ = ["kinetic_energy", "rotational_energy", "potential_energy", "momentum",
           "angular_momentum", "total_energy", "state_digest"]


def kinetic_energy(state) -> float:
    """sum_i m_i |v_i|^2 / 2 [J]."""
    return float(0.5 * np.sum(state.mass * np.einsum("ij,ij->i", state.v, state.v)))


def rotational_energy(state) -> float:
    """sum_i I_i |omega_i|^2 / 2 [J], I = 2/5 m r^2 (solid spheres); 0 without spin."""
    omega = getattr(state, "omega", None)
    if omega is None:
        return 0.0
    return float(0.2 * np.sum(state.mass * state.radius ** 2 * np.einsum("ij,ij->i", omega, omega)))


def angular_momentum(state, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
    """sum_i (x_i - origin) x m_i v_i + I_i omega_i, (3,) [kg m^2/s] (orbital and spin)."""
    out = np.cross(state.x - np.asarray(origin, dtype=np.float64),
                   state.mass[:, None] * state.v).sum(axis=0)
    omega = getattr(state, "omega", None)
    if omega is not None:
        out = out + ((0.4 * state.mass * state.radius ** 2)[:, None] * omega).sum(axis=0)
    return out


def potential_energy(state, gravity) -> float:
    """sum_i -m_i g.x_i [J] (gravity (3,) in m/s^2)."""
    return float(-np.sum(state.mass * (state.x @ np.asarray(gravity, dtype=np.float64))))


def total_energy(state, gravity) -> float:
    """Kinetic (translational and rotational) plus potential energy [J]."""
    return kinetic_energy(state) + rotational_energy(state) + potential_energy(state, gravity)


def momentum(state) -> np.ndarray:
    """sum_i m_i v_i, (3,) [kg m/s]."""
    return (state.mass[:, None] * state.v).sum(axis=0)


def state_digest(state, precision) -> str:
    """SHA-256 (hex, first 16 digits) of the bits of a State's positions and
    velocities in the simulation's ``precision`` ('f32' or 'f64'): equal digests mean
    bit-identical states (the float64 copies of f32 values are exact, so they are
    rounded back losslessly)."""
    dtype = np.float64 if precision == "f64" else np.float32
    h = hashlib.sha256()
    for a in (state.x, state.v):
        h.update(np.ascontiguousarray(a, dtype=dtype).astype("<f8" if dtype is np.float64
                                                           else "<f4").tobytes())
    return h.hexdigest()[:16]
