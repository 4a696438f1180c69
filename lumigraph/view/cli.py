"""``lumigraph view``: a local web page to look at artifacts and to mark
Façade edges (issue 18). Parses, opens the inputs, starts the server on
127.0.0.1 and prints its URL; the work is in :mod:`lumigraph.view.app`
(the routes), :mod:`lumigraph.view.looking` and :mod:`lumigraph.view.marking`.
"""

from __future__ import annotations

import sys

from lumigraph.capture.commandline import (
    input_path,
    make_parser,
    number,
    output_file,
    run,
    say,
)
from lumigraph.capture.errors import InputError

DESCRIPTION = """\
A local web page (http://127.0.0.1:PORT/, nothing listens on other addresses;
no network needed: every asset ships with lumigraph) to look at artifacts and
to mark the edges of a Façade block model on its photographs."""

EPILOG = """\
looking mode:
  lumigraph view out/radiance.exr out/flow.flo       each file with its controls
  lumigraph view out/                                every artifact in a folder
  (EXR/HDR/LogLuv radiance with an exposure slider, light fields with refocus,
  .flo and disparity PFM in colour with the value under the cursor, response.json
  curves, PLY and Façade meshes in 3-D; each artifact's .meta.json beside it)

marking mode (Façade, 'lumigraph stereo facade solve --help' for the files):
  lumigraph view --facade blocks.json photo_00.png photo_01.png ... --edges edges.json
  lumigraph view --facade scene/ --edges scene/my_edges.json
                   (a folder with stack.json, blocks.json and camera.json)
  In the page: wheel to zoom, drag with the middle button (or Shift+drag) to pan,
  drag to draw a segment (it snaps to a detected line when one is near, unless
  "snap" is unticked; the status line says how far it moved and how far the
  image's edge scatters about it (a weak or broken edge: the Solve counts it
  for less), and "Keep as drawn" undoes a snap that left the line you
  traced), click
  an edge in the list (or its reprojection) to assign the selected segment,
  Delete to remove it. "Solve" fits the model and overlays the reprojected
  edges and each mark's residual (px), lists the weakly constrained
  parameters with the edges to mark for them (click one to go to it), and
  up to three hand marks to check: those farthest from where the other
  marks put their edges, 2σ or more (click one to select it; a snap may
  have taken a line beside the model's edge); "mark noise" (default 0.5 px,
  what snapped marks achieve) is how far off its edge a mark may be: the
  Solve leaves out a mark more than 5x that off;
  "Propose" runs automatic marking (mark about four edges per photograph
  first), each proposal then accepted or rejected; "Re-snap to model", after
  a Solve, moves each mark onto the image step near its reprojected edge.
  A good order: four marks per photograph, Propose, accept, Solve, mark what
  the weak list names, then twice Re-snap, Propose, Solve; last, redraw with
  "snap" unticked each listed mark that is off its edge, and Solve. Every
  change is saved at once to --edges (atomically: the file is always
  complete); an existing --edges file is read first.

A port in use: with --port, exit 2; without it, another free port is taken.
--check opens every input as the page would and exits (0, or 2 with the
reason) without serving."""

DEFAULT_PORT = 8765


def build_parser(prog: str = "lumigraph view"):
    """The ``lumigraph view`` parser."""
    p = make_parser(prog, DESCRIPTION, epilog=EPILOG)
    p.add_argument("paths", nargs="*", type=input_path, metavar="FILES|FOLDER",
                   help="artifacts to look at (files, or folders of them)")
    p.add_argument("--port", type=number(int, lo=1, hi=65535),
                   help=f"the port to listen on (default {DEFAULT_PORT}, or any free one if "
                        "that is taken)")
    p.add_argument("--facade", nargs="+", action="extend", type=input_path, metavar="PATH",
                   help="marking mode: blocks.json and the photographs (or a folder with "
                        "stack.json, blocks.json, camera.json)")
    p.add_argument("--edges", type=output_file(".json"),
                   help="marking mode: the edges.json the marks are saved to (read first when "
                        "it exists)")
    p.add_argument("--camera", type=input_path,
                   help="marking mode: the photographs' camera.json (default: beside blocks.json)")
    p.add_argument("--no-browser", action="store_true", help="do not open a web browser")
    p.add_argument("--check", action="store_true",
                   help="open every input as the page would, then exit without serving")
    p.set_defaults(func=_view, arg_flags={"blocks": "--facade", "images": "--facade",
                                          "edges": "--edges", "camera": "--camera"})
    return p


def _view(args) -> int:
    from lumigraph.view.app import create_app, start_server

    session = None
    if args.facade:
        if not args.edges:
            raise InputError("edges", "marking mode saves the marks to a file: give --edges "
                                      "edges.json (an existing one is read first)")
        from lumigraph.view.marking import FacadeSession

        session = FacadeSession.open(args.facade[0], args.facade[1:], edges=args.edges,
                                     camera=args.camera)
    elif args.edges or args.camera:
        raise InputError("facade", "--edges and --camera belong to marking mode: give --facade "
                                   "blocks.json IMAGES...")
    if args.check:
        from lumigraph.view import artifacts

        found = artifacts.expand(args.paths)
        for path in found:
            artifacts.load(path)
        said = [f"{len(found)} artifact(s) readable"] if args.paths else []
        if session is not None:
            said.append(f"Façade session: {len(session.photos)} photographs, "
                        f"{len(session.marks)} marks")
        say(args, "; ".join(said) or "nothing to open")
        return 0
    app = create_app(artifacts=args.paths, facade=session)
    server = start_server(app, port=args.port, default=DEFAULT_PORT, quiet=not args.debug)
    url = f"http://127.0.0.1:{server.port}/"
    print(f"lumigraph view: {url}  (Ctrl-C to stop)", flush=True)
    if not args.no_browser:
        import threading
        import webbrowser

        threading.Timer(0.3, webbrowser.open, (url,)).start()
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        print("lumigraph view: stopped", file=sys.stdout, flush=True)
    finally:
        server.server_close()
    return 0


def main(argv=None, prog="lumigraph view") -> int:
    return run(build_parser(prog), argv)


if __name__ == "__main__":
    raise SystemExit(main())
