"""``lumigraph view``: a local page to look at artifacts and to mark Façade edges.

Looking mode (``lumigraph.view.looking``, a Flask blueprint) serves, for each
artifact the page was opened on (``current_app.config["LUMI_ARTIFACTS"]``: a
list of paths; a folder stands for the artifacts inside it):

``GET /api/look/list``
    ``[{id, path, kind, error?}]``.
``GET /api/look/<id>``
    ``{kind, shape, units, controls: [{name, kind: slider|select, min, max,
    step, default, options}], meta: the .meta.json beside it or null,
    error: one line or null}``.
``GET /api/look/<id>/image?<controls>``
    the artifact drawn at those control values (PNG; JPEG for radiance maps
    and light fields, where an exposure or refocus drag must be quick).
``GET /api/look/<id>/probe?x=&y=&<controls>``
    the full-resolution value under the cursor, with its units.
``GET /api/look/<id>/geometry``
    PLY point clouds and Façade meshes: positions (+ colours, faces) as JSON
    for the page's small WebGL viewer.

An artifact that cannot be read answers ``{"error": "<path>: <problem>"}``
(the project's ``InputError`` text) and the server keeps serving. The kinds
and their readers are in ``lumigraph.view.artifacts`` (one reader per kind:
the project's own). Importing this package imports neither Flask nor any
stage; ``lumigraph.view.looking`` imports Flask.
"""
