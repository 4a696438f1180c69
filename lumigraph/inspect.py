"""``lumigraph inspect``: describe images, stacks and artifacts (shape, type, bit
depth, exposure, value range), optionally as JSON. Reads through the same
validating readers every stage uses, so it is also a quick check of an input."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lumigraph.capture.commandline import (
    input_path,
    make_parser,
    number,
    numbers,
    output_file,
    run,
)

EPILOG = """\
examples:
  lumigraph inspect out/bracket                       a folder with stack.json
  lumigraph inspect img-*.png --times 1/30,1/8,1/2 --need-times
  lumigraph inspect flow.flo disparity.pfm radiance.exr --out summary.json
  lumigraph inspect memorial.hdr                      Radiance RGBE
"""


def describe(path: Path) -> dict:
    """Summary of one file read through ``capture.io`` (Radiance RGBE through
    its one codec, ``lumigraph.capture.rgbe``)."""
    from lumigraph.capture import io

    ext = path.suffix.lower()
    fmt = None
    if ext in io.RGBE_EXTS:
        arr, fmt = io.read_image(path), "Radiance RGBE"
    elif ext == ".flo":
        arr = io.read_flo(path)
    elif ext == ".pfm":
        arr = io.read_pfm(path)  # disparity: unknown (NaN) is legitimate
    elif ext == ".ply":
        pts, cols = io.read_ply(path)
        return {"path": str(path), "kind": "points", "count": len(pts),
                "colors": cols is not None}
    else:
        arr = io.read_image(path)
    finite = arr[np.isfinite(arr)] if arr.dtype.kind == "f" else arr
    info = {"path": str(path), "shape": list(arr.shape), "dtype": str(arr.dtype),
            "min": float(finite.min()) if finite.size else None,
            "max": float(finite.max()) if finite.size else None,
            "unknown": int((~np.isfinite(arr)).sum()) if arr.dtype.kind == "f" else 0}
    if fmt is not None:
        info["format"] = fmt
    if ext == ".png" and arr.dtype == np.uint16:
        info["bit_depth"] = io.png_significant_bits(path) or 16
    if ext in {".jpg", ".jpeg", ".tif", ".tiff"}:
        e = io.read_exif(path)
        info["exif"] = {"exposure_time_s": e.exposure_time_s, "f_number": e.f_number, "iso": e.iso}
    return info


def _inspect(args) -> int:
    from lumigraph.capture import io
    from lumigraph.capture.artifact import make_meta, write_artifact

    paths = [Path(p) for p in args.inputs]
    times = list(args.times) if args.times else None
    is_stack = len(paths) > 1 or (len(paths) == 1 and (paths[0].is_dir() or paths[0].name == "stack.json"))
    if is_stack and all(p.suffix.lower() not in {".flo", ".ply"} | io.RGBE_EXTS for p in paths):
        st = io.read_stack(paths, times=times, need_times=args.need_times)
        summary = {"kind": "stack", "count": len(st.paths), "shape": list(st.images.shape[1:]),
                   "dtype": str(st.images.dtype), "bit_depth": st.bit_depth,
                   "exposure_times_s": st.exposure_times_s, "linear": st.linear,
                   "files": list(st.paths)}
    else:
        summary = {"kind": "files", "files": [describe(p) for p in paths]}
    if args.out:
        write_artifact(args.out, lambda tmp: tmp.write_text(__import__("json").dumps(summary, indent=2)),
                       meta=make_meta("lumigraph.inspect", inputs=paths))
    else:
        import json

        print(json.dumps(summary, indent=2))
    return 0


def build_parser(prog: str = "lumigraph inspect"):
    """The ``lumigraph inspect`` parser."""
    p = make_parser(prog, "Describe images, stacks and artifacts; validate inputs.", epilog=EPILOG)
    p.add_argument("inputs", nargs="+", type=input_path, help="files, or a folder with stack.json")
    # exposure times are positive (capture.exposure.check_exposure_times checks the rest)
    p.add_argument("--times", type=numbers(number(float, lo=0, lo_open=True), length=(1, None)),
                   help="exposure times in seconds, comma-separated (1/30 allowed)")
    p.add_argument("--need-times", action="store_true",
                   help="fail unless every image has an exposure time")
    p.add_argument("--out", type=output_file(".json"),
                   help="write the summary as JSON here (atomically) instead of stdout")
    p.set_defaults(func=_inspect)
    return p


def main(argv=None, prog="lumigraph inspect") -> int:
    return run(build_parser(prog), argv)
