"""torchvision::nms registered with torch.library beside CPU torch (training venv only; CI skips).

Each check runs in a fresh interpreter: importing torch here would leak into the other tests
(which check that ``lapwrench.perception`` alone never imports torch).
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys

import pytest

if importlib.util.find_spec("torch") is None:
    pytest.skip("torch lives in the training venv only", allow_module_level=True)


def run(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=180)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip().splitlines()[-1]


def test_reference_nms_matches_a_brute_force_greedy_nms() -> None:
    code = """
import torch
from lapwrench.perception.torch_compat import nms_reference
g = torch.Generator().manual_seed(1)
xy = torch.rand(200, 2, generator=g) * 200
boxes = torch.cat([xy, xy + torch.rand(200, 2, generator=g) * 40 + 1], 1)
scores = torch.rand(200, generator=g)
keep = nms_reference(boxes, scores, 0.5).tolist()
def iou(b, c):
    iw = max(0.0, min(b[2], c[2]) - max(b[0], c[0])); ih = max(0.0, min(b[3], c[3]) - max(b[1], c[1]))
    inter = iw * ih
    return inter / ((b[2] - b[0]) * (b[3] - b[1]) + (c[2] - c[0]) * (c[3] - c[1]) - inter)
bl = boxes.tolist(); expect = []
for i in torch.argsort(scores, descending=True).tolist():
    if all(iou(bl[i], bl[j]) <= 0.5 for j in expect):
        expect.append(i)
assert nms_reference(torch.zeros((0, 4)), torch.zeros(0), 0.5).numel() == 0
print(keep == expect)
"""
    assert run(code) == "True"


def test_torchvision_imports_and_its_nms_works() -> None:
    if importlib.util.find_spec("torchvision") is None:
        pytest.skip("torchvision not installed")
    code = """
import lapwrench.perception.torch_compat as t; t.install_import_hook()
import torch, torchvision
b = torch.tensor([[0., 0, 10, 10], [1, 1, 11, 11], [50, 50, 60, 60]])
print(torchvision.ops.nms(b, torch.tensor([0.9, 0.8, 0.7]), 0.5).tolist())
"""
    assert run(code) == "[0, 2]"
