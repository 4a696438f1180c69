"""The checks every JSON artifact's loader makes, naming the file and the key.

A JSON artifact (``stack.json``, ``camera.json``, ``rig.json``,
``response.json``, ``rectification.json``, ``lightfield.json``, a scene's
``gt.json``) is read by one parser (ARCHITECTURE, "One parser per artifact");
each parser checks its keys once, at load time, with :func:`require`, so a
hand-edited file with wrong content is refused with
``InputError(<file>, "key 'images[3]': expected a file name (string), got 42")``
rather than failing later inside numpy. Key paths are written as in
JavaScript: ``left.K[0][0]``.

JSON cannot hold NaN or infinity (the writers store them as ``null``), so a
number is always finite here; ranges (``above=0`` for a focal length or an
exposure time) and shapes (``shape=(3, 3)``) are the artifact's own rules.

Examples
--------
>>> body = {"images": ["a.png", 42], "spacing": "wide", "K": [[1, 0], [0, 1]]}
>>> require(body, "images", "list", items="file name", path="stack.json")
Traceback (most recent call last):
...
lumigraph.capture.errors.InputError: stack.json: key 'images[1]': expected a file name (string), got 42
>>> require(body, "spacing", "number", above=0, path="lightfield.json")
Traceback (most recent call last):
...
lumigraph.capture.errors.InputError: lightfield.json: key 'spacing': expected a positive number, got 'wide'
>>> require(body, "K", "matrix", shape=(3, 3), path="camera.json", where="left")
Traceback (most recent call last):
...
lumigraph.capture.errors.InputError: camera.json: key 'left.K': expected a 3x3 matrix (a list of 3 rows), got 2 rows
>>> require(body, "alpha", "number", default=None, path="x.json") is None
True
"""

from __future__ import annotations

import math
import os

import numpy as np

from lumigraph.capture.errors import InputError

MISSING = object()
_KINDS = {"object": "an object", "list": "a list", "string": "a string",
          "file name": "a file name (string)", "integer": "an integer", "number": "a number",
          "boolean": "true or false", "matrix": "a matrix"}


def key_path(where: str, *keys: str | int) -> str:
    """``where`` extended by ``keys``: ``("left", "K", 0) -> "left.K[0]"``,
    ``("images", 3) -> "images[3]"``, ``("", "K") -> "K"``."""
    for key in keys:
        if isinstance(key, int):
            where = f"{where}[{key}]"
        else:
            where = f"{where}.{key}" if where else key
    return where


def fail(path: str | os.PathLike, key: str, problem: str) -> InputError:
    """The error of one key: ``InputError(path, "key '<key>': <problem>")``
    (only the problem at the top level, where ``key`` is empty)."""
    return InputError(path, f"key '{key}': {problem}" if key else problem)


