"""The web application of ``lumigraph view``: one page (``static/index.html``)
and two JSON APIs, looking mode (:mod:`lumigraph.view.looking`, ``/api/look/…``)
and marking mode (below, ``/api/facade/…``, over a
:class:`~lumigraph.view.marking.FacadeSession`).

Marking routes (JSON bodies and answers; a mark is ``{id, photo, edge,
segment [x0, y0, x1, y1] px, proposed}``):

``GET  /api/facade/state``                  photos, model edge names, marks, proposals, last solve
``GET  /api/facade/photo/<i>``              photograph ``i`` as PNG
``GET  /api/facade/detected/<i>``           line segments detected in it ``{"segments": [[4]…]}``
``POST /api/facade/marks``                  ``{photo, segment, edge?, snap?}`` -> the new mark,
                                           with ``snapped``, ``jump_px`` (how far the snap moved
                                           the drag) and ``dragged`` (the segment as drawn)
``POST /api/facade/marks/<id>``             ``{edge}`` (assign; null unassigns) or ``{segment}``
``DELETE /api/facade/marks/<id>``           remove a mark
``POST /api/facade/solve``                  ``{noise_px?}`` -> parameters, projected edges, residuals,
                                           ``weak`` (weakly constrained parameters and the
                                           unmarked edges that would hold them:
                                           :func:`~lumigraph.view.marking.weak_spots`);
                                           refused (422) when the marks do not constrain some
                                           unknowns, with ``unconstrained``: per unknown, the
                                           unmarked edges that would constrain it
                                           (:func:`~lumigraph.view.marking.unconstrained_spots`)
``POST /api/facade/propose``                automatic marking -> ``{"proposals": […]}``
``POST /api/facade/resnap``                 ``{every?}`` after a solve: marks onto the image step
                                           within their edge's band -> ``{moved, flagged, deleted}``
                                           (``every: false``: only marks beyond their band)
``POST /api/facade/proposals/<id>/accept``  (``all`` accepts every pending one)
``POST /api/facade/proposals/<id>/reject``

Every change is saved to ``edges.json`` before the answer. A request the
session refuses answers 400 (a bad request: ``InputError``), 422 (a fit the
marks cannot support: ``EstimationError``) or 404 with ``{"error": "<where>:
<problem>"}`` (one line); an unexpected fault answers 500 with
``{"error": "internal fault: …"}``. The server keeps serving either way.

>>> app = create_app(artifacts=[])
>>> app.test_client().get("/api/facade/state").get_json()
{'error': 'facade: no Façade session; start with lumigraph view --facade blocks.json IMAGES... --edges edges.json'}
"""

from __future__ import annotations

from pathlib import Path

from lumigraph.capture.errors import EstimationError, InputError

STATIC = Path(__file__).resolve().parent / "static"


def _line(text: str) -> str:
    return " ".join(str(text).split())


