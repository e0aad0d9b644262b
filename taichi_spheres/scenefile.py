"""Scene files (TOML) -> validated :class:`Scene`.

Strict schema: unknown keys are rejected with the nearest valid name, wrong types
are named, and every problem in the file is reported at once in one ValueError.
Units are SI, z is up. docs/scenes.md lists every key and its default.

    name = "seed_five"
    [box]      lo, hi (3 numbers, m), periodic (3 bools), wall_restitution
    [physics]  gravity (m/s^2, default none: not compiled in), restitution,
               restitution_model ("normal" | "smid"), rest_speed (m/s),
               step_fraction, max_sweeps, precision
    [run]      duration (s), fps
    [render]   width, height (multiples of 16), camera_position, camera_lookat, fov,
               colours ("group" | "speed" | "spin"), background
    [output]   video (path, .mp4), snapshots (bool: .npz), checkpoint_every (frames),
               trajectory (path, .gsd), trajectory_every (steps)
    [initial]  gsd (path of a GSD file, relative to the scene file), frame (index, -1:
               the last): the spheres of that frame instead of sphere tables
    [[spheres]]  one sphere: x, v, radius, and mass or density
    [[lattice]]  a simple-cubic block: lo, hi, spacing, radius, mass|density,
                 v (velocity of all) or speed (random directions), seed
    [[pour]]     count spheres on a jittered lattice filling a region (lo, hi) from
                 its top down, radius, mass|density, v, v_spread, seed: a pour
    [[random]]   count spheres at random non-overlapping places in a region
                 (lo, hi), radius (radius_spread p: uniform in radius * [1-p, 1]),
                 mass|density, v | speed, seed
    [physics] also: friction, wall_friction, tangential_restitution, rolling_friction;
    [[spheres]], [[lattice]], [[pour]], [[random]] also omega (rad/s; one vector for all
    the spheres of a table); [[pour]] and [[random]] place spheres clear of geometry
    [[plane]], [[cylinder]], [[cone]], [[sink]]: static geometry and sinks
                 (scenegeometry.py; keys as ts.Plane, ts.Cylinder, ts.Cone, ts.Sink)
    [[material]] name, restitution, friction, rolling_friction; [[material_pair]]
                 materials (two names) and the pair's values; the sphere tables'
                 material key names one (scenematerials.py; default: [physics])
    [tuning]   fields of config.Rules and config.Performance (the engine's options,
               e.g. relaxation, contact_iterations): scene.meta["tuning"], which a
               Simulation of the scene takes unless it is given tuning=
"""
from __future__ import annotations

import dataclasses
import difflib
import itertools
import math
import os
import re
try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib

import numpy as np

from .scene import DEFAULT_DENSITY, FRICTION_RANGES, RESTITUTION_MODELS, Scene
from .scenegeometry import geometry_tables, table_items
from .scenematerials import DEFAULT_MATERIAL, material_index, material_tables

__all__ = ["load_scene", "scene_from_dict", "SceneFileError"]

_TOP = {"name": str, "box": dict, "physics": dict, "run": dict, "render": dict, "output": dict,
        "initial": dict, "spheres": list, "lattice": list, "random": list, "pour": list,
        "plane": list, "cylinder": list, "cone": list, "sink": list, "material": list,
        "material_pair": list, "tuning": dict}
_RENDER = {"width": int, "height": int, "camera_position": "vec3", "camera_lookat": "vec3",
           "fov": float, "colours": str, "background": "vec3"}
_BOX = {"lo": "vec3", "hi": "vec3", "periodic": "bool3", "wall_restitution": float}
_PHYSICS = {"gravity": "vec3", "restitution": float, "step_fraction": float,
            "max_sweeps": int, "precision": str, "restitution_model": str,
            "rest_speed": float, "friction": float, "wall_friction": float,
            "tangential_restitution": float, "rolling_friction": float}
_RUN = {"duration": float, "fps": float}
_OUTPUT = {"video": str, "snapshots": bool, "checkpoint_every": int, "trajectory": str,
           "trajectory_every": int}
_INITIAL = {"gsd": str, "frame": int}
_SPHERE = {"colour": "vec3", "x": "vec3", "v": "vec3", "radius": float, "mass": float,
           "density": float, "omega": "vec3", "material": str}
_LATTICE = {"colour": "vec3", "v_spread": float, "lo": "vec3", "hi": "vec3",
            "spacing": float, "radius": float, "mass": float, "density": float, "v": "vec3",
            "speed": float, "seed": int, "omega": "vec3", "material": str}
