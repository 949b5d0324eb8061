"""A mapped column's candidate source labels, for files from several loggers: checked as a
mapping is read (:func:`~sumo_drvpw.data.adapters.columns.load_mapping`), and the one each
file holds chosen (:func:`for_file`).

A column may be labelled differently by two loggers (``Speed (km/h)`` in one file,
``GPS Speed [km/h]`` in another). One mapping reads both:

* ``also = ["GPS Speed [km/h]"]`` in ``[columns."Speed (km/h)"]``: other labels of the same
  column, read with the table's unit, scale, role and 'no reading' values, tried after the
  table's own label in the order listed;
* or several tables with the same ``name`` (each with its own unit: a logger in km/h,
  another in mph), tried in the mapping's order.

A file is read through the first of a column's labels it holds. A file holding two of them
is refused, naming both, unless ``first_wins = true`` (in a table of that column) says the
first listed wins: the others are then left out of the file (noted).
"""

from __future__ import annotations

from pathlib import Path

from sumo_drvpw.errors import UserError

#: the mapping entry's keys this module reads
KEYS = ("also", "first_wins")


def also_labels(p: Path, key: str, label: str, e: dict) -> list[str]:
    """The further labels an entry (``key`` of source label ``label``) lists in ``also``,
    stripped as header labels are read: a non-empty list of distinct non-empty texts, none
    the table's own label; else a UserError naming the mapping file and key."""
    if "also" not in e:
        return []
    v = e["also"]
    if not isinstance(v, list) or not v:
        raise UserError(f"{p}: {key}.also must be a non-empty list of source labels (other loggers' labels "
                        f"of this column, e.g. also = [\"GPS Speed [km/h]\"]), got {v!r}")
    out: list[str] = []
    for x in v:
        if not isinstance(x, str) or not x.strip():
            raise UserError(f"{p}: {key}.also must list source labels as non-empty texts, got {x!r}")
        x = x.strip()
        if x == label or x in out:
            raise UserError(f"{p}: {key}.also lists {x!r} twice (with the table's own label, labels are "
                            "read without their surrounding spaces)")
        out.append(x)
    return out


def first_wins(p: Path, key: str, e: dict) -> bool | None:
    """An entry's ``first_wins`` (None when not given): true or false, else a UserError."""
    v = e.get("first_wins")
    if v is not None and not isinstance(v, bool):
        raise UserError(f"{p}: {key}.first_wins must be true or false, got {v!r}")
    return v


def candidates(p: Path, entries: dict, wins: dict[str, bool | None]) -> tuple[dict[str, list[str]], set[str]]:
    """Each column name's labels in the mapping's order (``entries``: label → entry with
    ``name`` and ``key``; ``wins``: each table's ``first_wins`` by its key), and the names
    whose first present label wins. A column's tables that disagree on its role or on
    ``first_wins``, or ``first_wins`` on a column of one label: a UserError naming the keys."""
    groups: dict[str, list[str]] = {}
    for label, e in entries.items():
        groups.setdefault(e["name"], []).append(label)
    first: set[str] = set()
    for name, labels in groups.items():
        keys = list(dict.fromkeys(entries[lb]["key"] for lb in labels))
        roles = [(entries[lb]["key"], entries[lb]["role"]) for lb in labels if "role" in entries[lb]]
        other = [(k, r) for k, r in roles if r != roles[0][1]]
        if other:
            raise UserError(f"{p}: {roles[0][0]}.role {roles[0][1]!r} and {other[0][0]}.role {other[0][1]!r} "
                            f"are labels of '{name}', which has one role: give it once, or the same")
        yes, no = [k for k in keys if wins.get(k) is True], [k for k in keys if wins.get(k) is False]
        if yes and no:
            raise UserError(f"{p}: {yes[0]}.first_wins and {no[0]}.first_wins disagree: '{name}' is read "
                            "one way in every file")
        if yes:
            if len(labels) < 2:
                raise UserError(f"{p}: {keys[0]}.first_wins is for a column with several labels (also = [...], "
                                f"or another table with name = '{name}'): '{name}' has one")
            first.add(name)
    return groups, first


def for_file(m: dict, present, path) -> tuple[dict, list[str], set[str]]:
    """The mapping ``m`` for one file: of each column's labels (``m["candidates"]``) the
    first that ``present(label)`` finds in the file (none found: the first, so that reading
    says it is missing). Returns (``m`` with its ``columns`` so chosen, notes, the labels
    left out: present, but not chosen). Two present: a UserError naming the file and both,
    unless the column's first present label wins (``m["first_wins"]``)."""
    chosen, notes, left = set(), [], set()
    for name, labels in m.get("candidates", {}).items():
        here = [lb for lb in labels if present(lb)]
        if len(here) > 1 and name not in m.get("first_wins", ()):
            key = m["columns"][labels[0]]["key"]
            raise UserError(f"{path}: holds both '{here[0]}' and '{here[1]}', labels of '{name}' in {m['path']}: "
                            f"say which to read (first_wins = true in {key} reads the first listed, "
                            f"'{here[0]}'), or map the other to a name of its own")
        if len(here) > 1:
            notes.append(f"columns {', '.join(repr(x) for x in here)} all label '{name}' in {m['path']}: "
                         f"'{here[0]}' read (first_wins), the rest left out")
            left.update(here[1:])
        chosen.add(here[0] if here else labels[0])
    if not m.get("candidates"):
        return m, notes, left
    cand = m["candidates"]
    return {**m, "columns": {lb: e for lb, e in m["columns"].items() if e["name"] not in cand or lb in chosen}}, \
        notes, left


def all_labels(m: dict, label: str) -> list[str]:
    """A mapped label and its column's other labels, in the mapping's order."""
    e = m["columns"].get(label)
    return list(m.get("candidates", {}).get(e["name"], [label])) if e else [label]


def nor_others(m: dict, label: str) -> str:
    """' (nor its other labels 'B', 'C')' for a mapped label whose column has other labels (the
    first five, and how many more), else '' (the end of a 'missing column' error)."""
    e = m["columns"].get(label)
    others = [x for x in m.get("candidates", {}).get(e["name"], ()) if x != label] if e else []
    more = f" or {len(others) - 5:,} more" if len(others) > 5 else ""  # (a fleet's loggers: one line still)
    return f" (nor its other labels {', '.join(repr(x) for x in others[:5])}{more})" if others else ""
