#!/usr/bin/env bash
# Build a separate venv with NVIDIA Newton 1.8 and this project, then check that Newton's USD
# importer (ModelBuilder.add_usd) finds each warptissue scene's soft body with the right
# tetrahedra, E, nu and density.
#
#   scripts/tools/newton_import_check.sh            # venv in .venv-newton (ignored by git)
#   NEWTON_VENV=/tmp/nv scripts/tools/newton_import_check.sh
#
# Newton 1.8 needs usd-core < 26.9; warptissue accepts usd-core >= 25.5, < 27, so both
# co-install. Newton's own dependency is only warp-lang; its USD importer needs usd-core and
# newton-usd-schemas (the "importers" extra also pulls mesh tools this check does not use).
set -euo pipefail
cd "$(dirname "$0")/../.."
venv="${NEWTON_VENV:-.venv-newton}"
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
    "$venv/bin/python" -m pip install -q --upgrade pip
    "$venv/bin/python" -m pip install -q 'newton>=1.8,<1.9' 'usd-core>=25.5,<26.9' \
        'newton-usd-schemas>=0.6' -e .
fi
status=0
"$venv/bin/python" scripts/tools/newton_import_check.py 2>/dev/null | tail -n 1 || status=1
for scene in scenes/*.usda; do
    case "$scene" in *.asset.usda) continue ;; esac
    "$venv/bin/python" scripts/tools/newton_import_check.py --scene "$scene" 2>/dev/null | tail -n 1 \
        || status=1
done
exit "$status"
