"""Checkpoints (observe stage): save a running Simulation, continue it bit-for-bit.

A checkpoint is an .npz file: positions and velocities (float64, exact for both
precisions), the time, the step bound, the counters, the frame it was taken at, and
a digest of the scene so that it is only ever resumed on the scene that made it.
"""
from __future__ import annotations

import hashlib
import json
import os

import numpy as np

from .interrupts import hold_interrupts

__all__ = ["scene_digest", "save", "load", "set_aside", "copy_video_prefix"]


def scene_digest(scene) -> str:
    """sha1 of everything that defines the physics of a scene."""
    h = hashlib.sha1()
    for arr in (scene.x, scene.v, scene.radius, scene.mass, scene.box_lo, scene.box_hi,
                scene.gravity):
        h.update(np.ascontiguousarray(arr, dtype=np.float64).tobytes())
    h.update(repr((scene.periodic, scene.restitution, scene.wall_restitution,
                   scene.restitution_model, scene.rest_speed)).encode())
    if getattr(scene, "frictional", False) or getattr(scene, "geometry", ()) or \
            getattr(scene, "sinks", ()):
        h.update(np.ascontiguousarray(scene.omega, dtype=np.float64).tobytes())
        h.update(repr((scene.friction, scene.wall_friction, scene.tangential_restitution,
                       scene.rolling_friction, [g.packed().tolist() for g in scene.geometry],
                       [(list(s.low), list(s.high), s.recycle) for s in scene.sinks])).encode())
    if len(getattr(scene, "materials", ())) > 0:
        h.update(np.ascontiguousarray(scene.material, dtype=np.int32).tobytes())
        h.update(np.ascontiguousarray(scene.pair_values(), dtype=np.float64).tobytes())
    return h.hexdigest()


def save(path, sim, scene, frame, fps) -> None:
    """Write the checkpoint atomically (temporary file, then rename)."""
    ck = sim.checkpoint()
    meta = dict(time=ck["time"], vmax2=ck["vmax2"], vmax2_near=ck["vmax2_near"],
                stuck_in_sinks=ck["stuck_in_sinks"],
                totals=ck["totals"],
                last_step=ck["last_step"], n=ck["n"], precision=ck["precision"],
                step_fraction=ck["step_fraction"], max_sweeps=ck["max_sweeps"],
                frame=int(frame), fps=float(fps), scene=scene_digest(scene))
    arrays = dict(x=ck["x"], v=ck["v"], omega=ck["omega"], radius=ck["radius"],
                  mass=ck["mass"], sphere_ids=ck["sphere_ids"])
    if ck.get("warm") is not None:
        # the contact solver's warm start: the next steps give the same bits
        meta["warm_h_prev"] = ck["warm"]["h_prev"]
        arrays.update({"warm_" + k: value for k, value in ck["warm"].items()
                       if k != "h_prev"})
    tmp = path + ".tmp.npz"
    with hold_interrupts():
        np.savez(tmp, meta=np.array(json.dumps(meta)), **arrays)
        os.replace(tmp, path)


def load(path, sim, scene, fps) -> int:
    """Restore ``sim`` from a checkpoint; returns the frame it was taken at."""
    try:
        with np.load(path) as data:
            meta = json.loads(str(data["meta"]))
            arrays = {k: data[k] for k in ("x", "v", "omega", "radius", "mass", "sphere_ids")
                      if k in data}
            warm = None
            if "warm_key" in data:
                warm = {k[5:]: data[k] for k in data.files if k.startswith("warm_")}
                warm["h_prev"] = meta["warm_h_prev"]
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(f"cannot read checkpoint {path}: {exc}") from None
    if meta["scene"] != scene_digest(scene):
        raise ValueError(f"checkpoint {path} was made from a different scene")
    if meta["fps"] != float(fps):
        raise ValueError(f"checkpoint {path} was made at {meta['fps']:g} fps, not {fps:g}")
    sim.restore(dict(meta, warm=warm, **arrays))
    return int(meta["frame"])


def set_aside(video_path) -> str | None:
    """On resume, move the earlier video out of the way; returns its new path. If an
    earlier resume was interrupted while copying (its set-aside file is still there),
    that file is the earlier video and ``video_path`` only a partial copy of it."""
    old = video_path + ".before-resume.mp4"
    if os.path.exists(old):
        if os.path.exists(video_path):
            os.remove(video_path)
        return old
    if not os.path.exists(video_path):
        return None
    os.replace(video_path, old)
    return old


def copy_video_prefix(old_path, video, frames: int) -> None:
    """Start the new video with the first ``frames`` frames of the earlier one, so the
    finished file covers the whole run; then delete the earlier file."""
    import imageio.v2 as imageio
    reader = imageio.get_reader(old_path)
    try:
        for k, frame in enumerate(reader):
            if k >= frames:
                break
            video.write(frame)
    finally:
        reader.close()
    os.remove(old_path)
