#!/usr/bin/env bash
# Installs PyTorch CPU for the side-by-side benchmark into bench/pytorch/.venv (git-ignored),
# pinned by requirements.txt. Idempotent: does nothing when the venv already imports the
# pinned torch. Needs python3 (>= 3.10) with venv and access to PyPI; ~5.4 GB of disk.
#
#   bench/pytorch/setup.sh            # install or check
#   PYTHON=python3.11 bench/pytorch/setup.sh
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="$here/.venv"
python="${PYTHON:-python3}"
want="$(sed -n 's/^torch==//p' "$here/requirements.txt")"

if [[ -x "$venv/bin/python" ]] \
    && "$venv/bin/python" -c "import torch, sys; sys.exit(0 if torch.__version__.split('+')[0] == '$want' else 1)" 2>/dev/null; then
    echo "PyTorch $want already installed in $venv"
    exit 0
fi

"$python" -m venv "$venv"
# --no-cache-dir: the wheels are ~3 GB; a second copy in ~/.cache/pip is not wanted.
"$venv/bin/pip" install --no-cache-dir --disable-pip-version-check -q -r "$here/requirements.txt"
"$venv/bin/python" - <<'PY'
import torch
print(f"installed torch {torch.__version__}; CPU threads {torch.get_num_threads()}; "
      f"MKL {torch.backends.mkl.is_available()}; oneDNN {torch.backends.mkldnn.is_available()}")
x = torch.randn(64, 64, requires_grad=True)
(x @ x).sum().backward()
assert x.grad is not None and x.grad.shape == (64, 64)
PY