def shown(value) -> str:
    """A short description of a JSON value for a message: ``42``, ``'wide'``,
    ``null``, ``a list of 3``, ``an object``."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if isinstance(value, dict):
        return "an object"
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _is_number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _is_finite(v) -> bool:
    """A JSON number a float64 holds: not NaN/inf, not an integer beyond ~1.8e308."""
    try:
        return _is_number(v) and math.isfinite(v)
    except OverflowError:
        return False


def _range_text(kind: str, low, high, above) -> str:
    noun = kind  # "integer" or "number"
    if above == 0 and high is None and low is None:
        return f"a positive {noun}"
    if above is not None:
        return f"a number > {above}" + (f" and <= {high}" if high is not None else "")
    article = "an" if noun == "integer" else "a"
    if low is not None and high is not None:
        return f"{article} {noun} in {low}..{high}"
    if low is not None:
        return f"{article} {noun} >= {low}"
    if high is not None:
        return f"{article} {noun} <= {high}"
    return _KINDS[kind]


def check(value, kind: str, *, path: str | os.PathLike, key: str, low=None, high=None,
          above=None, length=None, min_length: int = 0, items: str | None = None,
          shape: tuple | None = None, nullable: bool = False):
    """Check one JSON value against ``kind`` and return it converted.

    Parameters
    ----------
    value
        The value as ``json.loads`` gave it.
    kind : str
        ``object``, ``list``, ``string`` (non-empty), ``file name``
        (non-empty, no NUL), ``integer`` (an integral number; returns int),
        ``number`` (finite; returns float), ``boolean``, or ``matrix``
        (nested lists of finite numbers of ``shape``, ``None`` for a free
        axis; returns float64 ndarray).
    path, key : str
        The file and the key path, for the error.
    low, high, above : float, optional
        Inclusive bounds and an exclusive lower bound (``above=0``:
        positive), of a number, of an integer or of every matrix entry.
    length, min_length : int, optional
        Exact or least length of a list.
    items : str, optional
        The kind of every element of a list (with the same bounds).
    shape : tuple of int or None
        Of a matrix.
    nullable : bool
        Accept (and return) ``null``.

    Raises
    ------
    InputError
        ``path``: ``key '<key>': expected <what>, got <value>``.
    """
    if value is None and nullable:
        return None
    bounds = {"low": low, "high": high, "above": above}
    if kind == "matrix":
        return _matrix(value, shape, path=path, key=key, **bounds)
    if kind == "list":
        if not isinstance(value, list):
            raise fail(path, key, f"expected a list, got {shown(value)}")
        if length is not None and len(value) != length:
            raise fail(path, key, f"expected a list of {length}, got {len(value)}")
        if len(value) < min_length:
            raise fail(path, key, f"expected a list of at least {min_length}, got {len(value)}")
        if items is None:
            return value
        return [check(v, items, path=path, key=key_path(key, i), **bounds)
                for i, v in enumerate(value)]
    if kind == "object":
        if not isinstance(value, dict):
            raise fail(path, key, f"expected an object, got {shown(value)}")
        return value
    if kind in ("string", "file name"):
        if not isinstance(value, str) or not value or (kind == "file name" and "\0" in value):
            raise fail(path, key, f"expected {_KINDS[kind]}, got {shown(value)}")
        return value
    if kind == "boolean":
        if not isinstance(value, bool):
            raise fail(path, key, f"expected true or false, got {shown(value)}")
        return value
    if kind in ("integer", "number"):
        what = _range_text(kind, low, high, above)
        ok = _is_finite(value) and (kind == "number" or float(value).is_integer())
        if ok:
            x = int(value) if kind == "integer" else float(value)
            ok = ((low is None or x >= low) and (high is None or x <= high)
                  and (above is None or x > above))
        if not ok:
            raise fail(path, key, f"expected {what}, got {shown(value)}")
        return x
    raise ValueError(f"kind: unknown kind {kind!r}")


def _matrix(value, shape, *, path, key, low, high, above) -> np.ndarray:
    """Nested lists of ``shape`` (``None``: any length >= 1) of finite numbers."""

    def count(n):
        return "N" if n is None else str(n)

    def walk(v, depth, k):
        n = shape[depth]
        if not isinstance(v, list) or (n is not None and len(v) != n) or not v:
            noun = "rows" if depth + 1 < len(shape) else "numbers"
            got = f"{len(v)} {noun}" if isinstance(v, list) else shown(v)
            if depth == 0 and len(shape) == 2:
                what = f"a {count(shape[0])}x{count(shape[1])} matrix (a list of {count(n)} rows)"
            elif depth == 0:
                what = f"a list of {count(n)} {noun}"
            else:
                what = f"a row of {count(n)} {noun}"
            raise fail(path, k, f"expected {what}, got {got}")
        if depth + 1 < len(shape):
            for i, row in enumerate(v):
                walk(row, depth + 1, key_path(k, i))
            return
        for i, x in enumerate(v):
            if not _is_finite(x):
                raise fail(path, key_path(k, i), f"expected a number, got {shown(x)}")
            if ((low is not None and x < low) or (high is not None and x > high)
                    or (above is not None and not x > above)):
                raise fail(path, key_path(k, i), f"expected "
                                                 f"{_range_text('number', low, high, above)}, "
                                                 f"got {shown(x)}")

    walk(value, 0, key)
    if len(shape) > 1 and shape[1] is None:  # rows of one free length must agree
        lengths = {len(r) for r in value}
        if len(lengths) > 1:
            raise fail(path, key, f"expected rows of one length, got lengths {sorted(lengths)}")
    return np.array(value, dtype=np.float64)


def require(body: dict, key: str, kind: str, *, path: str | os.PathLike, where: str = "",
            default=MISSING, **rules):
    """``body[key]`` checked by :func:`check` (with ``rules``) and converted;
    ``default`` when the key is absent and a default is given.

    ``where`` is the key path of ``body`` itself inside the file (``""`` at
    the top level, ``"left"`` for a rig's left camera); the error names
    ``where.key``. Without a default, a missing key is an error.
    """
    name = key_path(where, key)
    if key not in body:
        if default is not MISSING:
            return default
        raise fail(path, name, f"missing; expected {_what(kind, rules)}")
    return check(body[key], kind, path=path, key=name, **rules)


def _what(kind: str, rules: dict) -> str:
    if kind in ("integer", "number"):
        return _range_text(kind, rules.get("low"), rules.get("high"), rules.get("above"))
    if kind == "matrix":
        return "a " + "x".join("N" if n is None else str(n) for n in rules["shape"]) + " array"
    if kind == "list" and rules.get("items"):
        return f"a list of {rules['items']}s"
    return _KINDS[kind]


def require_object(value, *, path: str | os.PathLike, where: str, what: str,
                   keys: tuple[str, ...] = ()) -> dict:
    """``value`` as an object holding every one of ``keys``, or an error
    naming ``where`` and every missing key (``what`` says what it describes,
    e.g. ``"a camera (K, dist, image_size)"``)."""
    if not isinstance(value, dict):
        raise fail(path, where, f"expected an object describing {what}, got {shown(value)}")
    missing = [k for k in keys if k not in value]
    if missing:
        raise fail(path, where, f"missing key{'s' if len(missing) > 1 else ''} "
                                f"{', '.join(map(repr, missing))}; expected {what}")
    return value


def check_schema(body: dict, *, path: str | os.PathLike, schemas: tuple[str, ...],
                 versions: tuple[int, ...] = (1,)) -> None:
    """Refuse a file whose ``schema`` is none of ``schemas`` or whose
    ``schema_version`` is not one this version reads (a file without them,
    written by hand, is accepted)."""
    if "schema" in body and body["schema"] not in schemas:
        raise fail(path, "schema", f"expected {' or '.join(map(repr, schemas))}, got "
                                   f"{shown(body['schema'])}: not this kind of file")
    if "schema_version" in body:
        v = body["schema_version"]
        if not (_is_number(v) and v in versions):
            raise fail(path, "schema_version", f"version {shown(v)} is not one this lumigraph "
                                               f"reads ({', '.join(map(str, versions))}); "
                                               "upgrade lumigraph or rewrite the file")


def first_non_finite(body) -> str | None:
    """The key path of the first NaN or infinity in a parsed JSON value
    (Python's ``json`` reads the non-standard ``NaN``/``Infinity`` and turns
    ``1e999`` into infinity), or None. Iterative: any depth ``json`` parses."""
    todo = [("", body)]
    while todo:
        k, v = todo.pop()
        if isinstance(v, float) and not math.isfinite(v):
            return k
        if isinstance(v, dict):
            todo.extend((key_path(k, str(n)), x) for n, x in reversed(list(v.items())))
        elif isinstance(v, list):
            todo.extend((key_path(k, i), x) for i, x in reversed(list(enumerate(v))))
    return None
