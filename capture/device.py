"""Where the dense stages run: numpy/OpenCV on the CPU, or one torch code path.

Every dense library call that has a torch port takes ``device=`` with one of

``"cpu"``
    today's numpy/OpenCV code (the fastest on a CPU; the default);
``"cuda"``
    the torch/kornia port on the first CUDA GPU;
``"torch-cpu"``
    the same torch/kornia port on torch's CPU device: it is how the port is
    checked on machines without a GPU (CI) and compared with ``"cpu"``;
``"auto"``
    ``"cuda"`` when torch is installed and sees a GPU, else ``"cpu"``.

torch and kornia are an optional extra (``pip install 'lumigraph[gpu]'``) and
are imported only here, inside :func:`torch_modules`, so a plain install never
loads them. Asking for a torch device without the extra is bad input (exit 2,
one line naming the extra), not an internal fault.

>>> resolve_device("cpu")
Device(name='cpu', torch=None)
>>> resolve_device("auto").name in ("cpu", "cuda")
True
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass

from lumigraph.capture.errors import InputError

DEVICES = ("cpu", "cuda", "torch-cpu", "auto")

DEVICE_HELP = (
    "where the dense work runs: cpu = numpy/OpenCV (default, fastest without a GPU); "
    "cuda = the torch/kornia port on the GPU; torch-cpu = the same port on torch's CPU "
    "device (to check it); auto = cuda when torch sees a GPU, else cpu. cuda and "
    "torch-cpu need the optional extra: pip install 'lumigraph[gpu]'"
)

_EXTRA = "pip install 'lumigraph[gpu]'"


@dataclass(frozen=True)
class Device:
    """A resolved device: ``name`` is ``"cpu"``, ``"cuda"`` or ``"torch-cpu"``;
    ``torch`` is the torch device string (``"cuda"``/``"cpu"``) for the torch
    path, ``None`` for the numpy path."""

    name: str
    torch: str | None

    @property
    def uses_torch(self) -> bool:
        return self.torch is not None


def torch_available() -> bool:
    """True when torch and kornia can be imported (without importing them)."""
    return all(importlib.util.find_spec(m) is not None for m in ("torch", "kornia"))


def torch_modules(*, where: str = "device"):
    """Import and return ``(torch, kornia)``; InputError naming the extra when
    either is missing."""
    try:
        import kornia
        import torch
    except ImportError as e:
        raise InputError(where, f"the torch path needs torch and kornia ({e.name} is not "
                                f"installed): {_EXTRA}, or use device 'cpu'") from None
    return torch, kornia


def resolve_device(device: str | Device = "cpu", *, where: str = "device") -> Device:
    """Turn a ``device`` argument into a :class:`Device`; InputError for an
    unknown name, for ``"cuda"`` without a visible GPU, or for a torch device
    without the ``gpu`` extra."""
    if isinstance(device, Device):
        return device
    if device not in DEVICES:
        raise InputError(where, f"unknown device {device!r}; choose one of {', '.join(DEVICES)}")
    if device == "cpu":
        return Device("cpu", None)
    if device == "auto":
        if not torch_available():
            return Device("cpu", None)
        torch, _ = torch_modules(where=where)
        return Device("cuda", "cuda") if torch.cuda.is_available() else Device("cpu", None)
    torch, _ = torch_modules(where=where)
    if device == "cuda":
        if not torch.cuda.is_available():
            raise InputError(where, "device 'cuda' asked but torch sees no CUDA GPU "
                                    f"(torch {torch.__version__}); use 'cpu' or 'auto'")
        return Device("cuda", "cuda")
    return Device("torch-cpu", "cpu")


def add_device_option(parser) -> None:
    """``--device {cpu,cuda,torch-cpu,auto}`` on a command's parser."""
    parser.add_argument("--device", choices=DEVICES, default="cpu", help=DEVICE_HELP)


def to_torch(array, device: Device, *, dtype=None):
    """numpy array → contiguous torch tensor on ``device`` (float32 unless
    ``dtype`` says otherwise)."""
    torch, _ = torch_modules()
    import numpy as np

    a = np.ascontiguousarray(array)
    t = torch.from_numpy(a)
    if dtype is None and t.is_floating_point():
        dtype = torch.float32
    if dtype is not None:
        t = t.to(dtype)
    return t.to(device.torch)


def to_numpy(tensor):
    """torch tensor → numpy array on the host."""
    return tensor.detach().to("cpu").numpy()
