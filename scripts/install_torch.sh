#!/usr/bin/env bash
# Install the pinned CPU build of torch into a venv before the package's learning extras (an
# unpinned torch from the public index is the CUDA build: gigabytes of nvidia-* wheels).
#   scripts/install_torch.sh VENV_PYTHON EXTRAS
# Does nothing unless EXTRAS (comma-separated, as in `make setup EXTRAS=...`) holds all or
# learn. Uses PyTorch's own CPU wheel index (TORCH_CPU_INDEX) when it answers within 5 s;
# otherwise the configured package index (say, a local mirror that holds a CPU build), and
# says so.
set -euo pipefail
python="$1"
extras=",$2,"
version="${TORCH_VERSION:-2.13.0}"
index="${TORCH_CPU_INDEX:-https://download.pytorch.org/whl/cpu}"
case "$extras" in
  *,all,*|*,learn,*) ;;
  *) echo "torch: not needed for extras ${2} (learning baselines only)"; exit 0 ;;
esac
if "$python" -c "import torch, sys; sys.exit(0 if torch.__version__.split('+')[0] == '$version' else 1)" 2>/dev/null; then
  echo "torch $version: already installed"
  exit 0
fi
if "$python" - "$index" <<'PY' 2>/dev/null
import sys, urllib.request
urllib.request.urlopen(sys.argv[1] + "/torch/", timeout=5)
PY
then
  echo "torch $version: the CPU build from $index"
  "$python" -m pip install --progress-bar on "torch==$version" --index-url "$index"
else
  echo "torch $version: $index does not answer; from the configured package index (check that it is a CPU build: pip show torch)"
  "$python" -m pip install --progress-bar on "torch==$version"
fi