_POUR = {"colour": "vec3", "count": int, "lo": "vec3", "hi": "vec3", "radius": float,
         "mass": float, "density": float, "v": "vec3", "v_spread": float, "seed": int,
         "omega": "vec3", "material": str}
_RANDOM = {"colour": "vec3", "radius_spread": float, "v_spread": float, "count": int,
           "lo": "vec3", "hi": "vec3", "radius": float, "mass": float, "density": float,
           "v": "vec3", "speed": float, "seed": int, "omega": "vec3", "material": str}


class SceneFileError(ValueError):
    """All problems found in a scene file (``problems``: list of strings)."""

    def __init__(self, source, problems):
        self.problems = list(problems)
        super().__init__(f"{source}: {len(self.problems)} problem(s):\n  - "
                         + "\n  - ".join(self.problems))


def load_scene(path) -> Scene:
    """Read a TOML scene file and return a validated Scene (``scene.meta`` holds the
    [run], [physics] and [tuning] settings that are not part of the Scene itself)."""
    path = str(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise ValueError(f"scene file not found: {path}") from None
    except OSError as exc:  # a directory, no permission, ...
        raise ValueError(f"cannot read scene file {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise SceneFileError(path, [f"not valid TOML: not UTF-8 text ({exc.reason} at byte "
                                    f"{exc.start})"]) from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneFileError(path, [f"not valid TOML: {exc}"]) from None
    return scene_from_dict(data, source=path)


def scene_from_dict(data: dict, source="scene") -> Scene:
    """A validated Scene from the tables of a parsed scene file ``data`` (what
    tomllib.load returns; ``source`` names it in messages and anchors [initial] gsd).
    Raises SceneFileError listing every problem found."""
    problems: list = []
    tables = _settings_tables(data, problems)
    shapes = geometry_tables(data, _check_table, problems)
    groups = _sphere_groups(data, problems)
    kinds = _group_materials(data, groups, problems)
    box, physics, initial = tables["box"], tables["physics"], tables["initial"]
    _check_scene_wide(box, physics, initial, groups, problems)
    if "gsd" in initial and kinds["given"]:
        problems.append("material: the spheres of [initial] gsd take the [physics] values; "
                        "[[material]] and [[material_pair]] apply to sphere tables")
    meta = {"run": tables["run"], "physics": physics, "render": tables["render"],
            "output": tables["output"], "source": source}
    if tables["tuning"]:
        meta["tuning"] = tables["tuning"]
    if "gsd" in initial and not problems:
        return _scene_from_initial(initial, box, physics, dict(data, _shapes=shapes), meta,
                                   source)
    data = dict(data, _shapes=shapes, _materials=kinds)
    arrays = _generated_arrays(groups, box, problems, shapes) if not problems else None
    if problems:
        raise SceneFileError(source, problems)
    return _scene_from_groups(groups, arrays, box, physics, data, meta, source)


def _settings_tables(data, problems) -> dict:
    """The settings tables of a scene file by name (box, physics, run, render, output,
    initial, tuning; {} when absent or not a table), after checking their keys, types
    and the output, render and tuning values."""
    _check_table(data, _TOP, "", problems)
    tables = {key: _table(data, key, schema, problems) for key, schema in
              (("box", _BOX), ("physics", _PHYSICS), ("run", _RUN), ("render", _RENDER),
               ("output", _OUTPUT), ("initial", _INITIAL))}
    _check_output(tables["output"], problems)
    _check_render(tables["render"], tables["run"], problems)
    tables["tuning"] = _tuning_table(data, problems)
    return tables


def _tuning_table(data, problems) -> dict:
    """[tuning]: Tuning.with_ keywords (config.Rules and Performance fields), checked by
    name (an unknown one with the nearest valid name), type and range; {} when absent."""
    from .config import Tuning, field_types
    table = data.get("tuning", {})
    if not isinstance(table, dict):
        return {}
    schema = field_types()
    _check_table(table, schema, "tuning.", problems)
    valid = {k: v for k, v in table.items() if k in schema and _valid(table, k, schema) is not None}
    try:
        Tuning().with_(**valid)
    except ValueError as exc:
        problems.append(str(exc).replace("tuning ", "tuning.", 1))
    return valid


def _sphere_groups(data, problems) -> list:
    """(kind, where, table) of every sphere table, in file order: [[spheres]],
    [[lattice]], [[random]], then [[pour]] (where: e.g. 'lattice[0]'); each checked
    for what needs no geometry."""
    groups = []
    for key, schema in (("spheres", _SPHERE), ("lattice", _LATTICE), ("random", _RANDOM),
                        ("pour", _POUR)):
        for where, item in table_items(data, key, problems):
            _check_table(item, schema, where + ".", problems)
            _check_group(key, where, item, schema, problems)
            groups.append((key, where, item))
    return groups


def _group_materials(data, groups, problems) -> dict:
    """The file's materials (scenematerials.material_tables) with "given" (the file has
    material tables) and "groups": each sphere table's material index."""
    kinds = material_tables(data, _check_table, problems)
    kinds["given"] = len(kinds["materials"]) > 1 or bool(kinds["material_pairs"])
    kinds["groups"] = []
    for _, where, item in groups:
        name = item.get("material", DEFAULT_MATERIAL)
        index = material_index(name, kinds["names"], f"{where}.material", problems) \
            if isinstance(name, str) else 0
        kinds["groups"].append(0 if index is None else index)
    return kinds


def _check_scene_wide(box, physics, initial, groups, problems):
    """Problems of the scene as a whole: precision, [box] and [physics] ranges,
    [initial] against the sphere tables, and no spheres at all."""
    if "precision" in physics and physics["precision"] not in ("f32", "f64"):
        problems.append(f"physics.precision: must be \"f32\" or \"f64\", got {physics['precision']!r}")
    _check_values(box, physics, problems)
    _check_initial(initial, groups, problems)
    if not groups and "gsd" not in initial and not problems:
        problems.append("no spheres: add [[spheres]], [[lattice]], [[random]] or [[pour]] "
                        "tables, or [initial] gsd")


def _generated_arrays(groups, box, problems, shapes) -> dict:
    """Per-group lists of x (K, 3) [m], v (K, 3) [m/s], radius (K,) [m], mass (K,) [kg]
    and group (K,) index arrays, generated in file order (so each group's random draws
    come from its own seed); a group that cannot be generated adds a problem."""
    lo = box.get("lo", [0.0, 0.0, 0.0])
    hi = box.get("hi", [1.0, 1.0, 1.0])
    arrays = {"x": [], "v": [], "radius": [], "mass": [], "group": [], "omega": []}
    for kind, where, item in groups:
        try:
            _generate(kind, where, item, lo, hi, arrays, problems,
                      periodic=box.get("periodic", False), shapes=shapes["geometry"])
        except ValueError as exc:
            problems.append(f"{where}: {exc}")
    return arrays


def _scene_from_groups(groups, arrays, box, physics, data, meta, source) -> Scene:
    """The Scene of the generated groups, with ``meta`` plus each sphere's group index,
    the groups' colours ((G, 3), -1 where none is given) and names; a Scene error
    (e.g. an overlap) names the group tables its spheres come from."""
    lo = box.get("lo", [0.0, 0.0, 0.0])
    hi = box.get("hi", [1.0, 1.0, 1.0])
    try:
        scene = Scene.from_arrays(
            np.concatenate(arrays["x"]), np.concatenate(arrays["v"]),
            np.concatenate(arrays["radius"]), mass=np.concatenate(arrays["mass"]),
            omega=np.concatenate(arrays["omega"]),
            box=(lo, hi), periodic=box.get("periodic", [False, False, False]),
            **_physics_args(box, physics, data), **_material_args(data, arrays))
    except ValueError as exc:
        message = _table_names(str(exc), data.get("_shapes", {}))
        raise SceneFileError(source, [message + _origins(message, groups, arrays)]) from None
    colours = np.array([item.get("colour", [-1.0, -1.0, -1.0]) for _, _, item in groups],
                       dtype=np.float64)
    meta.update(groups=np.concatenate(arrays["group"]), group_colours=colours,
                group_names=[where for _, where, _ in groups])
    return dataclasses.replace(scene, meta=meta)


def _physics_args(box, physics, data) -> dict:
    """The arguments of Scene.from_arrays that the [physics] and [box] tables give,
    besides the box and its periodicity."""
    shapes = data.get("_shapes", {})
    return dict(gravity=physics.get("gravity", [0.0, 0.0, 0.0]),
                restitution=physics.get("restitution", 1.0),
                wall_restitution=box.get("wall_restitution", 1.0),
                restitution_model=physics.get("restitution_model", "normal"),
                rest_speed=physics.get("rest_speed"), name=data.get("name", "scene"),
                friction=physics.get("friction", 0.0),
                wall_friction=physics.get("wall_friction"),
                tangential_restitution=physics.get("tangential_restitution", -1.0),
                rolling_friction=physics.get("rolling_friction", 0.0),
                geometry=shapes.get("geometry", ()), sinks=shapes.get("sinks", ()))


def _material_args(data, arrays) -> dict:
    """material, materials and material_pairs of Scene.from_arrays (none when the file
    has no material tables)."""
    kinds = data["_materials"]
    if not kinds["given"]:
        return {}
    index = [np.full(len(x), k, dtype=np.int32) for x, k in zip(arrays["x"], kinds["groups"])]
    return dict(material=np.concatenate(index), materials=kinds["materials"],
                material_pairs=kinds["material_pairs"])


def _check_output(output, problems):
    for key, ending in (("video", ".mp4"), ("trajectory", ".gsd")):
        value = _valid(output, key, _OUTPUT)
        if value is not None and not value.lower().endswith(ending):
            problems.append(f"output.{key}: must end in {ending}, got {value!r}")
    for key, unit in (("checkpoint_every", "frame"), ("trajectory_every", "step")):
        value = _valid(output, key, _OUTPUT)
        if value is not None and value < 1:
            problems.append(f"output.{key}: must be >= 1 {unit}, got {value}")


def _check_initial(initial, groups, problems):
    """[initial]: gsd (a path) and frame (an index) go together; sphere tables do not."""
    if "frame" in initial and "gsd" not in initial:
        problems.append("initial.frame: needs initial.gsd (the file to read the frame from)")
    if "gsd" in initial and groups:
        tables = sorted({kind for kind, _, _ in groups})
        problems.append("initial.gsd: the spheres come from the GSD frame; remove the "
                        + ", ".join(f"[[{t}]]" for t in tables) + " tables, or [initial]")


def _scene_from_initial(initial, box, physics, data, meta, source) -> Scene:
    """The scene of a file whose spheres are a frame of [initial] gsd: box and periodic
    from [box] when given, else from the frame (trajectory.scene_from_gsd)."""
    from .trajectory import scene_from_gsd
    path = initial["gsd"]
    folder = os.path.dirname(source) if os.path.isfile(source) else ""
    if folder and not os.path.isabs(path):
        path = os.path.join(folder, path)
    frame = initial.get("frame", -1)
    given = "lo" in box or "hi" in box
    lo, hi = box.get("lo", [0.0, 0.0, 0.0]), box.get("hi", [1.0, 1.0, 1.0])
    try:
        scene = scene_from_gsd(path, frame, box=(lo, hi) if given else None,
                               periodic=box.get("periodic"), **_physics_args(box, physics, data))
    except ValueError as exc:
        key = "initial.frame" if "frame" in str(exc) and "does not exist" in str(exc) \
            else "initial.gsd"
        raise SceneFileError(source, [f"{key}: {exc}"]) from None
    meta.update(scene.meta)
    return dataclasses.replace(scene, meta=meta)


def _check_render(render, run, problems):
    for key in ("width", "height"):
        if key in render and isinstance(render[key], int) and (render[key] <= 0 or render[key] % 16):
            problems.append(f"render.{key}: must be a positive multiple of 16 (H.264 blocks), "
                            f"got {render[key]}")
    if "colours" in render and render["colours"] not in ("group", "speed", "spin"):
        problems.append(f"render.colours: must be \"group\", \"speed\" or \"spin\", got "
                        f"{render['colours']!r}")
    _check_colour("render.background", _valid(render, "background", _RENDER), problems)
    if "fov" in render and _is_number(render["fov"]) and not 0 < render["fov"] < 180:
        problems.append(f"render.fov: must be in (0, 180) degrees, got {render['fov']}")
    for key in ("duration", "fps"):
        if key in run and _is_number(run[key]) and not run[key] > 0:
            problems.append(f"run.{key}: must be > 0, got {run[key]}")


def _table(data, key, schema, problems):
    t = data.get(key, {})
    if not isinstance(t, dict):
        return {}
    _check_table(t, schema, key + ".", problems)
    return t


def _check_table(table, schema, prefix, problems):
    for key, value in table.items():
        if key not in schema:
            near = difflib.get_close_matches(key, list(schema), n=1)
            if near:
                hint = f" (did you mean '{prefix}{near[0]}'?)"
            elif schema is _TOP and (nested := _nested_match(key)):
                # e.g. `periodic = true` written above the first [table]
                hint = (f" (did you mean '{nested}'? put it under "
                        f"[{nested.split('.')[0]}])")
            else:
                hint = f" (valid: {', '.join(sorted(schema))})"
            problems.append(f"unknown key '{prefix}{key}'{hint}")
            continue
        msg = _type_problem(value, schema[key])
        if msg:
            problems.append(f"{prefix}{key}: {msg}")


def _nested_match(key):
    """'box.periodic' for a top-level key that belongs in [box], [physics] or [run]."""
    names = {k: f"{table}.{k}" for table, schema in
             (("box", _BOX), ("physics", _PHYSICS), ("run", _RUN)) for k in schema}
    near = difflib.get_close_matches(key, list(names), n=1)
    return names[near[0]] if near else None


_REQUIRED = {"spheres": ("x", "radius"), "lattice": ("radius",), "random": ("count", "radius"),
             "pour": ("count", "radius")}


def _valid(table, key, schema):
    """The value of key when present and of the right type, else None."""
    if key in table and _type_problem(table[key], schema[key]) is None:
        return table[key]
    return None


def _check_group(kind, where, item, schema, problems):
    """Problems in one [[spheres]]/[[lattice]]/[[random]] table that need no geometry."""
    misspelt = _misspelt_keys(item, schema)
    missing = [k for k in _REQUIRED[kind] if k not in item and k not in misspelt]
    if missing:
        problems.append(f"{where}: missing " + ", ".join(f"'{k}'" for k in missing))
    for a, b in (("mass", "density"), ("v", "speed")):
        if a in item and b in item:
            problems.append(f"{where}: give {a} or {b}, not both")
    for key in ("radius", "mass", "density", "spacing"):
        value = _valid(item, key, schema) if key in schema else None
        if value is not None and not value > 0:
            problems.append(f"{where}.{key}: must be > 0, got {value!r}")
    for key, least in (("speed", 0), ("seed", 0), ("count", 1), ("v_spread", 0)):
        value = _valid(item, key, schema) if key in schema else None
        if value is not None and not value >= least:
            problems.append(f"{where}.{key}: must be >= {least}, got {value!r}")
    _check_colour(f"{where}.colour", _valid(item, "colour", schema), problems)
    lo, hi = _valid(item, "lo", schema), _valid(item, "hi", schema)
    if kind != "spheres" and lo is not None and hi is not None:
        for a in range(3):
            if not hi[a] > lo[a]:
                problems.append(f"{where}: hi must exceed lo on axis {'xyz'[a]} "
                                f"({lo[a]} .. {hi[a]})")


def _misspelt_keys(table, schema):
    """The valid keys that unknown keys of ``table`` look like misspellings of (those are
    reported as unknown keys with the nearest name, not as missing)."""
    return {near[0] for key in table if key not in schema
            for near in [difflib.get_close_matches(key, list(schema), n=1)] if near}


def _check_colour(name, colour, problems):
    """A colour (None: absent or of the wrong type, reported elsewhere) is RGB in [0, 1]."""
    if colour is not None and not all(0.0 <= c <= 1.0 for c in colour):
        problems.append(f"{name}: red, green and blue must each be in [0, 1], got {colour}")


def _check_values(box, physics, problems):
    """Range problems in [box] and [physics] (types were checked already)."""
    lo, hi = _valid(box, "lo", _BOX), _valid(box, "hi", _BOX)
    for a in range(3):
        la = 0.0 if lo is None else lo[a]
        ha = 1.0 if hi is None else hi[a]
        if (lo is not None or hi is not None) and not ha > la:
            problems.append(f"box: hi must exceed lo on axis {'xyz'[a]} ({la} .. {ha})")
    for table, name, key in ((box, "box", "wall_restitution"), (physics, "physics", "restitution")):
        value = _valid(table, key, _BOX if name == "box" else _PHYSICS)
        if value is not None and not 0 <= value <= 1:
            problems.append(f"{name}.{key}: must be in [0, 1], got {value!r}")
    value = _valid(physics, "step_fraction", _PHYSICS)
    if value is not None and not 0 < value <= 1:
        problems.append(f"physics.step_fraction: must be in (0, 1], got {value!r}")
    value = _valid(physics, "restitution_model", _PHYSICS)
    if value is not None and value not in RESTITUTION_MODELS:
        problems.append(f"physics.restitution_model: must be one of "
                        f"{', '.join(repr(m) for m in RESTITUTION_MODELS)}, got {value!r}")
    value = _valid(physics, "rest_speed", _PHYSICS)
    if value is not None and not value >= 0:
        problems.append(f"physics.rest_speed: must be >= 0 m/s, got {value!r}")
    value = _valid(physics, "max_sweeps", _PHYSICS)
    if value is not None and value < 1:
        problems.append(f"physics.max_sweeps: must be >= 1, got {value!r}")
    for key, (low, high) in FRICTION_RANGES.items():
        value = _valid(physics, key, _PHYSICS)
        if value is not None and not (low <= value <= high and math.isfinite(value)):
            limit = f"in [{low:g}, {high:g}]" if math.isfinite(high) else \
                f">= {low:g} and finite"
            problems.append(f"physics.{key}: must be {limit}, got {value!r}")


def _table_names(message, shapes) -> str:
    """A Scene error with its geometry and sinks named by the file's tables:
    "geometry[2] (Cylinder)" -> "cylinder[0]", "sinks[1]" -> "sink[1]" (the geometry
    list holds the planes, then the cylinders, then the cones: geometry_tables)."""
    names, seen = [], {}
    for obj in shapes.get("geometry", ()):
        kind = type(obj).__name__
        names.append(f"{kind.lower()}[{seen.get(kind, 0)}]")
        seen[kind] = seen.get(kind, 0) + 1

    def table(m):
        k = int(m.group(1))
        return names[k] if k < len(names) else m.group(0)
    message = re.sub(r"\bgeometry\[(\d+)\] \(\w+\)", table, message)
    return re.sub(r"\bsinks\[(\d+)\]", r"sink[\1]", message)


def _origins(message, groups, arrays):
    """' (sphere 7 is lattice[0] #3)': where the sphere numbers in a Scene error come from."""
    starts, names, total = [], [], 0
    for (kind, where, _), x in zip(groups, arrays["x"]):
        starts.append(total)
        names.append((kind, where))
        total += len(x)
    if len(groups) < 2:
        return ""
    found = []
    for m in re.finditer(r"\bspheres? (\d+)(?: and (\d+))?", message):
        for g in m.groups():
            if g is not None and int(g) < total and g not in found:
                found.append(g)
    notes = []
    for g in found:
        k = int(g)
        idx = int(np.searchsorted(starts, k, side="right")) - 1
        kind, where = names[idx]
        notes.append(f"sphere {k} is {where}" if kind == "spheres"
                     else f"sphere {k} is {where} #{k - starts[idx]}")
    return f" ({'; '.join(notes)})" if notes else ""


def _type_problem(value, kind):
    if kind == "vec3":
        if not (isinstance(value, list) and len(value) == 3
                and all(_is_number(c) for c in value)):
            return f"must be 3 finite numbers, got {value!r}"
    elif kind == "bool3":
        if isinstance(value, bool):
            return None
        if not (isinstance(value, list) and len(value) == 3
                and all(isinstance(c, bool) for c in value)):
            return f"must be a bool or 3 bools, got {value!r}"
    elif kind is float:
        if not _is_number(value):
            return f"must be a number, got {value!r}"
    elif kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            return f"must be an integer, got {value!r}"
    elif not isinstance(value, kind):
        return f"must be a {kind.__name__}, got {value!r}"
    return None


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _mass_of(item, radius, where, count):
    if "mass" in item and "density" in item:
        raise ValueError("give mass or density, not both")
    if "mass" in item:
        return np.full(count, float(item["mass"]))
    dens = float(item.get("density", DEFAULT_DENSITY))
    return np.full(count, dens * 4.0 / 3.0 * math.pi * radius ** 3)


def _velocities(item, count, rng):
    """v (all the same), or speed (that magnitude in random directions), plus a
    Gaussian of rms v_spread per component [m/s]."""
    if "v" in item and "speed" in item:
        raise ValueError("give v or speed, not both")
    if "speed" in item:
        d = rng.normal(size=(count, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        out = float(item["speed"]) * d
    else:
        out = np.tile(np.asarray(item.get("v", [0.0, 0.0, 0.0]), dtype=np.float64), (count, 1))
    spread = float(item.get("v_spread", 0.0))
    if spread:
        out = out + rng.normal(scale=spread, size=(count, 3))
    return out


def pour_positions(count, radius, lo, hi, rng, shapes=()):
    """A pour: ``count`` spheres on a jittered lattice (spacing 2.5 r) filling the region
    [lo, hi] from the top down, as grains leaving a hopper, at sites clear of the
    geometry objects ``shapes`` (geometry.py); raises if it is too small."""
    spacing = 2.5 * radius
    axes = [np.arange(lo[a] + radius, hi[a] - radius + 1e-12, spacing) for a in range(3)]
    if any(len(ax) == 0 for ax in axes):
        raise ValueError("region too small for one sphere")
    grid = np.stack(np.meshgrid(axes[0], axes[1], axes[2][::-1], indexing="ij"), -1)
    sites = grid.transpose(2, 0, 1, 3).reshape(-1, 3)             # top layer first
    reach = radius + 0.5 * (spacing - 2 * radius)         # a sphere and its jitter
    for g in shapes:
        sites = sites[g.gap(sites, np.full(len(sites), reach)) >= 0]
    if len(sites) < count:
        raise ValueError(f"region holds {len(sites)} spheres at spacing {spacing:g} m"
                         + (" clear of the geometry" if shapes else "")
                         + f", not {count}: make it taller")
    sites = sites[:count]
    jitter = 0.5 * (spacing - 2 * radius) * (2 * rng.random((count, 3)) - 1)
    return np.clip(sites + jitter, lo + radius, hi - radius)


def _need(item, keys, where):
    missing = [k for k in keys if k not in item]
    if missing:
        raise ValueError("missing " + ", ".join(f"'{k}'" for k in missing))


def _generate(kind, where, item, box_lo, box_hi, arrays, problems, periodic=False,
              shapes=()):
    rng = np.random.default_rng(item.get("seed", 0))
    if kind == "spheres":
        _need(item, ("x", "radius"), where)
        x = np.asarray([item["x"]], dtype=np.float64)
        count = 1
    elif kind == "lattice":
        _need(item, ("radius",), where)
        lo = np.asarray(item.get("lo", box_lo), dtype=np.float64)
        hi = np.asarray(item.get("hi", box_hi), dtype=np.float64)
        r = float(item["radius"])
        spacing = float(item.get("spacing", 2.2 * r))
        if spacing < 2 * r:
            raise ValueError(f"spacing {spacing} is less than the diameter {2 * r}")
        # lo + r + k spacing can round past hi - r (0.1 + 4 * 0.2 = 0.9000000000000001):
        # keep such a last layer, on the wall, as the intended touching layer
        axes = [np.minimum(np.arange(lo[a] + r, hi[a] - r + 1e-12 * spacing, spacing), hi[a] - r)
                for a in range(3)]
        if any(len(ax) == 0 for ax in axes):
            raise ValueError("region too small for one sphere")
        x = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        count = len(x)
    elif kind == "pour":
        _need(item, ("count", "radius"), where)
        count = int(item["count"])
        lo = np.asarray(item.get("lo", box_lo), dtype=np.float64)
        hi = np.asarray(item.get("hi", box_hi), dtype=np.float64)
        x = pour_positions(count, float(item["radius"]), lo, hi, rng, shapes)
    else:
        _need(item, ("count", "radius"), where)
        count = int(item["count"])
        if count < 1:
            raise ValueError("count must be >= 1")
        lo = np.asarray(item.get("lo", box_lo), dtype=np.float64)
        hi = np.asarray(item.get("hi", box_hi), dtype=np.float64)
        spread = float(item.get("radius_spread", 0.0))
        if not 0.0 <= spread < 1.0:
            raise ValueError(f"radius_spread must be in [0, 1), got {spread}")
        radius = float(item["radius"]) * (1.0 - spread * rng.random(count))
        x = random_positions(count, radius, lo, hi, rng,
                             existing=(arrays["x"], arrays["radius"]),
                             box=(box_lo, box_hi), periodic=periodic, shapes=shapes)
    if kind != "random":
        radius = np.full(count, float(item["radius"]))
    arrays["x"].append(x)
    arrays["v"].append(_velocities(item, count, rng))
    arrays["radius"].append(radius)
    arrays["mass"].append(_mass_of(item, radius, where, count))
    arrays["group"].append(np.full(count, len(arrays["group"]), dtype=np.int64))
    arrays["omega"].append(np.tile(np.asarray(item.get("omega", [0.0, 0.0, 0.0]),
                                              dtype=np.float64), (count, 1)))


def random_positions(count, radius, lo, hi, rng, existing=((), ()), max_tries=200,
                     box=None, periodic=False, shapes=()):
    """count non-overlapping centres of spheres inside [lo, hi], (count, 3) [m]; radius
    is one number or one per sphere [m] (random sequential addition on a hash grid,
    largest first is not needed: raises if the region is too full).

    existing: (list of (K, 3) centres, list of (K,) radii) of spheres already placed,
    kept clear of. box: (lo, hi) of the simulation box and periodic: bool or 3 bools;
    on periodic axes spheres near one face are also kept clear of the images of
    spheres near the opposite face (minimum image), as :class:`Scene` checks. shapes:
    geometry objects (geometry.py) the spheres are kept clear of (gap >= 0); a draw
    inside one uses up a try and draws nothing more, so a table places its spheres at
    the same spots whenever the geometry rejects none of its draws."""
    radii = np.broadcast_to(np.asarray(radius, dtype=np.float64), (count,))
    if np.any(hi - lo < 2.0 * radii.max()):
        raise ValueError("region too small for one sphere")
    prev_x = np.concatenate(list(existing[0])) if len(existing[0]) else np.zeros((0, 3))
    prev_r = np.concatenate(list(existing[1])) if len(existing[1]) else np.zeros(0)
    cell = 2.0 * max(radii.max(), prev_r.max() if prev_r.size else 0.0)
    placed = _PlacedSpheres(cell, box, periodic)
    for p, r in zip(prev_x, prev_r):
        placed.add(p, r)
    out = np.empty((count, 3))
    for k in range(count):
        out[k] = _place_one(radii[k], lo, hi, rng, placed, max_tries, k, count, shapes)
    return out


def _place_one(radius, lo, hi, rng, placed, max_tries, k, count, shapes=()):
    """A centre [m] for sphere k of count, of ``radius`` [m], uniform in [lo + r, hi - r],
    clear of the geometry objects ``shapes`` and of every sphere ``placed`` (it is added
    there): up to max_tries draws of rng.random(3); ValueError when none is clear."""
    for _ in range(max_tries):
        p = lo + radius + rng.random(3) * (hi - lo - 2.0 * radius)
        if _clear_of(shapes, p, radius) and not placed.overlaps(p, radius):
            placed.add(p, radius)
            return p
    raise ValueError(f"could not place sphere {k} of {count} without overlap"
                     + (" or entering geometry" if shapes else "") + f" after {max_tries} tries: "
                     "the region is too full")


def _clear_of(shapes, p, radius) -> bool:
    """Whether a sphere of ``radius`` [m] at p (3,) [m] has a gap >= 0 to every geometry
    object in ``shapes``."""
    return all(g.gap(p[None, :], radius)[0] >= 0 for g in shapes)


class _PlacedSpheres:
    """Spheres placed so far on a hash grid of cubic cells of side ``cell`` [m] (at
    least the largest diameter, so only the 27 cells around a point can hold a sphere
    overlapping one there). box: (lo, hi) of the simulation box or None (then no axis
    is periodic); periodic: bool or 3 bools. A sphere near a periodic face is also
    stored at its image one box length away."""

    def __init__(self, cell, box, periodic):
        self.cell = cell
        self.periodic = (bool(periodic),) * 3 if isinstance(periodic, bool) else \
            tuple(bool(p) for p in periodic)
        if box is None:
            self.periodic = (False, False, False)
        else:
            self.box_lo = np.asarray(box[0], dtype=np.float64)
            self.box_hi = np.asarray(box[1], dtype=np.float64)
        self.buckets: dict = {}

    def key(self, p):
        """Hash-grid cell (3 ints) of a point p [m]."""
        return tuple(np.floor(p / self.cell).astype(np.int64))

    def images(self, p):
        """p and, on periodic axes, its copies one box length away when p lies within
        one cell of a face (only those can come within reach of a sphere inside)."""
        shifts = [(0.0,)] * 3
        for a in range(3):
            if self.periodic[a]:
                size = self.box_hi[a] - self.box_lo[a]
                s = [0.0]
                if p[a] - self.box_lo[a] < self.cell:
                    s.append(size)
                if self.box_hi[a] - p[a] < self.cell:
                    s.append(-size)
                shifts[a] = tuple(s)
        return [p + np.array((sx, sy, sz)) for sx in shifts[0] for sy in shifts[1]
                for sz in shifts[2]]

    def add(self, p, r):
        """Store a sphere of radius r [m] at p [m] (and its periodic images)."""
        for q in self.images(p):
            self.buckets.setdefault(self.key(q), []).append((q, r))

    def overlaps(self, p, radius):
        """Whether a sphere of ``radius`` [m] at p [m] would overlap a stored one."""
        c = self.key(p)
        for dx, dy, dz in itertools.product((-1, 0, 1), repeat=3):
            for q, rq in self.buckets.get((c[0] + dx, c[1] + dy, c[2] + dz), ()):
                if np.sum((p - q) ** 2) < (radius + rq) ** 2:
                    return True
        return False