def create_app(*, artifacts=(), facade=None):
    """The Flask app: the page, looking mode over ``artifacts`` (paths; a
    folder stands for the artifacts in it) and marking mode over ``facade``
    (a :class:`~lumigraph.view.marking.FacadeSession`, or None)."""
    from flask import Flask, Response, jsonify, request, send_from_directory

    from lumigraph.view import looking

    app = Flask("lumigraph.view", static_folder=str(STATIC), static_url_path="/static")
    app.config["LUMI_ARTIFACTS"] = [str(a) for a in artifacts]
    app.config["LUMI_FACADE"] = facade
    app.json.sort_keys = False
    app.register_blueprint(looking.blueprint)

    def err(where, problem, status):
        return jsonify({"error": _line(f"{where}: {problem}")}), status

    def session():
        s = app.config["LUMI_FACADE"]
        if s is None:
            raise LookupError("facade")
        return s

    def body() -> dict:
        data = request.get_json(silent=True)
        if not isinstance(data, dict):
            raise InputError("request", "expected a JSON object in the request body")
        return data

    @app.errorhandler(InputError)
    def _bad(e):
        return err(e.where, e.problem, 400)

    @app.errorhandler(EstimationError)
    def _fit(e):
        body, status = err(e.where, e.problem, 422)
        if getattr(e, "unconstrained", None) is not None:
            # a Solve refused for unconstrained unknowns: what would constrain each
            body = jsonify({"error": body.get_json()["error"], "unconstrained": e.unconstrained})
        return body, status

    @app.errorhandler(LookupError)
    def _missing(e):
        if str(e).strip("'\"") == "facade":
            return err("facade", "no Façade session; start with lumigraph view --facade "
                                 "blocks.json IMAGES... --edges edges.json", 404)
        return err("request", f"not found: {e}", 404)

    @app.errorhandler(404)
    def _not_found(e):
        if request.path.startswith("/api/"):
            return err(request.path, "no such route", 404)
        return e

    @app.errorhandler(Exception)
    def _fault(e):
        from werkzeug.exceptions import HTTPException

        if isinstance(e, HTTPException):
            return e
        app.logger.exception("internal fault")
        return err("internal fault", f"{type(e).__name__}: {e} (our bug: please report it)", 500)

    @app.get("/")
    def index():
        return send_from_directory(STATIC, "index.html")

    @app.get("/favicon.ico")
    def favicon():
        return Response(status=204)

    @app.get("/api/mode")
    def mode():
        return jsonify({"facade": app.config["LUMI_FACADE"] is not None,
                        "artifacts": len(app.config["LUMI_ARTIFACTS"])})

    @app.get("/api/facade/state")
    def state():
        return jsonify(session().state())

    @app.get("/api/facade/photo/<int:i>")
    def photo(i):
        return Response(session().png(i), mimetype="image/png")

    @app.get("/api/facade/detected/<int:i>")
    def detected(i):
        return jsonify({"segments": session().detected(i).tolist()})

    @app.post("/api/facade/marks")
    def add():
        d = body()
        snap = d.get("snap", True)
        return jsonify(session().add(d.get("photo"), d.get("segment"), edge=d.get("edge"),
                                     snap=bool(snap)))

    @app.post("/api/facade/marks/<mark_id>")
    def change(mark_id):
        d = body()
        s = session()
        if "segment" in d:
            s.move(mark_id, d["segment"])
        if "edge" in d or "segment" not in d:
            return jsonify(s.assign(mark_id, d.get("edge")))
        return jsonify(s.find(mark_id))

    @app.delete("/api/facade/marks/<mark_id>")
    def delete(mark_id):
        return jsonify(session().delete(mark_id))

    @app.post("/api/facade/solve")
    def solve():
        d = request.get_json(silent=True) or {}
        from lumigraph.view.marking import SOLVE_NOISE_PX

        noise = d.get("noise_px", SOLVE_NOISE_PX) if isinstance(d, dict) else SOLVE_NOISE_PX
        if not isinstance(noise, int | float) or isinstance(noise, bool):
            raise InputError("noise_px", f"expected a positive number of pixels, got {noise!r}")
        return jsonify(session().solve(noise_px=float(noise)))

    @app.post("/api/facade/resnap")
    def resnap():
        d = request.get_json(silent=True) or {}
        every = d.get("every", True) if isinstance(d, dict) else True
        if not isinstance(every, bool):
            raise InputError("every", f"expected true or false, got {every!r}")
        return jsonify(session().resnap(every=every))

    @app.post("/api/facade/propose")
    def propose():
        s = session()
        return jsonify({"proposals": s.propose(), "warnings": s.proposal_warnings})

    @app.post("/api/facade/proposals/<pid>/accept")
    def accept(pid):
        s = session()
        if pid == "all":
            return jsonify({"accepted": s.accept_all()})
        return jsonify(s.accept(pid))

    @app.post("/api/facade/proposals/<pid>/reject")
    def reject(pid):
        return jsonify(session().reject(pid))

    return app


def start_server(app, *, port: int | None = None, default: int | None = None, quiet: bool = True):
    """A threaded WSGI server for ``app`` bound to 127.0.0.1 only (not yet
    serving: call ``serve_forever``, in a thread for tests); ``server.port``
    is the port taken. ``port`` given and in use: :class:`InputError`
    (``port``); otherwise ``default`` is tried, then any free port."""
    import errno
    import logging
    import socket

    from werkzeug.serving import make_server

    if quiet:  # werkzeug logs every request; a user sees the URL line and errors only
        logging.getLogger("werkzeug").setLevel(logging.WARNING)
    tries = [port] if port is not None else ([default] if default else []) + [0]
    for k, p in enumerate(tries):
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # not over a live listener
        try:
            # bound here, not by werkzeug, which prints and exits on a port in use
            sock.bind(("127.0.0.1", int(p)))
            sock.listen(64)
        except OSError as e:
            sock.close()
            if k + 1 < len(tries):  # the default is taken: any free port
                continue
            if port is not None and e.errno in (errno.EADDRINUSE, errno.EACCES):
                raise InputError("port", f"port {port} on 127.0.0.1 is {_why(e)}; choose another, "
                                         "or leave out --port to take a free one") from None
            raise
        try:
            return make_server("127.0.0.1", sock.getsockname()[1], app, threaded=True,
                               fd=sock.fileno())
        finally:
            sock.close()  # the server holds its own duplicate
    raise AssertionError("unreachable")  # pragma: no cover


def _why(e: OSError) -> str:
    import errno

    return {errno.EADDRINUSE: "in use", errno.EACCES: "not allowed for this user"}.get(
        e.errno, e.strerror or str(e))
