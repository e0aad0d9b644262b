"""Scene-file tables of materials: [[material]] (name, restitution, friction,
rolling_friction) and [[material_pair]] (materials = [two names], and the pair's
values), and the ``material`` key of the sphere tables (materials.py). Checked like
every other table: unknown keys, wrong types, unknown names and bad values are named
and reported with the file's other problems (scenefile.py).

Material 0 of a scene file is "default": the [physics] values, for sphere tables
without a ``material`` key; the file's [[material]] tables follow in file order.
"""
from __future__ import annotations

import difflib

from .materials import COEFFICIENTS, Material
from .scenegeometry import table_items

__all__ = ["material_tables", "material_index", "DEFAULT_MATERIAL"]

#: name of material 0: the [physics] values
DEFAULT_MATERIAL = "default"
_VALUES = {key: float for key in COEFFICIENTS}
MATERIAL_SCHEMA = dict(name=str, **_VALUES)
PAIR_SCHEMA = dict(materials=list, **_VALUES)


def material_tables(data: dict, check_table, problems: list) -> dict:
    """{"materials": [Material...], "material_pairs": {(a, b): Material}, "names":
    [...]} from the file's [[material]] and [[material_pair]] tables (material 0 the
    default); problems go to ``problems``. check_table: scenefile's key and type
    check."""
    materials = [Material(DEFAULT_MATERIAL)]
    for where, item in table_items(data, "material", problems):
        before = len(problems)
        check_table(item, MATERIAL_SCHEMA, where + ".", problems)
        if "name" not in item:
            problems.append(f"{where}: missing 'name'")
        elif item["name"] in [m.name for m in materials]:
            problems.append(f"{where}.name: {item['name']!r} is taken (names must differ; "
                            f"{DEFAULT_MATERIAL!r} is the [physics] values)")
        if len(problems) == before:
            _append(materials, where, item, problems)
        elif _named(item, materials):
            materials.append(Material(item["name"]))
    names = [m.name for m in materials]
    pairs = {}
    for where, item in table_items(data, "material_pair", problems):
        before = len(problems)
        check_table(item, PAIR_SCHEMA, where + ".", problems)
        ends = _pair_names(where, item, names, problems)
        if len(problems) == before and tuple(sorted(ends)) in pairs:
            problems.append(f"{where}: the pair {names[ends[0]]}/{names[ends[1]]} is "
                            f"given by an earlier [[material_pair]] too")
        elif len(problems) == before:
            values = {k: v for k, v in item.items() if k != "materials"}
            try:
                label = f"{names[ends[0]]}/{names[ends[1]]}"
                pairs[tuple(sorted(ends))] = Material(label, **values)
            except ValueError as exc:
                problems.append(f"{where}: {exc}")
    return dict(materials=materials, material_pairs=pairs, names=names)


def _named(item, materials) -> bool:
    """True when a table with problems has a new name: it is kept (with its values
    left out) so that tables naming it report no problem of their own."""
    name = item.get("name")
    return isinstance(name, str) and name not in [m.name for m in materials]


def _append(materials, where, item, problems):
    """Add the material of a [[material]] table (a problem and a placeholder of its
    name when a value is bad)."""
    try:
        materials.append(Material(**item))
    except ValueError as exc:
        problems.append(f"{where}: {exc}")
        materials.append(Material(item["name"]))


def _pair_names(where, item, names, problems) -> tuple:
    """The two material indices of a [[material_pair]] table's ``materials`` key."""
    ends = item.get("materials")
    if not isinstance(ends, list) or len(ends) != 2:
        problems.append(f"{where}.materials: must be a list of two material names")
        return ()
    out = []
    for name in ends:
        index = material_index(name, names, f"{where}.materials", problems)
        if index is not None:
            out.append(index)
    return tuple(out) if len(out) == 2 else ()


def material_index(name, names, key, problems):
    """Index of the material called ``name`` (a problem naming ``key`` if none)."""
    if isinstance(name, str) and name in names:
        return names.index(name)
    near = difflib.get_close_matches(str(name), names, n=1)
    hint = f" (did you mean {near[0]!r}?)" if near else f" (known: {', '.join(names)})"
    problems.append(f"{key}: unknown material {name!r}{hint}")
    return None
