#!/usr/bin/env bash
# Render the independent flash-photo validation set (validation/README.md) with a pinned
# Mitsuba 3 in validation/.venv (created on first use; nothing is written outside
# validation/ but the output folder). Arguments go to render_flash_photos.py:
#
#   validation/run.sh --count 48 --out flash-val     # photos + simulation.json
#   validation/run.sh --check                        # the truth's projection vs a render
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
VENV="$HERE/.venv"
STAMP="$VENV/.requirements.sha256"
WANT="$(sha256sum "$HERE/requirements.txt" | cut -d' ' -f1)"
if [[ ! -x "$VENV/bin/python" || ! -f "$STAMP" || "$(cat "$STAMP")" != "$WANT" ]]; then
    echo "validation: creating $VENV" >&2
    rm -rf "$VENV"
    python3 -m venv "$VENV"
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check -r "$HERE/requirements.txt"
    echo "$WANT" >"$STAMP"
fi
exec "$VENV/bin/python" "$HERE/render_flash_photos.py" "$@"
