"""Looking mode of ``lumigraph view``: a Flask blueprint serving every artifact kind.

Routes are listed in ``lumigraph.view``'s docstring. The artifact list comes
from ``current_app.config["LUMI_ARTIFACTS"]``.
"""

from __future__ import annotations

from flask import Blueprint, current_app, jsonify

blueprint = Blueprint("look", __name__)


@blueprint.get("/api/look/list")
def look_list():
    paths = current_app.config.get("LUMI_ARTIFACTS", [])
    return jsonify([{"id": str(i), "path": str(p), "kind": None} for i, p in enumerate(paths)])
