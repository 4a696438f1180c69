"""Library errors name the function's argument, never a command-line flag
(ARCHITECTURE.md, "Validation once, in the library"): only a ``cli.py`` knows
its flags, and :func:`lumigraph.capture.commandline.run` maps an argument to
the flag that sets it."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# every library module of every stage; only the command line (a stage's cli.py
# or *_cli.py, and the CLI plumbing in capture/commandline.py) names flags
LIBRARY = ["capture", "calib", "stereo", "hdr", "lightfield", "separation"]
CLI = {"cli.py", "commandline.py"}
FLAG_ERROR = re.compile(
    r"""(InputError|EstimationError|ValueError|TypeError)\(\s*f?["']--""")


def _modules():
    for entry in LIBRARY:
        for f in sorted((ROOT / entry).rglob("*.py")):
            if f.name not in CLI and not f.name.endswith("_cli.py"):
                yield f


@pytest.mark.parametrize("module", list(_modules()), ids=lambda p: str(p.relative_to(ROOT)))
def test_library_errors_name_arguments_not_flags(module):
    hits = [f"{module.relative_to(ROOT)}:{n}: {line.strip()}"
            for n, line in enumerate(module.read_text().splitlines(), 1) if FLAG_ERROR.search(line)]
    assert not hits, "library errors must name the argument, not the flag:\n" + "\n".join(hits)


def test_calib_errors_name_arguments_and_the_cli_maps_them():
    from lumigraph.calib.calibrate import calibrate_stereo
    from lumigraph.calib.detect import BoardSpec
    from lumigraph.capture.errors import InputError

    with pytest.raises(InputError, match="^board: cannot parse"):
        BoardSpec.parse("chess:10x7")
    with pytest.raises(InputError, match="^right: expected as many right images"):
        calibrate_stereo([None], [])
