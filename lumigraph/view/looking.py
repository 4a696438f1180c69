"""Looking mode of ``lumigraph view``: a Flask blueprint serving every artifact kind.

The routes are listed in :mod:`lumigraph.view`'s docstring. The artifacts are
``current_app.config["LUMI_ARTIFACTS"]`` (a list of paths; a folder stands for
the artifacts in it, :func:`lumigraph.view.artifacts.expand`), numbered in
that order: an artifact's id is its index.

What was read is kept (:class:`Shelf`: the last :data:`KEEP` artifacts, keyed
by path, size and modification time, so a file rewritten while the page is
open is read again): each slider move draws from arrays in memory.

An artifact that cannot be read answers ``{"error": "<path>: <problem>"}``
(the ``InputError`` text): status 422 from the image, probe and geometry
routes, 200 with ``error`` set from the describe route (the page shows the
line where the picture would be). A bad control value is a 400 naming the
control. Nothing a request sends stops the server.

Examples
--------
>>> from flask import Flask
>>> app = Flask(__name__)
>>> app.register_blueprint(blueprint)
>>> app.config["LUMI_ARTIFACTS"] = ["missing.exr"]
>>> r = app.test_client().get("/api/look/0")
>>> r.status_code, r.get_json()["error"]
(200, 'missing.exr: file not found')
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from pathlib import Path

from flask import Blueprint, Response, current_app, jsonify, request

from lumigraph.capture.errors import EstimationError, InputError
from lumigraph.view import artifacts as A

blueprint = Blueprint("look", __name__)

# Artifacts kept in memory: a 9x9x512x512 RGB light field holds 255 MB and its
# spectrum 0.7 GB, a 12 MP radiance map 144 MB; three is a page's working set.
KEEP = 3


class Shelf:
    """The artifact list of one app and the artifacts read from it (LRU)."""

    def __init__(self, paths):
        self.paths = A.expand(paths)
        self.kinds = [A.kind_of(p) for p in self.paths]
        self.lock = threading.Lock()
        self.loaded: OrderedDict = OrderedDict()
        self.reading: dict[str, threading.Lock] = {}

    def path(self, ident: str) -> Path:
        try:
            i = int(ident)
        except ValueError:
            i = -1
        if not 0 <= i < len(self.paths):
            raise LookupError(ident)
        return self.paths[i]

    def get(self, ident: str) -> A.Artifact:
        """The artifact ``ident``, read once per version of its file (InputError if it
        cannot be read; the next request tries again)."""
        p = self.path(ident)
        try:
            st = (p / "lightfield.json" if p.is_dir() else p).stat()
            key = (str(p), st.st_size, st.st_mtime_ns)
        except OSError:
            key = (str(p), None, None)
        with self.lock:
            if key in self.loaded:
                self.loaded.move_to_end(key)
                return self.loaded[key]
            reading = self.reading.setdefault(key[0], threading.Lock())
        # one reader per file (two requests at once read a 1 GB light field once);
        # outside the shelf's lock: other artifacts are drawn meanwhile
        with reading:
            with self.lock:
                if key in self.loaded:
                    return self.loaded[key]
            art = A.load(p)
        with self.lock:
            for k in [k for k in self.loaded if k[0] == key[0]]:
                del self.loaded[k]  # an older version of the same file
            self.loaded[key] = art
            while len(self.loaded) > KEEP:
                self.loaded.popitem(last=False)
        return art


def shelf() -> Shelf:
    """This app's :class:`Shelf` (made on first use from ``LUMI_ARTIFACTS``)."""
    ext = current_app.extensions
    s = ext.get("lumigraph_look")
    paths = list(current_app.config.get("LUMI_ARTIFACTS", []))
    if s is None or getattr(s, "source", None) != paths:
        s = Shelf(paths)
        s.source = paths
        ext["lumigraph_look"] = s
    return s


@blueprint.errorhandler(EstimationError)
def _estimation(e):
    return jsonify({"error": str(e)}), 422


@blueprint.errorhandler(Exception)
def _fault(e):
    """Our bug: one JSON line for the page (and the traceback in the server's log);
    the server goes on serving. HTTP errors (404, 405) keep their own status."""
    from werkzeug.exceptions import HTTPException

    if isinstance(e, HTTPException):
        return jsonify({"error": f"{request.path}: {e.name}"}), e.code
    current_app.logger.exception("lumigraph view: internal fault")
    return jsonify({"error": f"internal fault (a lumigraph bug): {type(e).__name__}: {e}"}), 500


def _error(e: InputError, status: int):
    return jsonify({"error": str(e)}), status


def _artifact(ident: str):
    """(artifact, None) or (None, error response)."""
    s = shelf()
    try:
        return s.get(ident), None
    except LookupError:
        return None, (jsonify({"error": f"{ident}: no such artifact (see /api/look/list)"}), 404)
    except InputError as e:
        return None, _error(e, 422)


@blueprint.get("/api/look/list")
def look_list():
    s = shelf()
    out = []
    for i, (p, kind) in enumerate(zip(s.paths, s.kinds, strict=True)):
        row = {"id": str(i), "path": str(p), "kind": kind}
        if not p.exists():
            row["error"] = f"{p}: file not found"
        elif kind is None:
            row["error"] = f"{p}: not an artifact lumigraph view shows"
        out.append(row)
    return jsonify(out)


@blueprint.get("/api/look/<ident>")
def look_describe(ident):
    s = shelf()
    try:
        p = s.path(ident)
    except LookupError:
        return jsonify({"error": f"{ident}: no such artifact (see /api/look/list)"}), 404
    meta = A.read_meta(p)
    try:
        art = s.get(ident)
    except InputError as e:
        return jsonify({"id": ident, "path": str(p), "kind": A.kind_of(p), "shape": None,
                        "units": None, "controls": [], "meta": meta, "error": str(e)})
    with art.lock:
        body = art.describe()
    return jsonify({"id": ident, **body, "meta": meta, "error": None})


def _values(art: A.Artifact):
    return A.parse_controls(art.controls(), request.args)


@blueprint.get("/api/look/<ident>/image")
def look_image(ident):
    art, err = _artifact(ident)
    if err:
        return err
    fmt = request.args.get("format") or art.image_format
    try:
        if fmt not in ("png", "jpeg"):
            raise InputError("format", f"expected png or jpeg, got {fmt!r}")
        values = _values(art)
    except InputError as e:
        return _error(e, 400)
    try:
        with art.lock:
            img = art.image(values)
    except InputError as e:
        return _error(e, 422)
    r = Response(A.encode(img, fmt), mimetype="image/png" if fmt == "png" else "image/jpeg")
    r.headers["Cache-Control"] = "no-store"
    return r


@blueprint.get("/api/look/<ident>/probe")
def look_probe(ident):
    art, err = _artifact(ident)
    if err:
        return err
    try:
        values = _values(art)
    except InputError as e:
        return _error(e, 400)
    try:
        with art.lock:
            return jsonify(art.probe(request.args.get("x"), request.args.get("y", 0), values))
    except InputError as e:
        return _error(e, 400 if e.where == "x, y" else 422)


@blueprint.get("/api/look/<ident>/geometry")
def look_geometry(ident):
    art, err = _artifact(ident)
    if err:
        return err
    try:
        with art.lock:
            return jsonify(art.geometry())
    except InputError as e:
        return _error(e, 422)
