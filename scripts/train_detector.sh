#!/usr/bin/env bash
# Train the instrument detector on the synthetic dataset, on the CPU, and export ONNX.
#
# Optional extra, never run in CI. It uses its own venv (.venv-train) so that torch and
# ultralytics never enter the project's main environment.
#
#   scripts/train_detector.sh setup                 # create .venv-train only
#   scripts/train_detector.sh dataset [ARGS...]     # lapwrench.perception.cli dataset ARGS
#   scripts/train_detector.sh train [ARGS...]       # lapwrench.perception.cli train ARGS
#   scripts/train_detector.sh check                 # import check (torch CPU, torchvision nms)
#
# Training runs under `nice -n 15` so other work on the machine keeps a core.
#
# torch: exactly 2.13.0, the CPU build pip takes from this machine's disk; constraints-train.txt
# pins it for every later install so that ultralytics cannot swap it for a CUDA build.
# torchvision: the only wheel offered for torch 2.13.0 is a CUDA build whose C extension does not
# load beside CPU torch ("operator torchvision::nms does not exist"). lapwrench.perception.torch_compat
# defines torchvision::nms with torch.library (CPU kernel) before torchvision is imported; train_main
# does this itself, and a .pth hook installed here does it for any other process of the venv.
#
# Offline: YOLO_OFFLINE=1, a project-local YOLO_CONFIG_DIR (.yolo-config) holding a local TTF as
# Arial.ttf / Arial.Unicode.ttf, settings sync=False; models are built from yaml, no hub downloads.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
VENV="$ROOT/.venv-train"
PY="$VENV/bin/python"
export MUJOCO_GL="${MUJOCO_GL:-egl}"
export YOLO_OFFLINE=1
export YOLO_CONFIG_DIR="$ROOT/.yolo-config"
export PIP_CONSTRAINT="$ROOT/constraints-train.txt"

setup() {
    if [[ ! -x "$PY" ]]; then
        python3.11 -m venv "$VENV"
    fi
    # 1. CPU torch from local disk (pinned; pip never resolves a CUDA build with the constraint).
    "$PY" -m pip install --quiet -c constraints-train.txt "torch==2.13.0"
    # 2. ultralytics and the matching torchvision, torch held at 2.13.0 by the constraints.
    "$PY" -m pip install --quiet -c constraints-train.txt "ultralytics>=8.3" "torchvision==0.28.0" onnx onnxslim
    # 3. the project itself (editable).
    "$PY" -m pip install --quiet -c constraints-train.txt -e .
    # torchvision::nms before torchvision loads, in every process of this venv.
    local site
    site=$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
    echo "import lapwrench.perception.torch_compat as _t; _t.install_import_hook()" > "$site/lapwrench_torchvision_nms.pth"
    # Offline ultralytics settings and fonts.
    mkdir -p "$YOLO_CONFIG_DIR/Ultralytics"
    local ttf
    ttf=$(fc-match -f '%{file}' sans 2>/dev/null || true)
    [[ -f "$ttf" ]] || ttf=$(find /usr/share/fonts -name '*.ttf' | head -n1)
    for dir in "$YOLO_CONFIG_DIR" "$YOLO_CONFIG_DIR/Ultralytics"; do
        cp -f "$ttf" "$dir/Arial.ttf"
        cp -f "$ttf" "$dir/Arial.Unicode.ttf"
    done
    "$VENV/bin/yolo" settings sync=False >/dev/null
    check
}

check() {
    "$PY" - <<'PY'
import torch
assert torch.__version__.startswith("2.13.0"), torch.__version__
assert not torch.cuda.is_available() and "+cpu" in torch.__version__, f"not the CPU build: {torch.__version__}"
import torchvision, torchvision.ops
b = torch.tensor([[0, 0, 10, 10], [1, 1, 11, 11], [50, 50, 60, 60]], dtype=torch.float32)
keep = torchvision.ops.nms(b, torch.tensor([0.9, 0.8, 0.7]), 0.5).tolist()
assert keep == [0, 2], keep
import ultralytics
from ultralytics.utils.nms import TorchNMS  # ultralytics' own NMS, the reference
g = torch.Generator().manual_seed(0)
for n in (0, 7, 500, 3000):
    xy = torch.rand(n, 2, generator=g) * 300
    bx = torch.cat([xy, xy + torch.rand(n, 2, generator=g) * 60 + 2], 1)
    sc = torch.rand(n, generator=g)
    assert torch.equal(torchvision.ops.nms(bx, sc, 0.5), TorchNMS.nms(bx, sc, 0.5)), n
print(f"torch {torch.__version__}, torchvision {torchvision.__version__} (nms ok), ultralytics {ultralytics.__version__}")
PY
}

cmd="${1:-train}"
shift || true
case "$cmd" in
    setup) setup ;;
    check) check ;;
    dataset|train)
        [[ -x "$PY" ]] || setup
        exec nice -n 15 "$PY" -m lapwrench.perception.cli "$cmd" "$@"
        ;;
    *) echo "usage: $0 {setup|check|dataset|train} [ARGS...]" >&2; exit 2 ;;
esac
