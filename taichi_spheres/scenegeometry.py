"""Scene-file tables of static geometry and sinks: [[plane]], [[cylinder]], [[cone]] and
[[sink]] (keys as the arguments of ts.Plane, ts.Cylinder, ts.Cone and ts.Sink,
geometry.py), checked like every other table: unknown keys and wrong types are named,
and every problem is reported with the others (scenefile.py)."""
from __future__ import annotations

from .geometry import Cone, Cylinder, Plane, Sink

__all__ = ["geometry_tables", "table_items", "GEOMETRY_SCHEMAS"]

_MATERIAL = {"restitution": float, "friction": float}
#: table name -> (class, schema, required keys); geometry in this order in a Scene
GEOMETRY_SCHEMAS = {
    "plane": (Plane, dict(point="vec3", normal="vec3", hole=float, **_MATERIAL),
              ("point", "normal")),
    "cylinder": (Cylinder, dict(point="vec3", axis="vec3", radius=float, length=float,
                                inside=bool, **_MATERIAL), ("point", "axis", "radius")),
    "cone": (Cone, dict(point="vec3", axis="vec3", radius_at_point=float,
                        radius_at_end=float, length=float, inside=bool, **_MATERIAL),
             ("point", "axis", "radius_at_point", "radius_at_end", "length")),
    "sink": (Sink, dict(low="vec3", high="vec3", recycle=bool), ("low", "high")),
}


def table_items(data: dict, name: str, problems: list):
    """(where, table) of each entry of the array of tables [[name]] ('name[k]'); an entry
    that is not a table adds a problem."""
    items = data.get(name, [])
    if not isinstance(items, list):
        return
    for k, item in enumerate(items):
        where = f"{name}[{k}]"
        if not isinstance(item, dict):
            problems.append(f"{where}: must be a table ([[{name}]])")
            continue
        yield where, item


def geometry_tables(data: dict, check_table, problems: list) -> dict:
    """{"geometry": [...], "sinks": [...]} built from the file's tables (planes, then
    cylinders, then cones, each in file order); problems (keys, types, values such as
    "cylinder[0]: Cylinder.radius must be > 0, got -1") go to ``problems``.
    check_table: scenefile's key and type check."""
    out = {"geometry": [], "sinks": []}
    for name, (cls, schema, required) in GEOMETRY_SCHEMAS.items():
        for where, item in table_items(data, name, problems):
            before = len(problems)
            check_table(item, schema, where + ".", problems)
            missing = [key for key in required if key not in item]
            if missing:
                problems.append(f"{where}: missing " + ", ".join(f"'{m}'" for m in missing))
            if len(problems) > before:
                continue
            try:
                obj = cls(**item)
            except (TypeError, ValueError) as exc:
                problems.append(f"{where}: {exc}")
                continue
            out["sinks" if cls is Sink else "geometry"].append(obj)
    return out
