"""Make PyPI's torchvision usable beside the CPU build of torch (training venv only).

The only torchvision wheel offered for ``torch==2.13.0`` is built against the CUDA build of torch.
Beside the CPU build its C extension does not load, and ``import torchvision`` then fails with
``operator torchvision::nms does not exist`` (its meta registrations refer to that operator).
ultralytics needs torchvision only for ``torchvision.ops.nms`` (its validator imports torchvision and
then prefers torchvision's NMS).

:func:`register_torchvision_nms` defines the ``torchvision::nms`` operator with
:mod:`torch.library` (the documented way to add custom operators) and gives it a CPU kernel in plain
torch, **before** torchvision is imported, but only when torchvision's own extension cannot be
loaded. :func:`install_import_hook` does it lazily, the moment something imports torchvision, and
after torchvision's import lets its ``_has_ops()`` check pass (only ``nms``/``qnms`` exist; any other
torchvision C++ operator still fails with an error naming it). The training venv's ``.pth`` file
calls it (see ``scripts/train_detector.sh``).

Nothing here is imported by the controller or by CI (no torch there).
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys
from typing import Any

_LIB: Any = None  # keeps the torch.library.Library (and its registrations) alive
_HOOK_NAME = "lapwrench_torchvision_nms_hook"


def nms_reference(boxes: Any, scores: Any, iou_threshold: float) -> Any:
    """Greedy NMS in plain torch: indices of kept boxes (xyxy), best score first (int64)."""
    import torch

    if boxes.numel() == 0:
        return torch.empty(0, dtype=torch.int64, device=boxes.device)
    b = boxes.float()
    order = torch.argsort(scores.float(), descending=True, stable=True)
    b = b[order]
    x0, y0, x1, y1 = b.unbind(1)
    area = (x1 - x0).clamp(min=0) * (y1 - y0).clamp(min=0)
    ix0 = torch.maximum(x0[:, None], x0[None, :])
    iy0 = torch.maximum(y0[:, None], y0[None, :])
    ix1 = torch.minimum(x1[:, None], x1[None, :])
    iy1 = torch.minimum(y1[:, None], y1[None, :])
    inter = (ix1 - ix0).clamp(min=0) * (iy1 - iy0).clamp(min=0)
    iou = inter / (area[:, None] + area[None, :] - inter).clamp(min=1e-12)
    n = b.shape[0]
    suppressed = torch.zeros(n, dtype=torch.bool)
    over = (iou > iou_threshold).cpu()
    keep = []
    for i in range(n):
        if suppressed[i]:
            continue
        keep.append(i)
        suppressed |= over[i]
    return order[torch.tensor(keep, dtype=torch.int64, device=order.device)]


def _torchvision_extension_loads(locations: Any = None) -> bool:
    """Whether torchvision's compiled extension loads (then it defines its own operators)."""
    import glob
    import os

    import torch

    if locations is None:
        spec = importlib.machinery.PathFinder.find_spec("torchvision")
        if spec is None or not spec.submodule_search_locations:
            return False
        locations = spec.submodule_search_locations
    for loc in locations:
        for lib in glob.glob(os.path.join(loc, "_C*.so")):
            try:
                torch.ops.load_library(lib)
                return True
            except (OSError, RuntimeError):
                return False
    return False


def register_torchvision_nms(*, _locations: Any = None, _during_import: bool = False) -> bool:
    """Define ``torchvision::nms`` with a plain-torch CPU kernel unless torchvision provides it.

    Call before importing torchvision. Returns ``True`` when this module's kernel was registered,
    ``False`` when the operator already existed or torchvision's own extension loads.
    """
    global _LIB
    import torch

    if _LIB is not None:
        return True
    if hasattr(torch.ops.torchvision, "nms") or _torchvision_extension_loads(_locations):
        return False
    if "torchvision" in sys.modules and not _during_import:
        raise RuntimeError("register_torchvision_nms() must run before torchvision is imported")
    lib = torch.library.Library("torchvision", "DEF")
    for op in ("nms", "qnms"):  # torchvision's meta registrations refer to both
        lib.define(f"{op}(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
        lib.impl(op, nms_reference, "CPU")
    _LIB = lib
    return True


def _after_torchvision_import(module: Any) -> None:
    """torchvision checks ``extension._has_ops()`` (its C extension) before calling an operator;
    with our ``nms``/``qnms`` kernels registered, let that check pass. Any other torchvision C++
    operator (roi_align, deform_conv2d, ...) still fails, naming the missing operator."""
    if _LIB is not None and not module.extension._has_ops():
        module.extension._has_ops = lambda: True


def _remove_hook() -> None:
    sys.meta_path[:] = [f for f in sys.meta_path if getattr(f, "name", None) != _HOOK_NAME]


class _WrappedLoader(importlib.abc.Loader):
    """torchvision's own loader; registers the operators just before torchvision executes."""

    def __init__(self, inner: Any, locations: Any) -> None:
        self.inner = inner
        self.locations = locations

    def create_module(self, spec: Any) -> Any:
        return self.inner.create_module(spec)

    def exec_module(self, module: Any) -> None:
        _remove_hook()
        registered = register_torchvision_nms(_locations=self.locations, _during_import=True)
        self.inner.exec_module(module)
        if registered:
            _after_torchvision_import(module)


class _Hook(importlib.abc.MetaPathFinder):
    """Wraps torchvision's loader; finding the module (``importlib.util.find_spec``) has no side
    effect, only executing it (``import torchvision``) registers the operators."""

    name = _HOOK_NAME

    def find_spec(self, fullname: str, path: Any, target: Any = None) -> Any:
        if fullname != "torchvision":
            return None
        spec = importlib.machinery.PathFinder.find_spec(fullname, path)
        if spec is None or spec.loader is None:
            return None
        spec.loader = _WrappedLoader(spec.loader, spec.submodule_search_locations)
        return spec


def install_import_hook() -> None:
    """Register ``torchvision::nms`` lazily, when something first imports torchvision."""
    if "torchvision" in sys.modules or any(getattr(f, "name", None) == _HOOK_NAME for f in sys.meta_path):
        return
    sys.meta_path.insert(0, _Hook())
